"""Engine off at long planned stops, as SUMO's own emission models switch it off.

SUMO treats a vehicle at a planned stop whose duration is longer than its vType's
parameter ``shutOffStopDuration`` (default 300 s) as switched off from the stop's start
(``EnergyParams::isOff``; the electric models too since SUMO 1.24): a delivery van
unloading for ten minutes or a bus laying over at its terminus. Such a vehicle is not
booked while it stands there, as a parked one is not: no auxiliary power, no idle fuel,
no standing time. The step in which it comes to rest at the stop is booked as usual;
booking resumes in the step the stop ends, from standstill — after a ``parking`` stop too
(in a bus bay, beside the lane, in a parkingArea): SUMO puts the vehicle back on its lane
a step before its stop ends and writes it at 0 there, still switched off (SUMO 1.28,
probed 2026-11-27: tests/test_parking_exit_blocked.py; sim/parking.py keeps one parked
off the lane out of the booking for that step itself — it is no stop of this class, whose
``vehicle_s`` does not count it, as an FCD replay does not — and leaves one dwelling in a
bus bay to this class until its stop ends). A vType
keeps its engine on at every stop with a large ``shutOffStopDuration``.

The planned duration is the stop's ``duration``, or until its ``until`` when that is
later (TraCI's StopData, read once when the stop starts).

A start-stop system: a vType's ``shutOffAutoDuration`` (SUMO's default: never) switches
the engine off once the vehicle has stood longer than that (SUMO's waiting time,
``EnergyParams::isEngineOff``): from then until it moves, its fuel chains book no fuel.
SUMO's MMPEVEM does not read ``shutOffStopDuration`` (1.28: a car on it draws at any stop),
so its vTypes are never switched off at a stop. SUMO's electric models do not switch off in traffic (``isOff`` reads the planned stop
only), and neither do battery chains here: the auxiliaries of a car halted in traffic keep
running. (The standing time counts from the last step the vehicle moved, as SUMO's
waiting time, but also at a planned stop shorter than ``shutOffStopDuration``, where SUMO
does not count it.)

An FCD replay (:mod:`sumo_drvpw.sim.fcd`) switches vehicles off by the same rules, with
what the run's files say in place of SUMO: the vTypes' ``shutOffStopDuration`` and
``shutOffAutoDuration`` from ``<param>`` children of the route files' vTypes
(:mod:`sumo_drvpw.sim.vtypes`; a value that is no number is SUMO's default, as SUMO 1.28
reads it, warning "Invalid conversion from string to double"), the standing time from the FCD's speeds (as live: start-stop
fuel equal to the live run's, tests/test_sim_fcd_shutoff.py); and, as an FCD holds no
stops, the stops the route files declare for each vehicle, matched to where it stands
(:mod:`sumo_drvpw.sim.fcd_stops`, which answers SUMO's stop getters for the replay). Stops
the files do not hold — added while the run ran (TraCI, rerouters, taxis, parking
reroutes), or of a vehicle whose route is drawn from a ``routeDistribution`` — are booked
standing there; ``summary.json`` ``shut_off_at_long_stops.replay`` counts them.
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.model.constants import STANDSTILL_MPS
from sumo_drvpw.model.mmpevem import is_mmpevem_class

#: SUMO's default ``shutOffStopDuration`` [s] (EnergyParams.cpp, DEFAULT_VEH_SHUT_OFF_STOP)
SHUT_OFF_STOP_S = 300.0
#: the vType params of SUMO's emission models that switch a vehicle off (EnergyParams.cpp:
#: SUMO_ATTR_SHUT_OFF_STOP, SUMO_ATTR_SHUT_OFF_AUTO)
STOP_PARAM, AUTO_PARAM = "shutOffStopDuration", "shutOffAutoDuration"
SHUT_OFF_PARAMS = (STOP_PARAM, AUTO_PARAM)


def planned_duration_s(stop) -> float:
    """Planned duration of a stop that has just started [s]: ``duration``, or the time to
    ``until`` from its arrival when that is longer; −1 when neither is set."""
    d = float(getattr(stop, "duration", -1.0))
    until, arrival = float(getattr(stop, "until", -1.0)), float(getattr(stop, "arrival", -1.0))
    if until >= 0 and arrival >= 0:
        d = max(d, until - arrival)
    return d


class ShutOff:
    """Which vehicles stand switched off at a long planned stop (see the module docstring).

    :meth:`step` is called once per booked step, before the vehicles are read: a vehicle
    whose long stop has started is switched off (not read, not booked:
    ``Ledger.veh_parked``) from the step after the one in which it came to rest; a stop
    that ended in this step switches it on again.
    """

    def __init__(self, conn):
        sim = conn.simulation
        self.conn = conn
        self.starting = getattr(sim, "getStopStartingVehiclesIDList", None)
        self.ending = getattr(sim, "getStopEndingVehiclesIDList", None)
        self.available = (self.starting is not None and self.ending is not None
                          and hasattr(conn.vehicle, "getStops") and hasattr(conn, "vehicletype")
                          and hasattr(conn.vehicletype, "getParameter"))
        #: an FCD replay (sim/fcd_conn.py): its stops are the route files' (sim/fcd_stops.py)
        self.replay = bool(getattr(conn, "is_replay", False))
        self.limit_s: dict[str, float] = {}   # vType → its shutOffStopDuration [s]
        self.auto_s: dict[str, float] = {}    # vType → its shutOffAutoDuration [s]
        self.any_auto = False                 # a vehicle of a vType with a finite one
        self.auto_vehicle_s = 0.0             # time engines stood switched off in traffic [s]
        self.off: set[str] = set()
        self.waiting: set[str] = set()        # at a long stop, not yet at rest
        self.pending: list[str] = []          # came to rest at a long stop in the last step
        self.stops = 0                        # stops at which a vehicle was switched off
        self.vehicle_s = 0.0                  # time vehicles stood switched off [s]

    def _param(self, cache: dict, vtype: str, key: str, default: float) -> float:
        lim = cache.get(vtype)
        if lim is None:
            raw = self.conn.vehicletype.getParameter(vtype, key)
            try:
                lim = float(raw) if raw not in ("", None) else default
            except ValueError:  # SUMO itself refuses a vType whose value is no number
                lim = default
            cache[vtype] = lim
        return lim

    def limit_of(self, vtype: str) -> float:
        """The vType's ``shutOffStopDuration`` [s]; none (∞) for a vType on SUMO's MMPEVEM, which
        does not read it (SUMO 1.28 writes such a car's power standing at any stop: constant
        power and the holding torque; tests/test_mmpevem_shutoff.py)."""
        if vtype not in self.limit_s:
            get = getattr(self.conn.vehicletype, "getEmissionClass", None)
            if get is not None and is_mmpevem_class(str(get(vtype)) or None):
                self.limit_s[vtype] = np.inf
        return self._param(self.limit_s, vtype, STOP_PARAM, SHUT_OFF_STOP_S)

    def registered(self, ledger, i: int, vtype: str, vid: str) -> None:
        """A vehicle just registered in slot ``i``: its vType's ``shutOffAutoDuration``; an
        id used again starts with nothing of its earlier trip's stops."""
        self.arrived((vid,))
        lim = self._param(self.auto_s, vtype, AUTO_PARAM, np.inf)
        ledger.veh_auto_off[i] = lim
        self.any_auto |= bool(np.isfinite(lim))

    def auto_off(self, ledger, vidx, v, dt: float):
        """Engines a start-stop system has switched off in this step: (n,) bool over
        ``vidx``, or None when none is (and no vType of the run has one)."""
        if not self.any_auto:
            return None
        stand = np.where(np.asarray(v) < STANDSTILL_MPS, ledger.veh_stand[vidx] + dt, 0.0)
        ledger.veh_stand[vidx] = stand
        off = stand > ledger.veh_auto_off[vidx]
        n = int(np.count_nonzero(off))
        self.auto_vehicle_s += n * dt
        return off if n else None

    def step(self, stepper, ids) -> None:
        """Switch off the vehicles that came to rest at a long stop in the last step; switch
        on those whose stop ended in this one. ``ids``: the vehicles in the simulation (one
        a script removed between steps is in no arrived list: it is forgotten here)."""
        ledger, vmap, conn = stepper.ledger, stepper.vmap, self.conn
        if self.pending or self.off or self.waiting:
            present = set(ids)
            self.arrived([v for v in (*self.pending, *self.off, *self.waiting) if v not in present])
        self.vehicle_s += len(self.off) * stepper.dt
        if self.off:  # (a vehicle booked again by other means is no longer off)
            self.off = {v for v in self.off if v not in vmap or ledger.veh_parked[vmap[v]]}
        for vid in self.pending:
            i = vmap.get(vid)
            if i is None or not ledger.veh_keep[i] or ledger.veh_parked[i] or ledger.veh_done[i]:
                continue
            ledger.veh_parked[i] = True
            stepper.parking.forget(vid)
            self.off.add(vid)
            self.stops += 1
            stepper.prev_ids = None  # the selection of vehicles read changes
        self.pending = []
        for vid in self.ending():
            self.waiting.discard(vid)
            if vid in self.off:
                self.off.discard(vid)
                i = vmap.get(vid)
                if i is not None and ledger.veh_parked[i]:
                    ledger.veh_parked[i] = False
                    ledger.veh_lane[i] = -2          # read its lane and position again
                    ledger.veh_prev_speed[i] = 0.0   # from standstill
                    ledger.veh_at[i, 2] = np.nan
                    stepper.prev_ids = None
        for vid in self.starting():
            i = vmap.get(vid)
            if i is None or not ledger.veh_keep[i]:
                continue
            stops = conn.vehicle.getStops(vid, 1)
            if stops and planned_duration_s(stops[0]) > self.limit_of(ledger.veh_type[i]):
                self.waiting.add(vid)
        # off from the step after the one in which it came to rest (that one is booked: a
        # stop can start while the vehicle still creeps, and its last kinetic energy counts)
        for vid in [v for v in self.waiting if float(conn.vehicle.getSpeed(v)) == 0.0]:
            self.waiting.discard(vid)
            self.pending.append(vid)

    def arrived(self, vids) -> None:
        """Vehicles that left the simulation (arrived, or removed by a script): nothing of
        their stops is kept (an id added again is a new trip)."""
        gone = set(vids)
        self.off -= gone
        self.waiting -= gone
        self.pending = [v for v in self.pending if v not in gone]

    def summary(self) -> dict:
        return {"stops": self.stops, "vehicle_s": self.vehicle_s,
                "rule": "a planned stop longer than its vType's shutOffStopDuration (default "
                        f"{SHUT_OFF_STOP_S:g} s) switches the vehicle off from its start, as SUMO's "
                        "emission models do: not booked while it stands there (no auxiliary power, "
                        "no idle fuel)",
                "start_stop_vehicle_s": self.auto_vehicle_s,
                "start_stop_rule": "a vType's shutOffAutoDuration: its engine off once it has stood longer, "
                                   "no fuel until it moves (battery chains keep their auxiliaries)",
                **({"replay": self.replay_summary()} if self.replay else {})}

    def replay_summary(self) -> dict:
        """What an FCD replay knows of the stops and params (sim/fcd_stops.py)."""
        stops = getattr(self.conn, "stops", None)
        out = stops.report() if stops is not None else {"vehicles_with_declared_stops": 0}
        out["rule"] = (
            "an FCD holds no stops: the long stops are those the route files declare for the vehicle "
            "(lane, edge, busStop, containerStop, chargingStation, parkingArea; duration, until), matched "
            "where it stands at most 0.1 m/s fast, in their order, ending when it drives off or at the "
            "planned end; stops added while the run ran (TraCI, rerouters, taxis), those of a vehicle whose "
            "route is drawn from a routeDistribution or repeats, and a stop made long only by an until the "
            "replay cannot shift (a named route's stop of a vehicle with a random or no depart time) are "
            "booked standing; the shut-off params are the route files' vTypes' (a vType made by TraCI has "
            "none)")
        return out
