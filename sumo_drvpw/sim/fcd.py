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
- persons (``<person>``) are not vehicles and are ignored.
"""

from __future__ import annotations

import gzip
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError

#: our name → SUMO's tabular FCD column (``<element>_<attribute>``)
FCD_COLUMNS = {"time": "timestep_time", "id": "vehicle_id", "type": "vehicle_type",
               "speed": "vehicle_speed", "lane": "vehicle_lane", "pos": "vehicle_pos",
               "angle": "vehicle_angle", "slope": "vehicle_slope",
               "accel": "vehicle_acceleration"}
_REQUIRED = ("time", "id", "type", "speed", "lane", "pos")
_XML_ATTRS = {"id": "id", "type": "type", "speed": "speed", "lane": "lane", "pos": "pos",
              "angle": "angle", "slope": "slope", "accel": "acceleration"}


def _xml_rows(path: Path) -> pd.DataFrame:
    with open(path, "rb") as f:
        gz = f.read(2) == b"\x1f\x8b"
    cols: dict[str, list] = {k: [] for k in ("time", *_XML_ATTRS)}
    times: list[float] = []
    try:
        with (gzip.open(path, "rb") if gz else open(path, "rb")) as fh:
            t = None
            for ev, el in ET.iterparse(fh, events=("start", "end")):
                tag = el.tag
                if ev == "start":
                    if tag == "timestep":
                        t = float(el.attrib["time"])
                        times.append(t)
                    continue
                if tag == "vehicle" and t is not None:
                    a = el.attrib
                    cols["time"].append(t)
                    for k, xk in _XML_ATTRS.items():
                        cols[k].append(a.get(xk))
                    el.clear()
                elif tag == "timestep":
                    el.clear()
    except ET.ParseError as e:
        raise UserError(f"FCD file {path}: not valid XML: {e}") from None
    except (KeyError, ValueError) as e:
        raise UserError(f"FCD file {path}: a <timestep> without a valid time: {e}") from None
    df = pd.DataFrame({k: v for k, v in cols.items() if any(x is not None for x in v)
                       or k in _REQUIRED})
    df.attrs["times"] = np.asarray(times, float)
    return df


def fcd_parts(spec) -> list[Path]:
    """The Parquet files of a partitioned FCD: a folder (its ``*.parquet``, recursively) or
    a glob pattern (``fcd/part-*.parquet``), sorted by name; [] when ``spec`` is neither."""
    import glob

    p = Path(spec)
    if p.is_dir():
        files = sorted(f for f in p.rglob("*.parquet") if f.is_file())
        if not files:
            raise UserError(f"FCD folder {p}: no .parquet files in it")
        return files
    if any(c in str(spec) for c in "*?[") and not p.exists():
        files = sorted(Path(f) for f in glob.glob(str(spec), recursive=True) if Path(f).is_file())
        if not files:
            raise UserError(f"FCD pattern {spec}: matches no file")
        bad = [f for f in files if not f.name.lower().endswith(".parquet")]
        if bad:
            raise UserError(f"FCD pattern {spec}: {bad[0]} is not a .parquet file (a pattern "
                            "reads partitioned Parquet FCD only)")
        return files
    return []


def _read_parquet_fcd(files: list[Path], label) -> pd.DataFrame:
    """The FCD columns (only those) of one or several Parquet files, in file order."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    wanted = set(FCD_COLUMNS.values())
    tables = []
    for f in files:
        try:
            names = pq.read_schema(f).names
            tables.append(pq.read_table(f, columns=[c for c in names if c in wanted]))
        except Exception as e:  # pyarrow raises several error types for bad files
            raise UserError(f"FCD file {f}: cannot read Parquet: {e}") from None
    try:
        tbl = pa.concat_tables(tables, promote_options="default")
    except (pa.ArrowInvalid, pa.ArrowTypeError) as e:
        raise UserError(f"FCD {label}: the parts' columns do not agree: {e}") from None
    return tbl.to_pandas()


def read_fcd(path) -> pd.DataFrame:
    """FCD rows (time, id, type, speed, lane, pos, [angle, slope, accel]) sorted by time;
    ``df.attrs["times"]``: every timestep of the file, vehicles or not. UserError names
    the file and the missing column. ``path``: a file, or partitioned Parquet FCD (a folder
    or a glob pattern of ``.parquet`` files, read as one, only the FCD columns)."""
    parts = fcd_parts(path)
    path = Path(path)
    if not parts and not path.is_file():
        raise UserError(f"FCD file not found: {path}")
    name = path.name.lower()
    if parts or name.endswith(".parquet"):
        raw = _read_parquet_fcd(parts or [path], path)
    elif name.endswith(".csv") or name.endswith(".csv.gz"):
        try:
            raw = pd.read_csv(path, sep=None, engine="python")
        except Exception as e:
            raise UserError(f"FCD file {path}: cannot read CSV: {e}") from None
    else:
        df = _xml_rows(path)
        raw = None
    if raw is not None:
        missing = [FCD_COLUMNS[k] for k in _REQUIRED if FCD_COLUMNS[k] not in raw.columns]
        if missing:
            raise UserError(f"FCD file {path}: no column {missing[0]} (SUMO's tabular FCD "
                            f"has {', '.join(FCD_COLUMNS[k] for k in _REQUIRED)})")
        times = np.unique(pd.to_numeric(raw[FCD_COLUMNS["time"]], errors="coerce").dropna())
        df = pd.DataFrame({k: raw[c] for k, c in FCD_COLUMNS.items() if c in raw.columns})
        df.attrs["times"] = times
    times = df.attrs.get("times", np.zeros(0))
    df = df[df["id"].notna() & (df["id"].astype(str) != "")].copy()
    for k in ("time", "speed", "pos", "angle", "slope", "accel"):
        if k in df.columns:
            vals = pd.to_numeric(df[k], errors="coerce")
            bad = vals.isna() & df[k].notna()
            if bad.any():
                i = int(np.flatnonzero(bad.to_numpy())[0])
                raise UserError(f"FCD file {path}: column {k}: not a number at vehicle row "
                                f"{i + 1}: {df[k].iloc[i]!r}")
            df[k] = vals.astype(float)
    for k in ("speed", "pos"):
        if df[k].isna().any():
            i = int(np.flatnonzero(df[k].isna().to_numpy())[0])
            raise UserError(f"FCD file {path}: column {k} missing at vehicle row {i + 1} "
                            f"(vehicle {df['id'].iloc[i]!r})")
    for k in ("id", "type", "lane"):
        df[k] = df[k].astype(str)
    df = df.sort_values("time", kind="stable").reset_index(drop=True)
    df.attrs["times"] = times
    return df


class _Sim:
    def __init__(self, r):
        self.r = r

    def getTime(self):  # noqa: N802 (SUMO's names)
        return self.r.t

    def getDeltaT(self):  # noqa: N802
        return self.r.dt

    def getMinExpectedNumber(self):  # noqa: N802
        return len(self.r.times) - self.r.k

    def getDepartedIDList(self):  # noqa: N802
        return self.r.departed

    def getArrivedIDList(self):  # noqa: N802
        return self.r.arrived


class _Veh:
    def __init__(self, r):
        self.r = r

    def getIDList(self):  # noqa: N802
        return self.r.ids

    def getTypeID(self, vid):  # noqa: N802
        return self.r.types[vid]

    def _col(self, k):
        return lambda vid: self.r.state[vid][k]

    def __getattr__(self, name):
        k = {"getSpeed": 0, "getAcceleration": 1, "getAngle": 2, "getLaneID": 3,
             "getLanePosition": 4, "getSlope": 5}.get(name)
        if k is None:
            raise AttributeError(name)
        return self._col(k)


class _VType:
    def getVehicleClass(self, vt):  # noqa: N802 (not in FCD: the route files say)
        return ""

    def getParameter(self, vt, key):  # noqa: N802
        return ""


class FcdReplay:
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
        cols = [df["speed"].to_numpy(float),
                df["accel"].to_numpy(float) if "accel" in df else np.full(n, np.nan),
                df["angle"].to_numpy(float) if "angle" in df else np.zeros(n),
                df["lane"].to_numpy(object), df["pos"].to_numpy(float),
                df["slope"].to_numpy(float) if "slope" in df else np.zeros(n)]
        self._ids = df["id"].to_numpy(object)
        self._cols = cols
        self.types = dict(zip(df["id"], df["type"]))
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
        step = np.searchsorted(times, t)
        last = pd.Series(step).groupby(df["id"].to_numpy()).max() if n else pd.Series(dtype=int)
        self._leaving = {int(k): tuple(g.index) for k, g in last.groupby(last)}
        self.simulation, self.vehicle, self.vehicletype = _Sim(self), _Veh(self), _VType()

    def simulationStep(self, time=0.0):  # noqa: N802
        a, b = self._rows[self.k]
        self.t = float(self.times[self.k]) + self.dt
        self.k += 1
        ids = tuple(self._ids[a:b])
        self.ids = ids
        self.state = dict(zip(ids, zip(*(c[a:b] for c in self._cols)))) if ids else {}
        new = tuple(v for v in ids if v not in self._seen)
        self._seen.update(new)
        self.departed = new
        self.arrived = self._leaving.get(self.k - 2, ())

    def close(self):
        pass


def process_fcd(fcd_file, net=None, scenario=None, out_dir=None, equations=None,
                vtype_files=None, begin_s=None, keep_vehicles: bool = False,
                flush_vehicles: int | None = None, **overrides):
    """Book an FCD file as ``run`` books a live simulation; returns the RunResult and
    writes the outputs into ``out_dir`` when given.

    Parameters
    ----------
    fcd_file : SUMO FCD output (XML, .xml.gz, .parquet, .csv)
    net : the network the FCD was recorded on (default: the scenario's)
    scenario : optional scenario TOML (options, vTypes, equations)
    equations : equations instead of the scenario's (names, paths, Equation objects)
    vtype_files : route/additional files with the vTypes (default: the scenario's)
    begin_s : ignore timesteps before this simulation time [s]
    keep_vehicles, flush_vehicles : as for :func:`sumo_drvpw.sim.run.run_scenario` (a
        vehicle leaves memory the step after its last row in the file)
    overrides : scenario values to replace (``sumo_drvpw.sim.scenario.OVERRIDES``)
    """
    from sumo_drvpw.sim.accountant import Accountant
    from sumo_drvpw.sim.loop import step_until
    from sumo_drvpw.sim.run import check_vtype_filter
    from sumo_drvpw.sim.scenario import load_scenario
    from sumo_drvpw.sim.spill import SPILL_DIR, discard_parts, write_published

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
    import dataclasses

    changes = {"positions": "getter"}
    if net is not None:
        p = Path(net)
        if not p.is_file():
            raise UserError(f"SUMO network not found: {p}")
        changes["net_file"] = p.resolve()
    if vtype_files:
        files = [Path(f) for f in vtype_files]
        for f in files:
            if not f.is_file():
                raise UserError(f"vType file not found: {f}")
        changes["route_files"] = files
    sc = dataclasses.replace(sc, **changes)
    df = read_fcd(fcd_file)
    if begin_s is not None:
        times = df.attrs["times"]
        df = df[df["time"] >= begin_s - 1e-9].copy()
        df.attrs["times"] = times[times >= begin_s - 1e-9]
    replay = FcdReplay(df, dt=sc.step_length)
    if out_dir is not None:
        Path(out_dir).mkdir(parents=True, exist_ok=True)
    acc = Accountant(replay, scenario=sc,
                     trace_path=Path(out_dir) / "trace.parquet" if sc.trace and out_dir else None,
                     spill_dir=Path(out_dir) / SPILL_DIR if out_dir is not None else None,
                     keep_vehicles=keep_vehicles, flush_vehicles=flush_vehicles)
    try:
        end = sc.end
        info = step_until(replay, acc.stepper, end=None, progress=False, period=sc.period) \
            if end is None else _until(replay, acc, end, sc.period)
        acc.interrupted = info["interrupted"]
        extra = {"source": {"fcd": str(fcd_file), "rows": int(len(df)),
                            "timesteps": int(len(replay.times))}}
        if sc.trace and out_dir:
            extra["files"] = {"trace": "trace.parquet"}
        result = acc.result(extra)
        check_vtype_filter(sc, acc.ledger)
        if out_dir is not None:
            write_published(result, out_dir)
    finally:
        acc.close_trace()
        if out_dir is not None:
            discard_parts(acc.ledger)
    return result


def _until(replay: FcdReplay, acc, end: float, period):
    """Replay the timesteps before ``end`` [s] (as the live loop stops at end)."""
    from sumo_drvpw.sim.loop import step_until

    n = int(np.searchsorted(replay.times + replay.dt, end + 1e-9, side="right"))
    replay.times = replay.times[:n]
    replay._rows = replay._rows[:n]
    return step_until(replay, acc.stepper, end=None, progress=False, period=period)
