"""Measurement corrections applied to a read log: timing, grade, air density.

What the corrections are and how an equation declares them: :mod:`sumo_drvpw.model.measurement`.
This module does the signal processing, trip by trip (nothing crosses a trip boundary):

* **timing** — the power read ``power_lag_s`` later, y'(i) = y(i + ℓ) with ℓ = lag/Δt whole
  samples inside the trip, NaN (not usable) where i + ℓ leaves it;
* **grade from a longitudinal accelerometer**, which reads dv/dt + g·sin θ:
  sin θ_acc = (a_imu − dv/dt)/g over a centred 5-s mean (:func:`accelerometer_sin_grade`);
  ``fused``: sin θ = LP(sin θ_log) + sin θ_acc − LP(sin θ_acc), LP a centred mean over the
  crossover — the elevation's grade is unbiased over distance but smoothed, the
  accelerometer sharp but biased by its mounting pitch. The crossover is a time
  (:func:`fused_sin_grade`, the default), which weights standing and slow samples by time
  and lets the grade's integral drift from the elevation (tens of metres on long trips), or
  a distance (:func:`fused_sin_grade_distance`): LP weights each sample by the distance it
  drove, so the fused grade integrates over the trip, Σ sin θ·ds, to the logged elevation
  change (the grade energy m·g·Δh);
  ``accelerometer``: sin θ_acc minus one offset per trip fixed by Σ sin θ·ds = Δh
  (:func:`offset_corrected_sin_grade`), or, with ``accelerometer_offset_mps2``, minus the
  logger's own fixed offset (its mounting pitch; :func:`logger_offset_mps2` estimates it
  from many trips) and no elevation at all;
* **air density at altitude** — ρ·p(h)/p₀ with the standard-atmosphere pressure at the
  logged elevation (:func:`sumo_drvpw.model.air.pressure_at_altitude_kpa`), where pressure is
  not logged (the reader then assumed sea level);
* **logger dropouts** left out of the usable samples (:mod:`sumo_drvpw.data.dropouts`);
* **speed scale** — the logged speed times k, v' = k·v, before the reader derives anything
  from it (:func:`scale_speed`, called by :func:`sumo_drvpw.data.log.read_log`): the
  acceleration (k·a), the distance (k·s) and the grade from elevation over that distance
  (tan θ/k; its power m·g·v·sin θ, the elevation's rate, is unchanged) follow. k declared,
  or ``"gps"``: per trip, Σ GPS speed / Σ speed over its steady samples whose ratio lies near
  the trip's median (both above 8 m/s, |dv/dt| below 0.3 m/s², where a GPS speed neither lags
  nor is noise; :func:`gps_speed_scales`). A speed k too high puts 1/k² into the acc coefficient, 1/k
  into roll and 1/k³ into aero — coefficients SUMO, whose speeds are exact, would use.
"""

from __future__ import annotations

import math

import numpy as np

from sumo_drvpw.data.conditions import SPEED_GPS_MIN_MPS as GPS_SCALE_MIN_MPS, gps_speed_columns
from sumo_drvpw.data.trips import derivative, per_trip_rolling_mean, trip_codes_of, trip_starts
from sumo_drvpw.errors import UserError
from sumo_drvpw.model.air import pressure_at_altitude_kpa
from sumo_drvpw.model.constants import G, P_STD_KPA
from sumo_drvpw.model.measurement import FUSION_DISTANCE_M, FUSION_TAU_S, Measurement, gps_scale_column

#: smoothing of the accelerometer grade [s]
ACC_GRADE_WINDOW_S = 5.0
#: names of a longitudinal accelerometer column (reads dv/dt + g·sin θ)
ACCELEROMETER_COLUMNS = ("imu_accel_mps2", "accel_long_mps2", "longitudinal_accel_mps2")
#: largest |sin θ| a corrected grade may take (17°)
MAX_SIN_GRADE = 0.3
#: a corrected grade whose integral over a trip misses the logged elevation change by more
#: than this is reported [m] (20 m of a 1.5-t car: 0.08 kWh of grade energy)
GRADE_GAP_NOTE_M = 20.0
#: trips listed by name in that report (the largest gaps)
GAP_LISTED = 10
#: shortest trip whose elevation change fixes an offset for the logger's estimate [m]: over
#: 1 km a 10-m elevation error is a 0.1 m/s² offset error, over 10 km 0.01
MIN_OFFSET_DISTANCE_M = 1000.0


#: steady samples of a trip's speed against its GPS speed: both above GPS_SCALE_MIN_MPS (a GPS
#: speed is noise near standstill), |dv/dt| below STEADY_ACCEL_MPS2 [m/s²] (a GPS speed lags
#: behind a change of speed), at least GPS_SCALE_SAMPLES of them (their ratios' quartiles lie
#: about ±0.6 % apart on the shared Prius logs: a scale from 100 is within about ±0.1 %)
STEADY_ACCEL_MPS2, GPS_SCALE_SAMPLES = 0.3, 100
#: a steady sample's ratio gps/v farther than this from its trip's median is a GPS glitch, not
#: the speed's scale (the ratios' quartiles lie about ±0.6 % apart on the shared Prius logs)
GPS_SCALE_BAND = 0.05
#: width of the centred mean of the speed's derivative that tells a steady sample [s]
STEADY_WINDOW_S = 2.0
#: two GPS speeds of a log disagree where their scales of a trip lie further apart than this
#: (relative): each is measured within about ±0.1 % (GPS_SCALE_SAMPLES), so more is two
#: sensors, one of them off (a phone's GPS against a logger's), and the log must name one
GPS_COLUMNS_AGREE = 0.002


def gps_speed_scales(v, gps, t, trip_codes) -> tuple[np.ndarray, np.ndarray]:
    """Per trip, the scale k that takes a speed to the GPS speed logged beside it, and the
    number of the trip's steady samples it is measured on (both above
    :data:`GPS_SCALE_MIN_MPS`, |dv/dt| over a centred :data:`STEADY_WINDOW_S` below
    :data:`STEADY_ACCEL_MPS2`): k = Σ gps / Σ v over those of them whose ratio gps/v lies
    within :data:`GPS_SCALE_BAND` of the trip's median ratio. The band keeps a GPS speed's
    dropouts and jumps out; the sums, not the median itself, because speeds logged in whole
    km/h put the median ratio on a few fractions (59/60 on the shared Prius logs for a
    ratio of sums of 1/1.0166). NaN where a trip has no steady sample.

    Parameters
    ----------
    v, gps : speed and GPS speed per sample [m/s]
    t : time [s]; trip_codes : contiguous trip codes 0, 1, … per sample
    """
    v, g = np.asarray(v, float), np.asarray(gps, float)
    codes = np.asarray(trip_codes)
    a = derivative(v, np.asarray(t, float), codes, STEADY_WINDOW_S)
    ok = (np.isfinite(v) & np.isfinite(g) & (v > GPS_SCALE_MIN_MPS) & (g > GPS_SCALE_MIN_MPS)
          & (np.abs(a) < STEADY_ACCEL_MPS2))
    n_trips = int(codes.max()) + 1 if len(codes) else 0
    k, n = np.full(n_trips, np.nan), np.bincount(codes[ok], minlength=n_trips)
    order = np.argsort(codes[ok], kind="stable")  # each trip's steady samples together, in their order
    g, v = g[ok][order], v[ok][order]
    r = g / v
    cuts = np.cumsum(n[n > 0])[:-1]  # (one pass over the samples, not one per trip)
    for c, gi, vi, ri in zip(np.flatnonzero(n), np.split(g, cuts), np.split(v, cuts), np.split(r, cuts)):
        near = np.abs(ri - np.median(ri)) <= GPS_SCALE_BAND
        k[c] = float(gi[near].sum() / vi[near].sum())
    return k, n


def scale_speed(df, v, t, trip_codes, meas: Measurement | None, counts: dict, where: str) -> np.ndarray:
    """The speed times the scale of ``meas`` (``speed_scale``; the speed as read when it has
    none), for the reader to derive the rest from; ``counts["speed_scale"]``: the scale per
    trip (trip id → k). With ``"gps"``, each trip's own (:func:`gps_speed_scales`) against the
    log's GPS speed column, or the one ``"gps:COLUMN"`` names; a log without a GPS speed column
    (or without the one named), a trip with fewer than :data:`GPS_SCALE_SAMPLES` steady samples,
    or two GPS speeds whose scales of a trip differ by more than :data:`GPS_COLUMNS_AGREE` (none
    named), is a :class:`UserError` naming ``where``, the columns and the trip."""
    k_decl = getattr(meas, "speed_scale", None)
    if k_decl is None or k_decl == 1.0:
        return v
    trips = df["trip_id"].to_numpy()[trip_starts(trip_codes)] if len(trip_codes) else []
    if not isinstance(k_decl, str):
        counts["speed_scale"] = {str(tid): round(float(k_decl), 6) for tid in trips}
        return np.asarray(v, float) * float(k_decl)
    cols, named = gps_speed_columns(df.columns), gps_scale_column(k_decl)
    if named is not None and named not in cols:
        raise UserError(f"{where}: speed scale '{k_decl}': no column {named} (its GPS speeds: "
                        f"{', '.join(cols) or 'none'})")
    cols = [named] if named is not None else cols
    if not cols:
        raise UserError(f"{where}: speed scale 'gps' needs a GPS speed logged beside the speed (a column "
                        "gps_speed…_mps); declare the scale as a number instead (e.g. 0.984 for a speed 1.6 % high)")
    k, n = gps_speed_scales(v, df[cols[0]].to_numpy(float), t, trip_codes)
    few = np.flatnonzero(n < GPS_SCALE_SAMPLES)
    if len(few):
        c = int(few[0])
        raise UserError(f"{where}: trip '{trips[c]}': speed scale '{k_decl}' needs at least {GPS_SCALE_SAMPLES} steady "
                        f"samples of speed_mps and {cols[0]} (both above {GPS_SCALE_MIN_MPS:g} m/s, |dv/dt| below "
                        f"{STEADY_ACCEL_MPS2:g} m/s²), found {int(n[c])}; declare the scale as a number for it")
    for other in cols[1:]:  # two GPS speeds, none named: the same scale, or the user names one
        k2, n2 = gps_speed_scales(v, df[other].to_numpy(float), t, trip_codes)
        off = np.flatnonzero((n2 >= GPS_SCALE_SAMPLES) & (np.abs(k2 / k - 1) > GPS_COLUMNS_AGREE))
        if len(off):
            c = int(off[0])
            raise UserError(f"{where}: trip '{trips[c]}': speed scale 'gps': the log's GPS speeds disagree, "
                            f"{cols[0]} gives {k[c]:.4f} and {other} {k2[c]:.4f}; name the one to scale the speed "
                            f"to: speed_scale = \"gps:{cols[0]}\" or \"gps:{other}\"")
    counts["speed_scale"] = {str(tid): round(float(x), 6) for tid, x in zip(trips, k)}
    counts["speed_scale_column"] = cols[0]
    return np.asarray(v, float) * k[np.asarray(trip_codes)]


def shift_within_trips(y: np.ndarray, trip_codes: np.ndarray, lag: int) -> np.ndarray:
    """y(i + lag) where sample i + lag is in the same trip, else NaN."""
    n = len(y)
    out = np.full(n, np.nan)
    if lag == 0:
        return np.asarray(y, float).copy()
    src = np.arange(n) + lag
    ok = (src >= 0) & (src < n)
    ok[ok] &= trip_codes[src[ok]] == trip_codes[ok]
    out[ok] = y[src[ok]]
    return out


def _window(seconds: float, dt_s: float) -> int:
    return max(1, int(round(seconds / max(dt_s, 1e-3))))


def accelerometer_sin_grade(imu_mps2, accel_mps2, trip_codes, dt_s: float,
                            window_s: float = ACC_GRADE_WINDOW_S) -> np.ndarray:
    """sin θ from a longitudinal accelerometer: (a_imu − dv/dt)/g, a centred moving mean of
    ``window_s`` within trips, clipped to ±0.3 (17°).

    Parameters
    ----------
    imu_mps2 : accelerometer reading, dv/dt + g·sin θ [m/s²]
    accel_mps2 : dv/dt from the speed signal [m/s²]
    trip_codes : trip code per sample (contiguous trips)
    dt_s : sample interval [s]
    """
    s = (np.asarray(imu_mps2, float) - np.asarray(accel_mps2, float)) / G
    sm = per_trip_rolling_mean(s, np.asarray(trip_codes), _window(window_s, dt_s))
    return np.clip(sm, -MAX_SIN_GRADE, MAX_SIN_GRADE)


def fused_sin_grade(sin_acc, sin_log, trip_codes, dt_s: float, tau_s: float = FUSION_TAU_S) -> np.ndarray:
    """Complementary fusion of two grades: sin θ = LP(sin θ_log) + (sin θ_acc − LP(sin θ_acc)),
    LP a centred moving mean of ``tau_s`` within trips. The logged grade (from elevation) is
    unbiased over long distances but smoothed; the accelerometer is sharp but carries its
    mounting pitch as a bias. [sin θ, -]"""
    codes = np.asarray(trip_codes)
    w = _window(tau_s, dt_s)
    sa = np.asarray(sin_acc, float)
    out = per_trip_rolling_mean(np.asarray(sin_log, float), codes, w) + sa - per_trip_rolling_mean(sa, codes, w)
    return np.clip(out, -MAX_SIN_GRADE, MAX_SIN_GRADE)


def distance_mean(x, speed_mps, dt_s, trip_codes, length_m: float) -> np.ndarray:
    """Centred moving mean of ``x`` over ``length_m`` of driven distance, within trips.

    Each sample stands at the middle of the distance it drove, d = Σ v·Δt − v·Δt/2, and
    is weighted by that distance v·Δt: the mean at a sample is Σ x·ds / Σ ds over the
    samples within ±length_m/2 of it (so standing samples carry no weight and take the
    mean of where the car stands). NaN values and speeds carry no weight; where the window
    has none at all (a trip that never moves) the value itself is kept.

    Parameters
    ----------
    x : values per sample
    speed_mps : speed per sample [m/s]
    dt_s : sample duration [s], per sample or one number
    trip_codes : trip code per sample (contiguous trips; windows never cross them)
    length_m : window [m]
    """
    x = np.asarray(x, float)
    v = np.asarray(speed_mps, float)
    ds = np.where(np.isfinite(v) & (v > 0), v, 0.0) * np.broadcast_to(np.asarray(dt_s, float), v.shape)
    ds = np.where(np.isfinite(ds), ds, 0.0)
    codes = np.asarray(trip_codes)
    start = trip_starts(codes) if len(codes) else np.zeros(0, bool)
    # one monotone axis for every trip, each trip set length_m + 1 m beyond the last
    d = np.cumsum(ds) - ds / 2 + np.cumsum(start) * (float(length_m) + 1.0)
    w = np.where(np.isfinite(x), ds, 0.0)
    cs = np.r_[0.0, np.cumsum(np.where(w > 0, x, 0.0) * w)]
    cw = np.r_[0.0, np.cumsum(w)]
    lo = np.searchsorted(d, d - length_m / 2, "left")
    hi = np.searchsorted(d, d + length_m / 2, "right")
    den = cw[hi] - cw[lo]
    return np.where(den > 0, (cs[hi] - cs[lo]) / np.where(den > 0, den, 1.0), x)


def fused_sin_grade_distance(sin_acc, sin_log, speed_mps, dt_s, trip_codes,
                             length_m: float = FUSION_DISTANCE_M) -> np.ndarray:
    """Complementary fusion of two grades over distance: sin θ = LP(sin θ_log) + (sin θ_acc −
    LP(sin θ_acc)), LP the distance-weighted centred mean over ``length_m`` within trips
    (:func:`distance_mean`). Grade is a property of the road's position, and its energy is
    m·g·Σ sin θ·ds: the slow part, from the elevation, keeps the trip's elevation change,
    the fast part, from the accelerometer, integrates to about nothing over any window of
    ``length_m``, and the accelerometer's mounting pitch (a constant) drops out. [sin θ, -]"""
    sa = np.asarray(sin_acc, float)
    out = (distance_mean(sin_log, speed_mps, dt_s, trip_codes, length_m)
           + sa - distance_mean(sa, speed_mps, dt_s, trip_codes, length_m))
    return np.clip(out, -MAX_SIN_GRADE, MAX_SIN_GRADE)


def offset_corrected_sin_grade(sin_acc, speed_mps, dt_s, trip_codes, elevation_m, usable=None) -> np.ndarray:
    """Accelerometer grade with its per-trip offset removed: sin θ_acc − c, with c per trip
    such that Σ (sin θ_acc − c)·ds = Δh (elevation at the trip's last sample in ``usable``
    minus at its first). An input correction: the mounting pitch is one constant per trip, the
    elevation fixes it; no low-pass of the logged grade. ``usable`` must mark the whole
    driven path (braking included: leaving part of the path out biases c by the elevation
    change along it). [sin θ, -]"""
    s = np.asarray(sin_acc, float)
    v = np.asarray(speed_mps, float)
    dt = np.asarray(dt_s, float)
    h = np.asarray(elevation_m, float)
    codes = np.asarray(trip_codes)
    u = np.ones(len(s), bool) if usable is None else np.asarray(usable, bool)
    out = s.copy()
    for c in np.unique(codes):
        i = np.flatnonzero(codes == c)
        ok = u[i] & np.isfinite(s[i]) & np.isfinite(v[i]) & np.isfinite(h[i])
        if not ok.any():
            continue
        ds = np.where(ok, v[i] * dt[i], 0.0)
        dist = ds.sum()
        if dist <= 0:
            continue
        hh = h[i][ok]
        out[i] = s[i] - (float(np.sum(np.where(ok, s[i], 0.0) * ds)) - (hh[-1] - hh[0])) / dist
    return np.clip(out, -MAX_SIN_GRADE, MAX_SIN_GRADE)


def driven_path(log, speed_mps) -> np.ndarray:
    """The samples whose speed is a measurement of the path the car drove: finite, and not
    a logger dropout (:func:`sumo_drvpw.data.dropouts.log_dropouts`, where the log has an
    accelerometer). An elevation change is matched against the grade over all of them —
    braking and other samples left out of a power fit included."""
    from sumo_drvpw.data.dropouts import log_dropouts

    return _path(speed_mps, log_dropouts(log))


def _path(speed_mps, drop) -> np.ndarray:
    path = np.isfinite(np.asarray(speed_mps, float))
    return path if drop is None else path & ~drop


def logger_offset_mps2(per_trip_offsets, distances_m, min_distance_m: float = MIN_OFFSET_DISTANCE_M) -> float:
    """The logger's own accelerometer offset [m/s²]: the median over trips of the per-trip
    offsets that each trip's elevation change implies (g·(Σ sin θ_acc·ds − Δh)/Σ ds,
    :func:`sumo_drvpw.fit.input_checks.accelerometer_offsets`), over trips of at least
    ``min_distance_m``.

    A logger fixed in the car has one mounting pitch; what the per-trip offsets scatter by is
    the error of each trip's logged elevation change (GPS elevation settling, coarse or
    interpolated points) spread over its distance. The median over many trips keeps the
    mounting pitch and drops those errors; a single trip's elevation then no longer enters
    its grade. NaN when no trip is long enough.
    """
    off = np.asarray(per_trip_offsets, float)
    dist = np.asarray(distances_m, float)
    ok = np.isfinite(off) & np.isfinite(dist) & (dist >= min_distance_m)
    return float(np.median(off[ok])) if ok.any() else math.nan


def accelerometer_column(columns) -> str | None:
    """The first longitudinal-accelerometer column among ``columns``, or None."""
    return next((c for c in ACCELEROMETER_COLUMNS if c in columns), None)


def needed_columns(meas: Measurement | None) -> set[str]:
    """Log columns the corrections of ``meas`` read beyond the canonical inputs (a reader that
    selects columns adds these)."""
    if meas is None or meas.identity:
        return set()
    cols = set()
    if meas.grade != "logged" or meas.exclude_dropouts:
        cols |= set(ACCELEROMETER_COLUMNS) | {"elevation_m"}
    if meas.air_density == "altitude":
        cols |= {"elevation_m", "pressure_kpa"}
    return cols


def median_dt(time_s: np.ndarray, trip_codes: np.ndarray) -> float:
    """Median sample interval within trips [s] (NaN with fewer than two samples in a trip)."""
    d = np.diff(np.asarray(time_s, float))
    d = d[np.diff(trip_codes) == 0]
    return float(np.median(d)) if d.size else float("nan")


def has_values(df, col: str) -> bool:
    """Column ``col`` is in ``df`` with at least one finite value (an elevation logged as NaN
    throughout, a GPS without a fix, is no elevation)."""
    import pandas as pd

    return col in df and bool(np.isfinite(pd.to_numeric(df[col], errors="coerce").to_numpy(float)).any())


def apply_measurement(log, x, power_w: np.ndarray, usable: np.ndarray, meas: Measurement | None):
    """The corrections of ``meas`` applied to a read log's inputs and measured power.

    Parameters
    ----------
    log : the :class:`sumo_drvpw.data.log.DriveLog` (trip ids, time, elevation, columns)
    x : its :class:`sumo_drvpw.model.terms.Inputs` (``theta`` and ``rho`` are replaced)
    power_w : measured power [W] (shifted by the lag)
    usable : usable-sample mask (narrowed where a correction has no value)

    Returns ``(power_w, x, usable)``; the log itself is never modified. A correction the log
    cannot carry (no accelerometer column, no elevation) is a :class:`UserError` naming the
    log and the column.
    """
    if meas is None or meas.identity:
        return power_w, x, usable
    df = log.df
    codes = trip_codes_of(df["trip_id"])
    dt = median_dt(df["time_s"].to_numpy(float), codes)
    usable = np.asarray(usable, bool).copy()
    if meas.power_lag_s:
        if not np.isfinite(dt) or dt <= 0:
            raise UserError(f"{log.describe()}: a power lag needs at least two samples per trip to "
                            "know the sample interval")
        power_w = shift_within_trips(np.asarray(power_w, float), codes, int(round(meas.power_lag_s / dt)))
        usable &= np.isfinite(power_w)
    if meas.air_density == "altitude" and "pressure_kpa" not in df:
        if not has_values(df, "elevation_m"):
            raise UserError(f"{log.describe()}: air density at altitude needs column 'elevation_m' "
                            "(with values)")
        h = df["elevation_m"].to_numpy(float)
        x.rho = np.where(np.isfinite(h), x.rho * pressure_at_altitude_kpa(h) / P_STD_KPA, x.rho)
    drop = None  # logger dropouts, found once: left out (exclude_dropouts) and off the driven path
    if meas.exclude_dropouts or meas.grade != "logged":
        from sumo_drvpw.data.dropouts import log_dropouts

        drop = log_dropouts(log)
    if meas.exclude_dropouts:
        if drop is None:
            raise UserError(f"{log.describe()}: leaving out logger dropouts needs a longitudinal "
                            f"accelerometer column (one of {', '.join(ACCELEROMETER_COLUMNS)}): with "
                            "speed alone a steady cruise cannot be told from a held value")
        log.counts["excluded_dropouts"] = int((drop & usable).sum())  # usable samples taken out
        usable &= ~drop
    if meas.grade != "logged":
        col = accelerometer_column(df.columns)
        if col is None:
            raise UserError(f"{log.describe()}: grade '{meas.grade}' needs a longitudinal accelerometer "
                            f"column (one of {', '.join(ACCELEROMETER_COLUMNS)})")
        path = _path(x.v, drop)
        imu = df[col].to_numpy(float)
        if meas.grade == "accelerometer" and meas.accelerometer_offset_mps2 is not None:
            imu = imu - meas.accelerometer_offset_mps2
        s_acc = accelerometer_sin_grade(imu, x.a, codes, dt)
        if meas.grade == "accelerometer" and meas.accelerometer_offset_mps2 is not None:
            s = s_acc
        elif meas.grade == "accelerometer":
            if not has_values(df, "elevation_m"):
                raise UserError(f"{log.describe()}: grade 'accelerometer' needs column 'elevation_m' "
                                "with values (its per-trip offset is fixed by the elevation change)")
            s = offset_corrected_sin_grade(s_acc, x.v, df["dt_s"].to_numpy(float), codes,
                                           df["elevation_m"].to_numpy(float), path)
        elif meas.fusion_distance_m is None:
            s = fused_sin_grade(s_acc, np.sin(x.theta), codes, dt, meas.fusion_seconds)
        else:
            s = fused_sin_grade_distance(s_acc, np.sin(x.theta), x.v,
                                         df["dt_s"].to_numpy(float) if "dt_s" in df else dt, codes,
                                         meas.fusion_distance_m)
        x.theta = np.arcsin(s)
        usable &= np.isfinite(x.theta)
        if "elevation_m" in df and "dt_s" in df:
            gaps = grade_elevation_gaps(s, x.v, df["dt_s"].to_numpy(float), df["trip_id"].to_numpy(),
                                        df["elevation_m"].to_numpy(float), path)
            far = sorted((t for t, g in gaps.items() if abs(g) > GRADE_GAP_NOTE_M), key=lambda t: -abs(gaps[t]))
            log.counts["grade_elevation_gap_trips"] = len(far)
            if far:
                log.counts["grade_elevation_gap_m"] = {t: round(gaps[t], 1) for t in far[:GAP_LISTED]}
    return power_w, x, usable


def grade_elevation_gaps(sin_grade, speed_mps, dt_s, trip, elevation_m, path) -> dict:
    """Per trip: the elevation change the grade integrates to, Σ v·sin θ·Δt over the driven
    ``path``, minus the logged one (elevation at the path's last sample minus at its first)
    [m]. A grade consistent with the elevation gives 0; m·g·gap is the grade energy the two
    disagree by (a fusion in time weights its slow part by time, the grade power by
    distance, so it need not keep a trip's elevation change)."""
    s = np.asarray(sin_grade, float)
    v = np.asarray(speed_mps, float)
    dt = np.asarray(dt_s, float)
    h = np.asarray(elevation_m, float)
    trip = np.asarray(trip).astype(str)
    ok = np.asarray(path, bool) & np.isfinite(s) & np.isfinite(v) & np.isfinite(dt)
    out = {}
    for t in np.unique(trip):
        i = np.flatnonzero((trip == t) & ok & np.isfinite(h))
        if i.size < 2:
            continue
        j = np.flatnonzero((trip == t) & ok)
        out[str(t)] = float(np.sum(v[j] * s[j] * dt[j]) - (h[i[-1]] - h[i[0]]))
    return out
