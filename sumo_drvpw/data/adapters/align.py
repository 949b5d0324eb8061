"""Channels logged on their own clocks, put onto the speed samples.

A drive log has one row per speed sample. Loggers that poll one value at a time (OBD apps,
CAN-bus exports) and measurement files with a time base per channel (ASAM MDF) log every
other channel on its own clock, some slower than the speed, some faster. Each channel is put
onto the speed's time stamps ``ts`` as what the speed sample stands for:

* **slower or as fast** (:func:`interp_onto`): linear in time between its two neighbouring
  samples (a measured value), or its last sample held (:func:`held`: a state such as a
  gear or a flag);
* **faster** (its median sampling interval at most 1/:data:`AVERAGE_RATIO` of the speed's,
  :func:`window_mean`): its mean over the speed sample's interval, the window from the
  midpoint to the previous speed sample to the midpoint to the next (the time weight
  ``dt_s`` the drive log gives the sample). A 100-Hz battery current at 1-Hz speed samples
  then carries the charge of each second, not the current at one instant: Σ mean·dt_s is
  the channel's integral over the trip, so energy is kept, and what the channel does
  between the speed samples (a ripple, a spike) does not alias into the sample. The mean of
  a product is not the product of the means: V·I of a current and a voltage averaged
  apart differs from the mean power by the covariance of the two within the interval
  (the pack's internal resistance × the current's variance: +0.2 … +0.6 % of the net
  battery energy of the JLU car's 20-Hz road trips taken at 1 Hz), so where both factors
  of a power are averaged :func:`keep_power` keeps their mean product instead.

Across a gap in a channel longer than :data:`ALIGN_MAX_GAP_INTERVALS` × its median sampling
interval (the logger paused it) and outside its time span the value is missing (NaN).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sumo_drvpw.data.log_files import FLAGS

#: a channel logged on its own rows is interpolated across gaps up to this many of its median
#: sampling intervals; a longer gap (the logger paused the channel) stays missing
ALIGN_MAX_GAP_INTERVALS = 3.0
#: a channel whose median sampling interval is at most 1/AVERAGE_RATIO of the speed's is
#: averaged over each speed sample's interval (at least two of its samples per interval)
AVERAGE_RATIO = 2.0


def _own(tc: np.ndarray, xc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A channel's finite samples in time order; a repeated time keeps its last value."""
    tc, xc = np.asarray(tc, float), np.asarray(xc, float)
    ok = np.isfinite(tc) & np.isfinite(xc)
    if not ok.all():
        tc, xc = tc[ok], xc[ok]
    if len(tc) > 1 and not (tc[1:] >= tc[:-1]).all():  # a logger's samples are in order: no sort
        order = np.argsort(tc, kind="stable")
        tc, xc = tc[order], xc[order]
    if len(tc) > 1 and not (keep := np.r_[tc[1:] > tc[:-1], True]).all():
        tc, xc = tc[keep], xc[keep]
    return tc, xc


def _median_step(t: np.ndarray) -> float:
    d = np.diff(t)
    d = d[np.isfinite(d) & (d > 0)]
    return float(np.median(d)) if len(d) else np.inf


def interp_onto(ts: np.ndarray, tc: np.ndarray, xc: np.ndarray) -> np.ndarray:
    """One channel's own samples (times ``tc``, values ``xc``; any order, a repeated time
    keeps its last value) at the times ``ts``: linear in time between its two neighbouring
    samples where these are at most :data:`ALIGN_MAX_GAP_INTERVALS` of its median sampling
    interval apart (a sample at the very time is taken as it is); NaN elsewhere (a gap the
    logger left, or outside the channel's time span)."""
    tc, xc = _own(tc, xc)
    return _interp(np.asarray(ts, float), tc, xc, _median_step(tc))


def _interp(ts, tc, xc, step: float) -> np.ndarray:
    """:func:`interp_onto` of a channel in order (:func:`_own`) with median interval ``step``."""
    if len(tc) == 0:
        return np.full(len(ts), np.nan)
    if len(tc) < 2:
        return np.where(ts == tc[0], xc[0], np.nan)
    hi = np.clip(np.searchsorted(tc, ts, side="left"), 1, len(tc) - 1)
    exact = tc[np.minimum(np.searchsorted(tc, ts), len(tc) - 1)] == ts
    inside = (ts >= tc[0]) & (ts <= tc[-1])
    ok = inside & (exact | (tc[hi] - tc[hi - 1] <= ALIGN_MAX_GAP_INTERVALS * step))
    return np.where(ok, np.interp(ts, tc, xc), np.nan)


def windows(ts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each speed sample's interval (from, to) [s]: half the way to each neighbour (the
    drive log's time weight ``dt_s``), the first and last samples' from their own time on;
    a half longer than ½·ALIGN_MAX_GAP_INTERVALS of the median speed interval (a gap in
    the speed) stops there."""
    ts = np.asarray(ts, float)
    d = np.maximum(np.diff(ts), 0.0) if len(ts) > 1 else np.zeros(0)
    half = np.minimum(0.5 * d, 0.5 * ALIGN_MAX_GAP_INTERVALS * _median_step(ts))
    return ts - np.r_[0.0, half], ts + np.r_[half, 0.0]


def window_mean(ts: np.ndarray, tc: np.ndarray, xc: np.ndarray) -> np.ndarray:
    """One channel's mean over each speed sample's interval (:func:`windows`), the channel
    linear in time between its samples: Σ mean·(to − from) is its integral over the span.
    NaN where the interval reaches outside the channel's time span or over a gap longer
    than ALIGN_MAX_GAP_INTERVALS × its median sampling interval; a zero-length interval
    takes the channel at its time (:func:`interp_onto`)."""
    tc, xc = _own(tc, xc)
    return _window(np.asarray(ts, float), tc, xc, _median_step(tc))


def _window(ts, tc, xc, step: float) -> np.ndarray:
    """:func:`window_mean` of a channel in order (:func:`_own`) with median interval ``step``."""
    if len(tc) < 2:
        return _interp(ts, tc, xc, step)
    a, b = windows(ts)
    dtc = np.diff(tc)
    cum = np.zeros(len(tc))  # ∫ from tc[0] to each sample (trapezoids, in place: a long channel)
    part = xc[1:] + xc[:-1]
    part *= dtc
    part *= 0.5
    np.cumsum(part, out=cum[1:])
    del part

    def integral(t):
        t = np.clip(t, tc[0], tc[-1])
        k = np.clip(np.searchsorted(tc, t, side="right") - 1, 0, len(tc) - 2)
        x = xc[k] + (xc[k + 1] - xc[k]) * (t - tc[k]) / dtc[k]
        return cum[k] + 0.5 * (xc[k] + x) * (t - tc[k])

    width = b - a
    with np.errstate(invalid="ignore", divide="ignore"):
        out = (integral(b) - integral(a)) / width
    gaps = np.flatnonzero(dtc > ALIGN_MAX_GAP_INTERVALS * step)  # intervals over a pause
    ka = np.clip(np.searchsorted(tc, a, side="right") - 1, 0, len(tc) - 2)  # interval holding a
    kb = np.clip(np.searchsorted(tc, b, side="left") - 1, 0, len(tc) - 2)   # … and b
    over = np.searchsorted(gaps, np.maximum(kb, ka), side="right") > np.searchsorted(gaps, ka, side="left")
    ok = (a >= tc[0]) & (b <= tc[-1]) & ~over
    out = np.where(ok, out, np.nan)
    point = ~(width > 0)
    if point.any():
        out[point] = _interp(ts[point], tc, xc, step)
    return out


def faster(ts: np.ndarray, tc: np.ndarray) -> bool:
    """Whether a channel (times ``tc``) is logged fast enough against the speed (times
    ``ts``) to be averaged over each speed interval: its median sampling interval at most
    1/AVERAGE_RATIO of the speed's."""
    return _faster(np.asarray(ts, float), _median_step(np.sort(np.asarray(tc, float)[np.isfinite(tc)])))


def _faster(ts, step: float) -> bool:
    return bool(np.isfinite(step) and AVERAGE_RATIO * step <= _median_step(ts))


def onto(ts: np.ndarray, tc: np.ndarray, xc: np.ndarray) -> tuple[np.ndarray, bool]:
    """A measured channel at the speed samples ``ts``, and whether it was averaged: its mean
    over each speed interval when it is logged faster (:func:`faster`,
    :func:`window_mean`), else linear in time (:func:`interp_onto`)."""
    ts = np.asarray(ts, float)
    tc, xc = _own(tc, xc)
    step = _median_step(tc)
    if _faster(ts, step):
        return _window(ts, tc, xc, step), True
    return _interp(ts, tc, xc, step), False


#: canonical pairs whose product is a measured power (V·I, T·n): the first of each pair is
#: the one :func:`keep_power` adjusts
POWER_PAIRS = (("battery_current_a", "battery_voltage_v"), ("motor_torque_nm", "motor_speed_rpm"),
               ("mg1_torque_nm", "mg1_speed_rpm"), ("mg2_torque_nm", "mg2_speed_rpm"))
#: every column of a pair: only these channels' own samples are kept for :func:`keep_power`
POWER_FACTORS = frozenset(c for pair in POWER_PAIRS for c in pair)


def keep_power(ts: np.ndarray, raw: dict, out: dict) -> list[tuple[str, str]]:
    """Keep the mean power of each pair of :data:`POWER_PAIRS` that was averaged over the
    speed intervals: the first channel's mean is replaced by mean(product)/mean(partner),
    so that the product of the two columns is the power's mean over each interval.
    Averaged apart, the two would carry the product of their means, which differs from the
    mean power by their covariance within the interval (a battery's V = V₀ − R·I: the
    product of the means exceeds the mean power by R·var(I)). The new value is the first
    channel's mean weighted by its partner; it is taken where the partner keeps one sign
    over the interval (mean |partner| = |mean partner| > 0), so it stays within the
    channel's own range (up to the difference between the partner's column, its mean on its
    own clock, and its mean on the channel's clock, which weights the product: some 1e-5);
    elsewhere (a shaft standing or reversing) the plain mean stays.

    ``raw``: name → (times, values) of the channels averaged; ``out``: name → values at the
    speed samples, changed in place. Returns the pairs (channel, partner) adjusted."""
    done = []
    for a, b in POWER_PAIRS:
        if a not in raw or b not in raw:
            continue
        (ta, xa), (tb, xb) = raw[a], raw[b]
        partner = interp_onto(ta, tb, xb)
        mean_p = window_mean(ts, ta, xa * partner)
        mean_b = window_mean(ts, ta, partner)
        mean_abs = window_mean(ts, ta, np.abs(partner))
        one_sign = np.isclose(mean_abs, np.abs(mean_b), rtol=1e-9, atol=0.0) & (mean_abs > 0)
        col_b = np.asarray(out[b], float)  # the partner's column: its product is the power
        use = one_sign & np.isfinite(mean_p) & np.isfinite(col_b) & (np.sign(col_b) == np.sign(mean_b))
        out[a] = np.where(use, mean_p / np.where(use, col_b, 1.0), out[a])
        done.append((a, b))
    return done


def held(ts: np.ndarray, tc: np.ndarray, xc: np.ndarray) -> np.ndarray:
    """A state channel at the times ``ts``: its last sample at or before each (zero-order
    hold) until its next sample, across gaps up to ALIGN_MAX_GAP_INTERVALS × its median
    interval, and for one median interval after its last sample; NaN elsewhere."""
    ok = np.isfinite(tc) & np.isfinite(xc)
    order = np.argsort(tc[ok], kind="stable")
    tc, xc = tc[ok][order], xc[ok][order]
    out = np.full(len(ts), np.nan)
    if len(tc) == 0:
        return out
    step = float(np.median(np.diff(tc))) if len(tc) > 1 else 0.0
    j = np.searchsorted(tc, ts, side="right") - 1
    jj = np.maximum(j, 0)
    gap = np.where(jj < len(tc) - 1, tc[np.minimum(jj + 1, len(tc) - 1)] - tc[jj], step)
    ok = (j >= 0) & ((ts == tc[jj]) | ((gap <= ALIGN_MAX_GAP_INTERVALS * step) & (ts - tc[jj] <= gap)))
    out[ok] = xc[j[ok]]
    return out


def how(averaged=()) -> str:
    """The import note's account of how channels were put onto the speed samples."""
    return ("linear in time, across gaps up to "
            f"{ALIGN_MAX_GAP_INTERVALS:g}× the channel's median sampling interval"
            + (f"; logged faster than the speed, hence averaged over each speed sample's interval: "
               f"{', '.join(averaged)}" if averaged else ""))


def aligned_note(n_other: int, n_speed: int, aligned: dict[str, np.ndarray], report: dict,
                 averaged=()) -> None:
    """The import note of an asynchronous log whose channels ``aligned`` (name → values at
    the speed samples; ``averaged`` the names of those averaged over each speed interval)
    were put onto its ``n_speed`` speed samples, and the count of the ``n_other`` rows
    without speed under their drop reason."""
    still = [f"{c} {100 * m:.2g} %" for c, x in aligned.items()
             if x.size and (m := float(np.mean(~np.isfinite(x)))) > 0]
    report["notes"].append(
        f"asynchronous log: {n_other} rows carry no speed; {len(aligned)} channel(s) logged on their "
        f"own rows are put onto the {n_speed} speed samples ({how(averaged)})"
        + (f"; still missing: {', '.join(still)}" if still else ""))
    if n_other:
        reason = "rows without speed (their channels put onto the speed samples)"
        report["dropped"][reason] = report["dropped"].get(reason, 0) + int(n_other)


def align_channels(df: pd.DataFrame, report: dict) -> pd.DataFrame:
    """Put the channels of an asynchronous log onto its speed samples.

    Loggers that poll one value per row (OBD apps such as Car Scanner, CAN-bus exports)
    leave every other column empty on a speed row. A numeric channel logged mostly on
    rows without speed is asynchronous: its value at each speed sample is interpolated
    (:func:`interp_onto`), a value logged on the speed row itself kept; a channel logged
    faster than the speed is averaged over each speed interval instead (:func:`onto`,
    :func:`keep_power`). Channels logged on the speed rows (a synchronous log) are not touched. The report's
    notes say which channels were aligned, which averaged and how much of each stayed
    missing. Call per trip.
    """
    t = pd.to_numeric(df["time_s"], errors="coerce").to_numpy(float)
    speed_row = np.isfinite(t) & df["speed_mps"].notna().to_numpy()
    other = np.isfinite(t) & ~speed_row
    if not other.any() or not speed_row.any():
        return df
    aligned: dict[str, np.ndarray] = {}
    averaged, fast_raw = [], {}
    ts = t[speed_row]
    for c in df.columns:
        if c in ("time_s", "speed_mps", "trip_id") or not pd.api.types.is_numeric_dtype(df[c]):
            continue
        x = df[c].to_numpy(float)
        own = np.isfinite(t) & np.isfinite(x)
        if not own.any() or (own & speed_row).sum() >= 0.5 * own.sum():
            continue
        col = x[speed_row].copy()
        if c in FLAGS:  # a state (an on/off flag): its last value held, never averaged
            put, mean = held(ts, t[own], x[own]), False
        else:
            put, mean = onto(ts, t[own], x[own])
        if mean:
            col = put
            averaged.append(c)
            if c in POWER_FACTORS:
                fast_raw[c] = (t[own], x[own])
        else:
            todo = ~np.isfinite(col)
            col[todo] = put[todo]
        aligned[c] = col
    if not aligned:
        return df
    kept = keep_power(ts, fast_raw, aligned)
    out = df.loc[~other].copy()  # the speed rows, and rows without a time (dropped later)
    on_speed = speed_row[~other]
    for c, col in aligned.items():
        full = out[c].to_numpy(float, copy=True)
        full[on_speed] = col
        out[c] = full
    aligned_note(int(other.sum()), int(speed_row.sum()), aligned, report, averaged)
    report["notes"].extend(f"{a} is its mean weighted by {b} over each speed interval, so that {a} × {b} "
                           "carries the mean power" for a, b in kept)
    return out
