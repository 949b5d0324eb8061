"""Read and validate canonical drive logs (``../shared/spec/drive-log.md``).

A log is a Parquet or CSV file, or a folder of them, one row per sample. The reader
checks the spec's bad-input rules, derives what the spec lets a log omit (acceleration,
grade, wind, air density) and keeps every other column for the residual tracer.
"""

from __future__ import annotations

import numbers
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.data.log_files import (FLAGS, NUMERIC, REQUIRED, _check_flags, _check_numeric, _read_table,
                                       expand_paths, vendor_hint)
from sumo_drvpw.data.resolution import accel_counts, accel_derivation, accel_speed, accel_window, held_end_spans
from sumo_drvpw.data.conditions import derive_conditions
from sumo_drvpw.data.ranges import RANGES, check_ranges  # noqa: F401  (RANGES re-exported)
from sumo_drvpw.errors import UserError
from sumo_drvpw.model.terms import Inputs
from sumo_drvpw.data.trips import (derivative, grade_from_elevation,  # noqa: F401  (re-exported)
                                   per_trip_rolling_mean as _per_trip_rolling_mean,
                                   run_median_step, trip_array as _trip_array, trip_codes_of,
                                   trip_starts as _trip_starts, trips_without as _trips_without)
from sumo_drvpw.data.counters import check_counters
from sumo_drvpw.data.plausible import (KMH_SUSPECT_ACCEL_MPS2,  # noqa: F401
                                       check_distinct_trips, check_speed_unit, check_time_step,
                                       exclusions, implied_acceleration, speed_steps)

#: Columns the reader derives; every other column is an extra signal.
DERIVED = ("trip_id", "time_s", "speed_mps", "accel_mps2", "grade_rad", "wind_mps",
           "air_density_kgm3", "mass_kg", "brake", "reverse", "dt_s")
SPEED_MAX_MPS = 100.0
#: Speed units a log may declare (``ReadOptions.speed_unit``) → factor to m/s.
SPEED_UNITS = {"m/s": 1.0, "km/h": 1 / 3.6, "mph": 0.44704}
#: the largest lateral acceleration v·|ω| a yaw rate may give on more than 1 % of a log's
#: rows [m/s²]: about 1.2 g, beyond a road tyre's grip (a yaw rate in deg/s gives 57× its own)
LATERAL_MAX_MPS2 = 12.0
#: Bundled demo log (package data): a synthetic Prius3 test-track log, see its README.
BUNDLED_LOG = "prius3_testtrack.parquet"
GRADE_MAX_RAD = 0.6


@dataclass
class ReadOptions:
    """How derived signals are computed.

    Parameters
    ----------
    accel_window_s : width of the centred moving average applied to the central-
        difference acceleration [s]; the least width: a log whose speed is logged in coarse
        steps gets a wider one (:func:`sumo_drvpw.data.resolution.accel_window`)
    accel_noise_mps2 : the largest noise the speed's resolution may put into the derived
        acceleration [m/s²] (it sets the widening)
    grade_window_m : distance over which elevation is smoothed before differentiating [m]
    accel_outlier_mps2 : |a| above this is an outlier, left out of calibration [m/s²]
    grade_outlier : |tan θ| above this is no road grade but an elevation glitch (a phone's
        GPS altitude settling or jumping), left out of calibration [-]
    """

    accel_window_s: float = 0.5
    accel_noise_mps2: float = 0.05
    grade_window_m: float = 100.0
    accel_outlier_mps2: float = 8.0
    #: 35 %: steeper than the steepest public streets (Baldwin Street, Ffordd Pen Llech)
    grade_outlier: float = 0.35
    #: speeds in [−tolerance, 0) are standstill sensor noise: clipped to 0 and counted [m/s]
    negative_speed_tolerance_mps: float = 0.1
    #: unit of ``speed_mps`` as logged: None = m/s, checked against implausible implied
    #: accelerations (km/h mistaken for m/s); "m/s" = trust; "km/h" or "mph" = convert
    speed_unit: str | None = None
    #: measurement corrections applied when power and inputs are computed
    #: (:class:`sumo_drvpw.model.measurement.Measurement`: power lag, grade source, air
    #: density; :mod:`sumo_drvpw.data.corrections`); None = the log as read
    measurement: object | None = None
    #: read the logs as a flat road: grade_rad, grade_pct and elevation_m not read as grade (a GPS
    #: altitude that is noise; :func:`sumo_drvpw.data.conditions.derive_conditions`)
    flat_road: bool = False
    #: the fuel a fuel flow is read as when no vehicle file names one (the fuel of the
    #: equations' fuel chains, when they all burn one: cli.read_options); None = gasoline
    fuel: str | None = None


#: a logging gap: an interval within a trip longer than this many of the trip's median
#: steps and than GAP_MIN_S [s] (a 1-Hz hiccup of 2 s is no gap; a phone's 17-s pause is)
GAP_STEPS, GAP_MIN_S = 5.0, 2.0


@dataclass
class DriveLog:
    """A validated canonical drive log with derived columns.

    ``df`` holds every row read, the canonical SI columns (derived where absent), a
    per-sample ``dt_s`` (time weight for energies) and all extra columns. ``excluded``
    is a boolean mask of samples left out of calibration (brake, reverse, outliers,
    NaN in a needed value); ``counts`` reports why.
    """

    df: pd.DataFrame
    files: list[str]
    counts: dict = field(default_factory=dict)
    excluded: np.ndarray | None = None
    metadata: dict = field(default_factory=dict)
    options: ReadOptions = field(default_factory=ReadOptions)
    #: (stretch code per sample, moving-average width per stretch [s]) of the derived
    #: acceleration: stretches are trips cut at logging gaps (:meth:`derivative`)
    deriv: tuple | None = field(default=None, repr=False)
    #: a streamed batch: the fuel and air flows of its whole file that hold a value
    #: (:func:`sumo_drvpw.data.powertrain.fuel_column`); None: judged on ``df``
    logged: frozenset | None = field(default=None, repr=False)
    #: a folder read in memory: each file's columns (a file that cannot give the measured
    #: power is refused by name, as read alone), its fuel and air flows that hold a value
    #: (as ``logged``) and its trips; None: one table
    file_columns: dict | None = field(default=None, repr=False)
    file_logged: dict | None = field(default=None, repr=False)
    file_trips: dict | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.df)

    def derivative(self, y: np.ndarray, window_s: float | None = None) -> np.ndarray:
        """dy/dt of a per-sample signal as the reader derives the acceleration: the same
        stretches and each trip's window (``window_s`` [s]: one width instead)."""
        t = self.df["time_s"].to_numpy(float)
        if self.deriv is None:
            codes = trip_codes_of(self.df["trip_id"])
            return derivative(y, t, codes, self.options.accel_window_s if window_s is None else window_s)
        seg, win = self.deriv
        return derivative(y, t, seg, win if window_s is None else window_s)

    @property
    def extra_columns(self) -> list[str]:
        """Columns that are not canonical inputs: candidate signals for the tracer."""
        skip = set(DERIVED) | {"grade_pct", "elevation_m", "airspeed_mps"}
        return [c for c in self.df.columns if c not in skip]

    def inputs(self, mass_kg: float | None = None, signals: bool = True) -> Inputs:
        """Term-basis inputs for every row; mass from ``mass_kg`` column else the argument."""
        df = self.df
        if "mass_kg" in df and df["mass_kg"].notna().all():
            mass = df["mass_kg"].to_numpy(float)
        elif mass_kg is not None:
            # one constant mass: a read-only broadcast view costs no memory
            mass = np.broadcast_to(float(mass_kg), (len(df),))
            if "mass_kg" in df:
                given = df["mass_kg"].to_numpy(float)
                mass = np.where(np.isnan(given), mass, given)
        else:
            raise UserError(f"{self.describe()}: no vehicle mass: the log has no complete "
                            "'mass_kg' column; give the vehicle (a name or a vehicle file) for its mass")
        sig = {}
        if signals:
            for c in self.extra_columns:
                col = df[c]
                if pd.api.types.is_bool_dtype(col) or pd.api.types.is_numeric_dtype(col):
                    sig[c] = col.to_numpy(float, na_value=np.nan)
        return Inputs(v=df["speed_mps"].to_numpy(float), a=df["accel_mps2"].to_numpy(float),
                      theta=df["grade_rad"].to_numpy(float), wind=df["wind_mps"].to_numpy(float),
                      mass=mass, rho=df["air_density_kgm3"].to_numpy(float), signals=sig,
                      trip=_trip_array(df["trip_id"]))

    def describe(self) -> str:
        return self.files[0] if len(self.files) == 1 else f"{len(self.files)} files"


def bundled_log(name: str = BUNDLED_LOG) -> Path:
    """Path of a drive log shipped in the package (``sumo_drvpw/data/builtin/logs/``)."""
    from importlib import resources

    p = Path(str(resources.files("sumo_drvpw.data") / "builtin" / "logs" / name))
    if not p.is_file():
        raise UserError(f"bundled log {name!r} not found in the installed package ({p})")
    return p


def _validate(df: pd.DataFrame, p: Path, opt: ReadOptions | None = None) -> int:
    """The spec's bad-input rules; converts a declared speed unit and clips standstill noise.

    Returns the number of speeds in [−tolerance, 0) clipped to 0 (``df`` is changed in place).
    """
    opt = opt or ReadOptions()
    dup = df.columns[df.columns.duplicated()]
    if len(dup):
        raise UserError(f"{p}: column '{dup[0]}' appears twice; give each column once")
    if not isinstance(df.columns, pd.RangeIndex):
        mangled = [c for c in map(str, df.columns) if c.rsplit(".", 1)[0] in REQUIRED + NUMERIC
                   and c.rsplit(".", 1)[-1].isdigit() and c.rsplit(".", 1)[0] in df]
        if mangled:  # pandas renames a repeated CSV header 'x' to 'x.1'
            raise UserError(f"{p}: column '{mangled[0].rsplit('.', 1)[0]}' appears twice "
                            f"(the second is read as '{mangled[0]}'); give each column once")
    for c in REQUIRED:
        if c not in df:
            own = [str(x) for x in df.columns if not (x == "trip_id" and df.attrs.get("trip_id_added"))]
            raise UserError(f"{p}: missing required column '{c}' (columns: "
                            f"{', '.join(own[:12])}{'…' if len(own) > 12 else ''}); {vendor_hint()}")
    for c in NUMERIC:
        if c in df and pd.api.types.is_bool_dtype(df[c]):
            raise UserError(f"{p}: column '{c}' is boolean (True/False), not a number in "
                            f"{'m/s' if c == 'speed_mps' else 'SI units'}")
    _check_numeric(df, p)
    _check_flags(df, p)
    for c in REQUIRED:
        nan = df[c].isna().to_numpy()
        if nan.any():
            raise UserError(f"{p}: column '{c}' is empty (NaN) at row {int(np.flatnonzero(nan)[0])}; "
                            "a required column needs a value in every row")
    for c in NUMERIC:
        if c in df:
            x = df[c].to_numpy(float, na_value=np.nan)
            inf = np.isinf(x)
            if inf.any():
                i = int(np.flatnonzero(inf)[0])
                raise UserError(f"{p}: column '{c}' is {x[i]:g} at row {i}; values must be finite")
    if opt.speed_unit not in (None, "m/s"):
        df["speed_mps"] = df["speed_mps"].to_numpy(float) * SPEED_UNITS[opt.speed_unit]
    v = df["speed_mps"].to_numpy(float)
    if (v > SPEED_MAX_MPS).any():
        i = int(np.flatnonzero(v > SPEED_MAX_MPS)[0])
        if opt.speed_unit not in (None, "m/s"):  # the unit is declared already: the value is wrong
            raise UserError(f"{p}: column 'speed_mps' is {v[i] / SPEED_UNITS[opt.speed_unit]:g} {opt.speed_unit} "
                            f"({v[i]:g} m/s) at row {i}, above {SPEED_MAX_MPS:g} m/s: no road vehicle's speed")
        raise UserError(f"{p}: column 'speed_mps' is {v[i]:g} at row {i}, above {SPEED_MAX_MPS:g} m/s: "
                        "is the speed in km/h? read it with speed unit km/h, or convert it to m/s "
                        "(divide by 3.6)")
    tol = opt.negative_speed_tolerance_mps
    if (v < -tol).any():
        i = int(np.flatnonzero(v < -tol)[0])
        raise UserError(f"{p}: column 'speed_mps' is negative ({v[i]:g}) at row {i}, below the "
                        f"standstill noise tolerance −{tol:g} m/s; speed over ground is >= 0 "
                        "(mark reversing with the 'reverse' column)")
    noise = v < 0
    n_clipped = int(noise.sum())
    if n_clipped:
        v = np.where(noise, 0.0, v)
        df["speed_mps"] = v
    check_ranges(df, p)
    if "yaw_rate_rps" in df:  # in deg/s a gentle curve's yaw rate passes the range: the tyres' grip tells
        a_lat = np.abs(v * df["yaw_rate_rps"].to_numpy(float, na_value=np.nan))
        high = a_lat > LATERAL_MAX_MPS2
        if high.sum() > 0.01 * np.isfinite(a_lat).sum():
            i = int(np.flatnonzero(high)[0])
            raise UserError(f"{p}: column 'yaw_rate_rps' gives a lateral acceleration v·|ω| of {a_lat[i]:.3g} m/s² "
                            f"at row {i}, above {LATERAL_MAX_MPS2:g} m/s² (more than tyres carry) on "
                            f"{int(high.sum())} rows: a yaw rate in deg/s? multiply by π/180")
    t = df["time_s"].to_numpy(float)
    trip = trip_codes_of(df["trip_id"])  # integer codes: neighbour comparisons without strings
    same = trip[1:] == trip[:-1]
    back = same & (np.diff(t) <= 0)
    if back.any():
        i = int(np.flatnonzero(back)[0]) + 1
        raise UserError(f"{p}: column 'time_s' does not increase within trip '{df['trip_id'].iloc[i]}' at row {i} "
                        f"({t[i - 1]:g} then {t[i]:g}); time must be strictly increasing")
    check_time_step(t, same, p)
    check_counters(df, p, trip)
    for c, lim in (("grade_rad", GRADE_MAX_RAD), ("grade_pct", 100 * np.tan(GRADE_MAX_RAD))):
        if c in df:
            g = df[c].to_numpy(float)
            bad = np.abs(g) > lim
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise UserError(f"{p}: column '{c}' is {g[i]:g} at row {i}, beyond ±{lim:.3g} "
                                f"({'rad' if c == 'grade_rad' else '%'}): not a road grade")
    if opt.speed_unit is None:
        check_speed_unit(v, t, trip, p)
    return n_clipped


def read_log(paths, vehicle=None, options: ReadOptions | None = None) -> DriveLog:
    """Read canonical drive logs, validate them and derive the model inputs.

    Parameters
    ----------
    paths : file or folder paths (Parquet, CSV)
    vehicle : optional :class:`sumo_drvpw.model.vehicles.Vehicle`, or a built-in vehicle's
        name or a vehicle TOML file (mass when the log has none)
    options : :class:`ReadOptions`

    Derivations (all within a trip):
    acceleration = smoothed central difference of speed when ``accel_mps2`` is absent;
    grade = ``grade_rad``, else atan(``grade_pct``/100), else from ``elevation_m``
    smoothed over distance, else 0; wind = ``wind_mps``, else speed − ``airspeed_mps``,
    else 0; air density = ``air_density_kgm3``, else p/(R·T) from ``ambient_c`` and
    ``pressure_kpa`` (101.325 kPa if absent), else 1.2041 kg/m³. Each trip takes the first
    source that holds a value in it (:mod:`sumo_drvpw.data.conditions`), so a file of a
    folder of different loggers is read as it is alone. A CSV file cut inside its last row
    is read without it (``counts["truncated_rows"]``: file → row; :mod:`sumo_drvpw.data.truncated`).
    """
    opt = check_options(options or ReadOptions())
    vehicle = as_vehicle(vehicle)
    files = expand_paths(paths)
    from sumo_drvpw.data.powertrain import flow_columns

    frames, meta, clipped, owner, columns, logged, cuts = [], {}, 0, {}, {}, {}, {}
    for p in files:
        df, m, cuts[str(p)] = _read_table(p)
        meta.update(m)
        df, n = _prepare(df, p, p.stem, opt)
        for tid in pd.unique(df["trip_id"]):
            if tid in owner:
                raise UserError(f"{p}: trip_id '{tid}' is also in {owner[tid]}; samples of one trip "
                                "belong in one file, give each trip its own id")
            owner[tid] = p
        frames.append(df)
        columns[str(p)] = frozenset(map(str, df.columns))
        logged[str(p)] = frozenset(c for c in flow_columns(df.columns) if df[c].notna().any())
        clipped += n
    df = pd.concat(frames, ignore_index=True) if len(frames) > 1 else frames[0]
    log = _derive(df, [str(p) for p in files], meta, vehicle, opt, clipped)
    if any(r is not None for r in cuts.values()):  # files cut inside their last row (said by the commands)
        log.counts["truncated_rows"] = {f: r for f, r in cuts.items() if r is not None}
    if len(files) > 1:  # each file as read alone (data/powertrain.py)
        log.file_columns, log.file_logged = columns, logged
        log.file_trips = {str(f): [t for t, o in owner.items() if o == f] for f in files}
    return log


def check_declared_unit(paths, opt: ReadOptions) -> None:
    """UserError when a speed unit other than m/s is declared for a Parquet log that `import`
    wrote (its metadata ``sumo_drvpw.import``): its speed_mps is in m/s already, and the
    declared unit would convert it a second time. Reads only the files' schema."""
    if opt.speed_unit in (None, "m/s"):
        return
    import pyarrow.parquet as pq

    for p in expand_paths(paths):
        if p.suffix.lower() != ".parquet":
            continue
        try:
            meta = pq.read_schema(p).metadata or {}
        except (OSError, ValueError):
            continue  # (refused, named, where it is read)
        if b"sumo_drvpw.import" in meta:
            raise UserError(f"{p}: speed unit {opt.speed_unit} declared, but this log was written by "
                            "the import (metadata 'sumo_drvpw.import'): its speed_mps is in m/s already, "
                            "and the unit would convert it a second time (top speed / 3.6)")


def as_vehicle(vehicle):
    """A :class:`~sumo_drvpw.model.vehicles.Vehicle` from one, a built-in vehicle's name
    or a vehicle TOML path (None stays None), as the commands take ``--vehicle``."""
    if isinstance(vehicle, (str, Path)):
        from sumo_drvpw.model.vehicles import load_vehicle

        return load_vehicle(str(vehicle))
    return vehicle


#: ReadOptions fields that must be finite and > 0, and ≥ 0 (0: no smoothing)
_POSITIVE_OPTIONS, _NONNEGATIVE_OPTIONS = ("accel_outlier_mps2", "grade_outlier"), ("accel_window_s", "accel_noise_mps2", "grade_window_m")


def check_options(opt: ReadOptions) -> ReadOptions:
    """Reading options within their meaning; a UserError names the option's value."""
    if opt.speed_unit is not None and opt.speed_unit not in SPEED_UNITS:
        raise UserError(f"speed unit {opt.speed_unit!r} is not one of {', '.join(SPEED_UNITS)}")
    tol = opt.negative_speed_tolerance_mps
    if not (np.isfinite(tol) and 0 <= tol <= 1.0):
        raise UserError(f"negative speed tolerance {tol:g} m/s: give a value in [0, 1] m/s")
    for k in _POSITIVE_OPTIONS + _NONNEGATIVE_OPTIONS:
        v = getattr(opt, k)
        ok = isinstance(v, numbers.Real) and not isinstance(v, bool) and np.isfinite(v) and (v > 0 if k in _POSITIVE_OPTIONS else v >= 0)
        if not ok:
            raise UserError(f"reading option {k} = {v!r}: give a finite number "
                            + ("> 0" if k in _POSITIVE_OPTIONS else "≥ 0"))
    return opt


def from_frame(df: pd.DataFrame, vehicle=None, options: ReadOptions | None = None,
               name: str = "<frame>") -> DriveLog:
    """A :class:`DriveLog` from an in-memory canonical table (e.g. an adapter's output).

    Same validation and derivations as :func:`read_log` (one shared code path), without
    writing a file. ``df`` is copied, never modified; ``name`` stands for the file name in
    error messages and in ``DriveLog.files``.
    """
    opt = check_options(options or ReadOptions())
    vehicle = as_vehicle(vehicle)
    frame, clipped = _prepare(df.copy(), Path(name), Path(name).stem, opt)
    return _derive(frame.reset_index(drop=True), [str(name)], {}, vehicle, opt, clipped)


def _prepare(df: pd.DataFrame, p: Path, default_trip: str,
             opt: ReadOptions | None = None) -> tuple[pd.DataFrame, int]:
    """trip_id (default: the file stem) as text, then the spec's bad-input checks.

    Returns the frame and the number of standstill-noise speeds clipped to 0."""
    if "trip_id" not in df:
        df.insert(0, "trip_id", default_trip)
        df.attrs["trip_id_added"] = True  # (not the file's: messages list the file's columns)
    else:
        tid = df["trip_id"]
        if tid.isna().any():
            i = int(np.flatnonzero(tid.isna().to_numpy())[0])
            raise UserError(f"{p}: column 'trip_id' is empty at row {i}")
        if isinstance(tid.dtype, pd.CategoricalDtype):  # dictionary-encoded (streamed Parquet)
            cats = tid.cat.categories
            text = cats if pd.api.types.is_string_dtype(cats) else cats.astype(str)
            df["trip_id"] = tid.cat.rename_categories(text) if text.is_unique else tid.astype(str)
        else:
            df["trip_id"] = tid.astype(str)
    if len(df) < 2:
        raise UserError(f"{p}: a single sample; a drive log needs at least 2 samples per file "
                        "(acceleration and time weights come from neighbouring samples)")
    clipped = _validate(df, p, opt)
    return df, clipped


def _derive(df: pd.DataFrame, files: list[str], meta: dict, vehicle, opt: ReadOptions,
            clipped: int = 0) -> DriveLog:
    """Derived inputs, exclusion mask and counts of validated, concatenated tables."""
    counts: dict = {"files": len(files), "rows": int(len(df)),
                    "clipped_negative_speed": int(clipped),
                    "negative_speed_tolerance_mps": opt.negative_speed_tolerance_mps}
    if opt.speed_unit not in (None, "m/s"):
        counts["speed_unit"] = f"{opt.speed_unit} (converted to m/s)"
    # a trip that reappears after another trip (within a file, or across files)
    codes = trip_codes_of(df["trip_id"])
    first = np.flatnonzero(_trip_starts(codes))
    dup = pd.Series(codes[first]).duplicated().to_numpy()
    if dup.any():
        i = int(first[np.flatnonzero(dup)[0]])
        where = files[0] if len(files) == 1 else f"{len(files)} files"
        raise UserError(f"{where}: trip_id '{df['trip_id'].iloc[i]}' appears in more than one "
                        f"place (again at row {i}); samples of a trip must be contiguous, give "
                        "each trip its own id")
    trip_codes = np.cumsum(_trip_starts(codes)) - 1  # contiguous trips: 0, 1, … in order
    counts["trips"] = int(trip_codes.max() + 1)
    t = df["time_s"].to_numpy(float)
    v = df["speed_mps"].to_numpy(float)
    start = _trip_starts(trip_codes)
    if getattr(opt.measurement, "speed_scale", None) not in (None, 1.0):  # before anything derives from it
        from sumo_drvpw.data.corrections import scale_speed

        df["speed_mps"] = v = scale_speed(df, v, t, trip_codes, opt.measurement, counts,
                                          files[0] if len(files) == 1 else f"{len(files)} files")

    # time weight per sample: half the interval to each neighbour within the trip; an interval
    # longer than GAP_STEPS of the trip's own median step and GAP_MIN_S is a logging gap: no
    # samples, no weight (the neighbours' power is not stretched over it)
    dtf = np.r_[np.diff(t), 0.0]
    dtf[np.r_[start[1:], True]] = 0.0
    med = run_median_step(t, trip_codes)
    gap = dtf > np.maximum(GAP_STEPS * np.nan_to_num(med, nan=np.inf), GAP_MIN_S)[trip_codes]
    if np.isfinite(med).any():
        counts["time_gaps"] = int(gap.sum())
    if gap.any():
        counts["time_gaps_s"] = round(float(dtf[gap].sum()), 3)
        dtf[gap] = 0.0
    df["dt_s"] = 0.5 * (dtf + np.r_[0.0, dtf[:-1]])
    # stretches between gaps: derivatives never reach across one
    seg = np.cumsum(start | np.r_[False, gap[:-1]]) - 1

    # a file of a folder without the column: its trips' acceleration is derived (NaN there)
    lacking = None if "accel_mps2" not in df else _trips_without(df["accel_mps2"], trip_codes)
    if lacking is None or lacking.any():
        win, q = accel_window(opt, v, trip_codes)
        own = np.ones(len(win), bool) if lacking is None else lacking[start]  # trips derived
        win = np.where(own, win, opt.accel_window_s)  # a trip with the column: as read alone
        win_seg, (vd, hold) = win[trip_codes[_trip_starts(seg)]], accel_speed(opt, v, t, trip_codes, q)
        derived = derivative(vd, t, seg, win_seg, held_end_spans(vd, t, seg))  # ends over a held speed's updates
        if vd is not v:  # a speed held between updates: read between them, the terms' speed too
            df["speed_mps"] = v = vd
        df["accel_mps2"] = derived if lacking is None else np.where(lacking, derived, df["accel_mps2"].to_numpy(float))
        deriv = (seg, win_seg)
        n_derived = len(df) if lacking is None else int(lacking.sum())
        counts.update(accel_counts(accel_derivation(opt, win[own], q[own], len(df) - n_derived, n_derived,
                                                     med[own], hold[own])))
    else:
        counts.update(accel_counts(accel_derivation(opt, [], [], len(df), 0)))
        deriv = (seg, np.full(int(seg[-1]) + 1, opt.accel_window_s))

    derive_conditions(df, t, v, trip_codes, start, opt, counts)

    if "mass_kg" not in df and vehicle is not None:
        df["mass_kg"] = float(vehicle.mass_kg)
    elif vehicle is not None:  # a file of a folder without the column: the vehicle's mass
        lacking = _trips_without(df["mass_kg"], trip_codes)
        if lacking.any():
            df["mass_kg"] = np.where(lacking, float(vehicle.mass_kg), df["mass_kg"].to_numpy(float))
            counts["mass_from_vehicle_rows"] = int(lacking.sum())
    for c in FLAGS:  # a file of a folder without the flag (NaN there): not set, as read alone
        if c not in df:
            df[c] = False
        elif not pd.api.types.is_bool_dtype(df[c]):
            df[c] = df[c].astype("boolean").fillna(False).astype(bool)

    excluded = np.zeros(len(df), bool)
    for c in FLAGS:
        m = df[c].to_numpy(bool)
        counts[f"excluded_{c}"] = int(m.sum())
        excluded |= m
    a = df["accel_mps2"].to_numpy(float)
    out = np.abs(a) > opt.accel_outlier_mps2
    counts["excluded_accel_outlier"] = int((out & ~excluded).sum())
    counts["accel_outlier_limit_mps2"] = opt.accel_outlier_mps2
    excluded |= out
    steps, counts["speed_steps"] = speed_steps(df["speed_mps"].to_numpy(float), t, seg, 0.5 * deriv[1][seg],
                                               opt.accel_outlier_mps2)
    counts["excluded_speed_step"] = int((steps & ~excluded).sum())
    excluded |= steps
    steep = np.abs(np.tan(df["grade_rad"].to_numpy(float))) > opt.grade_outlier
    counts["excluded_grade_outlier"] = int((steep & ~excluded).sum())
    counts["grade_outlier_limit"] = opt.grade_outlier
    excluded |= steep
    for c in ("accel_mps2", "grade_rad", "wind_mps", "air_density_kgm3", "mass_kg"):
        if c in df:
            nan = df[c].isna().to_numpy()
            counts[f"excluded_nan_{c}"] = int((nan & ~excluded).sum())
            excluded |= nan
    counts["excluded_total"] = int(excluded.sum())
    return DriveLog(df=df, files=list(files), counts=counts, excluded=excluded,
                    metadata=meta, options=opt, deriv=deriv)
