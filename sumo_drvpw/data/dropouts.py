"""Logger dropouts: samples a logger filled by holding or by linear interpolation.

Speed AND a longitudinal accelerometer exactly linear in time (second difference within
the logged resolution) for at least ``DROPOUT_MIN_S`` within a trip. A real accelerometer
never repeats a straight line for seconds (it vibrates); held or interpolated samples do
(on the TUM i3 data: a 441-s hold while driving at 58 km/h, and a 165-s linear ramp of
every signal followed by a 28-m elevation jump). The power logged across the gap is filled
the same way, so it is not a measurement either. Samples within the grade-smoothing
distance of the gap are marked too: the elevation jump at its end becomes a steep grade
there. Inputs only: no target is read. An equation declares with ``[measurement]
exclude_dropouts = true`` that its logs were read without them
(:mod:`sumo_drvpw.model.measurement`, :mod:`sumo_drvpw.data.corrections`).
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.data.corrections import ACCELEROMETER_COLUMNS

#: shortest run of exactly linear speed and accelerometer samples read as a dropout [s]
DROPOUT_MIN_S = 5.0
#: second difference at or below this is "exactly linear" (float noise of a linear fill)
LINEAR_TOL = 1e-6
#: a run whose speed stays at or below this [m/s] is a car standing, no dropout: its speed is
#: constant, and a still accelerometer may read one value too (a coarse or filtered one)
STANDSTILL_MPS = 0.1
#: ... unless the next sample jumps faster than a car pulls away [m/s²] (4.5: hard launches)
#: and beyond the lowest speed a wheel-speed sensor reports after 0 [m/s] (they read 0 below
#: about 2–5 km/h, so a 20-Hz log's first reading may jump to that; 2 m/s = 7.2 km/h)
STANDSTILL_PULL_MPS2 = 4.5
STANDSTILL_FIRST_MPS = 2.0

def _runs(flag: np.ndarray):
    """(start, stop) of runs of True."""
    d = np.diff(np.r_[0, flag.astype(np.int8), 0])
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1)


def _stood(v: np.ndarray, t: np.ndarray, codes: np.ndarray, a: int, b: int) -> bool:
    """Whether the held run ``a:b`` is a car standing: its speed at or below STANDSTILL_MPS
    and the next sample of its trip no faster than a car pulls away (STANDSTILL_PULL_MPS2, or
    the first speed a wheel-speed sensor reports, STANDSTILL_FIRST_MPS; a logger that held 0
    while the car drove off ends in a jump to the speed it reached)."""
    if v[a:b].max() > STANDSTILL_MPS:
        return False
    if b >= len(v) or codes[b] != codes[b - 1]:
        return True
    return bool(v[b] <= max(STANDSTILL_MPS + STANDSTILL_PULL_MPS2 * max(t[b] - t[b - 1], 0.0), STANDSTILL_FIRST_MPS))


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
    speed_mps : speed per sample [m/s]; a run in which it stays at or below STANDSTILL_MPS
        is a car standing, not marked (unless the speed jumps after it: :func:`_stood`)
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
    v = None if speed_mps is None else np.abs(np.nan_to_num(np.asarray(speed_mps, float)))
    for a, b in zip(st, en):
        a0 = a - 2
        if t[b - 1] - t[a0] >= min_run_s and not (v is not None and _stood(v, t, codes, a0, b)):
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
