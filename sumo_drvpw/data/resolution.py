"""The resolution a speed is logged in, and the acceleration window it needs.

Used by the log reader (:func:`sumo_drvpw.data.log.read_log`, and so by the streaming
reader batch by batch) when it derives the acceleration from the speed.
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.data.trips import trip_starts


#: a speed is read as logged in steps of q when this share of its nonzero changes are whole
#: multiples of q (within MULTIPLE_TOL of one) and they take at least two different multiples
QUANTISED_SHARE = 0.9
MULTIPLE_TOL = 0.02
#: ... and at least this share of all changes are none (a value logged in steps repeats)
REPEAT_SHARE = 0.05


def speed_resolution(v: np.ndarray, trip_codes: np.ndarray) -> float:
    """The step in which a log's speed is logged [m/s], 0 when it is not logged in steps.

    q = the 10th percentile of the nonzero changes between consecutive samples within trips.
    The speed counts as logged in steps of q when at least QUANTISED_SHARE of those changes
    are whole multiples of q, at least two different multiples occur, and at least
    REPEAT_SHARE of all changes within trips are zero (a value logged in steps repeats while
    the true speed moves within one step). An OBD speed in whole km/h gives 0.278 m/s, a CAN
    speed in fine steps a small q; a smoothly varying float speed, or a ramp of equal steps,
    is no quantised speed: 0.
    """
    v = np.asarray(v, float)
    if v.size < 3:
        return 0.0
    codes = np.asarray(trip_codes)
    d = np.abs(np.diff(v))
    d = d[(codes[1:] == codes[:-1]) & np.isfinite(d)]
    repeats = float(np.mean(d <= 1e-9)) if d.size else 0.0
    d = d[d > 1e-9]
    if d.size < 2 or repeats < REPEAT_SHARE:
        return 0.0
    q = float(np.percentile(d, 10))
    k = d / q
    near = np.abs(k - np.round(k)) <= MULTIPLE_TOL
    mult = np.round(k[near])
    if near.mean() < QUANTISED_SHARE or mult.size == 0 or mult.min() == mult.max():   # O(n), no sort
        return 0.0
    return q


def accel_window(opt, v: np.ndarray, trip_codes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(width of the acceleration's moving average [s], the speed's resolution [m/s]), each
    per trip (runs of equal ``trip_codes``, in order), for reading options ``opt``
    (:class:`sumo_drvpw.data.log.ReadOptions`): each trip by its own speed, so a trip's
    acceleration does not depend on the trips read with it.

    A speed logged in steps of q carries a rounding error of s.d. q/√12 on every sample; the
    derived acceleration, a difference over the window T, then carries q/(√6·T). Physics of
    the fit: noise in the acceleration (an input) pulls the inertia coefficient towards 0
    (errors in variables: an OBD speed in whole km/h at 1.4 Hz gave a Prius mass factor of
    0.4), so the window is widened until that noise is below ``opt.accel_noise_mps2``:
    T = max(``opt.accel_window_s``, q/(√6·noise)). Speeds logged finely keep the least width.
    """
    v = np.asarray(v, float)
    codes = np.asarray(trip_codes)
    first = np.flatnonzero(trip_starts(codes)) if len(codes) else np.zeros(0, np.int64)
    q = np.array([speed_resolution(v[a:b], codes[a:b]) for a, b in zip(first, np.r_[first[1:], len(v)])])
    need = q / (np.sqrt(6.0) * opt.accel_noise_mps2) if opt.accel_noise_mps2 > 0 else np.zeros_like(q)
    return np.maximum(opt.accel_window_s, need), q
