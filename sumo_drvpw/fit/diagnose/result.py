"""The tracer's result: report documents, the final equation and the data behind the figures."""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, replace

import numpy as np

from sumo_drvpw.fit.diagnose.blocks import BlockModel
from sumo_drvpw.fit.diagnose.candidates import Candidate
from sumo_drvpw.fit.diagnose.options import METRIC_KEYS
from sumo_drvpw.model.equations import Equation


@dataclass
class DiagnoseResult:
    """What the tracer found: the report document, the final equation and plot data."""

    report: dict
    details: dict
    equation: Equation
    plot: dict
    n_candidates_scored: int


def zero_terms(equation: Equation, decl_vals: np.ndarray, rows: np.ndarray):
    """Declared terms that are 0 on every analysis sample (``grade`` on logs with no grade):
    nothing in the data fits them. Returns (held term names, the equation without them)."""
    held = [t for j, t in enumerate(equation.term_names) if not np.any(decl_vals[rows, j])]
    if not held or len(held) == len(equation.term_names):
        return [], equation
    return held, replace(equation, terms={t: c for t, c in equation.terms.items() if t not in held})


def restore_held(res: DiagnoseResult, equation: Equation, held: list) -> DiagnoseResult:
    """The terms :func:`zero_terms` held out, back in the baseline and the final equation
    at their declared coefficients (a grade term serves SUMO's hills), and said."""
    if not held:
        return res
    dec = {t: float(equation.terms[t]) for t in held}
    fin = res.equation
    fin.terms = {**{t: c for t, c in equation.terms.items() if t in dec}, **fin.terms}
    for key in ("baseline", "final"):
        res.report[key]["coefficients"] = {**dec, **res.report[key]["coefficients"]}
        res.report[key]["terms"] = held + [t for t in res.report[key]["terms"] if t not in dec]
    res.report["held_terms"] = {t: {"coefficient": c, "why": "0 on every analysis sample (the logs "
                                    "carry no grade or no such input): not fitted, kept at the "
                                    "declared coefficient"} for t, c in dec.items()}
    return res


def pick_metrics(m: dict) -> dict:
    """The metrics the report carries (``METRIC_KEYS``)."""
    return {k: m[k] for k in METRIC_KEYS}


def _measurement(log, lag_s: float):
    """The corrections the traced equation's logs need: those they were read with
    (``log.options.measurement``) plus the power lag the tracer found and applied in the
    data (issue #11 §3: measurement effects are corrected in the data, and the equation
    says how, so that later comparisons read new logs the same way). None when none."""
    from sumo_drvpw.model.measurement import Measurement

    base = getattr(getattr(log, "options", None), "measurement", None) or Measurement()
    meas = replace(base, power_lag_s=float(base.power_lag_s + lag_s))
    return None if meas.identity else meas


def assemble(*, tr: BlockModel, measured, equation: Equation, declared, calibrated: bool, opt,
             findings, rounds, ev0, base_coefs, plot, n_rows: int, n_usable: int,
             skipped, sig, n_candidates: int, n_trips: int, dropped, roles=None,
             extra=None, left_out=None) -> DiagnoseResult:
    """Final fit, report (``trace.json`` shape), details and the traced equation.
    ``left_out``: what each trip lost to samples outside the analysis
    (:func:`sumo_drvpw.fit.trip_energy.left_out_by_trip`), added to the per-trip energies."""
    from sumo_drvpw.fit.trip_energy import with_left_out

    log = measured.log
    n = tr.n
    final_fold = tr.fold_of(False)
    ev_final = tr.evaluate(final_fold) if findings else ev0
    m_final, m_base = ev_final["metrics"], ev0["metrics"]
    co, se = tr.coefficients()
    plot["pred_final"] = ev_final["pred"]
    final_terms = expand_terms(tr, co)
    lag = next((f for f in findings if f.get("kind") == "timing"), None)
    eq_se = expand_terms(tr, se, std=True)
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    prov = {"date": now, "method": "sumo-drvpw diagnose: residual tracer (sumo_drvpw.fit.diagnose)",
            "logs": list(log.files), "declared_equation": equation.name,
            "declared_terms": list(declared), "calibrated_on_the_spot": calibrated,
            "power_source": measured.source, "validation": tr.validation,
            "findings": [f["term"] for f in findings],
            "power_lag_s": lag["coefficient"] if lag else 0.0,
            "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(opt).items()}}
    final_eq = Equation(name=f"{equation.name}_traced", terms=dict(final_terms), mass_kg=equation.mass_kg,
                        description=f"{equation.name} refitted with the effects found by the residual tracer",
                        source="sumo-drvpw diagnose", std_err=eq_se, provenance=prov,
                        metrics={"heldout": pick_metrics(m_final), "n": n},
                        measurement=_measurement(log, lag["coefficient"] if lag else 0.0))
    report = {
        "target": f"measured driving power [W] ({measured.source})",
        "n_samples": n,
        "validation": tr.validation,
        "baseline": {"terms": list(declared), "coefficients": {t: base_coefs[t] for t in declared},
                     "metrics": pick_metrics(m_base)},
        "findings": findings,
        "final": {"terms": list(final_terms),
                  "coefficients": final_terms, "metrics": pick_metrics(m_final)},
    }
    # physical reading of the coefficients, before and after (issue #11 §3)
    from sumo_drvpw.fit.physical import implausible, physical_reading

    rho = tr.mean_rho()
    for key, coefs in (("baseline", report["baseline"]["coefficients"]), ("final", final_terms)):
        reading = physical_reading({t: c for t, c in coefs.items() if isinstance(c, float)}, rho)
        report[key]["physical"] = {t: r for t, r in reading.items() if r["plausible"] is not None}
        report[key]["implausible"] = implausible(reading)
    # energy per trip of the held-out predictions, before and after (issue #11 §5)
    for key, ev in (("baseline", ev0), ("final", ev_final)):
        report[key]["trip_energy"] = with_left_out(ev["trip_energy"], left_out)
        report[key]["trip_net_energy"] = with_left_out(ev["trip_net_energy"], left_out, net=True)
    details = {"declared_equation": equation.name, "calibrated_on_the_spot": calibrated,
               "samples": {"rows": n_rows, "usable": n_usable, "analysis": n,
                           "trips": n_trips, "blocks": tr.n_blocks},
               "signals_offered": sorted(sig), "signals_skipped": skipped,
               "signal_roles": roles or {},
               "candidates_dropped": dropped,
               "candidates_per_round": n_candidates, "candidates_scored": tr.n_scored,
               "rounds": rounds, "test": ("one-sided paired tests over held-out blocks of "
                                           "d = SSE(model) − SSE(model + candidate): 2 × min(p of t-test on "
                                           "mean d, p of Wilcoxon signed-rank), Bonferroni over the "
                                           f"candidates scored per round, alpha = {opt.alpha}, and relative "
                                           f"held-out RMSE gain ≥ {opt.min_gain}; equal gains are "
                                           "ranked by candidate order"),
               "final_std_err": se, "settings": prov["settings"]}
    details.update(extra or {})
    return DiagnoseResult(report, details, final_eq, plot, tr.n_scored)


def term_label(c: Candidate, mass_terms: dict) -> str:
    if c.kind == "trip_offset":
        return "trip=ID (one per trip)"
    if c.kind == "trip_mass":
        inner = " + ".join(f"{v:.6g}·{t}" for t, v in mass_terms.items())
        return f"trip=ID*({inner}) (one factor per trip)"
    return c.term


def expand_terms(tr: BlockModel, co: dict, std: bool = False) -> dict:
    """Terms of the final equation in the term grammar (per-trip effects expanded)."""
    out = {}
    for c in tr.cols:
        val = co[c.cand.term]
        if c.cand.kind == "trip_offset":
            for trip, v in val.items():
                out[f"trip={trip}"] = v
        elif c.cand.kind == "trip_mass":
            for trip, v in val.items():
                for t, ct in c.mass_terms.items():
                    out[f"trip={trip}*{t}"] = v * abs(ct) if std else v * ct
        else:
            out[c.cand.term] = val
    return out


def lag_decision(res: dict, per_trip_lag: dict, shifts_tried: int, opt, say) -> tuple[dict, bool]:
    """The timing search's note and whether its lag is applied (a non-zero lag, significant
    on the paired block test, with at least ``opt.min_gain`` held-out gain); said in one
    line. One place for the in-memory and the streamed tracer."""
    note = {k: v for k, v in res.items() if k != "d"}
    note["per_trip_lag_s"] = per_trip_lag
    note["shifts_tried"] = shifts_tried
    note["test"] = ("lag chosen per fold on the training folds, scored on held-out blocks; "
                    "d = SSE(lag 0) − SSE(chosen lag), the tracer's paired block test")
    accepted = bool(res["lag_samples"] != 0 and res["p_value"] < opt.alpha and res["rmse_gain"] >= opt.min_gain)
    note["accepted"] = accepted
    say(f"timing: best lag {res['lag_s']:+.3g} s, held-out gain {100 * res['rmse_gain']:.2f} %, "
        f"p = {res['p_value']:.3g} → {'applied' if accepted else 'not applied'}")
    return note, accepted


def lag_finding(res: dict, per_trip_lag: dict, metrics_before: dict, metrics_after: dict) -> dict:
    """The finding of an accepted lag (``res`` from the lag search: lag_s, p_value,
    fold_lags_s), in memory and streamed alike; per_trip_lag: trip → lag [s]."""
    same_sign = sum(1 for v in per_trip_lag.values() if np.sign(v) == np.sign(res["lag_s"]))
    return {
        "effect": (f"timing: the power signal is read {res['lag_s']:+.3g} s later relative to speed "
                   f"({'power late, speed leads' if res['lag_s'] > 0 else 'speed lags the power'}); "
                   "corrected in the data, not absorbed by coefficients"),
        "role": "structural", "kind": "timing", "signals": [], "term": f"lag {res['lag_s']:+.3g} s",
        "coefficient": res["lag_s"], "std_err": float(np.std(res["fold_lags_s"])),
        "p_value": res["p_value"], "energy_share": None,
        "metrics_before": metrics_before, "metrics_after": metrics_after,
        "replication": {"helped_trips": same_sign, "trips": len(per_trip_lag),
                        "per_trip": {k: {"lag_s": v} for k, v in per_trip_lag.items()},
                        "fold_lags_s": res["fold_lags_s"]}}
