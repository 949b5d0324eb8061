"""Book a finished simulation from SUMO's FCD output, through the same ledger as ``run``.

``process_fcd(fcd_file, net=..., scenario=..., out_dir=...) -> RunResult`` reads an FCD
file (``--fcd-output``: XML, ``.xml.gz``, or SUMO's Parquet/CSV tabular output) and replays
it step by step to the same :class:`~sumo_drvpw.sim.loop.Stepper` the live loop uses, with
a connection object that answers the getters from the file. So masses, vClasses, equations,
slopes, wind and outputs are exactly those of ``run``; only what FCD lacks differs:

- speeds are as precise as the file (XML: ``--precision``, default 2 decimals; Parquet:
  float32); run SUMO with ``--precision 6`` for energies equal to the live run's;
- acceleration is (v_t − v_t−1)/Δt from the file's speeds (SUMO's own definition), or the
  file's ``acceleration`` column with ``sumo.acceleration = "getter"`` (needs
  ``--fcd-output.acceleration``);
- lane and position are read for every vehicle-step (no tracking);
- vTypes' masses and vClasses come from the scenario's route/additional files (``--vtypes``
  or ``[sumo]`` of the scenario); without them every vType is a ``passenger`` car with the
  class's default mass (listed in ``summary.json`` ``assumptions``);
- persons (``<person>``; in SUMO's tabular FCD rows without a lane) are not vehicles: they
  are counted in ``skipped`` as the live loop counts them, and a person whose x, y and
  speed equal a vehicle's rides in it, adding its vType's mass (route files; else SUMO's
  70 kg) as in the live loop (``summary.json`` ``source.riding_person_rows``);
- a parked vehicle (SUMO writes it with its lane, at speed 0, at the parking space's x, y)
  is told from a standing one by its x, y beside the lane (:class:`ParkedTest`) and, as in
  the live loop, not booked (``summary.json`` ``source.parked_rows``); FCD without x, y
  (``--fcd-output.attributes`` without them, or ``.geo``/``.utm`` coordinates) books it
  as standing.

Bounded memory (#14): the file is read in blocks of ``chunk_rows`` rows
(:mod:`sumo_drvpw.sim.fcd_read`: XML iterparse, Parquet record batches, CSV chunks) and
replayed timestep by timestep (:class:`FcdStream`; a timestep cut by a block boundary is
joined first), so memory holds one block plus the running vehicles whatever the file's
length; the ledger writes finished vehicles out (:mod:`sumo_drvpw.sim.spill`). A vehicle
arrives the step after a timestep without it (SUMO's FCD does not tell an arrival from a
teleport: a vehicle back after a gap books on in its row, its acceleration starting at 0,
or in a second row once flushed). ``chunk_rows=None`` reads the whole file first
(:class:`FcdReplay`: the reference the streamed replay equals exactly on gap-free FCD).
The rows must be in time order (SUMO writes them so). Split by vehicle on Dask:
:mod:`sumo_drvpw.sim.fcd_dask`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.fcd_read import (CHUNK_ROWS, FCD_COLUMNS, fcd_parts,  # noqa: F401
                                     iter_fcd_blocks, read_fcd)


class _Sim:
    def __init__(self, r):
        self.r = r

    def getTime(self):  # noqa: N802 (SUMO's names)
        return self.r.t

    def getDeltaT(self):  # noqa: N802
        return self.r.dt

    def getMinExpectedNumber(self):  # noqa: N802
        return self.r.remaining()

    def getDepartedIDList(self):  # noqa: N802
        return self.r.departed

    def getArrivedIDList(self):  # noqa: N802
        return self.r.arrived

    def getStopEndingVehiclesIDList(self):  # noqa: N802 (here: the vehicles whose riders changed)
        return self.r.load_changed

    def getDepartedPersonIDList(self):  # noqa: N802
        return self.r.departed_persons if self.r.count_persons else ()


class _Person:
    def __init__(self, r):
        self.r = r

    def getIDCount(self):  # noqa: N802
        return self.r.person_count

    def getTypeID(self, pid):  # noqa: N802
        return self.r.person_types[pid]


class _Veh:
    def __init__(self, r):
        self.r = r

    def getIDList(self):  # noqa: N802
        return self.r.ids

    def getTypeID(self, vid):  # noqa: N802
        return self.r.types[vid]

    def getPersonIDList(self, vid):  # noqa: N802 (persons at the vehicle's x, y and speed)
        return self.r.riders.get(vid, ())

    def _col(self, k):
        return lambda vid: self.r.state[vid][k]

    def __getattr__(self, name):
        k = {"getSpeed": 0, "getAcceleration": 1, "getAngle": 2, "getLaneID": 3,
             "getLanePosition": 4, "getSlope": 5}.get(name)
        if k is None:
            raise AttributeError(name)
        return self._col(k)


class _VType:
    def __init__(self, r):
        self.r = r

    def getVehicleClass(self, vt):  # noqa: N802 (not in FCD: the route files say)
        return ""

    def getParameter(self, vt, key):  # noqa: N802
        return ""

    def getMass(self, vt):  # noqa: N802 (a person type's: the route files', else SUMO's 70 kg)
        return self.r.type_mass.get(vt, DEFAULT_PERSON_MASS_KG)


#: SUMO's default mass of a person's vType [kg] (libsumo vehicletype.getMass of a
#: pedestrian type without a mass)
DEFAULT_PERSON_MASS_KG = 70.0


class _Rows:
    """What the FCD replays share: a timestep's rows → the vehicles' columns, with parked
    vehicles off their lane (:func:`_unpark`) and the persons riding in each vehicle. SUMO's
    FCD writes riding persons at their vehicle's x, y and speed, without naming the vehicle:
    a person whose x, y and speed equal one vehicle's rides in it (as the live loop reads
    with vehicle.getPersonIDList; their vTypes' masses from the route files)."""

    def _init_rows(self):
        self.parked_rows = 0
        self.riders: dict = {}
        self.person_types: dict = {}
        self.person_count = 0
        self.departed_persons: tuple = ()
        self.load_changed: tuple = ()
        self.rider_rows = 0
        #: vType → mass [kg] of the route files (set by replay_fcd)
        self.type_mass: dict = {}
        self.count_persons = True
        self.person, self.vehicletype = _Person(self), _VType(self)

    def _vehicles(self, c: dict, nxt: dict | None) -> dict:
        """The vehicles' rows of timestep ``c`` (next timestep ``nxt``, None at the end)."""
        person = c.get("person")
        if person is not None and person.any():
            veh = ~person
            self._ride({k: v[person] for k, v in c.items()}, {k: v[veh] for k, v in c.items()})
            c = {k: v[veh] for k, v in c.items()}
        elif self.riders or self.person_count:
            self._ride(None, c)
        if "off" in c and len(c["id"]):  # parked vehicles (ParkedTest.mark)
            if nxt is not None and "person" in nxt and nxt["person"].any():
                keep = ~nxt["person"]
                nxt = {"id": nxt["id"][keep], "off": nxt["off"][keep]}
            lanes, n = _unpark(c["lane"], c["id"], c["off"], nxt["id"] if nxt else None,
                               nxt["off"] if nxt else None)
            c = dict(c, lane=lanes)
            self.parked_rows += n
        return c

    def _ride(self, p: dict | None, v: dict) -> None:
        """Riders per vehicle from the persons' rows ``p`` and the vehicles' rows ``v``."""
        riders: dict = {}
        if p is not None:
            self.person_count = len(p["id"])
            new = [q for q in p["id"] if q not in self.person_types]
            self.person_types.update(zip(p["id"], p["type"]))
            self.departed_persons = tuple(new)
            if "x" in p and "y" in p and len(v["id"]):
                at = dict(zip(zip(v["x"], v["y"], v["speed"]), v["id"]))
                for q, key in zip(p["id"], zip(p["x"], p["y"], p["speed"])):
                    vid = at.get(key)
                    if vid is not None:
                        riders.setdefault(vid, []).append(q)
        else:
            self.person_count, self.departed_persons = 0, ()
        old = self.riders
        # persons board and leave while the vehicle stands; the live loop reads its riders
        # when the stop ends (as it drives off): a standing vehicle keeps the riders it had
        # (SUMO lets them leave as the vehicle creeps into the stop, braked with them aboard)
        from sumo_drvpw.model.constants import STANDSTILL_MPS

        for vid, speed in zip(v["id"], v["speed"]):
            if speed < STANDSTILL_MPS:
                if vid in old:
                    riders[vid] = old[vid]
                else:
                    riders.pop(vid, None)
        self.load_changed = tuple(vid for vid in set(old) | set(riders)
                                  if old.get(vid) != riders.get(vid))
        self.riders = riders
        self.rider_rows += sum(len(r) for r in riders.values())


class ParkedTest:
    """Which FCD rows show a parked vehicle: standing (below ``STANDSTILL_MPS``) beside its
    lane (:func:`~sumo_drvpw.sim.network.off_lane`). SUMO's FCD writes a parked vehicle
    with its lane, at speed 0, at the parking space's x, y; libsumo gives it no lane, and
    the live loop books nothing for it (engine off; SUMO's emission output leaves it out
    too). Applied once per block of rows (:meth:`mark`), not per timestep."""

    def __init__(self, net):
        self.net = net

    def __call__(self, cols: dict) -> np.ndarray:
        """Rows (``speed``, ``lane``, ``pos``, ``x``, ``y``) → off their lane, standing."""
        from sumo_drvpw.model.constants import STANDSTILL_MPS
        from sumo_drvpw.sim.network import off_lane

        off = np.asarray(cols["speed"], float) < STANDSTILL_MPS
        if "x" not in cols or "y" not in cols:
            return np.zeros(len(off), bool)
        k = np.flatnonzero(off)  # only a standing vehicle can be parked
        if len(k):
            codes, uniq = pd.factorize(np.asarray(cols["lane"], object)[k])
            idx = self.net.lane_index
            lane = np.array([idx.get(u, -1) for u in uniq], np.int64)[codes]
            off[k] = off_lane(self.net, lane, np.asarray(cols["pos"], float)[k],
                              np.asarray(cols["x"], float)[k], np.asarray(cols["y"], float)[k])
        return off

    def mark(self, blocks):
        """The blocks (:func:`iter_fcd_blocks`) with a column ``off``: this test's rows."""
        for b in blocks:
            b.cols["off"] = self(b.cols)
            yield b


def _unpark(lanes, ids, off, nxt_ids, nxt_off) -> tuple[np.ndarray, int]:
    """The lanes of a timestep's rows with "" for the parked vehicles, and their number:
    off the lane (``off``) and still off it in the next timestep (``nxt_*``; None: none).
    libsumo's getLaneID reads "" from the step a vehicle parks to the one before it drives
    off; in the step it leaves it is on its lane again, where FCD still shows it at the
    parking space."""
    if not off.any():
        return lanes, 0
    off = off.copy()
    if nxt_ids is not None and len(nxt_ids):
        back = set(np.asarray(nxt_ids, object)[~nxt_off])
        off &= ~np.fromiter((v in back for v in ids), bool, len(ids))
    lanes = np.array(lanes, dtype=object)
    lanes[off] = ""
    return lanes, int(np.count_nonzero(off))


class FcdReplay(_Rows):
    """A connection whose ``simulationStep`` moves to the next FCD timestep and whose
    getters answer from the file (the subset of the libsumo API the Stepper uses)."""

    def __init__(self, df: pd.DataFrame, dt: float | None = None):
        times = np.asarray(df.attrs.get("times", np.zeros(0)), float)
        if len(times) == 0:
            times = np.unique(df["time"].to_numpy())
        self.times = times
        if dt is None:
            d = np.diff(times)
            d = d[d > 1e-9]
            if len(d) == 0:
                raise UserError("FCD file: fewer than two timesteps, cannot tell the step length")
            dt = float(np.round(np.min(d), 6))
        self.dt = float(dt)
        t = df["time"].to_numpy()
        starts = np.searchsorted(t, times, side="left")
        ends = np.searchsorted(t, times, side="right")
        self._rows = list(zip(starts, ends))
        n = len(df)
        self._all = {k: df[k].to_numpy() for k in df.columns}
        if "person" not in self._all:
            self._all["person"] = np.zeros(n, bool)
        person = self._all["person"].astype(bool)
        self._all["person"] = person
        self._init_rows()
        veh = df[~person]
        self.types = dict(zip(veh["id"], veh["type"]))
        self.k = 0
        # FCD time t is the state after SUMO executed step t; a live loop reads that state
        # after simulationStep() with getTime() = t + Δt: the replay labels steps alike
        self.t = float(times[0]) if len(times) else 0.0
        self.ids: tuple = ()
        self.state: dict = {}
        self.departed: tuple = ()
        self.arrived: tuple = ()
        self._seen: set = set()
        # a vehicle arrives (leaves the ledger's memory) the step after its last row
        step = np.searchsorted(times, t[~person])
        last = (pd.Series(step).groupby(veh["id"].to_numpy()).max() if len(veh)
                else pd.Series(dtype=int))
        self._leaving = {int(k): tuple(g.index) for k, g in last.groupby(last)}
        self.simulation, self.vehicle = _Sim(self), _Veh(self)

    def remaining(self) -> int:
        return len(self.times) - self.k

    def simulationStep(self, time=0.0):  # noqa: N802
        a, b = self._rows[self.k]
        self.t = float(self.times[self.k]) + self.dt
        self.k += 1
        c, d = self._rows[self.k] if self.k < len(self._rows) else (b, b)
        nxt = {k: v[c:d] for k, v in self._all.items()} if d > c else None
        cols = self._vehicles({k: v[a:b] for k, v in self._all.items()}, nxt)
        ids = tuple(cols["id"])
        self.ids = ids
        self.state = dict(zip(ids, zip(*_state_columns(cols)))) if ids else {}
        new = tuple(v for v in ids if v not in self._seen)
        self._seen.update(new)
        self.departed = new
        self.arrived = self._leaving.get(self.k - 2, ())

    def close(self):
        pass


def _state_columns(c: dict) -> list:
    """The getters' columns in the order of ``_Veh``: speed, acceleration, angle, lane,
    position, slope."""
    n = len(c["id"])
    return [c["speed"], c["accel"] if "accel" in c else np.full(n, np.nan),
            c["angle"] if "angle" in c else np.zeros(n), c["lane"], c["pos"],
            c["slope"] if "slope" in c else np.zeros(n)]


class _Step:
    """One timestep of a stream: its time and its rows' columns."""

    __slots__ = ("t", "cols")

    def __init__(self, t: float, cols: dict):
        self.t, self.cols = t, cols


def _cut(cols: dict, a: int, b: int) -> dict:
    return {k: v[a:b] for k, v in cols.items()}


def _join(pieces: list[dict]) -> dict:
    if len(pieces) == 1:
        return pieces[0]
    keys = dict.fromkeys(k for p in pieces for k in p)
    return {k: np.concatenate([p[k] if k in p else np.full(len(p["time"]), np.nan)
                               for p in pieces]) for k in keys}


def timesteps(blocks, begin_s: float | None = None, keep=None, label=""):
    """Whole timesteps (:class:`_Step`) from blocks (:func:`iter_fcd_blocks`), in time
    order: the rows of a timestep cut by a block boundary are joined first. ``keep``:
    optional function ids → boolean mask of the rows to keep (every timestep is still
    given, empty or not). UserError when a time comes before the one before it."""
    pending: _Step | None = None
    pieces: list[dict] = []
    last = -np.inf
    for blk in blocks:
        cols = blk.cols
        t = cols["time"]
        if len(t):
            back = np.flatnonzero(np.diff(t) < 0)
            if len(back) or t[0] < last:
                i = int(back[0]) + 1 if len(back) else 0
                prev = t[i - 1] if i else last
                raise UserError(f"FCD {label}: time {t[i]:g} after {prev:g} at vehicle row "
                                f"{blk.first_row + i + 1}: the rows must be in time order "
                                "(as SUMO writes them)")
            last = float(t[-1])
        if keep is not None and len(t):
            m = keep(cols["id"])
            if "person" in cols:  # persons stay: they are matched to the vehicles they ride
                m = m | cols["person"]
            if not m.all():
                cols = {k: v[m] for k, v in cols.items()}
                t = cols["time"]
        lo = np.searchsorted(t, blk.times, side="left")
        hi = np.searchsorted(t, blk.times, side="right")
        for u, a, b in zip(blk.times, lo, hi):
            u = float(u)
            if begin_s is not None and u < begin_s - 1e-9:
                continue
            if pending is not None and u == pending.t:
                pieces.append(_cut(cols, a, b))
                continue
            if pending is not None:
                pending.cols = _join(pieces)
                yield pending
            pending, pieces = _Step(u, None), [_cut(cols, a, b)]
    if pending is not None:
        pending.cols = _join(pieces)
        yield pending


class FcdStream(FcdReplay):
    """The replay of :class:`FcdReplay` fed timestep by timestep from a stream of
    :class:`_Step` (:func:`timesteps`): memory holds the current block and the running
    vehicles, not the file. A vehicle arrives (leaves the ledger's memory) the step after
    a timestep without it; ``dt`` None: the first two timesteps' distance (a shorter one
    later is a UserError: give the scenario's ``step_length``); ``end_s``: replay the
    timesteps t with t + Δt ≤ end (as the live loop stops at end)."""

    def __init__(self, steps, dt: float | None = None, end_s: float | None = None, label=""):
        self._steps = iter(steps)
        self._ahead = [s for s in (next(self._steps, None), next(self._steps, None)) if s]
        self._label, self._end = label, end_s
        self._dt_checked = dt is None
        if dt is None:
            if len(self._ahead) < 2:
                raise UserError(f"FCD file {label}: fewer than two timesteps, cannot tell the "
                                "step length")
            dt = float(np.round(self._ahead[1].t - self._ahead[0].t, 6))
            if dt <= 1e-9:
                raise UserError(f"FCD file {label}: two timesteps at {self._ahead[0].t:g}")
        self.dt = float(dt)
        self.k, self.rows = 0, 0
        self.t = self._ahead[0].t if self._ahead else 0.0
        self.ids: tuple = ()
        self.state: dict = {}
        self.types: dict = {}
        self.departed: tuple = ()
        self.arrived: tuple = ()
        self._prev: tuple = ()
        self._prev_set: set = set()
        self._init_rows()
        self.simulation, self.vehicle = _Sim(self), _Veh(self)

    def remaining(self) -> int:
        if not self._ahead:
            return 0
        if self._end is not None and self._ahead[0].t + self.dt > self._end + 1e-9:
            return 0
        return 1

    def simulationStep(self, time=0.0):  # noqa: N802
        st = self._ahead.pop(0)
        if not self._ahead:  # one timestep ahead (two at the start, for the step length)
            nxt = next(self._steps, None)
            if nxt is not None:
                self._ahead.append(nxt)
        if self._dt_checked and self._ahead:
            d = self._ahead[0].t - st.t
            if 1e-9 < d < self.dt - 1e-6:
                raise UserError(f"FCD file {self._label}: timesteps {self.dt:g} s apart at "
                                f"first, {d:g} s at t = {st.t:g}: give the step length "
                                "(sumo.step_length of the scenario)")
        self.t = st.t + self.dt
        self.k += 1
        self.rows += len(st.cols["id"])
        c = self._vehicles(st.cols, self._ahead[0].cols if self._ahead else None)
        ids = tuple(c["id"])
        n = len(ids)
        self.ids = ids
        self.state = dict(zip(ids, zip(*_state_columns(c)))) if n else {}
        self.types = dict(zip(ids, c["type"]))
        now = set(ids)
        self.departed = tuple(v for v in ids if v not in self._prev_set)
        self.arrived = tuple(v for v in self._prev if v not in now)
        self._prev, self._prev_set = ids, now


def fcd_scenario(net=None, scenario=None, equations=None, vtype_files=None, **overrides):
    """The scenario an FCD replay books with: the scenario file's (or defaults around
    ``net``), equations and vType files replaced when given, positions read every step."""
    import dataclasses

    from sumo_drvpw.sim.scenario import load_scenario

    if scenario is None and net is None:
        raise UserError("FCD: give the network the FCD was recorded on, or a scenario")
    if equations is not None:
        overrides["equations"] = list(equations)
    if scenario is not None:
        sc = load_scenario(scenario, **overrides)
    else:
        if "equations" not in overrides:
            raise UserError("FCD: give the equations, or a scenario that names them")
        sc = load_scenario(doc={"equations": overrides.pop("equations"),
                                "sumo": {"net": str(net)}}, **overrides)
    changes = {"positions": "getter"}
    if net is not None:
        p = Path(net)
        if not p.is_file():
            raise UserError(f"SUMO network not found: {p}")
        changes["net_file"] = p.resolve()
    if vtype_files:
        files = [Path(f).resolve() for f in vtype_files]
        for f in files:
            if not f.is_file():
                raise UserError(f"vType file not found: {f}")
        changes["route_files"] = files
    return dataclasses.replace(sc, **changes)


def process_fcd(fcd_file, net=None, scenario=None, out_dir=None, equations=None,
                vtype_files=None, begin_s=None, keep_vehicles: bool = False,
                flush_vehicles: int | None = None, chunk_rows: int | None = CHUNK_ROWS,
                **overrides):
    """Book an FCD file as ``run`` books a live simulation; returns the RunResult and
    writes the outputs into ``out_dir`` when given.

    Parameters
    ----------
    fcd_file : SUMO FCD output (XML, .xml.gz, .parquet, .csv), or partitioned Parquet FCD
        (a folder or a glob pattern of parts)
    net : the network the FCD was recorded on (default: the scenario's)
    scenario : optional scenario TOML (options, vTypes, equations)
    equations : equations instead of the scenario's (names, paths, Equation objects)
    vtype_files : route/additional files with the vTypes (default: the scenario's)
    begin_s : ignore timesteps before this simulation time [s]
    keep_vehicles, flush_vehicles : as for :func:`sumo_drvpw.sim.run.run_scenario` (a
        vehicle leaves memory the step after its last row in the file)
    chunk_rows : rows read at a time (the file streamed in bounded memory); None reads
        the whole file first (:func:`read_fcd`, :class:`FcdReplay`: the reference path)
    overrides : scenario values to replace (``sumo_drvpw.sim.scenario.OVERRIDES``)

    Streamed, ``summary["source"]["rows"]`` counts the rows of the replayed timesteps (in
    memory: every row from ``begin_s`` on). For many vehicles on several processes or
    machines see :func:`sumo_drvpw.sim.fcd_dask.process_fcd_dask`.
    """
    sc = fcd_scenario(net, scenario, equations, vtype_files, **overrides)
    return replay_fcd(sc, fcd_file, out_dir, begin_s=begin_s, keep_vehicles=keep_vehicles,
                      flush_vehicles=flush_vehicles, chunk_rows=chunk_rows)


def replay_fcd(sc, fcd_file, out_dir=None, begin_s=None, keep_vehicles: bool = False,
               flush_vehicles: int | None = None, chunk_rows: int | None = CHUNK_ROWS,
               keep=None, publish: bool = True, count_persons: bool = True):
    """:func:`process_fcd` with a prepared scenario (:func:`fcd_scenario`). ``keep``:
    optional function vehicle ids → boolean mask of the vehicles to book (a Dask task's
    share; every person's rows are kept, to be matched to the vehicle it rides);
    ``publish``: write the outputs into ``out_dir`` (else only the spill parts of the
    vehicles are left there, for :mod:`sumo_drvpw.sim.fcd_dask` to join);
    ``count_persons``: count the persons in ``summary.json`` ``skipped`` (one Dask task
    does)."""
    from sumo_drvpw.sim.accountant import Accountant
    from sumo_drvpw.sim.loop import step_until
    from sumo_drvpw.sim.network import load_network
    from sumo_drvpw.sim.run import check_vtype_filter
    from sumo_drvpw.sim.spill import SPILL_DIR, discard_parts, write_published

    net = load_network(sc.net_file, sc.road_class, sc.slope_window, sc.slope_max)
    parked = ParkedTest(net)
    if chunk_rows is None:
        df = read_fcd(fcd_file)
        df["off"] = parked({k: df[k].to_numpy() for k in df.columns})
        if keep is not None and len(df):
            times = df.attrs["times"]
            df = df[keep(df["id"].to_numpy(object)) | df["person"].to_numpy(bool)].copy()
            df.attrs["times"] = times
        if begin_s is not None:
            times = df.attrs["times"]
            df = df[df["time"] >= begin_s - 1e-9].copy()
            df.attrs["times"] = times[times >= begin_s - 1e-9]
        replay = FcdReplay(df, dt=sc.step_length)
        if sc.end is not None:
            n = int(np.searchsorted(replay.times + replay.dt, sc.end + 1e-9, side="right"))
            replay.times, replay._rows = replay.times[:n], replay._rows[:n]
    else:
        steps = timesteps(parked.mark(iter_fcd_blocks(fcd_file, chunk_rows)), begin_s, keep,
                          fcd_file)
        replay = FcdStream(steps, dt=sc.step_length, end_s=sc.end, label=fcd_file)
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    acc = Accountant(replay, scenario=sc,
                     trace_path=Path(out_dir) / "trace.parquet" if sc.trace and out_dir else None,
                     spill_dir=Path(out_dir) / SPILL_DIR if out_dir is not None else None,
                     keep_vehicles=keep_vehicles, flush_vehicles=flush_vehicles, net=net)
    replay.type_mass = {vt: i.mass_kg for vt, i in acc.file_vtypes.items() if i.mass_kg}
    replay.count_persons = count_persons
    try:
        info = step_until(replay, acc.stepper, end=None, progress=False, period=sc.period)
        acc.interrupted = info["interrupted"]
        rows = replay.rows if chunk_rows is not None else len(df)
        extra = {"source": {"fcd": str(fcd_file), "rows": int(rows),
                            "timesteps": int(replay.k), "parked_rows": int(replay.parked_rows),
                            "riding_person_rows": int(replay.rider_rows)}}
        if sc.trace and out_dir:
            extra["files"] = {"trace": "trace.parquet"}
        if not publish:
            acc.close_trace()
            return acc, extra
        result = acc.result(extra)
        check_vtype_filter(sc, acc.ledger)
        if out_dir is not None:
            write_published(result, out_dir)
    finally:
        acc.close_trace()
        if out_dir is not None and publish:
            discard_parts(acc.ledger)
    return result
