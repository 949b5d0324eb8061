"""The resolution a speed is logged in, and the acceleration window it needs.

Used by the log reader (:func:`sumo_drvpw.data.log.read_log`, and so by the streaming
reader batch by batch) when it derives the acceleration from the speed.
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.data.plausible import update_interval
from sumo_drvpw.data.trips import run_median_step, trip_starts


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


def trip_resolutions(v: np.ndarray, trip_codes: np.ndarray) -> np.ndarray:
    """:func:`speed_resolution` of each trip (runs of equal ``trip_codes``, in order) [m/s]."""
    v, codes = np.asarray(v, float), np.asarray(trip_codes)
    first = np.flatnonzero(trip_starts(codes)) if len(codes) else np.zeros(0, np.int64)
    return np.array([speed_resolution(v[a:b], codes[a:b]) for a, b in zip(first, np.r_[first[1:], len(v)])])


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
    q = trip_resolutions(v, codes)
    need = q / (np.sqrt(6.0) * opt.accel_noise_mps2) if opt.accel_noise_mps2 > 0 else np.zeros_like(q)
    return np.maximum(opt.accel_window_s, need), q


#: a trip whose samples lie further apart than this (its median step) [s] has a derived
#: acceleration over 2 steps or more: the commands say so
COARSE_STEP_S = 5.0


def accel_derivation(opt, win, q, column_rows: int, derived_rows: int, step=(), hold=()) -> dict:
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
    hold : the update interval of each of those trips' held speed [s], 0 where not held
        (``held_trips`` and ``hold_max_s``, the longest; :func:`accel_speed`)
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
    hold = np.asarray(hold, float)
    if (hold > 0).any():
        d.update(held_trips=int((hold > 0).sum()), hold_max_s=float(hold.max()))
    return d


def merge_accel_derivation(a: dict, b: dict) -> dict:
    """:func:`accel_derivation` of two sets of whole trips read apart (rows and trips add,
    the windows' range and the coarsest widened step span both)."""
    out = {k: a[k] + b[k] for k in ("column_rows", "derived_rows", "derived_trips", "widened_trips")}
    out.update(least_window_s=a["least_window_s"], noise_mps2=a["noise_mps2"])
    for k in ("coarse_trips", "held_trips"):
        if k in a or k in b:
            out[k] = a.get(k, 0) + b.get(k, 0)
    for k, f in (("window_min_s", min), ("window_max_s", max), ("widened_step_mps", max), ("coarse_step_s", max),
                 ("hold_max_s", max)):
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
    lo_s, hi_s = f"{lo:.3g}", f"{hi:.3g}"  # windows that print alike are said once ("2.27–2.27 s" was said)
    text = "derived: central difference of speed, " + (
        f"{lo_s} s moving average" if lo_s == hi_s else f"{lo_s}–{hi_s} s moving average (each trip's own)")
    if k:
        text += (f" (widened from {d['least_window_s']:g} s" + ("" if k == n else f" on {k} of {n} trips")
                 + f": the speed is logged in steps of {d['widened_step_mps']:.3g} m/s, whose rounding would "
                 f"put more than {d['noise_mps2']:g} m/s² of noise into the acceleration)")
    if d.get("coarse_trips"):
        c = d["coarse_trips"]
        text += (f"; the samples lie up to {d['coarse_step_s']:.3g} s apart" + ("" if c == n else f" on {c} of {n} trips")
                 + " (median step), so the difference spans twice that: the inertial power of shorter speed "
                 "changes is not in the log, and per-sample power fits poorly")
    if d.get("held_trips"):
        c = d["held_trips"]
        text += (f"; the speed is held between updates up to {d['hold_max_s']:.2g} s apart"
                 + ("" if c == n else f" on {c} of {n} trips") + " (it repeats where it must change): it is "
                 "read interpolated between its updates, and the acceleration derived from that")
    out["accel_window_s"] = hi
    if d["column_rows"]:  # the files without it are the exception
        text = f"accel_mps2 column; {text} for the {d['derived_rows']} rows of files without it"
        out["accel_derived_rows"] = d["derived_rows"]
    out["accel_source"] = text
    return out


#: a speed counts as held (logged more often than it is updated: a CAN or OBD speed polled
#: slower than the logger writes) when at least this share of its samples repeat the previous
#: value where the speed, moving and changing by two of its steps or more per sample, could not
HELD_SHARE = 0.3
#: ... judged on at least this many such samples of a trip
HELD_MIN_SAMPLES = 30
#: the speed a sample must exceed to be judged [m/s] (a standing car's speed repeats)
HELD_MIN_SPEED_MPS = 1.0
#: the half-width over which the speed's change is judged [s] (spans a few seconds' hold)
HELD_SPAN_S = 3.0


def speed_hold(v: np.ndarray, t: np.ndarray, trip_codes: np.ndarray, q=None) -> np.ndarray:
    """The interval at which each trip's speed is updated, when it is held between updates [s];
    0 for a trip whose speed is updated at every sample (or that cannot be judged).

    A logger that writes a speed more often than the speed is updated repeats its last value:
    the derived acceleration is 0 then a jump (a 3-s hold at 1 Hz: 0, 0, 3·a), noise in the
    input that pulls the inertia coefficient towards 0 (the RSK Renault Twizy's 1-Hz CAN speed,
    56 % of its moving samples repeats: acc 0.40 where the car's is about 1.1). Judged where a
    speed updated every sample could not repeat: moving (> HELD_MIN_SPEED_MPS) and changing,
    over ±HELD_SPAN_S, by at least two of its logged steps ``q`` [m/s] (per trip or one for all;
    None: each trip's own, :func:`trip_resolutions` — with 0 a speed in whole km/h at 1.4 Hz
    repeats while it changes by less than a step and is taken for held; or the one step it
    changes by, :func:`_one_step`) and 0.02 m/s per sample. A share r ≥ HELD_SHARE of repeats there
    gives the update interval dt/(1 − r) (dt: the trip's median step). A speed in steps too coarse
    to change by two of them in one sample (whole km/h at 10 Hz) is judged over the least lag of
    m = 2, 4, 8, … samples (m·dt ≤ HELD_SPAN_S) over which it must: repeats r over m samples give
    m·dt/(1 − r).
    """
    v, t, codes = np.asarray(v, float), np.asarray(t, float), np.asarray(trip_codes)
    first = np.flatnonzero(trip_starts(codes)) if len(codes) else np.zeros(0, np.int64)
    bounds = list(zip(first, np.r_[first[1:], len(v)]))
    q = np.broadcast_to(trip_resolutions(v, codes) if q is None else np.asarray(q, float), (len(bounds),))
    out = np.zeros(len(bounds))
    for j, (a, b) in enumerate(bounds):
        if b - a < HELD_MIN_SAMPLES + 2:
            continue
        tv, vv = t[a:b], v[a:b]
        dt = float(np.median(np.diff(tv)))
        if not dt > 0:
            continue
        step = _one_step(vv, q[j])
        k = min(max(1, int(np.ceil(HELD_SPAN_S / dt))), b - a)  # a window longer than the trip is the trip
        i = np.arange(1, b - a)
        lo, hi = np.maximum(i - k, 0), np.minimum(i + k, b - a - 1)
        slope = np.abs(vv[hi] - vv[lo]) / np.maximum(tv[hi] - tv[lo], dt)
        m = 1  # the lag [samples]: 1, or, for a speed in steps too coarse to change at every
        while m * dt <= HELD_SPAN_S and m < b - a:  # sample (whole km/h at 10 Hz), the least that it must change over
            im = i[i >= m]
            judged = ((vv[im] > HELD_MIN_SPEED_MPS) & (vv[im - m] > HELD_MIN_SPEED_MPS)
                      & (slope[im - 1] * m * dt >= max(2.0 * step, 0.02)) & np.isfinite(slope[im - 1]))
            if judged.sum() >= HELD_MIN_SAMPLES:
                r = float(np.mean(vv[im][judged] == vv[im - m][judged]))
                if r >= HELD_SHARE:
                    out[j] = m * dt / max(1.0 - r, 1e-3)
                break
            m *= 2
    return out


def _one_step(v: np.ndarray, q: float) -> float:
    """The step a trip's speed changes by [m/s]: its resolution ``q``, or, for a speed that
    changes by one step each time (whole km/h logged at 20 Hz: a ramp of equal steps, which
    :func:`speed_resolution` does not count as logged in steps), that step."""
    d = np.abs(np.diff(v))
    d = d[np.isfinite(d) & (d > 1e-9)]
    if d.size:
        s = float(np.percentile(d, 10))
        if np.mean(np.abs(d - s) <= MULTIPLE_TOL * s) >= QUANTISED_SHARE:
            return max(q, s)
    return q


def unheld_speed(v: np.ndarray, t: np.ndarray, trip_codes: np.ndarray, hold) -> np.ndarray:
    """The speed between its updates: each trip with a hold interval ``hold`` > 0 [s] (per trip,
    :func:`speed_hold`) interpolated linearly from each update (a sample whose value differs from
    the previous one) to the next; a value that stays longer than twice the hold is a speed that
    did not change (a stop, a steady cruise in the speed's steps) and is kept until one hold
    before the next update (then joined to it linearly, as any update). Trips without a hold are returned as they are."""
    v, t, codes = np.asarray(v, float), np.asarray(t, float), np.asarray(trip_codes)
    hold = np.asarray(hold, float)
    if not (hold > 0).any():
        return v
    out = v.copy()
    first = np.flatnonzero(trip_starts(codes))
    for (a, b), h in zip(zip(first, np.r_[first[1:], len(v)]), hold):
        if not h > 0 or b - a < 3:
            continue
        tv, vv = t[a:b], v[a:b]
        new = np.r_[True, vv[1:] != vv[:-1]]  # an update, or the trip's first sample
        run_start = np.flatnonzero(new)
        run_last = np.r_[run_start[1:] - 1, b - a - 1]
        steady = tv[run_last] - tv[run_start] > 2.0 * h
        # a steady value was last confirmed one hold before the next update (the speed left it
        # somewhere after that): kept until then, not until its last sample (a pull-away from a
        # stop read in one sample's step: an acceleration spike of Δv/dt at every start)
        nxt = np.minimum(run_last + 1, b - a - 1)
        left = steady & (run_last < b - a - 1)
        at_t = np.r_[tv[run_start], np.maximum(tv[nxt[left]] - h, tv[run_start[left]]), tv[run_last[steady & ~left]],
                     tv[-1]]
        at_v = np.r_[vv[run_start], vv[run_start[left]], vv[run_last[steady & ~left]], vv[-1]]
        order = np.argsort(at_t, kind="stable")
        at_t, at_v = at_t[order], at_v[order]
        ok = np.isfinite(at_v)
        if ok.sum() >= 2:  # a sample without a speed stays without one
            out[a:b] = np.where(np.isfinite(vv), np.interp(tv, at_t[ok], at_v[ok]), vv)
    return out


def accel_speed(opt, v: np.ndarray, t: np.ndarray, trip_codes: np.ndarray, q) -> tuple[np.ndarray, np.ndarray]:
    """(the speed the acceleration is derived from [m/s], each trip's hold interval [s]) for
    reading options ``opt``: a trip whose speed is held between updates for longer than the
    least acceleration window (:func:`speed_hold`; a hold within the window is averaged out)
    is interpolated between its updates (:func:`unheld_speed`), any other trip as logged. The
    reader takes that speed for the terms too (``speed_mps``): with the acceleration from one
    and the speed from the other, the acceleration term's energy Σ m·a·v·Δt would miss the
    kinetic-energy change by about m·h/2·Σa²·Δt (the held speed lags by half a hold)."""
    hold = speed_hold(v, t, trip_codes, q)
    hold = np.where(hold > opt.accel_window_s, hold, 0.0)
    return unheld_speed(v, t, trip_codes, hold), hold


#: a stretch's speed is held for its end samples when its update interval exceeds this many
#: of its rows (its median step): it changes at most every other row
HELD_END_ROWS = 1.5


def held_end_spans(v: np.ndarray, t: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """The least time the acceleration's one-sided differences at each stretch's ends span
    [s], per run of equal ``seg`` (in order; ``derivative``'s ``end_span_s``): the speed's
    update interval (:func:`sumo_drvpw.data.plausible.update_interval`) where it exceeds
    :data:`HELD_END_ROWS` rows, 0 elsewhere. A speed held between updates in a stretch too
    short for :func:`speed_hold` (2-Hz rows of a speed updated once a second) changes by an
    update's Δv within one row: a one-row difference at an end read 2·a, where the central
    differences inside span the update; a speed that changes at every row keeps its one-row
    ends."""
    upd = update_interval(v, t, seg)
    med = run_median_step(t, seg)
    return np.where(np.isfinite(med) & (upd > HELD_END_ROWS * np.nan_to_num(med, nan=np.inf)), upd, 0.0)
