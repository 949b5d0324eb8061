"""What an FCD replay warns of about the file itself: vehicle rows on lanes the network
lacks, no angles for an equation with radial drag, a recording of part of the run (a share
of the vehicles, part of the network), person rows that cannot be matched to vehicles,
vehicle rows without x, y (parking told only by the route files' stops), route or
additional files the recording names that are gone (their vTypes unknown), rows written
less often than the run stepped (the speed changes between them unseen, measured; the route
files' vehicles in no row counted)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError


def sparse_rows(head: dict | None) -> tuple[float, float] | None:
    """(step length, device.fcd.period) [s] of an XML FCD's header when its rows were written
    less often than its run stepped, else None."""
    try:
        step = float((head or {}).get("step-length", 1.0))
        period = float((head or {}).get("device.fcd.period", 0.0) or 0.0)
    except ValueError:
        return None
    return (step, period) if head is not None and step > 0 and period > step + 1e-9 else None


class KineticGain:
    """The kinetic energy per kg [J/kg] the vehicles of an FCD gain from each row to the next
    (½·max(0, v² − v_prev²)) and from each row to the one after next, and the number of
    such intervals: how much of the speed changes the rows' interval hides, measured on the
    file itself (rows taken two at a time hide more; :meth:`doubled_loss`)."""

    def __init__(self):
        self.last = pd.Series(dtype=float)  # vehicle id → ½v² of its last row
        self.last2 = pd.Series(dtype=float)  # … of the row before
        self.gain = np.zeros(2)
        self.n = np.zeros(2)

    def add(self, ids, speed) -> None:
        """One timestep's vehicles (ids, speeds [m/s]); a vehicle missing from a timestep
        starts again (a teleport, an arrival)."""
        e = pd.Series(0.5 * np.square(np.asarray(speed, float)), index=pd.Index(ids, dtype=object))
        p1, p2 = self.last.reindex(e.index), self.last2.reindex(e.index)
        for k, p in enumerate((p1, p2)):
            d = (e - p).to_numpy()
            ok = ~np.isnan(d)
            self.gain[k] += float(np.maximum(d[ok], 0.0).sum())
            self.n[k] += int(np.count_nonzero(ok))
        self.last, self.last2 = e, p1

    def doubled_loss(self) -> float | None:
        """The share of the kinetic energy gained per row interval lost when the rows are
        taken two at a time (1 − (gain per 2-row interval / 2) / gain per interval); None
        without intervals or gain."""
        if self.n[1] == 0 or self.gain[0] <= 0:
            return None
        return float(1.0 - (self.gain[1] / self.n[1] / 2.0) / (self.gain[0] / self.n[0]))


def unseen_vehicles(declared, head: dict | None, begin_s, end_s, keep=None) -> tuple[dict, str | None]:
    """The vehicles the route files (``declared``: :class:`~sumo_drvpw.sim.fcd_stops.
    DeclaredStops`) declare to depart from ``begin_s`` to ``end_s`` [s] (None: open), id →
    depart, for a replay of rows sparser than the steps to take out as they appear in a row
    (:func:`missed_count`; ``keep``: a Dask task's mask function of the ids it books); ({}, why)
    where their ids cannot be those of the FCD: no route file read, a run that scaled its
    demand (SUMO's ``scale``: other ids, fewer or more vehicles), an FCD of a share of the
    vehicles or of part of the network."""
    head = head or {}
    try:
        scale = float(head.get("scale", 1.0))
        share = float(head.get("device.fcd.probability", 1.0))
    except ValueError:
        scale = share = np.nan
    why = ("no route file read" if not (declared.departs or declared.flow_departs or declared.random_flows)
           else f"its run scaled the demand (scale {head.get('scale')})" if scale != 1.0
           else "it records a share of the vehicles" if share != 1.0
           else "it records part of the network" if any(head.get(k) for k in (
               "fcd-output.filter-edges.input-file", "fcd-output.filter-shapes")) else None)
    if why:
        return {}, why
    out = declared.departing(-np.inf if begin_s is None else begin_s, np.inf if end_s is None else end_s)
    if keep is not None and out:
        ids = np.array(list(out), dtype=object)
        out = {v: out[v] for v in ids[keep(ids)].tolist()}
    return out, None


def missed_count(unseen: dict, why: str | None, t0: float, t1: float, random_flows: int) -> tuple:
    """(vehicles of ``unseen`` (id → declared depart [s], those of :func:`unseen_vehicles` no
    row showed) declared to depart from the first replayed row ``t0`` to ``t1`` (the replay
    books to its last row + Δt: ``t1`` that less one step of the run, the last departure SUMO
    could insert — a vehicle that departed after the last row is in none either), or None; ``why`` they cannot be counted (None: they can), t0, t1, ``random_flows``: flows
    whose departures are random): what :func:`missed_vehicles` says, added up over Dask tasks
    by :func:`merge_missed`."""
    if why is not None:
        return None, why, t0, t1, random_flows
    return sum(1 for d in unseen.values() if t0 - 1e-9 <= d <= t1 + 1e-9), None, t0, t1, random_flows


def merge_missed(parts: list) -> tuple:
    """:func:`missed_count` of the vehicles of all Dask tasks from each one's."""
    why = next((p[1] for p in parts if p[1] is not None), None)
    n = None if why is not None else sum(p[0] for p in parts)
    return n, why, min(p[2] for p in parts), max(p[3] for p in parts), parts[0][4]


def missed_vehicles(n: int | None, why: str | None, t0: float, t1: float, random_flows: int) -> str:
    """What a replay of sparse rows says of the vehicles in none of its rows
    (:func:`missed_count`): ``n`` of those the route files declare to depart from ``t0`` to
    ``t1`` [s], or why they cannot be counted, and the flows of random departures."""
    if why is not None:
        return (f"; a vehicle whose whole trip fell between two rows is in none and is not booked (how many "
                f"cannot be told: {why})")
    rnd = (f"; {random_flows} flow{'s' if random_flows > 1 else ''} of random departures not counted"
           if random_flows else "")
    return (f"; {n} vehicle{'s' if n != 1 else ''} the route files declare to depart from {t0:g} to {t1:g} s "
            f"{'are' if n != 1 else 'is'} in no row and not booked (a trip that began and ended between two rows or "
            f"after the last, or one SUMO had not inserted by then: at most so many trips lost){rnd}")


def sparse_warning(fcd_file, sparse: tuple[float, float] | None, lost: float | None, missed=None) -> list[str]:
    """What a replay of rows written every ``sparse`` = (step, period) says: the speed
    changes between rows are not booked, and how much the file itself shows of them
    (``lost``: :meth:`KineticGain.doubled_loss`); ``missed``: what it says of the vehicles
    in no row (:func:`missed_count`; None: not told)."""
    if sparse is None:
        return []
    missed = missed_vehicles(*missed) if missed is not None else ""
    step, period = sparse
    told = ("" if lost is None else
            f"; its rows taken two at a time gain {max(lost, 0.0):.0%} less kinetic energy than taken one at a time, "
            f"and its {period:g}-s rows miss at least about as much of what the run gained at every {step:g}-s "
            "step (the first rows left out hide the most)")
    return [f"FCD {Path(fcd_file).name}: written every {period:g} s of a run stepping {step:g} s (its header): "
            "each vehicle is booked from the sampled trajectory, its speed changes between the rows unseen, so the "
            f"acceleration term, the traction and the battery or fuel are booked low{told}{missed} (record the FCD at every "
            "step, without device.fcd.period, to book what the run booked)"]


def missing_input_warnings(fcd_file, scenario=None, vtype_files=None) -> tuple[list[str], list[str]]:
    """Where a replay takes its vTypes from the files of the run that recorded ``fcd_file``
    (no ``scenario``, no ``vtype_files``: :func:`sumo_drvpw.sim.fcd_read.run_inputs`, its
    header's, else those of the SUMO config that writes it): a warning for the route and
    additional files named there and found nowhere — the vTypes defined there are unknown,
    their vehicles booked as passenger cars, SUMO's default vClass, at a car's mass — and
    those files as written ([], [] when none is missing or the files are given)."""
    if scenario is not None or vtype_files is not None:
        return [], []
    from sumo_drvpw.sim.fcd_read import run_inputs

    rec = run_inputs(fcd_file) or {"missing": []}
    gone = [v for k, v in rec["missing"] if k != "net-file"]  # (no network: refused before)
    if not gone:
        return [], []
    src = f"the SUMO config {rec['config'].name} that writes the FCD" if "config" in rec else "the FCD's header"
    return ([f"{src} names {', '.join(gone)}, not found beside the FCD {fcd_file} (looked in "
             f"{', '.join(str(p) for p in rec['looked_in'])}): the vTypes defined there are unknown, their "
             "vehicles booked as passenger cars (SUMO's default vClass) at a car's mass; give the run's route and "
             "additional files for its vTypes"], gone)


def unplaced_person_warning(fcd_file, rows: int) -> str:
    """What a replay whose person rows carry no x, y (or whose vehicle rows do not) says:
    riders are matched by place and speed (sim/fcd_conn)."""
    return (f"FCD file {fcd_file}: {rows} person rows without x, y (fcd-output.attributes without them): "
            "riding persons cannot be matched to their vehicles, whose riders' mass is not booked")


def unplaced_vehicle_warning(fcd_file, rows: int, told: int, stops_read: bool) -> str:
    """What a replay whose vehicle rows carry no x, y (``rows`` of them) says: SUMO's FCD
    shows a parked vehicle beside its lane, and without x, y only the route files' parking
    stops tell it (``told`` rows; ``stops_read``: the files declare any stop)."""
    how = (f"only where one stands at a parking stop the route files declare (parking=\"true\", a parkingArea, a "
           f"stop waiting for a person or container; {told} rows told so)" if stops_read
           else "nowhere: no route file declares a stop")
    return (f"FCD file {fcd_file}: {rows} vehicle rows without x, y (fcd-output.attributes without them): a "
            f"parked vehicle is told {how}; one parked elsewhere (at a stop added while the run ran) is booked "
            "standing there, with its auxiliary power and idle fuel, where the live run books it parked")


def partial_warnings(fcd_file, head: dict | None) -> list[str]:
    """What an FCD that records only part of the run says (its header's options): a share of
    the vehicles (``device.fcd.probability`` < 1), or of the network (``fcd-output.filter-edges
    .input-file``, ``fcd-output.filter-shapes``): the totals are that part's."""
    head = head or {}
    out = []
    try:
        share = float(head.get("device.fcd.probability", 1.0))
    except ValueError:
        share = 1.0
    if share < 1.0:
        out.append(f"FCD file {fcd_file} records a share of the vehicles (device.fcd.probability {share:g}): "
                   "the totals are those vehicles', not the run's")
    where = [k for k in ("fcd-output.filter-edges.input-file", "fcd-output.filter-shapes") if head.get(k)]
    if where:
        out.append(f"FCD file {fcd_file} records part of the network ({', '.join(f'{k} {head[k]}' for k in where)}): "
                   "the vehicles are booked there only")
    return out


def no_angle_warning(fcd_file) -> str:
    """What a replay of an FCD without angles, for an equation with the factor ``radial``, says."""
    return (f"FCD file {fcd_file} has no angle column (fcd-output.attributes without angle): the radial "
            "drag in curves (the factor radial, SUMO's radialDragCoefficient) is booked as 0")


def lane_warnings(fcd_file, net_file, unknown: int, known: int, first) -> list[str]:
    """What a replay's vehicle rows on lanes the network lacks (``unknown`` of them;
    ``known`` on its lanes; ``first``: the first one's (lane, time)) call for: a UserError
    when none is on one of its lanes (the FCD of another network), else a warning (the
    rows are not booked, as the live loop books no vehicle without a lane)."""
    if not unknown:
        return []
    lane, t = first
    if not known:
        raise UserError(f"FCD {fcd_file}: none of its vehicles' lanes is in the network "
                        f"{net_file} (the first: lane {lane!r} at t = {t:g} s): recorded on "
                        "another network?")
    return [f"{unknown} FCD row{'s' if unknown > 1 else ''} of vehicles on lanes the network {Path(net_file).name} lacks "
            f"{'were' if unknown > 1 else 'was'} not booked (the first: lane {lane!r} at t = {t:g} s); recorded on another "
            "version of the network?"]
