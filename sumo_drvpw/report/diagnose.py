"""The diagnose report: trace.json, trace_details.json, trace.md, final_equation.toml, figures.

Renders a :class:`sumo_drvpw.fit.diagnose.DiagnoseResult` (residual against the chosen
signal before and after each finding; error against speed before and after).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from sumo_drvpw.fit.drivetrain import describe as describe_wheel_grade
from sumo_drvpw.report.format import coef, energy_unit, partial_trip_flag, partial_trip_lines


def write_outputs(res, out, figures: bool = True) -> None:
    from sumo_drvpw.model.equations import save_equation
    from sumo_drvpw.fileio import write_json, write_text

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    for old in list(out.glob("finding*_residual_vs_*.png")) + [out / "error_vs_speed.png"]:
        if old.exists():  # figures of an earlier run in the same folder
            old.unlink()
    write_json(out / "trace.json", res.report)
    write_json(out / "trace_details.json", res.details)
    save_equation(res.equation, out / "final_equation.toml")
    figs = _figures(res, out) if figures else []
    write_text(out / "trace.md", markdown(res, figs))


def _fmt(x, nd=4):
    if isinstance(x, dict):
        vals = np.array(list(x.values()), float)
        if len(vals) == 0:
            return "–"
        return f"{len(vals)} values, {np.min(vals):.{nd}g} … {np.max(vals):.{nd}g}"
    return coef(x, nd)


def _pct(x, sign="+"):
    return "–" if x is None or (isinstance(x, float) and not np.isfinite(x)) else f"{100 * x:{sign}.2f} %"


def _mrow(name, m):
    return (f"| {name} | {m['rmse_w']:.1f} | {m['mae_w']:.1f} | {_fmt(m['r2'])} | {_fmt(m['r2_light'])} | "
            f"{_fmt(m['r2_heavy'])} | {m['bias_w']:.1f} |")


def markdown(res, figs) -> str:
    r, d = res.report, res.details
    L = [f"# Residual trace: {d['declared_equation']}", "",
         f"- target: {r['target']}", f"- analysis samples: {r['n_samples']} "
         f"(rows {d['samples']['rows']}, usable {d['samples']['usable']}, trips {d['samples']['trips']}, "
         f"blocks {d['samples']['blocks']})",
         f"- validation: {r['validation']}", f"- test: {d['test']}",
         f"- declared equation {'calibrated on the spot (stepwise, indt-var-1)' if d['calibrated_on_the_spot'] else 'given'}; "
         "its terms are kept and their coefficients refitted on each training fold"
         + "".join(f"; `{t}` is 0 on every analysis sample: held at its declared coefficient {h['coefficient']:.4g}, "
                   "not fitted" for t, h in r.get("held_terms", {}).items()),
         f"- signals offered ({len(d['signals_offered'])}): "
         + (", ".join(f"{c} ({d.get('signal_roles', {}).get(c, {}).get('role', 'unknown')})"
                      for c in d["signals_offered"]) or "none"),
         "- columns of unknown role are offered only after the screens (constant, NaN, id-like, "
         "derived from the inputs, same quantity as a power source, proxy of the target); "
         "response columns only on request",
         f"- candidates scored (all rounds): {d['candidates_scored']}", "",
         "## Error on held-out data (W)", "",
         "| model | RMSE | MAE | R² | R² light | R² heavy | bias |", "|---|---|---|---|---|---|---|",
         _mrow("baseline", r["baseline"]["metrics"])]
    for i, f in enumerate(r["findings"], 1):
        L.append(_mrow(f"+ finding {i}: `{f['term']}`", f["metrics_after"]))
    tb, tf = r["baseline"].get("trip_energy"), r["final"].get("trip_energy")
    if tb and tf:
        u = energy_unit("wheel")  # the tracer's target: driving power
        L += ["", "## Traction energy per trip (held-out predictions; predicted/measured − 1)", "",
              f"| trip | measured [{u.label}] | baseline | final | left out |", "|---|---|---|---|---|"]
        for t, v in tb["trips"].items():
            e0, e1 = v["error"], tf["trips"][t]["error"]
            L.append(f"| {t} | {u(v['measured_j'])} | {_pct(e0)} | {_pct(e1)} | {partial_trip_flag(v)} |")
        L.append(f"| mean abs. / worst abs. | | {_pct(tb['mean_abs_error'], '')} / {_pct(tb['max_abs_error'], '')} | "
                 f"{_pct(tf['mean_abs_error'], '')} / {_pct(tf['max_abs_error'], '')} | |")
        L += ([""] + partial_trip_lines(tb)) if partial_trip_lines(tb) else []
    L += ["", "## Findings", ""]
    if not r["findings"]:
        L.append("None: no candidate improved the held-out error significantly. The declared terms "
                 "explain what these data can tell apart.")
    for i, f in enumerate(r["findings"], 1):
        gain = 1 - f["metrics_after"]["rmse_w"] / f["metrics_before"]["rmse_w"]
        rep = f.get("replication") or {}
        helped = (f"; replicated on {rep['helped_trips']} of {rep['trips']} trips"
                  if rep.get("trips") else "")
        if f.get("kind") == "timing":
            L += [f"{i}. **{f['effect']}** (structural) — lag {f['coefficient']:+.3g} s "
                  f"(s.d. over folds {_fmt(f['std_err'])} s), held-out test p = {f['p_value']:.3g}; "
                  f"held-out RMSE {f['metrics_before']['rmse_w']:.1f} → {f['metrics_after']['rmse_w']:.1f} W "
                  f"({100 * gain:.2f} %){helped} (trips whose own best lag has the same sign)."]
            continue
        L += [f"{i}. **{f['effect']}** ({f.get('role', 'unknown')}) — term `{f['term']}`, signals: "
              f"{', '.join(f['signals']) or 'none'}; "
              f"coefficient {_fmt(f['coefficient'])} ± {_fmt(f['std_err'])} (s.e.), held-out test p = {f['p_value']:.3g} "
              f"(Bonferroni), energy share {100 * f['energy_share']:.2f} %; held-out RMSE "
              f"{f['metrics_before']['rmse_w']:.1f} → {f['metrics_after']['rmse_w']:.1f} W ({100 * gain:.2f} %){helped}."]
    if d.get("not_replicated"):
        L += ["", "## Passed the block test but rejected", ""]
        L += [f"- `{x['term']}` (round {x['round']}): {x['reason']}" for x in d["not_replicated"]]
    if d.get("timing"):
        tm = d["timing"]
        L += ["", "## Timing (power against speed)", "",
              f"Best lag on all data {tm['lag_s']:+.3g} s (power read that much later; + = power late), "
              f"held-out RMSE gain {100 * tm['rmse_gain']:.2f} %, p = {tm['p_value']:.3g}: "
              f"{'applied to the data' if tm['accepted'] else 'not applied'}. Per trip: "
              + ", ".join(f"{k} {v:+.3g} s" for k, v in tm.get("per_trip_lag_s", {}).items()) + ". "
              f"Test: {tm['test']}."]
    if d.get("structural"):
        L += ["", "## Structural notes", "", "```", json.dumps(d["structural"], indent=1, default=str), "```"]
    L += ["", "## Rounds (best candidates by held-out RMSE gain)", ""]
    for rd in d["rounds"]:
        L.append(f"Round {rd['round']}: {rd['candidates_scored']} candidates scored; "
                 f"{'added' if rd['accepted'] else 'nothing added'} (best `{rd['best']}`, gain "
                 f"{100 * rd['rmse_gain']:.2f} %, p·m = {rd['p_value_bonferroni']:.3g})."
                 + (f" Stopped: {rd['stop_reason']}." if rd.get("stop_reason") else ""))
        L += ["", "| candidate | RMSE gain % | p (Bonferroni) |", "|---|---|---|"]
        for t in rd["top"][:6]:
            L.append(f"| `{t['term']}` | {100 * t['rmse_gain']:.2f} | {t['p_value_bonferroni']:.3g} |")
        L.append("")
    L += ["## Final equation", "", "| term | coefficient | physical reading |", "|---|---|---|"]
    phys = r["final"].get("physical", {})
    for t, c in r["final"]["coefficients"].items():
        p = phys.get(t)
        read = "" if p is None else (f"{p['reads_as']} = {p['value']:.4g} {p['unit']}".rstrip(" -")
                                     + ("" if p["plausible"] else f" — implausible: {p['note']}")
                                     + (f"; {describe_wheel_grade(p['at_wheels'])}" if p.get("at_wheels") else ""))
        L.append(f"| `{t}` | {c:.6g} | {read} |")
    if r["final"].get("implausible"):
        L += ["", f"Implausible coefficients: {', '.join(r['final']['implausible'])}. The tracer refits the "
              "declared terms without constraints; calibrate with physical constraints "
              "(sumo_drvpw.fit.physical) before taking this equation into SUMO."]
    L += ["", "## Columns not offered", "", "| column | reason |", "|---|---|"]
    for s in d["signals_skipped"]:
        L.append(f"| {s['column']} | {s['reason']} |")
    if d.get("candidates_dropped"):
        L += ["", "## Candidates dropped before scoring (identical or spanned; first in order wins)", "",
              "| candidate | reason |", "|---|---|"]
        L += [f"| `{c['term']}` | {c['reason']} |" for c in d["candidates_dropped"]]
    if figs:
        L += ["", "## Figures", ""] + [f"![{Path(p).stem}]({Path(p).name})" for p in figs]
    return "\n".join(L) + "\n"


def _binned(xv, yv, nb=20, quantile=True):
    ok = np.isfinite(xv) & np.isfinite(yv)
    xv, yv = xv[ok], yv[ok]
    if len(np.unique(xv)) <= 2:
        edges = np.unique(xv)
        cx = edges
        mean = np.array([yv[xv == e].mean() for e in edges])
        rms = np.array([np.sqrt(np.mean(yv[xv == e] ** 2)) for e in edges])
        return cx, mean, rms
    edges = np.unique(np.quantile(xv, np.linspace(0, 1, nb + 1))) if quantile else np.linspace(xv.min(), xv.max(), nb + 1)
    k = np.clip(np.searchsorted(edges, xv, side="right") - 1, 0, len(edges) - 2)
    cnt = np.bincount(k, minlength=len(edges) - 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cx = np.bincount(k, xv, len(edges) - 1) / cnt
        mean = np.bincount(k, yv, len(edges) - 1) / cnt
        rms = np.sqrt(np.bincount(k, yv * yv, len(edges) - 1) / cnt)
    return cx, mean, rms


def _figures(res, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sumo_drvpw.fileio import write_figure

    p = res.plot
    y, v = p["y"], p["v"]
    rng = np.random.default_rng(0)
    sub = rng.choice(len(y), size=min(len(y), 20000), replace=False)
    files = []
    for i, f in enumerate(p["findings"], 1):
        c = f["cand"]
        if c.signals:
            xs, label = p["signals"][c.signals[0]], c.signals[0]
        else:
            xs, label = v * 3.6, "speed [km/h]"
        fig, ax = plt.subplots(1, 2, figsize=(11, 4), sharey=True)
        for a, key, title in ((ax[0], "before", "before"), (ax[1], "after", "after")):
            resid = y - f[key]
            a.scatter(xs[sub], resid[sub], s=2, alpha=0.15, color="0.5", rasterized=True)
            cx, mean, _ = _binned(xs, resid)
            a.plot(cx, mean, "o-", color="C3", label="binned mean")
            a.axhline(0, color="k", lw=0.8)
            a.set_title(f"{title} `{c.term}`")
            a.set_xlabel(label)
            lo, hi = np.percentile(resid, [1, 99])
            a.set_ylim(lo * 1.2, hi * 1.2)
        ax[0].set_ylabel("held-out residual, measured − predicted [W]")
        ax[0].legend()
        name = f"finding{i}_residual_vs_{''.join(ch if ch.isalnum() else '_' for ch in label)}.png"
        write_figure(out / name, fig)
        files.append(str(out / name))
    fig, ax = plt.subplots(1, 2, figsize=(11, 4))
    for key, lab, col in (("pred_base", "baseline", "C0"), ("pred_final", "final", "C2")):
        err = p[key] - y
        cx, mean, rms = _binned(v * 3.6, err, nb=16, quantile=False)
        ax[0].plot(cx, mean, "o-", color=col, label=lab)
        ax[1].plot(cx, rms, "o-", color=col, label=lab)
    ax[0].axhline(0, color="k", lw=0.8)
    ax[0].set_ylabel("mean error, predicted − measured [W]")
    ax[1].set_ylabel("RMS error [W]")
    for a in ax:
        a.set_xlabel("speed [km/h]")
        a.legend()
    fig.suptitle("held-out error against speed, before and after")
    write_figure(out / "error_vs_speed.png", fig)
    files.append(str(out / "error_vs_speed.png"))
    return files
