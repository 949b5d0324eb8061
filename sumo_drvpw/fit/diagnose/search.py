"""The forward search of the residual tracer and its held-out test (see the package docstring)."""

from __future__ import annotations

import math

import numpy as np
from scipy import stats

from sumo_drvpw.data.roles import of_log as column_roles
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.calibrate import CANDIDATES
from sumo_drvpw.fit.physical import physical_calibration
from sumo_drvpw.fit.compare import metrics as _metrics
from sumo_drvpw.fit.trip_energy import left_out_by_trip
from sumo_drvpw.fit.diagnose.blocks import BlockModel
from sumo_drvpw.fit.diagnose.candidates import (Candidate, check_include, generate_candidates, screen_signals,
                                               signal_split)
from sumo_drvpw.fit.diagnose.options import MIN_REPLICATION_TRIPS, DiagnoseOptions, stop_reason
from sumo_drvpw.fit.diagnose.structural import (lag_range, per_trip_lags, shift_within_trips,
                                                structural_signals, timing)
from sumo_drvpw.fit.diagnose.result import (DiagnoseResult, assemble, pick_metrics as _pick_metrics,
                                            restore_held, zero_terms, lag_decision, lag_finding,
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



def _role_of(cand: Candidate, roles: dict) -> str:
    """Role of a finding: its column's role; ``structural`` for effects no column names."""
    if not cand.signals:
        return "structural"
    return roles.get(cand.signals[0], {}).get("role", "unknown")


def _score_all(tr: BlockModel, pool: list[Candidate], opt: DiagnoseOptions) -> list[tuple]:
    """Held-out scores of every candidate in ``pool``, in candidate order:
    (cand, SSE with it, per-block d, SSE without, fold)."""
    results = {}
    tr.prefetch([c for c in pool if not c.scatter])
    for scatter in (False, True):
        group = [c for c in pool if c.scatter == scatter]
        if not group:
            continue
        fold = tr.fold_of(scatter)
        sse0, _ = tr.heldout_model(fold)
        # candidates per scoring call: opt.batch, fewer when the blocks are many (the
        # B × m × q statistics and their indices; each candidate is scored alone either way)
        step = 1 if scatter else max(1, min(opt.batch, SCORE_CELLS // max(tr.n_blocks * (len(tr.cols) + 1), 1)))
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

    check_include(x_all.signals, opt)  # before any work
    # declared equation
    calibrated = False
    if equation is None:
        equation, phys = physical_calibration(x_all, y_all, CANDIDATES["indt-var-1"], mask=usable,
                                              reference_mass_kg=float(x_all.mass[usable].mean()))
        equation.name = "calibrated_indt_var_1"
        equation.provenance["logs"] = list(log.files)
        calibrated = True
        say(f"calibrated on the spot ({phys['used']}): {', '.join(equation.term_names)}"
            + (f"; {phys['why']}" if phys["used"] == "constrained" else ""))
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
    declared_eq = equation
    held, equation = zero_terms(equation, decl_vals, ana)
    if held:
        say(f"declared term(s) {', '.join(held)} 0 on every analysis sample: kept at their declared "
            "coefficients, not fitted")
        decl_vals = decl_vals[:, [j for j, t in enumerate(declared) if t not in held]]
        declared = equation.term_names
    # what each trip lost to samples outside the analysis, on the power as logged (the streamed
    # tracer sees the same; a lag correction's few seconds at trip ends are not counted)
    left_out = left_out_by_trip(y_all, ana, dt_all, trip_all)
    # timing (measurement side): a power–speed lag is corrected in the data before the search
    timing_finding, lag_note = None, None
    if opt.structural and opt.max_lag_s > 0:
        y_all, ana, timing_finding, lag_note = _timing_step(
            y_all, ana, x_eq, decl_vals, trip_codes_all, trip_names, t_all, dt_all, declared, opt, say)
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
    tr = _declared_model(x, y, dt, t_all[idx], trip_codes, trip_names, dict(sig), opt, declared,
                         decl_vals[idx])
    say(f"{n} analysis samples, {n_trips} trip(s), {tr.n_blocks} blocks, {len(sig)} signal(s) offered")

    cands = generate_candidates(sig, declared, n_trips, opt, binary)
    structural_notes = {}
    if opt.structural:
        s_sig, s_cands, structural_notes = structural_signals(tr, declared, x_all.signals, idx, log.df,
                                                              log.counts)
        tr.signals.update(s_sig)
        cands = cands + s_cands
    cands, dropped = tr.drop_spanned(cands)
    if dropped:
        say(f"{len(dropped)} candidate(s) dropped before scoring: identical to or spanned by earlier ones")
    base_fold = tr.fold_of(False)
    ev0 = tr.evaluate(base_fold)
    base_coefs, _ = tr.coefficients()
    findings = [timing_finding] if timing_finding is not None else []
    plot = {"y": y, "v": x.v, "pred_base": ev0["pred"], "signals": tr.signals, "findings": []}
    rounds, rejected = search_rounds(tr, cands, declared, roles, opt, say, findings, plot)

    return restore_held(assemble(tr=tr, measured=measured, equation=equation, declared=declared,
                    calibrated=calibrated, opt=opt, findings=findings, rounds=rounds, ev0=ev0,
                    base_coefs=base_coefs, plot=plot, n_rows=len(y_all),
                    n_usable=int(usable.sum()), skipped=skipped, sig=sig, n_candidates=len(cands),
                    n_trips=n_trips, dropped=dropped,
                    roles={k: roles[k] for k in sig if k in roles},
                    left_out=left_out,
                    extra={"not_replicated": rejected, "timing": lag_note,
                           "structural": structural_notes}), declared_eq, held)


#: shifts on each side of zero on the coarse grid of the lag search
COARSE_LAGS = 20
#: block × candidate × column cells per scoring call (memory of the batched scoring)
SCORE_CELLS = 4_000_000
#: candidates tried per round when the best one does not replicate or is implausible
MAX_TRIES = 5
#: largest plausible |energy share| of one finding (a share beyond it is a proxy or a fit artefact)
MAX_ENERGY_SHARE = 0.5


def _declared_model(x, y, dt, t, trip_codes, trip_names, sig, opt, declared, decl_vals) -> BlockModel:
    """A block model holding the declared terms."""
    tr = BlockModel(x, y, dt, t, trip_codes, trip_names, sig, opt)
    for j, term in enumerate(declared):
        vals = decl_vals[:, j]
        tr._factor_cache[term] = vals
        tr.add(Candidate(term, f"declared term {term}", tuple(parse_term(term).signals), "declared"), vals)
    return tr


def search_rounds(tr: BlockModel, cands: list[Candidate], declared, roles: dict, opt: DiagnoseOptions,
                  say, findings: list, plot: dict) -> tuple[list, list]:
    """The forward search on a block model: rounds of scoring, the test, replication.

    Appends the findings to ``findings`` (and their held-out predictions to ``plot``, when
    the model gives them per sample); returns (rounds, not replicated)."""
    rounds, rejected = [], []
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
            p = paired_test(d)
            table.append({"term": c.term, "effect": c.effect, "rmse_gain": gains[i],
                          "p_value_bonferroni": min(1.0, p * m_scored)})
        added, tried = None, []  # tried: (candidate, the test it failed), for the stop line
        for pos, i in enumerate(order[:MAX_TRIES]):
            cbest, sse_b, d_b, sse0_b, fold_b = results[int(i)]
            p_adj = min(1.0, paired_test(d_b) * m_scored)
            if gains[int(i)] < opt.min_gain:
                tried.append((cbest.term, "gain", gains[int(i)]))
                break  # (gains fall down the order)
            if not p_adj < opt.alpha:
                # a large gain carried by a few blocks fails the test; the next candidate may
                # pass it (the Bonferroni factor already counts every candidate scored)
                tried.append((cbest.term, "significance", p_adj))
                continue
            f, extra = _try_add(tr, cbest, fold_b, roles, opt, p_adj)
            if f is None:
                in_model.add(cbest.term)          # not offered again
                rejected.append(dict(extra, term=cbest.term, round=rnd + 1, rmse_gain=gains[int(i)],
                                     p_value_bonferroni=p_adj))
                say(f"round {rnd + 1}: {cbest.term} passes the block test but {extra['reason']}")
                tried.append((cbest.term, "rejected", f"passes the block test but {extra['reason']}"))
                continue
            added = (cbest, gains[int(i)], p_adj)
            findings.append(f)
            if extra["before"] is not None:
                plot["findings"].append({"cand": cbest, "before": extra["before"], "after": extra["after"]})
            break
        best_i = int(order[0])
        rounds.append({"round": rnd + 1, "candidates_scored": m_scored,
                       "best": results[best_i][0].term, "rmse_gain": gains[best_i],
                       "p_value_bonferroni": min(1.0, paired_test(results[best_i][2]) * m_scored),
                       "accepted": added is not None, "added": added[0].term if added else None,
                       "top": table})
        if added is None:  # why: which test each candidate tried failed (trace.json, trace.md)
            rounds[-1]["stop_reason"] = stop_reason(tried, int(np.count_nonzero(tr.trip_counts())), m_scored, opt)
        say(f"round {rnd + 1}: {m_scored} candidates, best {results[best_i][0].term} gain "
            f"{100 * gains[best_i]:.2f} % → "
            + (f"added {added[0].term}" if added else f"stop: {rounds[-1]['stop_reason']}"))
        if added is None:
            break
        in_model.add(added[0].term)

    return rounds, rejected


def _try_add(tr: BlockModel, cand: Candidate, fold, roles, opt, p_adj):
    """Add ``cand``; keep it only if it replicates on held-out trips and is plausible (§4).

    Replication: the held-out SSE of each trip before and after; with ≥ 3 trips the
    finding must lower it on more than half of them. Plausibility: |energy share| ≤
    ``MAX_ENERGY_SHARE``, a logged column's share taken about its mean
    (``candidates.signal_split``: the zero of °C or K is no physical reference). Returns
    (finding dict, extras) or (None, {"reason", …}) after removing the column again.
    """
    ev_b = tr.evaluate(fold)
    before = ev_b["pred"]
    mass_terms = {}
    if cand.kind == "trip_mass":
        vals, mass_terms = tr.mass_part()
        tr.add(cand, vals, mass_terms)
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
        tr.add(cand)
    ev_a = tr.evaluate(tr.fold_of(False))
    after = ev_a["pred"]
    counts = tr.trip_counts()
    present = counts > 0
    sse_b, sse_a = ev_b["trip_sse"][present], ev_a["trip_sse"][present]
    helped, n_tr = int((sse_a < sse_b).sum()), int(present.sum())
    co, se = tr.coefficients()
    j_new = len(tr.cols) - 1
    role = _role_of(cand, roles)
    share = float(tr.energy_shares(signal_split(cand, role))[j_new])
    names = [str(tr.trip_names[i]) for i in np.flatnonzero(present)]
    per_trip = {t: {"rmse_before_w": math.sqrt(b / max(c, 1)), "rmse_after_w": math.sqrt(a / max(c, 1))}
                for t, b, a, c in zip(names, sse_b, sse_a, counts[present])}
    reason = None
    if n_tr >= MIN_REPLICATION_TRIPS and helped * 2 <= n_tr:
        reason = f"did not replicate: lowered the held-out error on {helped} of {n_tr} trips"
    elif not (abs(share) <= MAX_ENERGY_SHARE):
        reason = f"implausible: energy share {100 * share:.1f} % (|share| > {100 * MAX_ENERGY_SHARE:g} %)"
    if reason is not None:
        tr.drop_last()
        return None, {"reason": reason, "helped_trips": helped, "trips": n_tr, "energy_share": share}
    effect = cand.effect
    if role == "response":
        effect = f"response of the target — not an effect the model lacks ({effect})"
    finding = {
        "effect": effect, "role": role, "signals": list(cand.signals), "term": _term_label(cand, mass_terms),
        "coefficient": co[cand.term], "std_err": se[cand.term], "p_value": p_adj,
        "energy_share": share, "metrics_before": _pick_metrics(ev_b["metrics"]),
        "metrics_after": _pick_metrics(ev_a["metrics"]),
        "replication": {"helped_trips": helped, "trips": n_tr, "per_trip": per_trip}}
    return finding, {"before": before, "after": after, "ev_after": ev_a}


def _timing_step(y_all, ana, x_eq, decl_vals, trip_codes_all, trip_names, t_all, dt_all, declared, opt, say):
    """Estimate, test and (if accepted) apply a power–speed lag (see ``structural``)."""
    dt_med = float(np.median(np.diff(t_all)[np.diff(trip_codes_all) == 0])) if len(t_all) > 1 else 0.0
    lags = lag_range(dt_med, opt.max_lag_s)
    if len(lags) < 2:
        return y_all, ana, None, None
    # samples whose power is finite at every shift (one boolean pass per shift, none stored)
    common = ana.copy()
    for k in lags:
        common &= np.isfinite(shift_within_trips(y_all, trip_codes_all, int(k)))
    if common.sum() < 50:
        return y_all, ana, None, None
    idx = np.flatnonzero(common)
    x = x_eq.take(idx)
    tr0 = _declared_model(x, y_all[idx], dt_all[idx], t_all[idx], trip_codes_all[idx],
                          trip_names, {}, opt, declared, decl_vals[idx])
    # coarse-to-fine: at most ~41 shifts on a coarse grid, then every shift around the best
    big = int(lags[-1])
    step = max(1, math.ceil(big / COARSE_LAGS))
    tried = sorted(set(range(-big, big + 1, step)) | {0})
    shifted = {k: shift_within_trips(y_all, trip_codes_all, k)[idx] for k in tried}
    res = timing(tr0, shifted, dt_med, paired_test)
    if step > 1:
        fine = [k for k in range(res["lag_samples"] - step + 1, res["lag_samples"] + step)
                if -big <= k <= big and k not in shifted]
        shifted.update({k: shift_within_trips(y_all, trip_codes_all, k)[idx] for k in fine})
        res = timing(tr0, shifted, dt_med, paired_test)
    note, accepted = lag_decision(res, per_trip_lags(tr0, shifted, dt_med), len(shifted), opt, say)
    if not accepted:
        return y_all, ana, None, note
    y_new = shift_within_trips(y_all, trip_codes_all, res["lag_samples"])
    fold = tr0.fold_of(False)
    before = tr0.heldout_pred(fold)
    tr1 = _declared_model(x, y_new[idx], dt_all[idx], t_all[idx], trip_codes_all[idx],
                          trip_names, {}, opt, declared, decl_vals[idx])
    after = tr1.heldout_pred(fold)
    y0, y1 = shifted[0], y_new[idx]
    finding = lag_finding(res, note["per_trip_lag_s"], _pick_metrics(_metrics(before, y0)),
                          _pick_metrics(_metrics(after, y1)))
    return y_new, common, finding, note
