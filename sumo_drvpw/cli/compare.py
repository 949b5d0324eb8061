"""`sumo-drvpw compare`: any set of equations against a log's measured power."""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.cli import add_force, add_log_options, note_counts, output_set, read_options
from sumo_drvpw.cli._scale import add_engine_arguments
from sumo_drvpw.report.format import num


def configure(p):
    p.add_argument("logs", nargs="+", metavar="LOG", help="drive logs (Parquet/CSV files or folders)")
    p.add_argument("--vehicle", help="vehicle name or TOML file (optional when the log has power_w and mass_kg)")
    p.add_argument("--equation", action="append", required=True, metavar="NAME|FILE",
                   help="equation to compare (repeat); 'vsp_spec' = VSP from the vehicle's specs, 'roadload_spec' = its published road load A + B·v + C·v²")
    p.add_argument("--out", required=True, metavar="DIR", help="report folder (written whole, or not at all)")
    p.add_argument("--target", choices=("wheel", "battery", "fuel"),
                   help="compare driving power (wheel), battery V·I or fuel flow (default: what the "
                        "equations' energy chains predict when they all predict the same, else wheel)")
    add_force(p)
    add_log_options(p)
    add_engine_arguments(p)


def main(args) -> int:
    from sumo_drvpw.fit.compare import compare
    from sumo_drvpw.fit.trip_energy import left_out_by_trip
    from sumo_drvpw.report.comparison import write_comparison_report
    from sumo_drvpw.data.measured import load_measured, resolve_equations
    from sumo_drvpw.data.powertrain import measured_fuel
    from sumo_drvpw.data.trips import trip_signatures
    from sumo_drvpw.cli._scale import check_engine_arguments, compare_main

    check_engine_arguments(args)  # --workers, --scheduler only with --engine dask
    in_sample = in_sample_lines(args.equation, args.logs)
    for line in in_sample:
        print("note: " + line)
    if compare_main(args, in_sample) is not None:  # driving power, streamed in bounded memory (issue #14)
        return 0
    with output_set(args, args.out, [args.logs, args.vehicle, args.equation]) as tmp:
        target, note = compare_target(args)
        m = load_measured(args.logs, args.vehicle, read_options(args, args.equation), target=target)
        note_counts(m.counts)
        eqs = resolve_equations(args.equation, m.vehicle)
        more = in_sample_trips(eqs, trip_signatures(m.log.df), args.logs)
        for line in more:
            print("note: " + line)
        u = m.usable
        comp = compare(m.power_w[u], m.inputs.take(u), eqs, dt_s=m.log.df["dt_s"].to_numpy()[u],
                       target=target, battery_w=None if m.battery_w is None else m.battery_w[u])
        comp.measured_fuel = measured_fuel(m.vehicle, m.log.options.fuel)  # what the log's fuel flow was read as
        comp.left_out = left_out_by_trip(m.power_w, u, m.log.df["dt_s"].to_numpy(), m.inputs.trip)
        what = {"wheel": "driving", "battery": "battery", "fuel": "fuel"}[target]
        ctx = m.context()
        if note:
            ctx["target"] = note
        if in_sample + more:
            ctx["in sample"] = in_sample + more
        write_comparison_report(comp, tmp, f"Equations against measured {what} power", ctx)
    print_summary(comp.to_json(), args.out)
    return 0


def in_sample_lines(equations, logs) -> list[str]:
    """One line per equation file calibrated on some of the log files compared (its
    ``[provenance]`` or ``[chain.provenance]`` ``logs``, named relative to the equation's
    folder): its errors there are in sample, not held out. Files only: the same trips
    imported into another file are not recognised."""
    from sumo_drvpw.data.log_files import expand_paths
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.model.equations import SPEC_EQUATIONS, load_equation

    try:
        files = [str(f) for f in expand_paths(logs)]
    except UserError:  # the reader says what is wrong with them, below
        return []
    out = []
    for spec in equations:
        if spec in SPEC_EQUATIONS or not Path(spec).is_file():
            continue
        eq = load_equation(spec)
        seen = calibration_files(eq, files)
        if seen:
            out.append(f"{eq.name} was calibrated on {len(seen)} of these {len(files)} log file(s) "
                       f"({', '.join(Path(f).name for f in seen[:3])}{' …' if len(seen) > 3 else ''}): its "
                       "errors there are in sample, not held out")
    return out


def calibration_files(eq, files: list[str]) -> list[str]:
    """The ``files`` an equation was calibrated on: its ``[provenance]`` or
    ``[chain.provenance]`` ``logs``, named relative to the equation's folder."""
    from sumo_drvpw.data.paths import files_in_common

    named = [str(x) for prov in (eq.provenance or {}, getattr(eq.chain, "provenance", None) or {})
             for x in prov.get("logs") or []]
    if eq.path:
        named += [str(Path(eq.path).parent / x) for x in named if not Path(x).is_absolute()]
    return files_in_common(named, files)


def in_sample_trips(eqs, trips: dict, logs) -> list[str]:
    """One line per equation calibrated on some of the compared ``trips`` (trip → signature,
    data/trips.trip_signatures; the equation's in its ``[provenance]`` or ``[chain.provenance]``
    ``trip_signatures``) read from other files than those it was calibrated on (``logs``
    compared; those files :func:`in_sample_lines` names: a trip of them re-exported into
    another file beside them was said held out)."""
    from sumo_drvpw.data.log_files import expand_paths
    from sumo_drvpw.data.plausible import trip_ids
    from sumo_drvpw.data.trips import same_trips
    from sumo_drvpw.errors import UserError

    try:
        files = [str(f) for f in expand_paths(logs)]
    except UserError:
        files = []
    out = []
    n = len(trips)
    for eq in eqs:
        sigs = [s for prov in (eq.provenance or {}, getattr(eq.chain, "provenance", None) or {})
                for s in prov.get("trip_signatures") or []]
        seen = same_trips(sigs, trips)
        said = calibration_files(eq, files) if seen else []
        if said:  # the trips of the files named already are said
            inside = {t for f in said for t in trip_ids(Path(f))}
            seen = [t for t in seen if t not in inside]
        if seen:
            out.append(f"{eq.name} was {'also ' if said else ''}calibrated on {len(seen)} of these {n} trip(s) "
                       f"({', '.join(seen[:3])}{' …' if len(seen) > 3 else ''}; the same samples, read "
                       "from other files): its errors there are in sample, not held out")
    return out


def compare_target(args) -> tuple[str, str | None]:
    """The target ``compare`` measures against: ``--target``, else what the equations'
    energy chains predict when they all predict the same battery or fuel, else the driving
    power; and a note, printed and kept in the report's context, when equations predict
    different targets (their chains then unused)."""
    target = getattr(args, "target", None)
    if target is not None:
        return target, None
    from sumo_drvpw.model.equations import SPEC_EQUATIONS, load_equation

    by = {s: getattr(load_equation(s), "predicts", "wheel") if s not in SPEC_EQUATIONS else "wheel"
          for s in args.equation}
    pred = set(by.values())
    if len(pred) == 1 and pred <= {"battery", "fuel"}:
        return pred.pop(), None
    chains = sorted(p for p in pred if p in ("battery", "fuel"))  # (powertrain_output: a driving power)
    if not chains:
        return "wheel", None
    note = (f"the equations predict different targets ({'; '.join(f'{s}: {p}' for s, p in by.items())}): "
            "compared on the driving power at the wheels, their energy chains unused; "
            + " or ".join(f"--target {c}" for c in chains) + " compares at the "
            + " or ".join("battery" if c == "battery" else "tank" for c in chains))
    print("note: " + note)
    return "wheel", note


def print_summary(doc: dict, out) -> None:
    """The notes on each equation of a comparison's report.json (chain inputs the log lacks,
    its chain's calibration warnings), one line per equation, then where the report is."""
    from sumo_drvpw.report.comparison import calibration_warnings, unknown_input_lines

    for name, r in doc["equations"].items():
        for x in unknown_input_lines(name, r.get("chain_unknown_inputs"), r["n"]):
            print("note: " + x)
        for w in calibration_warnings(name, r):
            print("warning: " + w)
    import json

    written = Path(out) / "report.json"  # the per-trip energies and the context, as written
    report = json.loads(written.read_text(encoding="utf-8")) if written.is_file() else doc
    for name, r in doc["equations"].items():
        print(f"{name:<24} n={r['n']:<8} R²={num(r['r2'], 3)}  R²<50kW={num(r['r2_light'], 3)}  "
              f"R²≥50kW={num(r['r2_heavy'], 3)}  RMSE={r['rmse_w'] / 1000:.2f} kW  bias={r['bias_w'] / 1000:+.2f} kW")
        line = trip_energy_line(report.get("equations", {}).get(name, r))
        if line:
            print(f"{'':<24} {line}")
    source = str((report.get("context") or {}).get("power_source", ""))
    if "counters" in source:
        print("note: the measured power is the battery's energy counters', spread between their readings: the "
              "per-sample figures set the model's sharp power beside it; read the per-trip energies")
    elif "battery V·I" in source and (report.get("settings") or {}).get("target", "wheel") == "wheel":
        print("note: the measured driving power is the battery's V·I (the logs hold no wheel or motor power): "
              "it carries the drivetrain's losses, less what braking returns, and the auxiliary loads, which "
              "a driving-power equation does not — its errors here are those as much as the road load's; "
              "compare a battery chain on the battery with --target battery")
    print(f"wrote {Path(out) / 'report.md'}")


def trip_energy_line(r: dict) -> str:
    """An equation's per-trip energy errors of a report.json (``trip_energy``, ``trip_net_energy``)
    on one line: mean and worst |predicted/measured − 1| and the worst trip, both over the
    trips the report scores (its small trips, listed in ``small_trips``, left out as there:
    the worst named was a small trip's, +859.9 % where report.md's worst reads +207.8 %);
    '' without trips."""
    parts, small = [], set()
    for key, what in (("trip_energy", "traction"), ("trip_net_energy", "net")):
        te = r.get(key) or {}
        small |= set(te.get("small_trips") or ())
        trips = {t: x["error"] for t, x in (te.get("trips") or {}).items()
                 if x.get("error") is not None and x["error"] == x["error"] and t not in (te.get("small_trips") or ())}
        if not trips:
            continue
        worst = max(trips, key=lambda t: abs(trips[t]))
        parts.append(f"{what} energy |error| mean {100 * te['mean_abs_error']:.1f} %, worst "
                     f"{100 * trips[worst]:+.1f} % ({worst})")
    if not parts:
        return ""
    n = len((r.get("trip_energy") or r.get("trip_net_energy") or {}).get("trips") or {})
    return (f"per trip ({n}" + (f"; {len(small)} small, left out of mean and worst" if small else "") + "): "
            + "; ".join(parts))

