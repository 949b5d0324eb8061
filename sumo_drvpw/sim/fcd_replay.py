"""The replay's connection to the ledger's loop, stepping through an FCD's timesteps: a file read
whole (:class:`FcdReplay`), or a stream of whole timesteps (:class:`FcdStream`) joined from
the file's blocks in time order (:func:`timesteps`); its getters answer from the rows
(sim/fcd_conn.py). The replay itself: sim/fcd.py."""

from __future__ import annotations

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.fcd_begin import accel_at_begin
from sumo_drvpw.sim.fcd_conn import _Rows, _Sim, _Veh


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
        self.types: dict = {}  # vehicle id → its vType in the current step
        self.k = 0
        # FCD time t is the state after SUMO executed step t; a live loop reads that state
        # after simulationStep() with getTime() = t + Δt: the replay labels steps alike
        self.t = float(times[0]) if len(times) else 0.0
        self.ids: tuple = ()
        self.state: dict = {}
        self.departed: tuple = ()
        self.arrived: tuple = ()
        self.back: tuple = ()
        self._seen: set = set()
        # a vehicle arrives (leaves the ledger's memory) the step after its last row
        step = np.searchsorted(times, t[~person])
        vid = veh["id"].to_numpy()
        last = (pd.Series(step).groupby(vid).max() if len(veh) else pd.Series(dtype=int))
        self._leaving = {int(k): tuple(g.index) for k, g in last.groupby(last)}
        # and is back after steps without its row (a teleport, as SUMO writes it): SUMO's
        # ending teleports of that step
        gap = (pd.Series(step).groupby(vid).diff() > 1).to_numpy() if len(veh) else np.zeros(0, bool)
        self._back = {int(k): tuple(g) for k, g in pd.Series(vid[gap]).groupby(step[gap])}
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
        self.types = dict(zip(ids, cols["type"]))  # this step's: a vType can change in a trip
        self.no_angle = self.no_angle or (bool(ids) and "angle" not in cols)
        new = tuple(v for v in ids if v not in self._seen)
        self.back = self._back.get(self.k - 1, ())
        self._seen.update(new)
        self.departed = new
        self.saw(new)
        self.arrived = self._leaving.get(self.k - 2, ())

    def close(self):
        pass


def _state_columns(c: dict) -> list:
    """The getters' columns in the order of ``_Veh``: speed, acceleration, angle, lane,
    position, slope (NaN without the column: unknown, so a ``vtype_energy`` equation books the
    rise of the step, sim/sumo_inputs.as_sumo)."""
    n = len(c["id"])
    return [c["speed"], c["accel"] if "accel" in c else np.full(n, np.nan),
            c["angle"] if "angle" in c else np.zeros(n), c["lane"], c["pos"],
            c["slope"] if "slope" in c else np.full(n, np.nan)]


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


def timesteps(blocks, begin_s: float | None = None, keep=None, label="", info: dict | None = None):
    """Whole timesteps (:class:`_Step`) from blocks (:func:`iter_fcd_blocks`), in time
    order: the rows of a timestep cut by a block boundary are joined first. ``keep``:
    optional function ids → boolean mask of the rows to keep (every timestep is still
    given, empty or not). UserError when a time comes before the one before it. ``info``:
    ``info["skipped"]`` is set True when a timestep before ``begin_s`` was left out."""
    pending: _Step | None = None
    pieces: list[dict] = []
    skipped = None  # the last timestep before begin_s: (its time, its pieces)
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
                if info is not None:
                    info["skipped"] = True
                skipped = (u, [*(skipped[1] if skipped and skipped[0] == u else ()), _cut(cols, a, b)])
                continue
            if pending is not None and u == pending.t:
                pieces.append(_cut(cols, a, b))
                continue
            if pending is not None:
                pending.cols = _join(pieces)
                if skipped:  # the first timestep replayed: its accelerations (accel_at_begin)
                    pending.cols = accel_at_begin(pending.cols, _join(skipped[1]), pending.t, skipped[0])
                    skipped = None
                yield pending
            pending, pieces = _Step(u, None), [_cut(cols, a, b)]
    if pending is not None:
        pending.cols = _join(pieces)
        if skipped:
            pending.cols = accel_at_begin(pending.cols, _join(skipped[1]), pending.t, skipped[0])
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
        self.no_angle = self.no_angle or (bool(n) and "angle" not in c)
        self.types = dict(zip(ids, c["type"]))
        now = set(ids)
        self.departed = tuple(v for v in ids if v not in self._prev_set)
        self.saw(self.departed)
        self.arrived = tuple(v for v in self._prev if v not in now)
        self._prev, self._prev_set = ids, now
