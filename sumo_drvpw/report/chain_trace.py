"""The report of a chain trace (``diagnose`` on a battery or fuel target): trace.json,
trace.md and final_equation.toml (the closed equation with its chain).

Renders a :class:`sumo_drvpw.fit.chain_linear.ChainTraceResult`.
"""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.report.comparison import unknown_input_lines
from sumo_drvpw.report.format import coef, energy_unit, num, partial_trip_flag, partial_trip_lines


def write_chain_outputs(res, out) -> None:
    """Write trace.json, trace.md and final_equation.toml of a chain trace into ``out``."""
    from sumo_drvpw.fileio import write_json, write_text
    from sumo_drvpw.model.equations import save_equation

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    write_json(out / "trace.json", res.report)
    save_equation(res.equation, out / "final_equation.toml")
    write_text(out / "trace.md", markdown(res.report))


def _pct(x) -> str:
    return "–" if x is None or x != x else f"{100 * x:+.1f} %"


def _coef(f) -> str:
    c = f["coefficient"]
    if c is None:
        return "1 (fixed)"
    return ", ".join(coef(v) for v in c) if isinstance(c, list) else coef(c)


def markdown(r: dict) -> str:
    """trace.md of a chain trace report (the dict of ``ChainTraceResult.report``)."""
    tgt = r["target"]
    L = [f"# Chain trace: {r['declared_equation']} on the {tgt} target", "",
         f"- samples: {r['n_samples']} (standing included: the {tgt} draws auxiliary power there); "
         f"trips: {', '.join(r['trips'])}",
         f"- validation: {r['validation']}", f"- test: {r['test']}",
         f"- linearisation: {r['linearisation']}",
         f"- candidates: {', '.join(c['effect'] for c in r['candidates'])}"]
    L += ["- " + x for x in unknown_input_lines(r["declared_equation"], r.get("chain_unknown_inputs"),
                                                 r["n_samples"])]
    L += [f"- {r['fuel_note']}"] if r.get("fuel_note") else []  # a chain of another fuel than the log's
    L += [f"- **{x}**" for x in r.get("notes", [])]  # its calibration's warnings; logs it was fitted on
    L += ["", "## Findings", ""]
    L.append("Coefficients and readings from the final joint fit of every finding; gain, p and energy share "
             "as the finding was accepted (its coefficient then: trace.json `coefficient_when_found`).")
    L.append("")
    if not r["findings"]:
        L.append("None: the declared chain lacks nothing these data can show.")
    else:
        L += ["| effect | role | coefficient | parameter | reading | block-energy gain | p (Bonferroni) | "
              "energy share | helped on trips |", "|---|---|---|---|---|---|---|---|---|"]
        for f in r["findings"]:
            rep = f["replication"]
            L.append(f"| `{f['term']}` | {f['role']} | {_coef(f)} | "
                     f"{'–' if f['parameter'] is None else coef(f['parameter'], 4)} | {f['reading']} | "
                     f"{100 * f['energy_gain']:.1f} % | {coef(f['p_value'], 2)} | {_pct(f['energy_share'])} | "
                     f"{rep['helped_trips']} of {rep['trips']} |")
    stop = next((x for x in r.get("rounds", []) if x.get("stop_reason")), None)
    if stop is not None:
        L += ["", f"Search stopped in round {stop['round']} (best `{stop['best']}`, block-energy gain "
                  f"{100 * stop['energy_gain']:.1f} %): {stop['stop_reason']}."]
    if r["not_replicated"]:
        L += ["", "Passed the block test but not kept:", ""]
        L += [f"- `{x['effect']}` (round {x['round']}): {x['reason']}" for x in r["not_replicated"]]
    b, a = r["baseline"], r["final"]
    u = energy_unit(tgt, r.get("declared_chain"))  # kWh, or litres of the chain's fuel
    L += ["", "## Before and after, per trip (net energy; after = held out)", "",
          f"Mean |error| per trip: before **{_pct(b['trip_net_energy']['mean_abs_error'])[1:]}**, after "
          f"**{_pct(a['trip_net_energy']['mean_abs_error'])[1:]}**; RMSE {num(b['metrics']['rmse_w'], 0)} → "
          f"{num(a['metrics']['rmse_w'], 0)} W. {a['note']}." + (f" {u.note()}" if u.note() else ""), "",
          f"| trip | measured {u.label} | before {u.label} | before | after {u.label} | after | left out |",
          "|---|---|---|---|---|---|---|"]
    for t, x in b["trip_net_energy"]["trips"].items():
        y = a["trip_net_energy"]["trips"].get(t, {})
        L.append(f"| {t} | {u(x['measured_j'])} | {u(x['predicted_j'])} | {_pct(x['error'])} | "
                 f"{u(y.get('predicted_j'))} | {_pct(y.get('error'))} | {partial_trip_flag(x)} |")
    L += ([""] + partial_trip_lines(b["trip_net_energy"])) if partial_trip_lines(b["trip_net_energy"]) else []
    L += ["", f"## Closed equation `{r['closed_equation']}` (final_equation.toml)", "",
          f"- road load: {', '.join(f'{k} {coef(v)}' for k, v in r['closed_terms'].items())}",
          f"- chain: {', '.join(f'{k} {v if isinstance(v, str) else coef(v)}' for k, v in r['closed_chain'].items() if not isinstance(v, dict))}",
          "", "It drops into `compare` (same target) and SUMO runs unchanged.", ""]
    return "\n".join(L)
