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


#: a trip whose samples lie further apart than this (its median step) [s] has a derived
#: acceleration over 2 steps or more: the commands say so
COARSE_STEP_S = 5.0


def accel_derivation(opt, win, q, column_rows: int, derived_rows: int, step=()) -> dict:
    """Where a log's acceleration came from, as sums that merge over batches and files
    (:func:`merge_accel_derivation`) and read as the reader's text (:func:`accel_counts`).

    Parameters
    ----------
    opt : the reading options (:class:`sumo_drvpw.data.log.ReadOptions`)
    win, q : the moving-average width [s] and speed resolution [m/s] of each trip whose
        acceleration is derived (:func:`accel_window`)
    column_rows, derived_rows : rows whose acceleration is the ``accel_mps2`` column, and
        rows whose acceleration is derived from the speed [-]
    step : the median time step of each of those trips [s] (``coarse_trips`` and
        ``coarse_step_s``, the largest, count the trips sampled over COARSE_STEP_S apart)
    """
    win, q = np.asarray(win, float), np.asarray(q, float)
    wide = win > opt.accel_window_s
    d = {"column_rows": int(column_rows), "derived_rows": int(derived_rows), "derived_trips": int(len(win)),
         "widened_trips": int(wide.sum()), "least_window_s": float(opt.accel_window_s),
         "noise_mps2": float(opt.accel_noise_mps2)}
    if len(win):
        d.update(window_min_s=float(win.min()), window_max_s=float(win.max()))
    if wide.any():
        d["widened_step_mps"] = float(q[wide].max())
    step = np.asarray(step, float)
    coarse = step[np.isfinite(step) & (step > COARSE_STEP_S)]
    if coarse.size:
        d.update(coarse_trips=int(coarse.size), coarse_step_s=float(coarse.max()))
    return d


def merge_accel_derivation(a: dict, b: dict) -> dict:
    """:func:`accel_derivation` of two sets of whole trips read apart (rows and trips add,
    the windows' range and the coarsest widened step span both)."""
    out = {k: a[k] + b[k] for k in ("column_rows", "derived_rows", "derived_trips", "widened_trips")}
    out.update(least_window_s=a["least_window_s"], noise_mps2=a["noise_mps2"])
    if "coarse_trips" in a or "coarse_trips" in b:
        out["coarse_trips"] = a.get("coarse_trips", 0) + b.get("coarse_trips", 0)
    for k, f in (("window_min_s", min), ("window_max_s", max), ("widened_step_mps", max), ("coarse_step_s", max)):
        have = [x[k] for x in (a, b) if k in x]
        if have:
            out[k] = f(have)
    return out


def accel_counts(d: dict) -> dict:
    """The reader's counts of :func:`accel_derivation` ``d``: ``accel_source`` (the text),
    ``accel_derivation`` (``d``), ``accel_window_s`` (the widest window, when any trip's
    acceleration is derived) and ``accel_derived_rows`` (when some rows have the column and
    others not: the files of a folder without it)."""
    out: dict = {"accel_derivation": d}
    if not d["derived_rows"]:
        out["accel_source"] = "accel_mps2 column"
        return out
    lo, hi, n, k = d["window_min_s"], d["window_max_s"], d["derived_trips"], d["widened_trips"]
    text = "derived: central difference of speed, " + (
        f"{lo:.3g} s moving average" if lo == hi else f"{lo:.3g}–{hi:.3g} s moving average (each trip's own)")
    if k:
        text += (f" (widened from {d['least_window_s']:g} s" + ("" if k == n else f" on {k} of {n} trips")
                 + f": the speed is logged in steps of {d['widened_step_mps']:.3g} m/s, whose rounding would "
                 f"put more than {d['noise_mps2']:g} m/s² of noise into the acceleration)")
    if d.get("coarse_trips"):
        c = d["coarse_trips"]
        text += (f"; the samples lie up to {d['coarse_step_s']:.3g} s apart" + ("" if c == n else f" on {c} of {n} trips")
                 + " (median step), so the difference spans twice that: the inertial power of shorter speed "
                 "changes is not in the log, and per-sample power fits poorly")
    out["accel_window_s"] = hi
    if d["column_rows"]:  # the files without it are the exception
        text = f"accel_mps2 column; {text} for the {d['derived_rows']} rows of files without it"
        out["accel_derived_rows"] = d["derived_rows"]
    out["accel_source"] = text
    return out
