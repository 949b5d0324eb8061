"""Plausibility checks of a log's inputs, per trip (issue #11: why do trips miss?).

Each check reads the inputs (speed, accelerometer, elevation, declared mass), never a
held-out target; it either marks samples that cannot be measurements or reports a
disagreement between a declared input and what the data say.

- :func:`dropout_mask` — a logger dropout filled by holding or by linear interpolation:
  speed AND accelerometer exactly linear in time (second difference zero) for at least
  ``min_run_s``. A real accelerometer at 10 Hz never repeats a straight line for seconds
  (it vibrates); held or interpolated samples do (on the TUM i3 data: a 441-s hold while
  driving at 58 km/h, and a 165-s linear ramp of every signal followed by a 28-m elevation
  jump). The power logged across the gap is filled the same way, so it is not a
  measurement either. Samples within the grade-smoothing distance of the gap are marked
  too: the elevation jump at its end becomes a steep grade there.
- :func:`accelerometer_offsets` — a longitudinal accelerometer reads dv/dt + g·sin θ
  (+ its mounting pitch). Per trip the offset from standstill samples (v = 0 ⇒ reading =
  g·sin θ_stop + offset) and from the elevation (Σ sin θ·ds = Δh over the trip).
- :func:`inertial_mass` — a per-trip least-squares mass from acceleration phases (a check
  of the declared mass on training trips; it is reported, never substituted).
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.data.corrections import offset_corrected_sin_grade  # noqa: F401  (re-exported)
from sumo_drvpw.model.constants import G

#: shortest run of exactly linear speed and accelerometer samples read as a dropout [s]
DROPOUT_MIN_S = 5.0
#: second difference at or below this is "exactly linear" (float noise of a linear fill)
LINEAR_TOL = 1e-6
#: standstill: speed below this [m/s]
STANDSTILL_MPS = 0.05


def _runs(flag: np.ndarray):
    """(start, stop) of runs of True."""
    d = np.diff(np.r_[0, flag.astype(np.int8), 0])
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def dropout_mask(time_s, signals, trip_codes, speed_mps=None, min_run_s: float = DROPOUT_MIN_S,
                 margin_m: float = 0.0) -> np.ndarray:
    """True on samples of a dropout: every signal in ``signals`` exactly linear in time (held
    or interpolated) for at least ``min_run_s`` within a trip; with ``speed_mps`` and
    ``margin_m`` > 0, also the samples within ``margin_m`` of travelled distance of it.

    Parameters
    ----------
    time_s : time per sample [s]
    signals : arrays that a real sensor never draws as a straight line for seconds (speed
        and a longitudinal accelerometer) — at least two, so a steady cruise is not a dropout
    trip_codes : integer trip code per sample (contiguous trips)
    """
    t = np.asarray(time_s, float)
    codes = np.asarray(trip_codes)
    n = len(t)
    lin = np.ones(n, bool)
    same = np.r_[False, False, (codes[2:] == codes[1:-1]) & (codes[1:-1] == codes[:-2])]
    dt = np.diff(t)
    step = np.r_[np.nan, dt]
    for s in signals:
        x = np.asarray(s, float)
        # straight in time within the logged resolution q (the smallest step of the signal:
        # a linear fill is rounded to the logged digits): |Δ²x| ≤ q at a constant time step
        # (per trip: files of one data set are logged with different digits)
        dx = np.r_[np.nan, np.abs(np.diff(x))]
        q = np.zeros(n)
        bounds = np.r_[np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]]), n]
        for a, b in zip(bounds[:-1], bounds[1:]):
            d = dx[a + 1:b]
            d = d[d > LINEAR_TOL]
            q[a:b] = d.min() if len(d) else 0.0
        d2 = np.r_[np.nan, np.nan, np.abs(np.diff(x, 2))]
        even = np.r_[np.nan, np.abs(np.diff(step))] <= LINEAR_TOL * np.maximum(step, 1.0)
        lin &= same & even & (d2 <= q * (1 + 1e-6) + LINEAR_TOL)
    # a run of k linear second differences covers k + 2 samples
    st, en = _runs(lin)
    out = np.zeros(n, bool)
    for a, b in zip(st, en):
        a0 = a - 2
        if t[b - 1] - t[a0] >= min_run_s:
            out[a0:b] = True
    if margin_m > 0 and speed_mps is not None and out.any():
        v = np.nan_to_num(np.asarray(speed_mps, float))
        ds = np.r_[0.0, np.where(same[1:] | (codes[1:] == codes[:-1]), 0.5 * (v[1:] + v[:-1]) * np.maximum(dt, 0), 0)]
        dist = np.cumsum(ds)
        st, en = _runs(out)
        for a, b in zip(st, en):
            tr = codes[a]
            lo = np.searchsorted(dist, dist[a] - margin_m, side="left")
            hi = np.searchsorted(dist, dist[b - 1] + margin_m, side="right")
            rng = np.arange(lo, hi)
            out[rng[codes[rng] == tr]] = True
    return out


def log_dropouts(log) -> np.ndarray | None:
    """:func:`dropout_mask` of a read drive log (``data.log.DriveLog``): speed and its
    longitudinal accelerometer exactly linear in time for ≥ ``DROPOUT_MIN_S``, widened by the
    log's grade-smoothing distance (the elevation jump at a gap's end becomes a steep grade
    there). ``None`` when the log has no accelerometer column: with speed alone a steady
    cruise could not be told from a held value, so nothing is marked."""
    from sumo_drvpw.data.corrections import ACCELEROMETER_COLUMNS

    df = log.df
    acc = [c for c in ACCELEROMETER_COLUMNS if c in df]
    if not acc:
        return None
    codes = np.unique(np.asarray(df["trip_id"]).astype(str), return_inverse=True)[1]
    v = df["speed_mps"].to_numpy(float)
    return dropout_mask(df["time_s"].to_numpy(float), [v, df[acc[0]].to_numpy(float)], codes, v,
                        margin_m=log.options.grade_window_m)


def dropout_report(mask, trip, dt_s) -> dict:
    """trip → seconds marked by :func:`dropout_mask` (trips with none left out)."""
    mask = np.asarray(mask, bool)
    trip = np.asarray(trip)
    dt = np.asarray(dt_s, float)
    return {str(t): float(np.sum(dt[mask & (trip == t)])) for t in np.unique(trip[mask])}


def accelerometer_offsets(imu_mps2, accel_mps2, speed_mps, elevation_m, dt_s, trip,
                          usable=None, min_stand_s: float = 4.0) -> dict:
    """Per trip: the accelerometer's offset [m/s²] from standstill samples and from the
    elevation, and the elevation change each implies.

    Returns trip → {"offset_standstill", "offset_elevation", "standstill_s", "dh_m",
    "dh_accelerometer_m", "distance_m", "max_gap_m"}: ``max_gap_m`` the largest distance
    along the trip between the logged elevation and the accelerometer's integral with that
    offset removed; ``offset_elevation`` = g·(Σ s·ds − Δh)/Σ ds with
    s = (reading − dv/dt)/g; ``offset_standstill`` = median reading at standstill held for at
    least ``min_stand_s`` (it also holds the slope of where the car stood).
    """
    imu = np.asarray(imu_mps2, float)
    a = np.asarray(accel_mps2, float)
    v = np.asarray(speed_mps, float)
    h = np.asarray(elevation_m, float)
    dt = np.asarray(dt_s, float)
    trip = np.asarray(trip)
    u = np.ones(len(v), bool) if usable is None else np.asarray(usable, bool)
    out = {}
    for t in np.unique(trip):
        i = np.flatnonzero(trip == t)
        ok = u[i] & np.isfinite(imu[i]) & np.isfinite(a[i]) & np.isfinite(v[i])
        stand = (v[i] < STANDSTILL_MPS) & ok
        st, en = _runs(stand)
        held = np.zeros(len(i), bool)
        for s0, s1 in zip(st, en):
            if np.sum(dt[i][s0:s1]) >= min_stand_s:
                held[s0:s1] = True
        ds = np.where(ok, v[i] * dt[i], 0.0)
        dist = float(ds.sum())
        hh = h[i][np.isfinite(h[i]) & ok]
        dh = float(hh[-1] - hh[0]) if len(hh) else np.nan
        s = np.where(ok, (imu[i] - a[i]) / G, 0.0)
        dh_acc = float(np.sum(s * ds))
        # the logged elevation against the accelerometer's, its offset fixed by the elevation:
        # the largest gap along the trip [m] (GPS elevation settling or drifting shows here)
        c = (dh_acc - dh) / dist if dist > 0 else 0.0
        hi = np.where(np.isfinite(h[i]) & ok, h[i], np.nan)
        first = hi[np.isfinite(hi)][0] if np.isfinite(hi).any() else np.nan
        gap = (hi - first) - np.cumsum((s - c) * ds)
        out[str(t)] = {"max_gap_m": float(np.nanmax(np.abs(gap))) if np.isfinite(gap).any() else np.nan,
                       "offset_standstill": float(np.median(imu[i][held])) if held.any() else np.nan,
                       "standstill_s": float(np.sum(dt[i][held])),
                       "offset_elevation": G * (dh_acc - dh) / dist if dist > 0 else np.nan,
                       "dh_m": dh, "dh_accelerometer_m": dh_acc, "distance_m": dist}
    return out


def inertial_mass(power_w, x, usable, trip, v_min: float = 2.0, v_max: float = 20.0) -> dict:
    """Per trip the inertia seen in the measured power: least squares of P on
    [m_decl·a·v, v, v³, m_decl·g·sin θ·v] over usable samples with v_min < v < v_max;
    the first coefficient × the declared mass is the inertial mass [kg] (rotating masses
    and 1/η included, as the ``acc`` coefficient). Returns trip → {"declared_kg",
    "inertial_kg", "ratio"} (ratio = inertial / declared)."""
    p = np.asarray(power_w, float)
    v, a, th, m = (np.asarray(z, float) for z in (x.v, x.a, x.theta, x.mass))
    trip = np.asarray(trip)
    ok = np.asarray(usable, bool) & np.isfinite(p) & (v > v_min) & (v < v_max) & np.isfinite(th)
    out = {}
    for t in np.unique(trip[ok]):
        i = ok & (trip == t)
        if i.sum() < 200:
            continue
        md = float(np.median(m[i]))
        X = np.c_[md * a[i] * v[i], v[i], v[i] ** 3, md * G * np.sin(th[i]) * v[i]]
        b = np.linalg.lstsq(X, p[i], rcond=None)[0]
        out[str(t)] = {"declared_kg": md, "inertial_kg": float(b[0] * md), "ratio": float(b[0])}
    return out


