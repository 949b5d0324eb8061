"""The chain tracer's held-out search, on any source of block statistics.

:func:`search` is the forward search of :func:`sumo_drvpw.fit.chain_linear.trace_chain`
(the module docstring there: candidates, the test, replication, plausibility, the closed
loop). It reads the samples only through an *engine*: the in-memory one holds every
sample's columns (``chain_linear._Memory``), the streamed one gathers the same
statistics in passes over batches of whole trips (``chain_trace_stream._Streamed``).
An engine has ``bl`` (:class:`~sumo_drvpw.fit.chain_blocks.Blocks`), ``sw`` (Σ w [s]),
``e_pred`` (Σ w·P_declared [J]) and

* ``score(acc, pool)`` — per candidate of ``pool`` on top of the model ``acc`` (a list of
  (candidate, variant index)), or of ``acc`` alone for ``None``: held-out per-block SSE and
  energy errors (:func:`~sumo_drvpw.fit.chain_blocks.heldout_from_stats`);
* ``best_variant(acc, c, fold)`` — the variant of ``c`` on all samples, or on those
  outside ``fold``, refined between grid values (:func:`~sumo_drvpw.fit.chain_effects.refine`);
* ``fit(acc, fold)`` — (β, standard errors) of the model's free columns;
* ``free_coef(acc, c, vi)``, ``contrib_j(c, vi, coef)`` — what a free coefficient on a
  fixed column reads; Σ w·(the effect's power) [J].
"""

from __future__ import annotations

import copy
import math

import numpy as np

from sumo_drvpw.fit.chain_effects import apply
from sumo_drvpw.fit.diagnose.options import stop_reason


def _gain(before, after) -> float:
    return 1.0 - math.sqrt(float(np.sum(after)) / float(np.sum(before))) if np.sum(before) > 0 else 0.0


def rms(e) -> float:
    return math.sqrt(float(np.mean(np.asarray(e) ** 2)))


def n_free(c, vi) -> int:
    var = c.variants[vi]
    return 0 if var[0] is None else (var[0].shape[1] if hasattr(var[0], "shape") else int(var[0]))


def replication(bl, n_trips, e_cur, e_c, trip_names):
    """Per trip: the held-out block energy error (RMS [J]) before and after; trips helped."""
    bt = bl.block_trip
    nb = np.bincount(bt, minlength=n_trips)
    before = np.bincount(bt, weights=e_cur ** 2, minlength=n_trips)
    after = np.bincount(bt, weights=e_c ** 2, minlength=n_trips)
    present = nb > 0
    helped = int((after[present] < before[present]).sum())
    per = {str(trip_names[i]): {"block_energy_rms_before_j": math.sqrt(before[i] / nb[i]),
                                "block_energy_rms_after_j": math.sqrt(after[i] / nb[i])}
           for i in np.flatnonzero(present)}
    return helped, int(present.sum()), per


def closed_from_beta(equation, acc, beta):
    """The equation with every finding of ``acc`` written in from coefficients ``beta``:
    (equation, (last reading, [(reading, coefficients)])), or (None, reason) when implausible."""
    eq, readings, j = equation, [], 0
    for c, vi in acc:
        k = n_free(c, vi)
        eq, reading = apply(eq, c.name, beta[j:j + k], c.variants[vi][2])
        if eq is None:
            return None, reading
        readings.append((reading, beta[j:j + k]))
        j += k
    if not acc:
        eq = copy.deepcopy(equation)
    return eq, (readings[-1][0] if readings else "", readings)


def search(eng, equation, cands, opt, trip_names, say):
    """The rounds of the search (module docstring). Returns (findings, rounds, rejected,
    accepted [(candidate, variant)], (baseline per-block SSE, energy errors), (final ditto))."""
    from sumo_drvpw.fit.diagnose import paired_test

    bl, sw = eng.bl, eng.sw
    accepted: list[tuple] = []
    sse_cur, e_cur = eng.score(accepted, [None])[0]
    sse_base, e_base = sse_cur.copy(), e_cur.copy()
    findings, rounds, rejected = [], [], []
    in_model: set[str] = set()
    for rnd in range(opt.max_findings):
        pool = [c for c in cands if c.name not in in_model]
        if not pool:
            break
        scored = []
        for c, (sse_c, e_c) in zip(pool, eng.score(accepted, pool)):
            e0, e1 = float(np.sum(e_cur ** 2)), float(np.sum(e_c ** 2))
            gain = 1.0 - math.sqrt(e1 / e0) if e0 > 0 else 0.0
            scored.append((gain, c, sse_c, e_c))
        scored.sort(key=lambda s: -s[0])
        m_scored = len(scored)
        top = [{"effect": c.name, "energy_gain": g, "rmse_gain": _gain(sse_cur, s),
                "p_value_bonferroni": min(1.0, paired_test(e_cur ** 2 - e ** 2) * m_scored)}
               for g, c, s, e in scored[:10]]
        added, tried = None, []  # tried: (effect, test failed, value) for the stop line
        for gain, c, sse_c, e_c in scored[:5]:
            p_adj = min(1.0, paired_test(e_cur ** 2 - e_c ** 2) * m_scored)
            if not (p_adj < opt.alpha and gain >= opt.min_gain):
                tried.append((c.name, "gain", gain) if gain < opt.min_gain else (c.name, "significance", p_adj))
                break  # (not the wheel tracer's rule: the chain's noise leaves a ~36 W standing bias a
                # next candidate would pass the test on, tests/test_diagnose_target.py)
            helped, n_tr, per_trip = replication(bl, len(trip_names), e_cur, e_c, trip_names)
            if n_tr >= 3 and helped * 2 <= n_tr:
                rejected.append({"effect": c.name, "round": rnd + 1, "rmse_gain": gain, "p_value_bonferroni": p_adj,
                                 "reason": f"did not replicate: lowered the held-out error on {helped} of {n_tr} trips"})
                in_model.add(c.name)
                tried.append((c.name, "rejected", rejected[-1]["reason"]))
                continue
            # full-data fit of the model with the candidate (variant chosen on all samples)
            vi = eng.best_variant(accepted, c, None)
            var = c.variants[vi]
            beta, se = eng.fit(accepted + [(c, vi)], None)
            q0 = beta.size - n_free(c, vi)
            coef = beta[q0:]
            trial, reading = closed_from_beta(equation, accepted + [(c, vi)], beta)
            if trial is not None:
                reading = reading[0]
            if trial is None:
                rejected.append({"effect": c.name, "round": rnd + 1, "rmse_gain": gain, "p_value_bonferroni": p_adj,
                                 "reason": reading})
                in_model.add(c.name)
                say(f"round {rnd + 1}: {c.name} passes the block test but {reading}")
                tried.append((c.name, "rejected", f"passes the block test but {reading}"))
                continue
            free_coef = None if var[1] is None else eng.free_coef(accepted, c, vi)
            energy = eng.contrib_j(c, vi, coef)
            free = var[0] is not None
            findings.append({
                "term": c.name, "effect": c.effect, "role": c.role, "unit": c.unit,
                "coefficient": (None if not free else (float(coef[0]) if coef.size == 1 else [float(v) for v in coef])),
                "std_err": (None if not free else [float(v) for v in se[q0:]]),
                "parameter": (None if var[2] is None or c.name == "hvac" else var[2]),
                "free_coefficient": free_coef,
                "reading": reading, "p_value": p_adj, "energy_gain": gain, "rmse_gain": _gain(sse_cur, sse_c),
                "energy_share": energy / eng.e_pred if eng.e_pred else math.nan, "energy_j": energy,
                "metrics_before": {"rmse_w": math.sqrt(sse_cur.sum() / sw), "block_energy_rms_j": rms(e_cur)},
                "metrics_after": {"rmse_w": math.sqrt(sse_c.sum() / sw), "block_energy_rms_j": rms(e_c)},
                "replication": {"helped_trips": helped, "trips": n_tr, "per_trip": per_trip}})
            accepted.append((c, vi))
            sse_cur, e_cur = sse_c, e_c
            added = c
            break
        best = scored[0]
        rounds.append({"round": rnd + 1, "candidates_scored": m_scored, "best": best[1].name,
                       "energy_gain": best[0], "accepted": added is not None,
                       "added": added.name if added else None, "top": top,
                       **({} if added else {"stop_reason": stop_reason(tried, len(trip_names), m_scored, opt)})})
        say(f"round {rnd + 1}: {m_scored} candidates, best {best[1].name} block-energy gain {100 * best[0]:.2f} % → "
            + (f"added {added.name}" if added else f"stop: {rounds[-1]['stop_reason']}"))
        if added is None:
            break
        in_model.add(added.name)
    return findings, rounds, rejected, accepted, (sse_base, e_base), (sse_cur, e_cur)


def close(eng, equation, accepted, findings, target: str, files) -> object:
    """The closed equation from the final joint fit; the findings' readings and coefficients
    updated to it (those when found kept)."""
    from sumo_drvpw.fit.chain_effects import mark_changed

    closed, (_, final) = closed_from_beta(equation, accepted, eng.fit(accepted, None)[0])
    for f, (reading, co) in zip(findings, final):   # the final joint fit's values
        f["reading_when_found"], f["coefficient_when_found"] = f["reading"], f["coefficient"]
        f["reading"] = reading
        if f["coefficient"] is not None:
            f["coefficient"] = float(co[0]) if co.size == 1 else [float(v) for v in co]
    closed.name = f"{equation.name}_closed" if accepted else equation.name
    if accepted:  # the declared chain's fit statistics no longer describe what was changed
        mark_changed(equation.chain, closed.chain, [f"{f['term']}: {f['reading']}" for f in findings])
    closed.provenance = dict(getattr(equation, "provenance", {}) or {},
                             closed_loop={"declared": equation.name, "target": target,
                                          "findings": [f"{f['term']}: {f['reading']}" for f in findings],
                                          "logs": list(files)})
    return closed


def fold_equations(eng, equation, accepted) -> list:
    """Each fold's closed equation: the findings' variants and coefficients fitted without
    the fold (a finding implausible on a fold is left out there)."""
    out = []
    for k in range(eng.bl.K):
        acc = []
        for c, _ in accepted:
            acc.append((c, eng.best_variant(acc, c, k)))
        beta = eng.fit(acc, k)[0]
        eq, j = equation, 0
        for c, vi in acc:
            kk = n_free(c, vi)
            eq2, _ = apply(eq, c.name, beta[j:j + kk], c.variants[vi][2])
            eq = eq2 if eq2 is not None else eq   # implausible on this fold: the finding is left out
            j += kk
        out.append(eq)
    return out


def report_doc(target, equation, closed, bl, n, trip_names, unknown, base, fin, before, after, findings,
               rounds, rejected, cands) -> dict:
    """The chain trace's report (JSON-ready) from its parts."""
    return {
        "target": target, "declared_equation": equation.name, "closed_equation": closed.name,
        "declared_chain": equation.chain.to_dict(), "closed_chain": closed.chain.to_dict(),
        "declared_terms": dict(equation.terms), "closed_terms": dict(closed.terms),
        "n_samples": int(n), "trips": [str(s) for s in trip_names],
        "chain_unknown_inputs": unknown,
        "validation": bl.how,
        "test": (f"held-out {bl.block_s:g}-s blocks: one-sided paired test of d_b = e_b(model)² − "
                 "e_b(model + effect)², e_b the block's energy error Σ w·(P_meas − P_pred) [J], Bonferroni over "
                 "the round's candidates; relative gain in the blocks' RMS energy error ≥ min_gain; kept when it "
                 "lowers the held-out error on more than half of the trips and is physically plausible"),
        "linearisation": "columns in the target's watts: road-load changes × g_wheel (1/η_t traction, η_r "
                         "recuperation, 0 beyond the limit), auxiliary loads × g_aux; baseline = the declared "
                         "chain unchanged",
        "candidates": [{"effect": c.name, "role": c.role, "unit": c.unit, "variants": c.grid} for c in cands],
        "baseline": {"metrics": base, "trip_net_energy": before},
        "findings": findings,
        "final": {"metrics": fin, "trip_net_energy": after,
                  "note": "each sample predicted by the closed equation (exact chain) of the fold that held it out"},
        "not_replicated": rejected, "rounds": rounds,
    }
