"""The road and the air a drive log was driven in: grade, wind and air density, derived
where the log omits them (:func:`sumo_drvpw.data.log.read_log`'s derivations).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sumo_drvpw.data.trips import grade_from_elevation
from sumo_drvpw.model.air import air_density
from sumo_drvpw.model.constants import P_STD_KPA, RHO_DEFAULT
from sumo_drvpw.model.measurement import gps_scale_column


#: each condition's sources in the order a trip takes them: the first one that holds a
#: value in the trip (a trip with no value in a column is read as a file without it)
GRADE_SOURCES = ("grade_rad column", "grade_pct column", "elevation_m over distance", "none")
WIND_SOURCES = ("wind_mps column", "speed − airspeed_mps", "none")
DENSITY_SOURCES = ("air_density_kgm3 column", "ideal gas", "default")
#: the measured driving power's (:func:`sumo_drvpw.data.powertrain.measured_power`)
POWER_SOURCES = ("direct", "power-split", "single motor (motor torque × motor speed)", "single motor",
                 "battery", "fuel flow", "ESTIMATE: fuel from the mass air flow")
#: count → its sources; the count holds the rows of each source, keyed by the source's text
ROWS_OF = {"grade_rows": GRADE_SOURCES, "wind_rows": WIND_SOURCES, "air_density_rows": DENSITY_SOURCES,
           "power_rows": POWER_SOURCES}


def _pick(df: pd.DataFrame, cols, trip_codes: np.ndarray, least: int = 1) -> np.ndarray:
    """Per row, the index of the first of ``cols`` that holds at least ``least`` values in
    the row's trip; ``len(cols)`` where none does."""
    n = int(trip_codes.max()) + 1
    pick = np.full(n, len(cols))
    for i in range(len(cols) - 1, -1, -1):
        if cols[i] in df:
            held = np.bincount(trip_codes, weights=np.isfinite(df[cols[i]].to_numpy(float)), minlength=n)
            pick[held >= least] = i
    return pick[trip_codes]


def _rows(texts, pick: np.ndarray) -> dict:
    """Rows per source text, in the sources' order (sources without rows left out)."""
    n = np.bincount(pick, minlength=len(texts))
    return {t: int(k) for t, k in zip(texts, n) if k}


def _rank(key: str, count: str) -> int:
    return next(i for i, s in enumerate(ROWS_OF[count]) if key.startswith(s))


def merge_rows(a: dict, b: dict, count: str) -> dict:
    """Rows per source of two sets of whole trips read apart (:data:`ROWS_OF` ``count``)."""
    out = {k: a.get(k, 0) + b.get(k, 0) for k in {**a, **b}}
    return dict(sorted(out.items(), key=lambda kv: (_rank(kv[0], count), kv[0])))


def said(rows: dict) -> str:
    """One source: its text; several: each with its rows."""
    if len(rows) == 1:
        return next(iter(rows))
    return "; ".join(f"{k} for {n} rows" for k, n in rows.items())


def source_counts(counts: dict) -> dict:
    """The reader's source texts of the rows per source in ``counts`` (``grade_rows``,
    ``wind_rows``, ``air_density_rows``): ``grade_source`` (a flat road is said only when
    no trip has a grade: flat trips are listed in ``grade_flat_trips``; "elevation_m holds no
    value" when ``grade_elevation_column``), ``wind_source``,
    ``air_density_source``, ``power_source`` (the measured power's, ``power_rows``), and
    ``grade_filled_rows`` (rows without a grade_rad or grade_pct value in a log with such a
    column, ``grade_column``: the files of a folder without it)."""
    out = {}
    if "grade_rows" in counts:
        g = counts["grade_rows"]
        some = {k: n for k, n in g.items() if _rank(k, "grade_rows") < 3}
        out["grade_source"] = said(some) if some else (
            "none, set aside: read as a flat road (the logs' grade_rad, grade_pct and elevation_m not read as grade)"
            if counts.get("grade_set_aside_rows") else
            "none (elevation_m holds no value: flat road assumed)" if counts.get("grade_elevation_column")
            else "none (flat road assumed)")
        n_col = sum(n for k, n in g.items() if _rank(k, "grade_rows") < 2)
        if counts.get("grade_column") and n_col < sum(g.values()):
            out["grade_filled_rows"] = sum(g.values()) - n_col
    for c, text in (("wind_rows", "wind_source"), ("air_density_rows", "air_density_source"),
                    ("power_rows", "power_source")):
        if c in counts:
            out[text] = said(counts[c])
    return out


#: how far [m] the elevation jumps, steeper than any road, into a value a logger writes where
#: it has no fix (an RSK Twizy log: ALT = −111 in 122 samples of three trips, its roads at
#: 40–120 m): entered so at least twice and this far from its trip's median, it is no height
NO_FIX_JUMP_M = 50.0


def no_fix_elevations(z: np.ndarray, dist: np.ndarray, trip_codes: np.ndarray, use: np.ndarray,
                      steepest: float) -> tuple[list[float], int]:
    """The elevation values that are a logger's 'no fix' value, not a height, and the samples
    holding them: values the elevation jumps into, within a trip, by more than
    :data:`NO_FIX_JUMP_M` and steeper than ``steepest`` (rise over distance) at least twice,
    each more than :data:`NO_FIX_JUMP_M` from its trip's median (a hilltop logged in whole
    metres, stopped at, is none: no jump leads there). ``use``: the rows whose grade comes
    from ``z``; ``dist``: the distance driven within each trip [m]."""
    idx = np.flatnonzero(use & np.isfinite(z))
    if len(idx) < 3:
        return [], 0
    zz, dd, tc = z[idx], dist[idx], trip_codes[idx]
    dz = np.abs(np.diff(zz))
    jump = (tc[1:] == tc[:-1]) & (dz > NO_FIX_JUMP_M) & (dz > steepest * np.abs(np.diff(dd)))
    if not jump.any():
        return [], 0
    far = np.abs(zz - pd.Series(zz).groupby(tc).transform("median").to_numpy()) > NO_FIX_JUMP_M
    vals, cnt = np.unique(zz[1:][jump & far[1:]], return_counts=True)
    vals = vals[cnt >= 2]
    return [float(v) for v in vals], int(np.isin(zz, vals).sum())


#: a speed against a GPS speed logged beside it: compared where both exceed this [m/s] (a
#: GPS speed is good when moving, noisy near standstill), from this many samples, and said
#: where they differ by more than SPEED_GPS_DIFF
SPEED_GPS_MIN_MPS, SPEED_GPS_SAMPLES, SPEED_GPS_DIFF = 8.0, 200, 0.01


def gps_speed_columns(names) -> list[str]:
    """The GPS speeds among a log's column names (``gps_speed…_mps``), in their order: read
    beside the speed where a streamed reader reads only the columns it needs."""
    return [str(c) for c in names if str(c).startswith("gps_speed") and str(c).endswith("_mps")]


def speed_against_gps(df: pd.DataFrame, v: np.ndarray, counts: dict, column: str | None = None) -> None:
    """The log's speed against a GPS speed logged beside it (a column ``gps_speed…_mps``, a
    mapping's or an adapter's; the first, or ``column`` where a speed scale names it): their
    sums over the samples where both exceed :data:`SPEED_GPS_MIN_MPS`, in mm/s so that batches add (``speed_gps_samples``,
    ``speed_gps_sum_mm``, ``gps_speed_sum_mm``, ``speed_gps_column``). A speedometer or a
    wheel-speed signal reads high or low by a few per cent (tyre wear, pressure, a
    manufacturer's margin), and the coefficients take it: v' = k·v scales the kinetic term
    by k² and the aerodynamic by k³, so a fit reads acc ≈ 1/k² and aero ≈ 1/k³ of the
    vehicle's, where a SUMO run's speeds are exact (:func:`speed_gps_note`)."""
    cols = [column] if column in df else gps_speed_columns(df.columns)
    if not cols:
        return
    g = df[cols[0]].to_numpy(float)
    both = np.isfinite(g) & np.isfinite(v) & (g > SPEED_GPS_MIN_MPS) & (v > SPEED_GPS_MIN_MPS)
    if both.any():
        counts["speed_gps_column"] = cols[0]
        counts["speed_gps_samples"] = int(both.sum())
        counts["speed_gps_sum_mm"] = int(round(float(v[both].sum()) * 1000))
        counts["gps_speed_sum_mm"] = int(round(float(g[both].sum()) * 1000))


def speed_gps_note(counts: dict) -> str:
    """What a speed reading high or low against the GPS speed beside it does to a fit
    (:func:`speed_against_gps`'s counts); '' where they agree within :data:`SPEED_GPS_DIFF`
    or too few samples compare them."""
    n, sv, sg = (int(counts.get(k, 0) or 0) for k in ("speed_gps_samples", "speed_gps_sum_mm", "gps_speed_sum_mm"))
    if n < SPEED_GPS_SAMPLES or sg <= 0:
        return ""
    k = sv / sg
    if abs(k - 1.0) <= SPEED_GPS_DIFF:
        return ""
    col = counts.get("speed_gps_column", "the GPS speed")
    return (f"speed_mps reads {abs(k - 1):.1%} {'above' if k > 1 else 'below'} {col} ({n} samples where both exceed "
            f"{SPEED_GPS_MIN_MPS:g} m/s): a speedometer's {'over' if k > 1 else 'under'}-read, which the coefficients take "
            f"(acc × {1 / k ** 2:.3f}, aero × {1 / k ** 3:.3f} of the vehicle's, where a SUMO run's speeds are exact); "
            f"correct the speed: the measurement correction speed_scale = \"gps\" (each trip's own scale against "
            f"the GPS speed) or {1 / k:.4f}, a mapping's scale = {1 / k:.4f} on it, or the GPS speed logged as speed_mps")


def derive_conditions(df: pd.DataFrame, t: np.ndarray, v: np.ndarray, trip_codes: np.ndarray,
                      start: np.ndarray, opt, counts: dict) -> None:
    """``grade_rad``, ``wind_mps`` and ``air_density_kgm3`` of a validated table (``df``
    changed in place; their sources and fills in ``counts``), each trip from its own
    columns: the first source that holds a value in the trip, so a file of a folder is read
    as it is alone, and a batch of whole trips as in the whole log.

    Grade: ``grade_rad``, else atan(``grade_pct``/100), else from ``elevation_m`` (at least
    two values) over distance, else a flat road. Wind: ``wind_mps``, else speed −
    ``airspeed_mps``, else still air. Air density: ``air_density_kgm3``, else the ideal gas
    from ``ambient_c`` and ``pressure_kpa`` (standard pressure where none is logged, the
    default density where no temperature is), else the default density.

    Parameters
    ----------
    df : the concatenated, validated table; t, v : its time [s] and speed [m/s]
    trip_codes : contiguous trip code per row (0, 1, … in order); start : a trip's first row
    opt : the reading options (:class:`sumo_drvpw.data.log.ReadOptions`)
    """
    n = len(df)
    speed_against_gps(df, v, counts, gps_scale_column(getattr(opt.measurement, "speed_scale", None)))

    def col(c):
        return df[c].to_numpy(float) if c in df else np.full(n, np.nan)

    # grade; columns without values are said so (flags, only ever True: kept when batches merge)
    if "elevation_m" in df:
        counts["grade_elevation_column"] = True
    if "grade_rad" in df or "grade_pct" in df:
        counts["grade_column"] = True
    g = _pick(df, ("grade_rad", "grade_pct"), trip_codes)
    z_trip = _pick(df, ("elevation_m",), trip_codes, least=2) == 0
    g = np.where((g == 2) & z_trip, 2, np.where(g == 2, 3, g))
    aside = bool(getattr(opt, "flat_road", False)) and bool((g < 3).any())
    if aside:  # read as a flat road, as asked: the logged grade and elevation set aside
        counts["grade_set_aside_rows"] = counts.get("grade_set_aside_rows", 0) + int((g < 3).sum())
        g = np.full(n, 3)
    theta = np.zeros(n)
    theta = np.where(g == 0, col("grade_rad"), theta)
    theta = np.where(g == 1, np.arctan(col("grade_pct") / 100.0), theta)
    elev = g == 2
    if elev.any():
        step = v * np.r_[0.0, np.diff(t)]
        step[start] = 0.0
        dist = pd.Series(step).groupby(trip_codes, sort=False).cumsum().to_numpy()
        z = col("elevation_m")
        theta = np.where(elev, grade_from_elevation(z, dist, trip_codes, opt.grade_window_m), theta)
        # a stretch without elevation (no GPS fix) is bridged or held: said (no grade energy there)
        counts["elevation_missing_samples"] = int((elev & ~np.isfinite(z)).sum())
        held, n_held = no_fix_elevations(z, dist, trip_codes, elev, opt.grade_outlier)
        if held:  # a logger's value for 'no fix' read as a height: said (the user maps it away)
            counts["elevation_no_fix_values"], counts["elevation_no_fix_samples"] = held, n_held
    df["grade_rad"] = theta
    counts["grade_rows"] = _rows(GRADE_SOURCES[:2] + (
        f"elevation_m over distance: 1 m grid, {opt.grade_window_m:g} m moving average, gradient",
        "none (flat road assumed)"), g)
    flat = df["trip_id"].to_numpy()[start & (g == 3)]  # a trip without grade is read flat: said
    if len(flat) and not getattr(opt, "flat_road", False):
        counts["grade_flat_trips"] = [str(x) for x in flat]

    # wind
    w = _pick(df, ("wind_mps", "airspeed_mps"), trip_codes)
    df["wind_mps"] = np.where(w == 0, col("wind_mps"), np.where(w == 1, v - col("airspeed_mps"), 0.0))
    counts["wind_rows"] = _rows(WIND_SOURCES[:2] + ("none (still air assumed)",), w)

    # air density
    r = _pick(df, ("air_density_kgm3", "ambient_c"), trip_codes)
    rho = np.where(r == 0, col("air_density_kgm3"), RHO_DEFAULT)
    gas = r == 1
    # each row's source: 0 the column, 1 ideal gas at the logged pressure, 2 at standard
    # pressure (none logged in that row), 3 the default density
    src = np.where(r == 0, 0, 3)
    if gas.any():
        p_kpa = col("pressure_kpa")
        std = np.isnan(p_kpa)
        p_kpa = np.where(std, P_STD_KPA, p_kpa)  # missing pressure: standard
        ideal = air_density(col("ambient_c"), p_kpa)
        missing = gas & np.isnan(ideal)  # no temperature logged in that sample: the default density
        rho = np.where(gas & ~missing, ideal, rho)
        src = np.where(gas & ~missing, np.where(std, 2, 1), src)
        counts["air_density_default_samples"] = int(missing.sum())
    df["air_density_kgm3"] = rho
    counts["air_density_rows"] = _rows(("air_density_kgm3 column", "ideal gas from ambient_c and pressure_kpa",
                                        f"ideal gas from ambient_c at standard pressure ({P_STD_KPA:g} kPa)",
                                        f"default {RHO_DEFAULT} kg/m³"), src)
    counts.update(source_counts(counts))
