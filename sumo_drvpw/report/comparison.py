"""The comparison report: ``report.json``, ``report.md`` and PNG figures (paper Table 3, Fig. 4–10).

Numbers are SI in ``report.json`` (W, J, m/s); ``report.md`` shows kW, kWh and km/h for
reading, converted here at the edge.
"""

from __future__ import annotations

import math
from pathlib import Path

from sumo_drvpw.report import figures as plots
from sumo_drvpw.fit.compare import Comparison
from sumo_drvpw.model.constants import HEAVY_LOAD_W, HIGH_SPEED_MPS, KMH
from sumo_drvpw.fileio import write_json, write_text
from sumo_drvpw.report.format import (KW as _KW, coef, energy_unit, num, partial_trip_flag,
                                      partial_trip_lines)

#: Figure file name → (plot function, caption).
FIGURES = {
    "fig4_parity.png": (plots.parity, "Predicted against measured power (cf. Fig. 4)"),
    "fig5_error_hist.png": (plots.error_histograms, "Error histograms, light and heavy load (cf. Fig. 5)"),
    "fig8_error_speed.png": (plots.error_vs_speed, "Error against speed, ≥ 80 km/h shaded (cf. Fig. 8)"),
    "fig9_error_terms.png": (plots.error_vs_term_power, "Error against each term's power (cf. Fig. 9)"),
    "fig10_energy_share.png": (plots.energy_share_bars, "Energy share of each term (cf. Fig. 10)"),
}



def write_comparison_report(comparison: Comparison, out_dir, title: str,
                            context: dict | None = None) -> None:
    """Write ``report.json``, ``report.md`` and the figures of a comparison to ``out_dir``.

    Parameters
    ----------
    comparison : result of :func:`sumo_drvpw.fit.compare.compare`
    out_dir : output folder (created if missing)
    title : report title
    context : what was compared (log files, vehicle, calibration result …); copied into
        ``report.json`` under ``"context"`` and listed at the top of ``report.md``

    Notes
    -----
    ``report.json`` = ``comparison.to_json()`` plus ``title``, ``context`` and
    ``figures`` (file names). Every file is written atomically.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc = comparison.to_json()
    doc["title"] = title
    doc["context"] = context or {}
    doc["figures"] = list(FIGURES)
    for fname, (fn, _) in FIGURES.items():
        fn(comparison, out / fname)
    write_json(out / "report.json", doc)
    write_text(out / "report.md", render_markdown(comparison, doc, title, context or {}))


# ------------------------------------------------------------------------ Markdown

def _ctx_value(v) -> str:
    """One-line rendering of a context value (long structures stay in report.json)."""
    if isinstance(v, (list, tuple)):
        if any(isinstance(x, (dict, list, tuple)) for x in v):
            return f"{len(v)} entries (see report.json)"
        return ", ".join(_ctx_value(x) for x in v)
    if isinstance(v, dict):
        text = ", ".join(f"{k} = {_ctx_value(x)}" for k, x in v.items())
        return text if len(text) <= 300 else f"{len(v)} entries (see report.json)"
    if isinstance(v, float):
        return f"{v:.0f}" if 1e4 <= abs(v) < 1e12 else f"{v:.4g}"
    return str(v)


def _ctx_lines(context: dict, depth: int = 0) -> list[str]:
    """Bullets for the context: nested dicts become one level of sub-bullets."""
    out = []
    for k, v in context.items():
        if isinstance(v, dict) and v and depth == 0:
            out.append(f"- **{k}**:")
            out += ["  " + line for line in _ctx_lines(v, depth + 1)]
        else:
            out.append(f"- {'**' + str(k) + '**' if depth == 0 else k}: {_ctx_value(v)}")
    return out


def unknown_input_note(name: str, col: str, u: dict, n: int) -> str:
    """One sentence: an equation's chain input unknown on some samples, and what that means."""
    trips = u.get("trips") or []
    where = (f" ({len(trips)} trip(s): {', '.join(trips[:8])}{'…' if len(trips) > 8 else ''})"
             if trips else "")
    read_as = u.get("read_as", "no load")
    lacks = "what it drew" if read_as == "no load" else "what the air temperature adds"
    return (f"{name}: chain input '{col}' unknown (NaN) on {u['samples']} of {n} samples{where}; "
            f"read as {read_as} there, so the prediction lacks {lacks}")


def unknown_input_lines(name: str, unknown: dict | None, n: int) -> list[str]:
    """:func:`unknown_input_note` for each of an equation's unknown chain inputs."""
    return [unknown_input_note(name, col, u, n) for col, u in (unknown or {}).items()]


def calibration_warnings(name: str, eq_doc: dict) -> list[str]:
    """The warnings an equation's energy chain was calibrated with (an IMPLAUSIBLE idle fuel,
    a target that is not the fuel …), from its entry in report.json: a comparison's figures
    are read with them, as a SUMO run prints them."""
    prov = (eq_doc.get("chain") or {}).get("provenance") or {}
    return [f"{name}: its chain's calibration warned: {w}" for w in prov.get("warnings", [])]


def chain_lines(comp) -> list[str]:
    """The energy chains of the compared equations: each parameter, ± its standard error
    where known, and its physical reading (the table above shows the road-load terms only)."""
    rows = []
    for nm, r in comp.results.items():
        ch = r.equation.chain
        if ch is None or ch.predicts not in ("battery", "fuel"):
            continue
        d = ch.to_dict()
        held = (ch.provenance or {}).get("fixed") or {}  # held at given values (calibrate --fix)
        for k, v in d.items():
            if k in ("predicts", "std_err", "reading", "provenance", "metrics") or isinstance(v, (dict, list)):
                continue
            se = (ch.std_err or {}).get(k)
            val = coef(v) if isinstance(v, float) and math.isfinite(v) else str(v)
            val += " (fixed)" if k in held else f" ± {coef(se)}" if se is not None else ""
            rows.append(f"| {nm} | `{k}` | {val} | "
                        f"{(ch.reading or {}).get(k, '')} |")
    if not rows:
        return []
    return ["## Energy chains", "", "What each chain predicts the target from (the driving power of its terms):",
            "", "| Equation | parameter | value | reading |", "|---|---|---|---|", *rows, ""]


def render_markdown(comp: Comparison, doc: dict, title: str, context: dict) -> str:
    """The Markdown text of the report (see :func:`write_comparison_report`)."""
    eqs = doc["equations"]
    meas = doc["measured"]
    n = doc["n_samples"]
    lines = [f"# {title}", ""]
    if context:
        lines += _ctx_lines(context) + [""]

    lines += ["## Summary", ""]
    lines.append(f"{n} samples: {meas['n_light']} at light load (< {HEAVY_LOAD_W * _KW:.0f} kW "
                 f"measured), {meas['n_heavy']} at heavy load (≥ {HEAVY_LOAD_W * _KW:.0f} kW), "
                 f"{meas['n_high_speed']} at ≥ {HIGH_SPEED_MPS / KMH:.0f} km/h.")
    lines.append("Error is predicted minus measured power: negative means the equation "
                 "underpredicts.")
    tgt = doc["settings"].get("target", "wheel")
    if tgt in ("battery", "fuel"):  # the paper's split is of the driving power
        lines.append(f"The {HEAVY_LOAD_W * _KW:.0f}-kW split (the paper's, of the driving power) is here of the "
                     f"measured {tgt} power" + (" (fuel power at its heating value: about 2.5 × the engine's "
                                                "output)" if tgt == "fuel" else "") + ".")
    heavy_ranked = sorted(((d["r2_heavy"], nm) for nm, d in eqs.items()
                           if d["r2_heavy"] is not None), reverse=True)
    if heavy_ranked and heavy_ranked[0][0] > 0:  # (a negative R² fits worse than the mean: no best fit)
        r2, nm = heavy_ranked[0]
        lines.append(f"Best fit at heavy load: **{nm}** (R² = {num(r2, 3)}).")
    if len(heavy_ranked) > 1:
        r2w, nmw = heavy_ranked[-1]
        lines.append(f"Weakest at heavy load: **{nmw}** (R² = {num(r2w, 3)}).")
    for nm, d in eqs.items():
        lines += [x + "." for x in unknown_input_lines(nm, d.get("chain_unknown_inputs"), n)]
        lines += [f"**{w}**" for w in calibration_warnings(nm, d)]
    first = next(iter(eqs.values()), {})
    lines += partial_trip_lines(first.get("trip_energy"))
    if doc["settings"].get("fuel_note"):  # a chain of another fuel than the log was read as
        lines.append(doc["settings"]["fuel_note"])
    if doc["settings"].get("battery_correction"):  # what 'measured' and 'predicted' are on a hybrid
        lines.append(doc["settings"]["battery_correction"][0].upper() + doc["settings"]["battery_correction"][1:] + ".")
    lines.append("")

    lines += ["## Goodness of fit (cf. paper Table 3)", "",
              "Coefficients are on this project's basis (`acc` = m·v·a, `grade` = m·g·v·sin θ, "
              "`aero` = v·(v − v_wind)·|v − v_wind|, `roll` = m·g·v·cos θ, …), "
              "± one standard error where known. R² is 1 − SSE/SST, each load range on its "
              "own mean.", "",
              "| Equation | Coefficients | R² < 50 kW | R² ≥ 50 kW | R² all | RMSE [kW] "
              "| RMSE ≥ 50 kW [kW] | Bias [kW] | n |",
              "|---|---|---|---|---|---|---|---|---|"]
    for nm, d in eqs.items():
        eq = comp.results[nm].equation
        parts = []
        for t, c in eq.terms.items():
            s = f"`{t}` {coef(c)}"
            if t in eq.std_err:
                s += f" ± {coef(eq.std_err[t])}"
            parts.append(s)
        if eq.mass_kg is not None:
            parts.append(f"(m = {eq.mass_kg:.0f} kg)")
        lines.append(f"| {nm} | {'<br>'.join(parts)} | {num(d['r2_light'], 3)} "
                     f"| {num(d['r2_heavy'], 3)} | {num(d['r2'], 3)} "
                     f"| {num(d['rmse_w'], 2, _KW)} | {num(d['rmse_heavy_w'], 2, _KW)} "
                     f"| {num(d['bias_w'], 2, _KW)} | {d['n']} |")
    lines.append("")
    lines += chain_lines(comp)

    lines += [f"## Error at ≥ {HIGH_SPEED_MPS / KMH:.0f} km/h (cf. paper Fig. 8)", ""]
    for nm, d in eqs.items():
        hs = d["high_speed"]
        if not hs["n"]:
            lines.append(f"- **{nm}**: no samples at ≥ {hs['threshold_kmh']:.0f} km/h.")
            continue
        mean, kmh = hs["mean_w"], f"{hs['threshold_kmh']:.0f} km/h"
        where = f"{hs['n']} samples, {num(100 * hs['fraction'], 1)} % of the log"
        if abs(mean) < 0.1 * hs["rmse_w"]:
            head = (f"**{nm}** shows no systematic error above {kmh} "
                    f"(mean {num(mean, 2, _KW)} kW; {where}).")
        else:
            verb = "underpredicts" if mean < 0 else "overpredicts"
            head = f"**{nm}** {verb} by {num(abs(mean), 2, _KW)} kW on average above {kmh} ({where})."
        lines.append(
            f"- {head} RMSE there is {num(hs['rmse_w'], 2, _KW)} kW; 90 % of errors lie "
            f"between {num(hs['p5_w'], 2, _KW)} and {num(hs['p95_w'], 2, _KW)} kW. "
            f"Below {kmh}, the mean error is {num(hs['mean_below_w'], 2, _KW)} kW.")
    lines.append("")

    lines += ["## Which term carries the error (cf. paper Fig. 9)", "",
              "Correlation r of the error with each term's power in the same equation, and "
              "the partial slope when the error is regressed on all terms at once. A partial "
              "slope s means the data ask for about (1 − s) times that term: −0.5 → the term "
              "is too small by half of itself. A missing term shows as “–”."
              + ("" if _target(doc) == "wheel" else
                 f" The error is in {_target(doc)} power, and each term's power is taken as it reaches "
                 "it: its driving power times the chain's slope from zero to the sample's driving power."),
              ""]
    lines += _corr_table(eqs, "error_term_correlation")
    if doc["settings"].get("reference"):
        ref = doc["settings"]["reference"]
        lines += [f"Against the term powers of the reference equation **{ref}** (this reveals "
                  "a term an equation lacks):", ""]
        lines += _corr_table(eqs, "error_reference_correlation")

    scats = _categories(eqs, "energy_share")
    units = {nm: energy_unit(_target(doc), d.get("chain")) for nm, d in eqs.items()}  # kWh, or L of a fuel
    one = len(set(units.values())) <= 1
    what = next(iter(units.values())).what if one else "L of the row's fuel"
    lines += ["## Energy share of each term (cf. paper Fig. 10)", "",
              "Share of the predicted traction energy (samples where the equation's total "
              "power is positive). A negative share is energy the term returns during "
              "traction, e.g. downhill grade."
              + (" With a battery or fuel target the shares are the road-load terms' at the wheel, while "
                 "predicted and measured traction are the target's (the chain's battery or fuel power)."
                 if any(d.get("predicts") in ("battery", "fuel") for d in eqs.values()) else "")
              + ("" if what == "kWh" else " Traction energies in litres: the fuel energy at the lower heating "
                 "value over the fuel's energy per litre (see Energy per trip)."), "",
              "| Equation | " + " | ".join(f"{c} [%]" for c in scats)
              + f" | Predicted traction [{what}] | Measured traction [{what}] | Predicted / measured |",
              "|---|" + "---|" * (len(scats) + 3)]
    for nm, d in eqs.items():
        cells = [num(d["energy_share"].get(c), 1, 100.0) for c in scats]
        u = units[nm]
        lines.append(f"| {nm}{'' if one else f' ({u.what})'} | " + " | ".join(cells)
                     + f" | {u(d.get('predicted_traction_energy_j', d['energy_j']['total']))}"
                     f" | {u(meas['traction_energy_j'])} | {num(d['traction_energy_ratio'], 3)} |")
    lines.append("")

    lines += trip_energy_lines(doc)

    lines += ["## Figures", ""]
    for fname, (_, caption) in FIGURES.items():
        lines += [f"![{caption}]({fname})", f"*{caption}*", ""]
    return "\n".join(lines)


def _categories(eqs: dict, key: str) -> list[str]:
    cats: list[str] = []
    for d in eqs.values():
        for c in d.get(key) or {}:
            if c not in cats:
                cats.append(c)
    return cats


def _corr_table(eqs: dict, key: str) -> list[str]:
    """Markdown table of r / partial slope per equation and term category (``key``)."""
    cats = _categories(eqs, key)
    lines = ["| Equation | " + " | ".join(f"{c}: r / partial slope" for c in cats) + " |",
             "|---|" + "---|" * len(cats)]
    for nm, d in eqs.items():
        lines.append(f"| {nm} | " + " | ".join(_corr_cell(d[key].get(c)) for c in cats) + " |")
    return lines + [""]


def _corr_cell(c: dict | None) -> str:
    if not c or c.get("r") is None and c.get("partial_slope") is None:
        return "–"
    return f"{num(c.get('r'), 2)} / {num(c.get('partial_slope'), 2)}"


# ------------------------------------------------------------- energy per trip

#: at most this many trips per table of report.md (the largest errors; report.json has all)
MAX_TRIP_ROWS = 200


def _target(doc: dict) -> str:
    """What a report compared: its ``settings.target``; a report written before it was
    recorded: what its equations' chains all predict when battery or fuel, else wheel (the
    command's default)."""
    t = doc.get("settings", {}).get("target")
    if t:
        return t
    pred = {d.get("predicts", "wheel") for d in doc["equations"].values()}
    return pred.pop() if len(pred) == 1 and pred <= {"battery", "fuel"} else "wheel"


def _trip_key(t: str):
    """Trip ids in natural order (T2 before T10)."""
    import re

    return [(0, int(x), "") if x.isdigit() else (1, 0, x) for x in re.split(r"(\d+)", str(t)) if x]


def _signed_pct(x) -> str:
    s = num(x, 1, 100.0)
    return s if s == "–" else ("+" if s[0].isdigit() and float(s) != 0.0 else "") + s + " %"


def _worst(te: dict) -> str:
    """Mean and worst |error| of a per-trip document as report.json has them, and the worst
    trip (small trips left out, as there)."""
    small = set(te.get("small_trips") or [])
    worst = te.get("max_abs_error")
    trip = next((t for t, v in te["trips"].items() if t not in small and worst is not None
                 and v.get("error") is not None and abs(v["error"]) == worst), None)
    return (f"{num(te.get('mean_abs_error'), 1, 100.0)} % / {num(worst, 1, 100.0)} %"
            + (f" ({trip})" if trip is not None else ""))


def _decimals(first: dict, unit) -> int:
    """Decimals that give the median trip's measured energy four significant digits (1–6)."""
    import math

    xs = sorted(abs(v["measured_j"]) * unit.scale for v in first["trips"].values()
                if v.get("measured_j") is not None and v["measured_j"] == v["measured_j"] and v["measured_j"])
    if not xs:
        return unit.nd
    return min(max(3 - math.floor(math.log10(xs[len(xs) // 2])), 1), 6)


def _trip_table(names: list, docs: dict, unit) -> list[str]:
    """One table: per trip, measured and each equation's predicted energy and error."""
    import dataclasses

    first = docs[names[0]]
    unit = dataclasses.replace(unit, nd=_decimals(first, unit))
    trips = list(first["trips"])
    lines = []
    if len(trips) > MAX_TRIP_ROWS:
        def worst(t):
            errs = [abs(e) for nm in names if (e := docs[nm]["trips"].get(t, {}).get("error")) is not None
                    and e == e]
            return max(errs, default=-1.0)
        keep = set(sorted(trips, key=worst, reverse=True)[:MAX_TRIP_ROWS])
        lines += [f"The {MAX_TRIP_ROWS} trips with the largest |error| of {len(trips)}; "
                  f"{len(trips) - MAX_TRIP_ROWS} omitted (report.json has every trip).", ""]
        trips = [t for t in trips if t in keep]
    small = set(first.get("small_trips") or [])
    lines += ["| trip | measured [" + unit.label + "] | "
              + " | ".join(f"{nm} [{unit.label}] | {nm} error" for nm in names) + " | note |",
              "|---|---|" + "---|---|" * len(names) + "---|"]
    for t in sorted(trips, key=_trip_key):
        x = first["trips"][t]
        note = "; ".join(s for s in ("small: left out of mean and worst" if t in small else "",
                                      partial_trip_flag(x)) if s)
        cells = [f"{unit(docs[nm]['trips'].get(t, {}).get('predicted_j'))} | "
                 f"{_signed_pct(docs[nm]['trips'].get(t, {}).get('error'))}" for nm in names]
        lines.append(f"| {t} | {unit(x.get('measured_j'))} | " + " | ".join(cells) + f" | {note} |")
    lines.append("| mean / worst abs. error | | " + " | ".join(f" | {_worst(docs[nm])}" for nm in names) + " | |")
    return lines + [""]


def trip_energy_lines(doc: dict) -> list[str]:
    """The "Energy per trip" section of report.md from report.json's per-trip energies
    (``trip_energy``, ``trip_net_energy``): per trip the measured and each equation's
    predicted energy and error, traction and net, in the unit of what is compared (kWh, or
    litres of a fuel chain's fuel: :func:`sumo_drvpw.report.format.energy_unit`), and each
    equation's mean and worst |error| as report.json has them; [] without trips."""
    eqs = {nm: d for nm, d in doc["equations"].items() if d.get("trip_energy")}
    if not eqs:
        return []
    target = _target(doc)
    groups: dict = {}  # one table per unit (equations of different fuels)
    for nm, d in eqs.items():
        groups.setdefault(energy_unit(target, d.get("chain")), []).append(nm)
    lines = ["## Energy per trip", "",
             "Energy of each trip, measured and predicted by each equation; error = predicted / measured − 1. "
             "Traction counts the samples of positive power (Σ max(P, 0)·Δt), net every sample (Σ P·Δt: "
             "recuperation returns energy). Mean and worst |error| are report.json's (`trip_energy`, "
             "`trip_net_energy`): small trips are left out of them, partial trips are kept and marked."]
    lines += [u.note() for u in groups if u.note()]
    if len({u.fuel for u in groups} - {None}) > 1:
        lines.append("The equations' chains burn different fuels while the log measured one: an equation's "
                     "measured litres are the measured fuel energy in litres of its own chain's fuel.")
    lines.append("")
    for u, names in groups.items():
        trac = {nm: eqs[nm]["trip_energy"] for nm in names}
        net = {nm: eqs[nm]["trip_net_energy"] for nm in names if eqs[nm].get("trip_net_energy")}
        if len(net) == len(trac) and all(_same_energies(trac[nm], net[nm]) for nm in names):
            lines += [f"### Traction and net energy [{u.what}] (equal here: no sample has negative power)", ""]
            lines += _trip_table(names, trac, u)
            continue
        lines += [f"### Traction energy [{u.what}]", ""] + _trip_table(names, trac, u)
        if net:
            lines += [f"### Net energy [{u.what}]", ""] + _trip_table(list(net), net, u)
    return lines


def _same_energies(a: dict, b: dict) -> bool:
    """Two per-trip documents with the same trips and the same measured and predicted energies."""
    keys = ("measured_j", "predicted_j")
    return a["trips"].keys() == b["trips"].keys() and all(
        a["trips"][t].get(k) == b["trips"][t].get(k) for t in a["trips"] for k in keys)
