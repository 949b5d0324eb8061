"""Structural effects no column names (issue #11 §2): timing, regimes, air density, grade.

Measurement-side effects are corrected in the data, not absorbed by coefficients:

* **timing** — a lag between the power signal and the speed signal. For every shift ℓ
  (whole samples, |ℓ·Δt| ≤ ``max_lag_s``) the measured power is read ℓ samples later,
  y_ℓ(i) = y(i + ℓ) within a trip, and the declared terms are refitted. Held out: for each
  fold the lag is chosen on the other folds (smallest training SSE) and the held-out
  blocks are scored with it; d_b = SSE_b(ℓ = 0) − SSE_b(ℓ_fold) feeds the same paired test
  as every candidate (one test, no multiplicity beyond it). When accepted, the lag chosen
  on all data is applied to the measured power before the search goes on, and reported in
  seconds: τ > 0 means the power signal is late relative to the speed signal (the speed
  leads), τ < 0 that the speed lags. Per-trip lags are reported too.

Model-side structure is offered as candidates (their own kind, role ``structural``):

* **regimes** — ``[recuperation]*model``: the baseline model's power where it is negative
  (drivetrain efficiency differs by direction: a coefficient c scales recuperation by
  1 + c); ``[recuperation_below_<X>kW]``: min(P̂ + X, 0), the part of predicted
  recuperation beyond X kW that friction brakes take over (c ≈ −1 when measured power
  stops following the model there);
* **inertia by direction** — ``acc_pos`` (m·v·max(a, 0)) when the declared equation has
  ``acc``: the drivetrain delivers kinetic energy at 1/η and returns it at η, so the
  inertial power takes a larger coefficient while the car speeds up;
* **air density** — ``[air_density_altitude]*TERM`` for each declared aero term, when the
  log has elevation and ambient temperature but no pressure (the reader then assumes
  101.325 kPa): the relative error of ρ, p(h)/p₀ − 1 with the standard-atmosphere
  pressure p(h) = p₀·(1 − L·h/T₀)^(g·M/(R·L)) (ISO 2533);
* **missing grade** — ``grade`` when the declared equation has none (calibrated on a flat
  road or a dynamometer) and the data's grade varies;
* **grade from an accelerometer** — where the log has a longitudinal accelerometer
  (``imu_accel_mps2``, which reads dv/dt + g·sin θ), sin θ_acc = (a_imu − dv/dt)/g
  smoothed over ``ACC_GRADE_WINDOW_S``; the candidate ``[grade_accelerometer]*grade`` is
  (sin θ_acc − sin θ_log)/sin-scale × the grade term, i.e. it replaces the logged grade by
  the accelerometer's where that fits better. Both grades are reported.
"""

from __future__ import annotations

import math

import numpy as np

# the log corrections and air physics the tracer shares (data/corrections.py, model/air.py),
# re-exported for the tracer's modules
from sumo_drvpw.data.corrections import (ACC_GRADE_WINDOW_S, ACCELEROMETER_COLUMNS,  # noqa: F401
                                         accelerometer_sin_grade, fused_sin_grade, shift_within_trips)
from sumo_drvpw.fit.diagnose.candidates import Candidate
from sumo_drvpw.model.air import pressure_at_altitude_kpa  # noqa: F401
from sumo_drvpw.model.constants import G
from sumo_drvpw.model.constants import P_STD_KPA as P0_KPA  # noqa: F401
from sumo_drvpw.model.measurement import FUSION_TAU_S  # noqa: F401
from sumo_drvpw.model.terms import parse_term

#: recuperation levels of the brake-limit candidates: quantiles of predicted recuperation
RECUP_QUANTILES = (0.5, 0.75, 0.9)


def lag_range(dt_s: float, max_lag_s: float) -> np.ndarray:
    """Whole-sample shifts to try: −L … L with L = floor(max_lag_s / dt)."""
    if not dt_s > 0:
        return np.array([0])
    k = int(math.floor(max_lag_s / dt_s + 1e-9))
    return np.arange(-k, k + 1)


def timing(tr, y_by_lag: dict[int, np.ndarray], dt_s: float, paired_test) -> dict:
    """Held-out test of a power–speed lag on the declared model (see module docstring).

    Parameters
    ----------
    tr : :class:`~sumo_drvpw.fit.diagnose.blocks.BlockModel` with the declared terms, built
        on samples where every shifted power is finite
    y_by_lag : shift [samples] → measured power read that many samples later [W] (on tr's samples)
    dt_s : sample interval [s]
    paired_test : the tracer's one-sided block test (d_b → p)

    Returns a dict with ``lag_samples``, ``lag_s`` (chosen on all data), ``fold_lags_s``,
    ``p_value``, ``rmse_gain`` and the per-block ``d``.
    """
    lags = sorted(y_by_lag)
    raw_zy, raw_yy = block_lag_sums([c.values for c in tr.cols],
                                    np.column_stack([y_by_lag[lag] for lag in lags]), tr.starts)
    zy, yy = scale_lag_sums(tr, raw_zy, raw_yy)
    return timing_from_blocks(tr, {lag: zy[:, :, i] for i, lag in enumerate(lags)},
                              {lag: yy[:, i] for i, lag in enumerate(lags)}, dt_s, paired_test)


def scale_lag_sums(tr, raw_zy: np.ndarray, raw_yy: np.ndarray):
    """Sums of raw values (:func:`block_lag_sums`) → sums of the model's scaled columns and
    the scaled power (÷ column scale × ``y_scale``; ÷ ``y_scale``²)."""
    s = np.array([c.scale for c in tr.cols])
    return raw_zy / (s[None, :, None] * tr.y_scale), raw_yy / (tr.y_scale * tr.y_scale)


def block_lag_sums(z: list, ys: np.ndarray, starts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sums per contiguous segment (block or trip) for the lag search.

    Parameters
    ----------
    z : model columns, one array of n values each
    ys : scaled power read ℓ samples later, one column per shift (n × L)
    starts : first sample of each segment

    Returns Σ z_j·y_ℓ (S × q × L) and Σ y_ℓ² (S × L): one product of a sparse segment
    indicator (weighted by z_j) with ys per column — a sum in sample order per segment,
    whatever the batch the segment came in (so the streamed tracer adds the same numbers).
    """
    from scipy import sparse

    n = ys.shape[0]
    shape = (len(starts), n)
    ptr, idx = np.r_[starts, n], np.arange(n)
    yy = sparse.csr_matrix((np.ones(n), idx, ptr), shape=shape) @ (ys * ys)
    zy = np.stack([sparse.csr_matrix((np.asarray(zj, float), idx, ptr), shape=shape) @ ys for zj in z],
                  axis=1) if z else np.zeros((len(starts), 0, ys.shape[1]))
    return zy, yy


def timing_from_blocks(tr, zy_by_lag: dict, yy_by_lag: dict, dt_s: float, paired_test) -> dict:
    """:func:`timing` from per-block statistics: shift → Z_bᵀy_b (B × q) and y_bᵀy_b (B),
    y read that many samples later and scaled by ``tr.y_scale``."""
    lags = sorted(zy_by_lag)
    fold = tr.fold_of(False)
    k = int(fold.max()) + 1
    zz = tr.block_zz                                   # B × q × q
    fold_zz = np.zeros((k,) + zz.shape[1:])
    np.add.at(fold_zz, fold, zz)
    train_zz = fold_zz.sum(0)[None] - fold_zz           # K × q × q
    sse_train, sse_block = {}, {}
    for lag in lags:
        zy, yy = zy_by_lag[lag], yy_by_lag[lag]
        fzy = np.zeros((k, zy.shape[1]))
        np.add.at(fzy, fold, zy)
        fyy = np.bincount(fold, weights=yy, minlength=k)
        tzy, tyy = fzy.sum(0)[None] - fzy, fyy.sum() - fyy
        beta = tr._solve(train_zz, tzy)                                # K × q
        sse_train[lag] = tyy - np.einsum("kq,kq->k", beta, tzy)
        b = beta[fold]
        sse_block[lag] = np.maximum(yy - 2 * np.einsum("bq,bq->b", b, zy)
                                    + np.einsum("bi,bij,bj->b", b, zz, b), 0.0)
        # all-data fit for the lag reported
        full = tr._solve(fold_zz.sum(0), fzy.sum(0))
        sse_train[(lag, "all")] = fyy.sum() - float(full @ fzy.sum(0))
    train = np.array([sse_train[lag] for lag in lags])                # L × K
    best_fold = np.argmin(train, axis=0)                               # per fold, in lag order
    chosen = np.array([sse_block[lags[best_fold[f]]][b] for b, f in enumerate(fold)])
    d = sse_block[0] - chosen
    sse0, sse1 = float(sse_block[0].sum()), float(chosen.sum())
    gain = 1.0 - math.sqrt(sse1 / sse0) if sse0 > 0 else 0.0
    all_sse = [sse_train[(lag, "all")] for lag in lags]
    lag_all = lags[int(np.argmin(all_sse))]
    return {"lag_samples": int(lag_all), "lag_s": lag_all * dt_s,
            "fold_lags_s": [lags[i] * dt_s for i in best_fold],
            "p_value": paired_test(d) if lag_all != 0 else 1.0, "rmse_gain": gain, "d": d,
            "rmse_by_lag_s": {f"{lag * dt_s:+.3g}": math.sqrt(max(s, 0.0) / tr.n) * tr.y_scale
                              for lag, s in zip(lags, all_sse)}}


def per_trip_lags(tr, y_by_lag: dict[int, np.ndarray], dt_s: float) -> dict[str, float]:
    """Best lag of each trip alone [s] (declared terms refitted per trip; for the report)."""
    lags = sorted(y_by_lag)
    # each trip's rows from one stable sort (a mask per trip made this O(trips × rows))
    order = np.argsort(tr.trip, kind="stable")
    codes = np.asarray(tr.trip)[order]
    bounds = np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])
    x = [np.asarray(c.values, float)[order] for c in tr.cols]
    zy, yy = block_lag_sums(x, np.column_stack([y_by_lag[lag][order] for lag in lags]), bounds)
    ends = np.r_[bounds[1:], len(order)]
    xm = np.column_stack(x)
    stats = {int(codes[lo]): (hi - lo, xm[lo:hi].T @ xm[lo:hi], zy[i], yy[i])
             for i, (lo, hi) in enumerate(zip(bounds, ends))}
    return per_trip_lags_from_stats(tr, stats, lags, dt_s)


def per_trip_lags_from_stats(tr, stats: dict, lags, dt_s: float) -> dict[str, float]:
    """:func:`per_trip_lags` from per-trip sums of raw values: trip code → (n, XᵀX,
    Xᵀy per lag (q × L), yᵀy per lag (L)); trips with fewer than 10 samples per column
    are left out. One least-squares solve per trip for all lags."""
    s = np.array([c.scale for c in tr.cols])
    out = {}
    for t in sorted(stats):
        n, a, b_all, yy = stats[t]
        if n < 10 * a.shape[0]:
            continue
        a = a / np.outer(s, s)
        b_all = b_all / (s[:, None] * tr.y_scale)
        sol = np.linalg.lstsq(a, b_all, rcond=None)[0]
        sse = yy / (tr.y_scale * tr.y_scale) - np.einsum("ql,ql->l", b_all, sol)
        out[str(tr.trip_names[t])] = lags[int(np.argmin(sse))] * dt_s
    return out


#: the inertia-by-direction candidate (term ``acc_pos``) and its plain-language name
INERTIA_EFFECT = ("inertial power on its own coefficient while speeding up: the drivetrain delivers "
                  "kinetic energy at 1/η and returns it at η")


def model_side_candidates(declared, theta_ptp: float) -> list[Candidate]:
    """Structure the declared equation lacks, named by no column: a grade term (when the
    grade varies, ``theta_ptp`` its range [rad]) and inertia by direction (``acc_pos`` when
    the equation has ``acc`` and not yet ``acc_pos``); the in-memory and streamed tracers
    both offer these."""
    cands = []
    if not any(parse_term(t).category == "grade" for t in declared) and theta_ptp > 1e-4:
        cands.append(Candidate("grade", "road grade: the declared equation has no grade term "
                               "(calibrated where the road is flat, e.g. on a dynamometer)", (), "structural"))
    if "acc" in declared and "acc_pos" not in declared:
        cands.append(Candidate("acc_pos", INERTIA_EFFECT, (), "structural"))
    return cands


def accelerometer_grade_power(x, sin_acc) -> np.ndarray:
    """The ``[grade_accelerometer]`` column: m·g·v·(sin θ_acc − sin θ_log), the grade power the
    accelerometer's grade adds to the logged one (a factor on the grade term,
    (sin θ_acc − sin θ_log)/sin θ_log, is ill-posed at 0)."""
    return x.mass * G * x.v * (sin_acc - np.sin(x.theta))


def accelerometer_candidate(acc_col: str) -> Candidate:
    """The ``[grade_accelerometer]`` candidate of an accelerometer column (in memory and streamed)."""
    return Candidate("[grade_accelerometer]", f"grade measured by the accelerometer '{acc_col}' (reads "
                     "dv/dt + g·sin θ) instead of the logged grade: m·g·v·(sin θ_acc − sin θ_log)", (), "structural")


def structural_signals(tr, declared, x_all_signals: dict, idx: np.ndarray, log_df,
                       counts: dict) -> tuple[dict, list[Candidate], dict]:
    """Derived columns and candidates of the model-side structural effects.

    Returns (name → values on the analysis samples, candidates, notes for the report).
    """
    sig, cands, notes = {}, [], {}
    # regimes from the baseline (declared terms, all-data fit) prediction
    f = tr.full_fit()
    pred = np.zeros(tr.n)
    for j, c in enumerate(tr.cols):
        pred += f["beta"][c.offset] * tr.scaled(j) * tr.y_scale
    neg = pred < 0
    if neg.mean() > 0.02:
        sig["recuperation"] = np.where(neg, pred, 0.0)
        cands.append(Candidate("[recuperation]", "recuperation on its own coefficient: "
                               "drivetrain efficiency differs by direction (1 + c scales recuperation)",
                               (), "structural"))
        for q in RECUP_QUANTILES:
            lim = float(np.quantile(-pred[neg], q))
            if lim <= 0:
                continue
            name = f"recuperation_below_{lim / 1000:.3g}kW"
            sig[name] = np.minimum(pred + lim, 0.0)
            cands.append(Candidate(f"[{name}]", f"a recuperation limit: beyond {lim / 1000:.3g} kW "
                                   "of predicted recuperation, friction brakes take over", (), "structural"))
    # air density from altitude when pressure is not logged
    if ("elevation_m" in log_df and "ambient_c" in log_df and "pressure_kpa" not in log_df
            and str(counts.get("air_density_source", "")).startswith("ideal gas")):
        h = log_df["elevation_m"].to_numpy(float)[idx]
        if np.isfinite(h).all():
            rel = pressure_at_altitude_kpa(h) / P0_KPA - 1.0
            sig["air_density_altitude"] = rel
            notes["air_density_altitude"] = {"mean_relative_error_of_rho": float(np.mean(rel)),
                                             "altitude_m": [float(h.min()), float(h.max())]}
            for t in declared:
                if parse_term(t).category == "aero" and not parse_term(t).signals:
                    cands.append(Candidate(f"[air_density_altitude]*{t}",
                                           f"air density from altitude: the log's ρ assumes sea-level "
                                           f"pressure; {t} scaled by p(h)/p₀ − 1", (), "structural"))
    # a missing grade term (an equation calibrated where the road is flat: a dynamometer)
    cands += model_side_candidates(declared, float(np.ptp(tr.x.theta)))
    # grade from a longitudinal accelerometer
    acc_col = next((c for c in ACCELEROMETER_COLUMNS if c in x_all_signals), None)
    grade_terms = [t for t in declared if parse_term(t).category == "grade" and not parse_term(t).signals]
    if acc_col is not None and grade_terms:
        imu = np.asarray(x_all_signals[acc_col], float)[idx]
        if np.isfinite(imu).all():
            x = tr.x
            t = log_df["time_s"].to_numpy(float)
            dt_med = float(np.median(np.diff(t))) if len(t) > 1 else 1.0
            sin_acc = accelerometer_sin_grade(imu, x.a, tr.trip, dt_med)
            sin_log = np.sin(x.theta)
            # factor on the grade term: (sin θ_acc − sin θ_log)/sin θ_log is ill-posed at 0;
            # the candidate is the grade power difference m·g·v·(sin θ_acc − sin θ_log)
            sig["grade_accelerometer"] = accelerometer_grade_power(x, sin_acc)
            cands.append(accelerometer_candidate(acc_col))
            notes["grade_sources"] = {
                "accelerometer_column": acc_col,
                "logged": {"mean_abs_deg": float(np.degrees(np.mean(np.abs(np.arcsin(np.clip(sin_log, -1, 1)))))),
                           "sd_deg": float(np.degrees(np.std(np.arcsin(np.clip(sin_log, -1, 1)))))},
                "accelerometer": {"mean_abs_deg": float(np.degrees(np.mean(np.abs(np.arcsin(sin_acc))))),
                                  "sd_deg": float(np.degrees(np.std(np.arcsin(sin_acc))))},
                "fused": (lambda f: {"mean_abs_deg": float(np.degrees(np.mean(np.abs(np.arcsin(f))))),
                                     "sd_deg": float(np.degrees(np.std(np.arcsin(f)))),
                                     "crossover_s": FUSION_TAU_S})(
                    fused_sin_grade(sin_acc, sin_log, tr.trip, dt_med)),
                "corr": float(np.corrcoef(sin_acc, sin_log)[0, 1]) if sin_log.std() > 0 else math.nan}
    return sig, cands, notes
