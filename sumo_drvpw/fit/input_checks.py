"""Plausibility checks of a log's inputs, per trip (issue #11: why do trips miss?).

Each check reads the inputs (speed, accelerometer, elevation, declared mass), never a
held-out target; it either marks samples that cannot be measurements or reports a
disagreement between a declared input and what the data say.

- :func:`dropout_mask` — a logger dropout filled by holding or by linear interpolation
  (:mod:`sumo_drvpw.data.dropouts`, re-exported here; a reading option, since an equation
  may declare that its logs were read without them).
- :func:`accelerometer_offsets` — a longitudinal accelerometer reads dv/dt + g·sin θ
  (+ its mounting pitch). Per trip the offset from standstill samples (v = 0 ⇒ reading =
  g·sin θ_stop + offset) and from the elevation (Σ sin θ·ds = Δh over the trip).
- :func:`inertial_mass` — a per-trip least-squares mass from acceleration phases (a check
  of the declared mass on training trips; it is reported, never substituted).
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.data.corrections import offset_corrected_sin_grade  # noqa: F401  (re-exported)
from sumo_drvpw.data.dropouts import (DROPOUT_MIN_S, LINEAR_TOL, _runs, dropout_mask,  # noqa: F401
                                      dropout_report, log_dropouts)
from sumo_drvpw.model.constants import G

#: standstill: speed below this [m/s]
STANDSTILL_MPS = 0.05


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


