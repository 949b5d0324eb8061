"""Cars idling in their parking space in an FCD replay: parked, their parking over, their
way back onto the road blocked — booked standing there, as the live run books them
(:mod:`sumo_drvpw.sim.parking`).

SUMO (``MSVehicleTransfer::checkInsertions``) tries each step from a parking's end on to
put the car back on its lane; while that fails it keeps the car in its space *idling*,
engine on, blinker on (towards the road), and its emission output writes every such step
at speed 0 on the parking lane. Its FCD writes the car as it writes a parked one: beside
the lane (:class:`~sumo_drvpw.sim.fcd_conn.ParkedTest`), at speed 0. The replay tells the
idling rows of a parked car:

- by the FCD's ``signals`` (``--fcd-output.signals``), where it has them: a parked row
  with a blinker bit (1 | 2) on idles (SUMO sets it only when the car fails to re-enter);
- else by the declared stop it parked at (:mod:`sumo_drvpw.sim.fcd_stops`: the route
  files' stop matched where it stands, its arrival its first parked row, as SUMO parks a
  car in the step it reaches its stop): a parked row at time t idles once t + Δ ≥ the
  stop's planned end, the later of arrival + ``duration`` and ``until`` (Δ the recording's
  step length: SUMO 1.28 counts the stop's duration down from its arrival step and ends
  it, and first fails to re-insert, in the step before; at 0.5 and 1 s steps, for
  ``duration``, ``until`` and both, the emission output's first idling step is that row).
  A stop *triggered* by a person (``triggered="person"``/``"true"``, all of its
  ``expected`` persons when it names them) waits, parked and not idling, until she
  boards: it ends at the later of her boarding and its planned end. SUMO's FCD writes a
  riding person at her vehicle's x, y and speed (:class:`~sumo_drvpw.sim.fcd_conn._Rows`
  tells the riders so): the car idles from the row in which a person not riding in it as
  it came (its row before the one it parks in: one waiting there boards in that very step)
  (all the expected ones) rides in it, or from its planned end's row when that
  is later (SUMO 1.28: boarding at 30 and 60 s, 20 s parked from 22 s, and without a
  ``duration``: the emission output's first idling step is that row). A stop waiting for a
  container or a joining train (``container``, ``join``, ``containerTriggered``), or with
  an ``extension``, the replay does not tell: its rows are left out as parked (and a
  person-triggered one in an FCD without x, y, whose riders are not matched). So are
  those of a parked car whose stop the files do not hold (added by TraCI, a rerouter, a
  parking reroute) or whose ``until`` the replay cannot shift.

A car switched off for its stop (planned longer than its vType's
``shutOffStopDuration``: :mod:`sumo_drvpw.sim.shutoff`) stays off while it idles (SUMO
1.28 writes it at 0) and is not booked, with or without signals (a stop the files do not
hold: not switched off, as the replay books such a stop standing); nor is the row before
the one it drives off in, where SUMO put it back on its lane a step before its stop ends,
still switched off (written at 0; ``_Rows._vehicles``); another car is booked there,
standing on its lane (:func:`~sumo_drvpw.sim.fcd_conn._unpark`). ``summary.json`` ``source.idling_rows`` counts the rows booked
idling (``parked_rows`` no longer counts them); ``source.untold_parked_rows`` and
``untold_parked_vehicles`` the parked rows without signals whose idling the replay cannot
tell (their stop not declared, or its end not known), booked parked and warned of.
"""

from __future__ import annotations

from itertools import repeat

import numpy as np

from sumo_drvpw.sim.shutoff import planned_duration_s

#: vehicle signal bits: blinker right (1) and left (2); SUMO switches on the one towards
#: the road while a parked car waits to re-enter it (TraCI's getSignals, FCD's ``signals``)
BLINKERS = 1 | 2
#: tolerance of the replay's times [s] (FCD times are written to at most 6 decimals)
TIME_EPS_S = 1e-6


class Idling:
    """Which parked rows of a replay's timesteps idle (see the module docstring).

    ``stops``: the replay's :class:`~sumo_drvpw.sim.fcd_stops.StopTracker` (None: the files
    declare no stop); ``limit``: vType → its ``shutOffStopDuration`` [s]; ``step_s``: the
    step length of the run that recorded the FCD [s]. Per parked vehicle it keeps the time
    from which its rows idle (∞: not told, a triggered stop or one without a planned end)
    and whether it is switched off for its stop, until it is back on the lane or leaves."""

    def __init__(self, stops, limit, step_s: float):
        self.stops, self.limit, self.step_s = stops, limit, float(step_s)
        self.idle_from: dict[str, float] = {}  # parked vehicle id → FCD time it idles from [s]
        self.shut: set[str] = set()            # parked vehicles switched off for their stop
        #: parked vehicle id → (its riders at its arrival, the persons it waits for (none:
        #: any), its planned end [s] or −∞) while a person-triggered stop waits for one
        self.waiting: dict[str, tuple] = {}
        #: parked rows without signals whose idling the replay cannot tell (no declared stop
        #: matched, or one without a planned end it knows): booked parked, and their vehicles
        self.untold_rows = 0
        self.untold_ids: set[str] = set()

    def _parked(self, vid: str, vtype: str, stop, riders: dict) -> None:
        """Vehicle ``vid`` of ``vtype`` just parked at its declared ``stop`` (fcd_stops);
        ``riders``: vehicle id → the persons riding in it as it came (its row before: one who
        boards in the step it parks, waiting there, ends a person-triggered stop at once)."""
        ends = [x for x, given in ((stop.arrival + stop.duration, stop.duration >= 0),
                                   (stop.until, stop.until >= 0)) if given]
        # an until the replay cannot shift (NaN): its end not known; a triggered stop ends
        # when its trigger comes: a person boarding, which the FCD's riders tell
        known, trig = stop.until == stop.until, stop.trigger
        self.idle_from[vid] = np.inf
        self.waiting.pop(vid, None)
        if known and trig is not None and trig[0] == "person":
            self.waiting[vid] = (set(riders.get(vid, ())), set(trig[1]), max(ends) if ends else -np.inf)
        elif known and ends and trig is None:
            # SUMO ends it, and first fails to re-insert the car, in the step before its end
            self.idle_from[vid] = max(ends) - self.step_s - TIME_EPS_S
        if planned_duration_s(stop) > self.limit(vtype):
            self.shut.add(vid)  # switched off for its stop: off while it idles
        else:
            self.shut.discard(vid)

    def forget(self, vids) -> None:
        """Vehicles that left the replay, or are back on the lane."""
        for v in vids:
            self.idle_from.pop(v, None)
            self.shut.discard(v)
            self.waiting.pop(v, None)

    def rows(self, t: float, ids, types, off, signals=None, riders=None, entering=None,
             riders_before=None, boardings: bool = True) -> np.ndarray:
        """Timestep ``t`` [s] (the FCD's time): which of its rows (ids, vTypes, ``off``:
        parked, :class:`~sumo_drvpw.sim.fcd_conn.ParkedTest`; ``signals``: the FCD's, NaN
        or None where it has none; ``riders``: vehicle id → the persons riding in it;
        ``entering``: the rows a vehicle parks in, booked driven, never untold;
        ``riders_before``: the riders of the timestep before, default ``riders``;
        ``boardings``: False where the FCD cannot match persons to vehicles — no x, y —, so
        a person-triggered stop's end is untold) idle
        in their parking space; call it for every timestep, in order, after the stop
        tracker's step."""
        riders = riders or {}
        for vid, j, stop in (self.stops.parking if self.stops is not None else ()):
            self._parked(vid, types[j], stop, riders if riders_before is None else riders_before)
        for vid, (before, expected, end) in list(self.waiting.items()):
            now = set(riders.get(vid, ()))
            if (expected <= now) if expected else bool(now - before):  # boarded: the stop
                del self.waiting[vid]  # ends then, or at its planned end when that is later
                self.idle_from[vid] = max(t, end - self.step_s) - TIME_EPS_S
        ids = np.asarray(ids, object)
        idle = np.zeros(len(ids), bool)
        if self.idle_from:  # back on the lane: parked again elsewhere, at no declared stop
            get = self.idle_from.get
            self.forget([v for v in ids[~off] if get(v) is not None])
        k = np.flatnonzero(off)
        if not len(k):
            return idle
        vk = ids[k]
        frm = (np.fromiter(map(self.idle_from.get, vk, repeat(np.inf)), float, len(k))
               if self.idle_from else np.full(len(k), np.inf))
        idle[k] = t >= frm
        has = np.zeros(len(k), bool)
        if signals is not None:  # the FCD's blinker says it, where it has signals
            sk = np.asarray(signals, float)[k]
            has = ~np.isnan(sk)
            idle[k[has]] = (sk[has].astype(np.int64) & BLINKERS) != 0
        untold = ~has & ~np.isfinite(frm)
        if entering is not None:
            untold &= ~entering[k]
        if untold.any() and self.waiting and boardings:  # a person-triggered stop ends when she boards
            untold &= ~np.fromiter(map(self.waiting.__contains__, vk), bool, len(k))
        if untold.any():
            self.untold_rows += int(np.count_nonzero(untold))
            self.untold_ids.update(vk[untold])
        if self.shut and idle.any():
            j = np.flatnonzero(idle)
            idle[j[np.fromiter(map(self.shut.__contains__, ids[j]), bool, len(j))]] = False
        return idle


def untold_warning(fcd_file, rows: int, vehicles: int) -> str:
    """One line for a replay of ``fcd_file`` whose parked rows without signals it could not
    tell idling or not (:attr:`Idling.untold_rows`)."""
    return (f"FCD file {fcd_file}: {rows} parked FCD rows of {vehicles} vehicle(s), at stops the route files "
            "do not hold (a taxi device's, a parking reroute's, a script's) or whose end the replay cannot "
            "tell (one waiting for a container or a joining train; without x, y for a person), carry no signals: "
            "all are booked parked, "
            "so a car SUMO kept idling in its space, its way out blocked, books nothing there (record the FCD "
            "with SUMO's option fcd-output.signals, whose blinker says it)")
