"""`sumo-drvpw demo`: the main job on bundled data, offline.

1. synthesize a 40-minute Prius3 test-track log (truth: Table 3 Indt var. 1);
2. calibrate DrvPw on it (stepwise, Indt var. 1 candidates);
3. compare the calibrated equation, the paper's DrvPw and the classic VSP equations on
   the bundled log (another seed: held-out data) and write the report;
4. run the bundled city and highway SUMO scenarios with the same equations and write
   where the energy goes (per term, per road class).
"""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.cli import add_force, output_set
from sumo_drvpw.fileio import repo_root, write_text
from sumo_drvpw.report.format import num

COMPARED = ["drvpw_prius3", "vsp_ldv1999", "vsp_prius3spec", "moves_passenger_car", "epa_prius3"]


def configure(p):
    p.add_argument("--out", default="demo-out",
                   help="output folder (default demo-out), written whole or not at all")
    add_force(p)
    p.add_argument("--minutes", type=float, default=40.0, help="length of the calibration log [min]")
    p.add_argument("--no-sumo", action="store_true", help="skip the SUMO scenario runs")


def main(args) -> int:
    from sumo_drvpw.data.log import bundled_log

    from sumo_drvpw.cli.synth import MAX_MINUTES, MIN_MINUTES

    if not MIN_MINUTES <= args.minutes <= MAX_MINUTES:
        from sumo_drvpw.errors import UserError

        raise UserError(f"--minutes must be from {MIN_MINUTES:g} to {MAX_MINUTES:g}, got {args.minutes}")
    final = Path(args.out)
    held_log = bundled_log()
    with output_set(args, final, [held_log]) as out:
        _demo(args, out, final, held_log)
    print(f"done: {final / 'README.md'}")
    return 0


def _demo(args, out: Path, final: Path, held_log: Path) -> None:
    """Every step of the demo, written into ``out`` (the set published as ``final``)."""
    from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
    from sumo_drvpw.fit.compare import compare
    from sumo_drvpw.model.equations import save_equation
    from sumo_drvpw.report.comparison import write_comparison_report
    from sumo_drvpw.synth.track import SynthOptions, synthesize, write_synth
    from sumo_drvpw.data.measured import load_measured, resolve_equations

    lines = ["# sumo-drvpw demo", ""]

    log_path = out / "prius3_calibration_log.parquet"
    df, truth = synthesize(SynthOptions(minutes=args.minutes, seed=7, trip_id="synth-cal"))
    write_synth(df, truth, log_path)
    print(f"[1/4] synthesized {final / log_path.name} ({len(df)} samples at 8 Hz, truth {truth['equation']})")

    m = load_measured([log_path], "prius3")
    res = calibrate(m.inputs, m.power_w, CANDIDATES["indt-var-1"], mask=m.usable,
                    counts=m.counts, reference_mass_kg=float(m.vehicle.mass_kg))
    eq = res.to_equation("drvpw_calibrated", provenance={"logs": m.log.files, "vehicle": m.vehicle.path,
                                                         "power_source": m.source})
    from sumo_drvpw.data.powertrain import terms_predict_of

    eq.terms_predict = terms_predict_of(m.source)  # the power-split's P_PTdrv: its output
    eq_path = out / "drvpw_calibrated.toml"
    save_equation(eq, eq_path)
    print(f"[2/4] calibrated {final / eq_path.name}\n{res.summary()}")
    lines += ["## Calibration", "", f"Log: `{log_path.name}`; equation: `{eq_path.name}`", "",
              "```", res.summary(), "```", "",
              "Truth (Table 3 Indt var. 1 on this basis): " +
              ", ".join(f"{k} = {v:.6g}" for k, v in truth["terms"].items()), ""]

    held = load_measured([held_log], "prius3")
    eqs = [eq] + resolve_equations(COMPARED, held.vehicle)
    u = held.usable
    comp = compare(held.power_w[u], held.inputs.take(u), eqs, dt_s=held.log.df["dt_s"].to_numpy()[u],
                   reference=eq.name)
    rep = out / "report"
    ctx = held.context()
    ctx["calibrated_on"] = str(final / log_path.name)
    write_comparison_report(comp, rep, "DrvPw against classic VSP on a held-out Prius3 test-track log", ctx)
    doc = comp.to_json()
    print(f"[3/4] compared on the bundled held-out log → {final / 'report' / 'report.md'}")
    lines += ["## Comparison on the bundled held-out log", "", "Full report: `report/report.md`", "",
              "| equation | R² < 50 kW | R² ≥ 50 kW | RMSE [kW] | bias [kW] |", "|---|---|---|---|---|"]
    for name, r in doc["equations"].items():
        lines.append(f"| {name} | {num(r['r2_light'], 3)} | {num(r['r2_heavy'], 3)} | {r['rmse_w'] / 1e3:.2f} | "
                     f"{r['bias_w'] / 1e3:+.2f} |")
        print(f"    {name:<22} R²<50kW={num(r['r2_light'], 3)} R²≥50kW={num(r['r2_heavy'], 3)} "
              f"RMSE={r['rmse_w'] / 1e3:.2f} kW")
    lines.append("")

    if not args.no_sumo:
        lines += _sumo_runs(out, eq_path, final)
    else:
        print("[4/4] SUMO runs skipped (--no-sumo)")
    write_text(out / "README.md", "\n".join(lines) + "\n")


def _scenario(name: str) -> Path:
    """A bundled scenario: package data when the build ships it, else the checkout's."""
    try:
        from sumo_drvpw.sim.scenario_paths import bundled_scenario
    except ImportError:
        return repo_root() / "scenarios" / f"{name}.toml"
    return Path(bundled_scenario(name))


def _sumo_runs(out: Path, eq_path: Path, final: Path) -> list[str]:
    """Run the bundled city and highway scenarios, adding the calibrated equation."""
    try:
        from sumo_drvpw.sim import run_scenario
    except ImportError as e:  # the SUMO plug-in is not part of this build
        print(f"[4/4] SUMO runs skipped: {e}")
        return ["SUMO runs skipped: the plug-in is not available in this build.", ""]
    lines = ["## Where the energy goes in SUMO (traction energy per term, per road class)", ""]
    for name in ("city", "highway"):
        scen = _scenario(name)
        if not scen.is_file():
            print(f"[4/4] {scen} missing, skipped")
            continue
        from sumo_drvpw.model.equations import load_equation
        from sumo_drvpw.sim.scenario import load_scenario

        calibrated = load_equation(eq_path)
        calibrated.path = str(final / eq_path.name)  # where it will be (summary.json equation_sources)
        eqs = list(load_scenario(scen).equations) + [calibrated]
        summary = run_scenario(scen, out / f"sumo_{name}", equations=eqs)
        print(f"[4/4] SUMO {name}: {summary['steps']} steps, {summary['vehicles']} vehicles → {final / f'sumo_{name}'}")
        lines += [f"### {name} (`sumo_{name}/`)", "", "| equation | class | acc | grade | aero | roll | traction [kWh] |",
                  "|---|---|---|---|---|---|---|"]
        for eqn, e in summary["equations"].items():
            for cls, en in e["energy_j"].items():
                tot = en.get("total", 0.0) or 0.0
                if tot <= 0:  # this scenario has no traction in that class
                    continue
                sh = [f"{100 * en.get(t, 0.0) / tot:.1f} %" if tot > 0 else "–" for t in ("acc", "grade", "aero", "roll")]
                lines.append(f"| {eqn} | {cls} | " + " | ".join(sh) + f" | {tot / 3.6e6:.2f} |")
        lines.append("")
    return lines

