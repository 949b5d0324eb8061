"""``sumo-drvpw dynamics LOG... --out DIR``: the driving dynamics of drive logs, measured as
a SUMO run measures its trajectories (sim/dynamics.py): the EU RDE trip-dynamics figures per
urban/rural/motorway part, the positive kinetic energy per kg and km, and the 1-Hz
accelerations by speed, with a SUMO vType's speed-dependent desired acceleration
(``speedTable``/``desAccelProfile``) from them. Writes ``dynamics.json`` and ``report.md``.
"""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.cli import add_force, add_read_options, note_counts, output_set, read_options


def configure(p):
    p.add_argument("logs", nargs="+", metavar="LOG", help="drive logs (Parquet/CSV files or folders)")
    p.add_argument("--out", required=True, metavar="DIR", help="report folder (written whole, or not at all)")
    add_force(p)
    add_read_options(p)


def main(args) -> int:
    from sumo_drvpw.data.log import read_log
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.fileio import write_json, write_text
    from sumo_drvpw.sim.dynamics import MIN_SAMPLES, SOURCE, coverage_warning, of_log, report_md, sumo_profile

    log = read_log(args.logs, None, read_options(args))
    note_counts(log.counts)
    if not (log.df["speed_mps"] > 0).any():
        raise UserError(f"{args.logs[0]}: column 'speed_mps' is 0 on every row: the vehicle never "
                        "moves, so there are no driving dynamics")
    dyn, trips = of_log(log.df)
    if not dyn.get("parts"):
        step = dyn.get("median_step_s", float("nan"))
        raise UserError(f"{args.logs[0]}: no trip has speeds one and two seconds apart (at least 3 s "
                        "of samples, no gap over 2.5 s): no 1-Hz figures"
                        + (f" — its samples are {step:g} s apart (median): the RDE figures need a log "
                           "sampled at 1 Hz or faster" if step == step else ""))
    doc = {"source": SOURCE, "logs": [str(f) for f in log.files], "trips": trips,
           "samples": int(len(log.df)), "driving_dynamics": dyn,
           "sumo_vtype": sumo_profile(dyn.get("accel_profile", []))}
    with output_set(args, args.out, [args.logs]) as tmp:
        write_json(tmp / "dynamics.json", doc)
        write_text(tmp / "report.md", report_md(doc))
    for name, p in dyn["parts"].items():
        mark = {k: "" if p[k] else "*" for k in ("va_pos_95_judged", "rpa_judged")}
        print(f"{name:<9} v̄ {p['mean_speed_kmh']:5.1f} km/h  v·a_pos 95th pct. {p['va_pos_95_m2ps3']:5.1f}"
              f"{mark['va_pos_95_judged']} (RDE max {p['rde_va_pos_95_max']:.1f}) m²/s³  RPA {p['rpa_mps2']:.3f}"
              f"{mark['rpa_judged']} (RDE min {p['rde_rpa_min']:.3f}) m/s²")
    if not all(p["va_pos_95_judged"] and p["rpa_judged"] for p in dyn["parts"].values()):
        print(f"* not judged against the RDE bound: fewer than {MIN_SAMPLES} samples in that part")
    print(f"kinetic energy {dyn['kinetic_j_per_kg_km']:.0f} J/(kg·km) over {trips} trips")
    if (w := coverage_warning(dyn)):
        print(f"warning: {w}")
    print(f"wrote {Path(args.out) / 'report.md'}")
    return 0
