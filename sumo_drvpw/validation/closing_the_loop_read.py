"""The closing-the-loop study's logs (:mod:`sumo_drvpw.validation.closing_the_loop`):
training and held-out trips written as canonical logs, read with the measurement
corrections a closed-loop equation declares (power lag, grade source, ρ at altitude,
logger dropouts: :func:`measurement_of`), and the input checks on them (inputs only)."""

from __future__ import annotations

import math

import numpy as np

#: the grade source "the accelerometer less the logger's offset" (an entry of
#: closing_the_loop_fit.TAU_GRID_S; the offset: :func:`logger_offset`)
LOGGER_OFFSET = "logger offset"

#: take logger dropouts (held or linearly filled inputs) out of the usable samples of every
#: log, training and held out alike, for every equation (fit.input_checks.dropout_mask)
CHECK_DROPOUTS = True


def distance_crossover_m(tau) -> float | None:
    """The crossover [m] of a grid entry "<L> m" (a fusion over driven distance), else None."""
    if isinstance(tau, str) and tau.endswith(" m"):
        return float(tau[:-2])
    return None


def write_subset(df, trips, path, keep: bool, roles: dict | None = None):
    """The trips (``keep``) or all but them, as a canonical log with the adapter's roles."""
    import pyarrow as pa

    from sumo_drvpw.data.roles import to_metadata
    from sumo_drvpw.fileio import write_parquet

    sub = df[df["trip_id"].isin(trips) == keep].reset_index(drop=True)
    table = pa.Table.from_pandas(sub, preserve_index=False)
    kept = {c: r for c, r in (roles or {}).items() if c in sub.columns}
    if kept:
        table = table.replace_schema_metadata({**(table.schema.metadata or {}), **to_metadata(kept)})
    write_parquet(path, table)
    return path


def _has_accelerometer(path) -> bool:
    import pyarrow.parquet as pq

    from sumo_drvpw.data.corrections import ACCELEROMETER_COLUMNS

    return any(c in pq.read_schema(path).names for c in ACCELEROMETER_COLUMNS)


def _load(path, vehicle, meas):
    """load_measured with the measurement corrections ``meas`` (data/corrections.py, as any
    command reads a log whose equation declares them); ``m.dropouts`` = trip → seconds of
    logger dropouts taken out (None without the check)."""
    from sumo_drvpw.data.dropouts import dropout_report, log_dropouts
    from sumo_drvpw.data.log import ReadOptions
    from sumo_drvpw.data.measured import load_measured

    m = load_measured([path], vehicle, ReadOptions(measurement=meas))
    m.dropouts = None
    if meas is not None and meas.exclude_dropouts:
        df = m.log.df
        drop = log_dropouts(m.log)
        m.dropouts = dropout_report(drop, df["trip_id"].to_numpy(), df["dt_s"].to_numpy(float))
    return m


def load_checked(path, vehicle):
    """load_measured with the logger-dropout check (data.dropouts: speed and a longitudinal
    accelerometer exactly linear in time for ≥ 5 s, and the grade-smoothing distance around
    it; inputs only) taken out of the usable samples — ``[measurement] exclude_dropouts``."""
    from sumo_drvpw.model.measurement import Measurement

    return _load(path, vehicle, Measurement(exclude_dropouts=_has_accelerometer(path)))


def _offsets(m):
    from sumo_drvpw.data.corrections import accelerometer_column, driven_path
    from sumo_drvpw.fit.input_checks import accelerometer_offsets

    df = m.log.df
    return accelerometer_offsets(df[accelerometer_column(df.columns)], m.inputs.a, df["speed_mps"], df["elevation_m"],
                                 df["dt_s"], df["trip_id"], driven_path(m.log, m.inputs.v))


def _trip_inputs(m) -> dict:
    """Per trip, what its inputs say (no power): weather, mean ambient, declared mass,
    net elevation change, distance and share of standstill."""
    df = m.log.df
    out = {}
    for t, i in df.groupby("trip_id", sort=True).indices.items():
        u = m.usable[i]
        r = {}
        if "weather" in df:
            r["weather"] = str(df["weather"].iloc[i[0]])
        if "ambient_c" in df:
            r["ambient_c"] = float(np.nanmean(df["ambient_c"].to_numpy(float)[i][u]))
        r["mass_kg"] = float(np.nanmedian(m.inputs.mass[i][u]))
        if "elevation_m" in df:
            h = df["elevation_m"].to_numpy(float)[i][u]
            h = h[np.isfinite(h)]
            r["dh_m"] = float(h[-1] - h[0]) if len(h) else math.nan
        v = m.inputs.v[i][u]
        r["distance_km"] = float(np.sum(v * df["dt_s"].to_numpy(float)[i][u])) / 1000.0
        r["standstill"] = float(np.mean(v < 0.1))
        out[str(t)] = r
    return out


def input_checks(m_train, eq, held) -> dict:
    """Plausibility of the declared inputs (fit.input_checks): per training trip the inertial
    mass seen in the measured power (relative to the declared mass × the calibrated mass
    factor ``acc``: a check of the declared mass, never substituted); per trip (training and,
    added later, held out: inputs only) the accelerometer offset from standstill and from the
    elevation; dropouts taken out."""
    from sumo_drvpw.fit.input_checks import inertial_mass

    df = m_train.log.df
    out = {"dropouts_train": getattr(m_train, "dropouts", None), "offsets": {}, "mass": {}}
    acc = float(eq.terms.get("acc", np.nan))
    # a comparison across trips: with fewer than 3 training trips it only restates the fit
    if "mass_kg" in df and np.isfinite(acc) and df["trip_id"].nunique() >= 3:
        im = inertial_mass(m_train.power_w, m_train.inputs, m_train.usable, df["trip_id"].to_numpy())
        for t, r in im.items():
            r["vs_declared"] = r["ratio"] / acc - 1.0
        out["mass"] = im
        out["acc"] = acc
    if "imu_accel_mps2" in df and "elevation_m" in df:
        out["offsets"] = _offsets(m_train)
    return out


def measurement_of(path, lag_s: float, accel_grade: bool, tau_s=None, offset_mps2: float | None = None):
    """The corrections of a log (:class:`sumo_drvpw.model.measurement.Measurement`): the power
    read ``lag_s`` later within trips; the grade fused from the accelerometer (fast part) and
    the logged grade (slow part, free of the accelerometer's mounting pitch; ``tau_s`` a
    crossover in time [s] or over driven distance, "<L> m"), or with ``tau_s`` = ∞ the
    accelerometer alone with its per-trip offset fixed by the elevation, or
    with ``tau_s`` = LOGGER_OFFSET the accelerometer less the logger's offset ``offset_mps2``;
    ρ at the logged altitude (standard atmosphere) when pressure is not logged; logger
    dropouts left out (CHECK_DROPOUTS). The closed-loop equations carry it as their
    ``[measurement]``, so `sumo-drvpw compare` reads new logs the same way."""
    import pyarrow.parquet as pq

    from sumo_drvpw.model.measurement import Measurement

    cols = set(pq.read_schema(path).names)
    acc = _has_accelerometer(path)
    dist_m = distance_crossover_m(tau_s)
    timed = isinstance(tau_s, (int, float)) and not isinstance(tau_s, bool) and math.isfinite(tau_s)
    fused = timed or dist_m is not None
    grade, offset = "logged", None
    if accel_grade and acc:
        grade = "accelerometer" if tau_s is not None and not fused else "fused"
        if tau_s == LOGGER_OFFSET:
            offset = float(offset_mps2)
    return Measurement(
        power_lag_s=float(lag_s), grade=grade, accelerometer_offset_mps2=offset,
        fusion_tau_s=float(tau_s) if timed else None, fusion_distance_m=dist_m,
        air_density="altitude" if {"elevation_m", "ambient_c"} <= cols and "pressure_kpa" not in cols else "logged",
        exclude_dropouts=CHECK_DROPOUTS and acc)


def corrected_measured(path, vehicle, lag_s: float, accel_grade: bool, tau_s=None,
                       offset_mps2: float | None = None):
    """Measured power and inputs of a log with the corrections of :func:`measurement_of`."""
    return _load(path, vehicle, measurement_of(path, lag_s, accel_grade, tau_s, offset_mps2))


def logger_offset(m) -> dict:
    """The logger's accelerometer offset from a Measured's inputs (never its power): the
    median over its trips of the offsets their elevation changes imply
    (data.corrections.logger_offset_mps2), with the per-trip spread it replaces."""
    from sumo_drvpw.data.corrections import accelerometer_column, logger_offset_mps2

    if "elevation_m" not in m.log.df or accelerometer_column(m.log.df.columns) is None:
        return {"offset_mps2": math.nan, "trips": 0, "iqr_mps2": [math.nan, math.nan]}
    per = _offsets(m)
    offs = [d["offset_elevation"] for d in per.values()]
    est = logger_offset_mps2(offs, [d["distance_m"] for d in per.values()])
    q = np.nanpercentile(offs, [25, 75]) if len(offs) else [math.nan, math.nan]
    return {"offset_mps2": est, "trips": len(offs), "iqr_mps2": [float(q[0]), float(q[1])]}
