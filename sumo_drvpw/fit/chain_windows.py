"""A fuel chain's Willans line on windowed means: noise in the driving power (errors in the
variables) and what the line fitted on 1-Hz samples makes of it.

A drive log's driving power holds the acceleration derived from a logged speed (and a grade
from a logged elevation); at a truck's mass the derivative's noise alone reaches megawatts. In
the regressor it flattens the Willans line (regression dilution: the marginal efficiency reads
high, the zero-output fuel too — the fuel the noise does not buy is booked at zero output). A
derivative's noise cancels over a window (the mean acceleration is the speed's change over it),
so the line fitted on means over windows of whole seconds sees the driving power, not the
logger. A window is a run of the same trip's usable samples, chopped every ``window_s`` [s]; it
never straddles

* the line's kink at zero driving power (the mean of max(P, 0) is not max of the mean): runs
  split where the sign of the driving power, smoothed over :data:`SIGN_SMOOTH_S` centred
  within the trip (long enough for a derivative's noise to cancel, short enough to find the
  change), changes — the driving power's, also with logged loads: the engine demand
  max(P, 0)/η_t + P_aux + Σ g·L (model/chain_values.py ``engine_demand``) takes the loads, and
  the design a hybrid's battery V·I, after the max, and never falls below the auxiliaries, so
  its kink is at P = 0 and it has no sign change of its own (tests/test_chain_window_splits.py);
* the engine's state as the log shows it: fuel flowing or not (``FUEL_FLOWING_W``), so an
  engine-off (a hybrid's — at light load, or below its engine-on speed —, or a fuel cut on
  overrun) is never averaged into an engine-on window;
* standing and moving (``STANDSTILL_MPS``): the standing idle fuel stays the standstill's;
* the line's other kink, the engine's rated output where a fuel chain has one (the mean of
  min(P, P_max) is not min of the mean): runs split where the smoothed driving power plus the
  logged loads reaches it (the engine delivers both: fit/chain_fuel.py ``capped_drive``).

The splits are found once per trip (:func:`trip_runs`) and chopped per window length
(:func:`chop`), so the ATTENUATED check's three lengths cost one pass of the smoothing.

Every usable sample is in exactly one window; a window weighs its duration. Windows of less
than half ``window_s`` (at the splits) are left out of the windowed fit: their noise is not
averaged.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from sumo_drvpw.model.constants import STANDSTILL_MPS

#: windows [s] the plausibility check refits the per-sample line on (:func:`windowed_lines`)
DILUTION_WINDOWS_S = (10.0, 30.0, 60.0)
#: the smoothing [s] of the driving power whose sign splits the windows (a longer one blurs
#: where braking starts: windows then mix it with driving and the zero-output fuel reads high)
SIGN_SMOOTH_S = 5.0
#: a windowed marginal efficiency this far (relative) from the per-sample one, and beyond twice its
#: standard error, flags the per-sample line as attenuated (chain_checks.dilution_note): a
#: planted truck with 0.3 m/s of speed noise moves 0.93 → 0.40, the measured class-8 trucks 0.51 →
#: 0.36 (docs/hdv-fuel.md); the Prius Gen-2's measured driving power 0.386 → 0.363–0.374, which
#: held out is no better on windows (docs/energy-chain.md), stays below it
DILUTION_REL = 0.10


def window_ids(p, v, fuel_w, dt_s, ok, trip, window_s: float, cap_w: float | None = None,
               runs: "Runs | None" = None, load_w=None) -> np.ndarray:
    """Per sample, the window it is averaged in (0, 1, …; −1 where not ``ok``), as the module
    docstring says: runs of one trip's usable samples with one sign of the smoothed driving
    power ``p`` [W], one engine state (fuel ``fuel_w`` [W] flowing or not) and one of standing
    or moving (``v`` [m/s]), below or at the rated output ``cap_w`` [W] of driving power (None:
    none; with the logged loads ``load_w`` [W] added, :func:`trip_runs`), chopped every ``window_s``
    [s] of duration ``dt_s``. Each trip's
    windows are found on its own clock (from 0 at its first sample), so a trip is cut alike
    read whole or in a batch of other trips (a streamed fit's, fit/chain_stream.py). ``runs``:
    the same samples' :func:`trip_runs`, found once for every window length (None: found here)."""
    if runs is None:
        runs = trip_runs(p, v, fuel_w, dt_s, ok, trip, cap_w, load_w)
    return chop(runs, window_s)


class Runs(NamedTuple):
    """The runs windows are chopped from (:func:`trip_runs`), whatever the window's length."""

    run: np.ndarray     #: per sample, its run (0, 1, … in sample order; a new one at each trip's start)
    offset: np.ndarray  #: per sample, its start's time [s] since its run's first sample started
    ok: np.ndarray      #: the usable samples


def trip_runs(p, v, fuel_w, dt_s, ok, trip, cap_w: float | None = None, load_w=None) -> Runs:
    """The runs of :func:`window_ids` (one trip's samples of one smoothed-power sign, engine
    state, standing or moving, usability and side of the rated output ``cap_w`` [W]), found once:
    windows of any length are chopped from them (:func:`chop`). The engine delivers the driving
    power and the logged loads ``load_w`` [W at the engine output, their sum per sample; None:
    none] together, so it reaches its rating where the smoothed driving power plus the loads do
    (fit/chain_fuel.py ``capped_drive``, the line's kink)."""
    p, v, y = (np.asarray(a, float) for a in (p, v, fuel_w))
    n = p.size
    dt = np.nan_to_num(np.broadcast_to(np.asarray(dt_s, float), (n,)))
    ok = np.asarray(ok, bool)
    if n == 0:
        return Runs(np.zeros(0, np.int64), np.zeros(0), ok)
    load = np.zeros(n) if load_w is None else np.nan_to_num(np.broadcast_to(np.asarray(load_w, float), (n,)))
    tr = np.zeros(n, int) if trip is None else np.asarray(trip)
    starts = np.flatnonzero(np.r_[True, tr[1:] != tr[:-1]])
    run, offset = np.zeros(n, np.int64), np.zeros(n)
    base = 0
    for a, b in zip(starts, np.r_[starts[1:], n]):  # (one trip at a time: its own time from 0)
        r, o = _trip_cuts(p[a:b], v[a:b], y[a:b], dt[a:b], ok[a:b], cap_w, load[a:b])
        run[a:b], offset[a:b] = r + base, o
        base += int(r[-1]) + 1
    return Runs(run, offset, ok)


def chop(runs: Runs, window_s: float) -> np.ndarray:
    """:func:`window_ids` from the :func:`trip_runs` ``runs``: each run chopped every
    ``window_s`` [s] of its duration."""
    run, ok = runs.run, runs.ok
    n = run.size
    if n == 0:
        return np.zeros(0, int)
    k = np.floor(runs.offset / window_s).astype(np.int64)
    cut = np.r_[True, (run[1:] != run[:-1]) | (k[1:] != k[:-1])]
    wid = np.where(ok, np.cumsum(cut) - 1, -1)
    return np.unique(wid, return_inverse=True)[1].reshape(n) - (1 if (~ok).any() else 0)


def _trip_cuts(p, v, y, dt, ok, cap_w: float | None = None, load=0.0) -> tuple[np.ndarray, np.ndarray]:
    """One trip's runs (:func:`trip_runs`): per sample its run (0, 1, …; a new one wherever the
    smoothed power's sign, the engine state, standing or moving, or usability changes, or the
    smoothed power plus the loads ``load`` [W] reaches or leaves ``cap_w`` [W]) and its start's
    time [s] since its run's first sample started."""
    from sumo_drvpw.fit.chain_fuel import FUEL_FLOWING_W

    half = SIGN_SMOOTH_S / 2.0
    t = np.cumsum(dt)
    cp, ck = np.r_[0.0, np.cumsum(np.where(ok, p, 0.0))], np.r_[0, np.cumsum(ok)]
    lo, hi = np.searchsorted(t, t - half, "left"), np.searchsorted(t, t + half, "right")
    ps = (cp[hi] - cp[lo]) / np.maximum(ck[hi] - ck[lo], 1)
    state = (ps > 0) * 1 + (y > FUEL_FLOWING_W) * 2 + (v < STANDSTILL_MPS) * 4 + (~ok) * 8
    if cap_w is not None:
        state = state + (ps + load >= cap_w) * 16
    run = np.cumsum(np.r_[True, state[1:] != state[:-1]])
    start = np.flatnonzero(np.r_[True, run[1:] != run[:-1]])
    tb = t - dt  # each sample's start
    return run - 1, tb - tb[start][run - 1]


def load_sum(signals: dict | None, cap_w: float | None):
    """The logged loads of ``signals`` (a fuel fit's: its load columns only) summed per sample [W],
    where a rated output ``cap_w`` splits windows (:func:`trip_runs`); None where none does or
    there are no loads."""
    if cap_w is None or not signals:
        return None
    return sum(np.nan_to_num(np.asarray(signals[c], float)) for c in sorted(signals))


def window_means(wid, dt_s, *cols):
    """The duration-weighted means of ``cols`` over the windows ``wid`` (:func:`window_ids`) and
    the windows' durations [s]: ``(durations, mean col 1, …)``."""
    use = wid >= 0
    k = int(wid.max()) + 1 if use.any() else 0
    dt = np.broadcast_to(np.asarray(dt_s, float), wid.shape)[use]
    dur = np.bincount(wid[use], dt, k)
    return (dur, *(np.bincount(wid[use], np.broadcast_to(np.asarray(c, float), wid.shape)[use] * dt, k)
                   / np.where(dur > 0, dur, 1.0) for c in cols))


def windowed(p, v, fuel_w, dt_s, battery_w, signals: dict, ok, trip, window_s: float, cap_w: float | None = None,
             runs: Runs | None = None):
    """The fuel chain's inputs as means over windows of ``window_s`` [s] (:func:`window_ids`;
    the short ones left out): (P, v, fuel, durations, battery or None, signals) to calibrate
    on, and the number of windows and of the samples in them. ``runs``: :func:`trip_runs` of
    these samples, found once for several window lengths (None: found here)."""
    wid = window_ids(p, v, fuel_w, dt_s, ok, trip, window_s, cap_w, runs, load_sum(signals, cap_w))
    names = sorted(signals or {})
    cols = [p, v, fuel_w] + ([] if battery_w is None else [np.nan_to_num(np.asarray(battery_w, float))])
    out = window_means(wid, dt_s, *cols, *[np.nan_to_num(np.asarray(signals[c], float)) for c in names])
    keep = out[0] >= window_s / 2.0
    got = [np.asarray(a)[keep] for a in out]
    nb = len(cols) - 3
    sig = {c: a for c, a in zip(names, got[4 + nb:])}
    return (got[1], got[2], got[3], got[0], got[4] if nb else None, sig,
            int(keep.sum()), int(np.isin(wid, np.flatnonzero(keep)).sum()))


def windowed_lines(fit_template, p, v, fuel_w, dt_s, battery_w, signals, ok, trip,
                   windows=DILUTION_WINDOWS_S, cap_w: float | None = None) -> list[dict]:
    """The per-sample fit's line refitted on means over each of ``windows`` [s]
    (``fit_template(P, v, fuel, durations, battery, signals)`` → ChainFit: the same engine
    state and form as the per-sample fit; ``cap_w`` its rated output [W], None: none): per window its zero-output fuel, marginal efficiency
    and standard error, and the windows' number (windows too few for a line are skipped)."""
    # (the splits found once, chopped per length)
    rows, runs = [], trip_runs(p, v, fuel_w, dt_s, ok, trip, cap_w, load_sum(signals, cap_w))
    for ws in windows:
        pp, vv, yy, dur, pb, sig, nw, _ = windowed(p, v, fuel_w, dt_s, battery_w, signals, ok, trip, ws, cap_w, runs)
        if nw < 10:
            continue
        f = fit_template(pp, vv, yy, dur, pb, sig)
        eta = f.parameters["marginal_efficiency"]
        rows.append({"window_s": ws, "windows": nw, "idle_fuel_power_w": f.chain.idle_fuel_power_w,
                     "marginal_efficiency": eta["value"], "std_err": eta["std_err"],
                     "at_bound": eta["at_bound"]})
    return rows


def calibrate_windowed(calibrate, p, v, fuel_w, dt_s, battery_w, signals, ok, trip, window_s, **kw):
    """``calibrate`` (:func:`~sumo_drvpw.fit.chain_fuel.calibrate_fuel`, with its keywords
    ``kw``) on the means over windows of ``window_s`` [s] (:func:`windowed`) of the samples
    ``ok``; its R², RMSE and energy ratio on those samples, as a per-sample fit's. UserError
    for a window that is no positive number of seconds, shorter than two samples (the
    per-sample fit), or too few windows for a line."""
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.fit.chain import _stats
    from sumo_drvpw.fit.chain_fuel import standing_sums
    from sumo_drvpw.model.chain import corrected_fuel_power

    ws = float(window_s) if isinstance(window_s, (int, float)) else float("nan")
    if not np.isfinite(ws) or ws <= 0:
        raise UserError(f"energy chain: window_s {window_s!r}: the window of the means to fit on is a positive "
                        "number of seconds (e.g. 30)")
    dts = np.broadcast_to(np.asarray(dt_s, float), ok.shape)[ok]
    step = float(np.median(dts)) if dts.size else float("nan")
    if ws < 2.0 * step:  # (one sample a window: the per-sample fit, labelled windowed)
        raise UserError(f"energy chain: windows of {ws:g} s: shorter than two of the logs' samples ({step:g} s apart): "
                        "its windows hold one sample, or two, and the fit is the per-sample one, labelled windowed; "
                        "give a window of several samples (e.g. 30 s)")
    cap = kw.get("engine_max_w")  # (a declared rating splits the windows; a profiled one is not known yet)
    cap = float(cap) if isinstance(cap, (int, float)) else None
    pp, vv, yy, dur, pb, sig, nw, ns = windowed(p, v, fuel_w, dt_s, battery_w, signals, ok, trip, ws, cap)
    if nw < 10:
        raise UserError(f"energy chain: windows of {ws:g} s: only {nw} of at least {ws / 2:g} s on the "
                        f"{int(ok.sum())} usable samples, too few for a line: fit on a shorter window or more logs")
    fit = calibrate(pp, vv, yy, dur, pb, sig, check_windows=False, **kw)
    ch, w = fit.chain, np.broadcast_to(np.asarray(dt_s, float), ok.shape)
    pred = ch.evaluate(p[ok], v[ok], signals={k: np.asarray(a)[ok] for k, a in signals.items()})["power_w"]
    bw = np.zeros(ok.shape) if battery_w is None else np.nan_to_num(np.asarray(battery_w, float))
    target = corrected_fuel_power(np.asarray(fuel_w, float), bw, ch.battery_fuel_factor)[ok]
    fit.r2, fit.rmse_w, fit.energy_ratio = _stats(pred, target, w[ok])
    fit.n = int(ok.sum())
    ch.metrics.update({"n": fit.n, "r2": fit.r2, "rmse_w": fit.rmse_w, "energy_ratio": fit.energy_ratio,
                       "fit_window_s": ws, "fit_windows": nw, "fit_windowed_samples": ns})
    fit.standing = standing_sums(v, np.asarray(fuel_w, float), w, ok)
    fit.parameters["marginal_efficiency"]["reading"] += (
        f"; fitted on means over {nw} windows of {ws:g} s ({ns} of the {fit.n} usable samples; the shorter "
        "ones at a change of power sign, engine state or standing left out): the noise of a derived "
        "acceleration and grade averages out of the regressor there, not at 1 Hz")
    return fit


def window_designs(grid, p, v, fuel_w, dt_s, battery_w, signals, loads, ok, trip, windows=DILUTION_WINDOWS_S):
    """For a streamed fit (fit/chain_stream.py): per window length of ``windows`` [s] and template
    ``i`` of ``grid``, ``((i, window), X, y, durations)``, the Willans design (fit/chain_fuel.py
    ``fuel_design``) on a batch's windowed means — batches hold whole trips, so their factors add up
    to the in-memory refit's (:func:`windowed_lines`)."""
    from sumo_drvpw.fit.chain_fuel import fuel_design

    caps = {t.engine_max_w for t in grid}  # (the grid's templates keep one declared rating)
    cap = caps.pop() if len(caps) == 1 else None
    runs = trip_runs(p, v, fuel_w, dt_s, ok, trip, cap, load_sum(signals, cap))  # (the splits once; chopped per length)
    for ws in windows:
        pp, vv, yy, dur, pb, sig, nw, _ = windowed(p, v, fuel_w, dt_s, battery_w, signals, ok, trip, ws, cap, runs)
        if nw:
            pb = np.zeros(nw) if pb is None else pb
            for i, tmpl in enumerate(grid):
                yield (i, ws), fuel_design(tmpl, pp, vv, pb, [sig[c] for c in loads]), yy, dur


def factored_lines(fac: dict, i: int, bounds, windows=DILUTION_WINDOWS_S) -> list[dict]:
    """:func:`windowed_lines`' rows from a streamed fit's factors ``fac[(i, window)]`` = [R, rows,
    …] of its chosen template ``i`` (bounds: fit/chain_fuel.py ``fuel_bounds``)."""
    from sumo_drvpw.fit.chain import _covariance, _nan_none, solve_factor

    rows = []
    for ws in windows:
        if (i, ws) not in fac or fac[(i, ws)][1] < 10:
            continue
        beta, rss, act, xs = solve_factor(fac[(i, ws)][0], fac[(i, ws)][1], *bounds)
        se = _covariance(xs, rss, act)
        rows.append({"window_s": ws, "windows": int(fac[(i, ws)][1]), "idle_fuel_power_w": float(beta[0]),
                     "marginal_efficiency": 1.0 / beta[1], "std_err": _nan_none(se[1] / beta[1] ** 2),
                     "at_bound": bool(act[1] != 0)})
    return rows
