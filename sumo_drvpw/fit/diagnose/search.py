"""The forward search of the residual tracer and its held-out test (see the package docstring)."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from sumo_drvpw.data.roles import of_log as column_roles
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
from sumo_drvpw.fit.compare import metrics as _metrics
from sumo_drvpw.fit.diagnose.blocks import BlockModel
from sumo_drvpw.fit.diagnose.candidates import Candidate, generate_candidates, screen_signals
from sumo_drvpw.fit.diagnose.options import DiagnoseOptions
from sumo_drvpw.fit.diagnose.result import (DiagnoseResult, assemble, pick_metrics as _pick_metrics,
                                            term_label as _term_label)
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.model.terms import parse_term, term_matrix


def paired_test(d: np.ndarray) -> float:
    """One-sided p-value that held-out blocks improve: d_b = SSE_b(model) − SSE_b(model + c).

    Two tests, Bonferroni-combined (2 × the smaller p): the paired t-test of mean(d) > 0
    (power when the gain is concentrated in a few blocks) and the Wilcoxon signed-rank
    test of a positive shift (robust when a few heavy-tailed blocks dominate the mean).
    """
    d = d[np.isfinite(d)]
    if len(d) < 3:
        return 1.0
    sd = float(d.std(ddof=1))
    mean = float(d.mean())
    if sd == 0:
        return 0.0 if mean > 0 else 1.0
    tval = mean / (sd / math.sqrt(len(d)))
    p_t = float(stats.t.sf(tval, len(d) - 1))
    try:
        p_w = (float(stats.wilcoxon(d, alternative="greater", zero_method="wilcox").pvalue)
               if np.any(d != 0) else 1.0)
    except ValueError:
        p_w = 1.0
    return min(1.0, 2.0 * min(p_t, p_w))


_paired_test = paired_test


def _role_of(cand: Candidate, roles: dict) -> str:
    """Role of a finding: its column's role; ``structural`` for effects no column names."""
    if not cand.signals:
        return "structural"
    return roles.get(cand.signals[0], {}).get("role", "unknown")


def _score_all(tr: BlockModel, pool: list[Candidate], opt: DiagnoseOptions) -> list[tuple]:
    """Held-out scores of every candidate in ``pool``, in candidate order:
    (cand, SSE with it, per-block d, SSE without, fold)."""
    results = {}
    for scatter in (False, True):
        group = [c for c in pool if c.scatter == scatter]
        if not group:
            continue
        fold = tr.fold_of(scatter)
        sse0, _ = tr.heldout_model(fold)
        step = 1 if scatter else opt.batch
        for lo in range(0, len(group), step):
            sub = group[lo:lo + step]
            sse, valid = tr.score(sub, scatter, fold)
            for i, c in enumerate(sub):
                if valid[i]:
                    results[c.term] = (c, float(sse[:, i].sum()), sse0 - sse[:, i], float(sse0.sum()), fold)
    return [results[c.term] for c in pool if c.term in results]


def diagnose(measured, equation: Equation | None = None, opt: DiagnoseOptions | None = None,
          progress=None) -> DiagnoseResult:
    """Trace the residual of ``equation`` against a log's measured power.

    Parameters
    ----------
    measured : :class:`sumo_drvpw.data.measured.Measured` (measured power [W], inputs, usable mask)
    equation : the declared equation (its terms are kept, coefficients refitted per fold);
        None: calibrate one by stepwise OLS on the indt-var-1 candidates
    opt : :class:`DiagnoseOptions`
    progress : optional callable(str) for progress messages
    """
    opt = opt or DiagnoseOptions()
    opt.check()
    say = progress or (lambda s: None)
    log = measured.log
    y_all = np.asarray(measured.power_w, float)
    x_all = measured.inputs
    usable = np.asarray(measured.usable, bool).copy()
    trip_all = np.asarray(log.df["trip_id"].astype(str).to_numpy())
    trip_names, trip_codes_all = np.unique(trip_all, return_inverse=True)
    t_all = log.df["time_s"].to_numpy(float)
    dt_all = log.df["dt_s"].to_numpy(float)

    # declared equation
    calibrated = False
    if equation is None:
        res = calibrate(x_all, y_all, CANDIDATES["indt-var-1"], mask=usable,
                        reference_mass_kg=float(x_all.mass[usable].mean()))
        equation = res.to_equation("calibrated_indt_var_1", provenance={"logs": log.files})
        calibrated = True
        say(f"calibrated on the spot: {', '.join(equation.term_names)}")
    declared = equation.term_names
    x_eq = x_all.with_mass(equation.mass_kg)
    for s in equation.signals:
        if s not in x_eq.signals:
            raise UserError(f"equation '{equation.name}' needs the log column '{s}', which the data lack")

    # screen signals
    binary = set()
    roles = column_roles(log)
    kept, skipped = screen_signals(dict(x_all.signals), y_all, x_all, trip_codes_all, usable, opt, roles)
    for name in list(kept):
        if name in equation.signals:
            skipped.append({"column": name, "reason": "already a factor of a declared term"})
            kept.pop(name)
    # analysis samples: usable, declared terms finite, kept signals finite
    decl_vals = term_matrix(declared, x_eq)
    ana = usable & np.all(np.isfinite(decl_vals), axis=1) & (x_eq.v >= opt.min_speed_mps)
    for name, arr in kept.items():
        ana &= np.isfinite(arr)
    n = int(ana.sum())
    if n < 50:
        raise UserError(f"{log.describe()}: only {n} analysis samples (usable, with finite terms and signals); "
                        "need at least 50")
    idx = np.flatnonzero(ana)
    x = x_eq.take(idx)
    sig = {k: np.asarray(v, float)[idx] for k, v in kept.items()}
    for k, v in sig.items():
        if len(np.unique(v[: min(len(v), 200000)])) <= 2 and len(np.unique(v)) <= 2:
            binary.add(k)
    y = y_all[idx]
    dt = dt_all[idx]
    trip_codes = trip_codes_all[idx]
    n_trips = len(np.unique(trip_codes))
    tr = BlockModel(x, y, dt, t_all[idx], trip_codes, trip_names, sig, opt)
    for j, t in enumerate(declared):
        vals = decl_vals[idx, j]
        cand = Candidate(t, f"declared term {t}", tuple(parse_term(t).signals), "declared")
        tr._factor_cache[t] = vals
        tr.add(cand, vals)
    say(f"{n} analysis samples, {n_trips} trip(s), {tr.n_blocks} blocks, {len(sig)} signal(s) offered")

    cands = generate_candidates(sig, declared, n_trips, opt, binary)
    cands, dropped = tr.drop_spanned(cands)
    if dropped:
        say(f"{len(dropped)} candidate(s) dropped before scoring: identical to or spanned by earlier ones")
    base_fold = tr.fold_of(False)
    pred0 = tr.heldout_pred(base_fold)
    m_base = _metrics(pred0, y)
    base_coefs, _ = tr.coefficients()
    findings, rounds = [], []
    plot = {"y": y, "v": x.v, "pred_base": pred0, "signals": sig, "findings": []}
    in_model = set(declared)
    for rnd in range(opt.max_findings):
        pool = [c for c in cands if c.term not in in_model]
        if not pool:
            break
        results = _score_all(tr, pool, opt)
        if not results:
            break
        m_scored = len(results)
        gains = [1.0 - math.sqrt(r[1] / r[3]) if r[3] > 0 else 0.0 for r in results]
        # largest gain first; equal gains keep candidate order (stable), never rounding
        order = np.argsort(-np.asarray(gains), kind="stable")
        table = []
        for i in order[:10]:
            c, s, d, s0, _ = results[i]
            p = _paired_test(d)
            table.append({"term": c.term, "effect": c.effect, "rmse_gain": gains[i],
                          "p_value_bonferroni": min(1.0, p * m_scored)})
        best = int(order[0])
        cbest, sse_b, d_b, sse0_b, fold_b = results[best]
        p_raw = _paired_test(d_b)
        p_adj = min(1.0, p_raw * m_scored)
        accepted = p_adj < opt.alpha and gains[best] >= opt.min_gain
        rounds.append({"round": rnd + 1, "candidates_scored": m_scored, "best": cbest.term,
                       "rmse_gain": gains[best], "p_value_bonferroni": p_adj, "accepted": bool(accepted),
                       "top": table})
        say(f"round {rnd + 1}: {m_scored} candidates, best {cbest.term} gain {100 * gains[best]:.2f} % "
            f"p·m = {p_adj:.3g} → {'added' if accepted else 'stop'}")
        if not accepted:
            break
        before_pred = tr.heldout_pred(fold_b)
        m_before = _metrics(before_pred, y)
        mass_terms = {}
        if cbest.kind == "trip_mass":
            vals, mass_terms = tr.mass_part()
            tr.add(cbest, vals, mass_terms)
            # the composite was built with coefficients fitted without per-trip mass: rebuild it
            # from the refitted (mean-mass) coefficients until they settle (≤ 3 passes)
            for _ in range(3):
                vals, new_terms = tr.mass_part()
                change = max(abs(new_terms[k] / mass_terms[k] - 1.0) for k in mass_terms) if mass_terms else 0.0
                mass_terms = new_terms
                tr.replace_last(vals, mass_terms)
                if change < 1e-4:
                    break
        else:
            tr.add(cbest)
        in_model.add(cbest.term)
        fold_after = tr.fold_of(False)
        after_pred = tr.heldout_pred(fold_after)
        m_after = _metrics(after_pred, y)
        co, se = tr.coefficients()
        # energy share of the new term
        j_new = len(tr.cols) - 1
        powers = np.column_stack([tr.column_power(j) for j in range(len(tr.cols))])
        total = powers.sum(axis=1)
        wgt = np.where(total > 0, dt, 0.0)
        e_tot = float(total @ wgt)
        share = float(powers[:, j_new] @ wgt) / e_tot if e_tot > 0 else math.nan
        role = _role_of(cbest, roles)
        effect = cbest.effect
        if role == "response":
            effect = f"response of the target — not an effect the model lacks ({effect})"
        findings.append({
            "effect": effect, "role": role, "signals": list(cbest.signals), "term": _term_label(cbest, mass_terms),
            "coefficient": co[cbest.term], "std_err": se[cbest.term], "p_value": p_adj,
            "energy_share": share, "metrics_before": _pick_metrics(m_before),
            "metrics_after": _pick_metrics(m_after)})
        plot["findings"].append({"cand": cbest, "before": before_pred, "after": after_pred})

    return assemble(tr=tr, measured=measured, equation=equation, declared=declared,
                    calibrated=calibrated, opt=opt, findings=findings, rounds=rounds, pred0=pred0,
                    m_base=m_base, base_coefs=base_coefs, plot=plot, y=y, n_rows=len(y_all),
                    n_usable=int(usable.sum()), skipped=skipped, sig=sig, n_candidates=len(cands),
                    n_trips=n_trips, dropped=dropped,
                    roles={k: roles[k] for k in sig if k in roles})
