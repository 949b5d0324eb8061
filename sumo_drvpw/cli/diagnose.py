"""`sumo-drvpw diagnose`: trace the residual of an equation to effects it lacks.

Writes, as one output set (whole or absent, with manifest.json; ``--force`` to replace a
folder sumo-drvpw did not write), DIR/trace.json (the issue's shape), DIR/trace_details.json (screening, every
round's best candidates, the test), DIR/trace.md, DIR/final_equation.toml and figures
(residual against the chosen signal before and after each finding; error against speed
before and after). See :mod:`sumo_drvpw.fit.diagnose` for the method and the test.
"""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.report.diagnose import write_outputs

#: logs with more rows than this are traced streamed (``--stream auto``)
STREAM_ROWS = 1_000_000
#: a CSV log larger than this [bytes] counts as more than STREAM_ROWS rows
STREAM_CSV_BYTES = 200_000_000


def configure(p):
    p.add_argument("logs", nargs="+", metavar="LOG", help="drive logs (Parquet/CSV files or folders)")
    p.add_argument("--vehicle", help="vehicle name or TOML file")
    p.add_argument("--equation", help="declared equation, name or TOML file (default: calibrate one "
                                      "on the spot, stepwise on indt-var-1)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--target", choices=("wheel", "battery", "fuel"),
                   help="trace driving power (wheel), battery V·I or fuel flow (default: what the equation's "
                        "energy chain predicts, else wheel); battery/fuel start from the equation's chain and "
                        "find what the data add to it (sumo_drvpw.fit.chain_linear)")
    p.add_argument("--validation", default="auto", choices=("auto", "trip", "blocks"),
                   help="held-out data: whole trips (needs ≥ 3), contiguous blocks within trips, or "
                        "auto (trips when ≥ 3, else blocks; default)")
    p.add_argument("--block-s", type=float, default=60.0, help="block length [s] (default 60)")
    p.add_argument("--folds", type=int, default=5, help="number of folds K (default 5)")
    p.add_argument("--alpha", type=float, default=0.05, help="family-wise level of the test per round (default 0.05)")
    p.add_argument("--min-gain", type=float, default=0.01,
                   help="minimum relative held-out RMSE gain to accept a finding (default 0.01)")
    p.add_argument("--max-findings", type=int, default=5, help="stop after this many findings (default 5)")
    p.add_argument("--signals", help="comma list of glob patterns: offer only these columns")
    p.add_argument("--exclude", help="comma list of glob patterns: never offer these columns")
    p.add_argument("--max-nan", type=float, default=0.05,
                   help="skip columns with more than this fraction of NaN (default 0.05)")
    p.add_argument("--proxy-corr", type=float, default=0.9,
                   help="skip columns whose |corr(c·v^k, P)| reaches this: proxies of the target (default 0.9)")
    p.add_argument("--no-per-trip", action="store_true", help="do not offer per-trip offsets and masses")
    p.add_argument("--responses", action="store_true",
                   help="also offer columns whose role is 'response' (pedal, torques, currents, SOC …); "
                        "such findings are labelled 'response of the target', not effects the model lacks")
    p.add_argument("--min-speed", type=float, default=0.1, help="leave out samples slower than this [m/s] (default 0.1)")
    p.add_argument("--no-figures", action="store_true", help="skip the figures")
    p.add_argument("--stream", choices=("auto", "yes", "no"), default="auto",
                   help="read the logs batch by batch of whole trips in bounded memory (yes), all at once "
                        f"(no), or auto: streamed above {STREAM_ROWS:,} rows (default); streamed runs "
                        "screen columns on the first rows and draw no figures; the tracer of an energy "
                        "chain (--target battery|fuel) streams too (not a target of a BMS's energy "
                        "counters)")
    p.add_argument("--quiet", action="store_true", help="no progress messages")
    from sumo_drvpw.cli import add_force
    from sumo_drvpw.cli import add_log_options

    add_force(p)
    add_log_options(p)


def _globs(s):
    return tuple(x.strip() for x in s.split(",") if x.strip()) if s else ()


def options_from_args(args):
    from sumo_drvpw.fit.diagnose import DiagnoseOptions

    return DiagnoseOptions(validation=args.validation, block_s=args.block_s, folds=args.folds, alpha=args.alpha,
                        min_gain=args.min_gain, max_findings=args.max_findings, include=_globs(args.signals),
                        exclude=_globs(args.exclude), max_nan=args.max_nan, proxy_corr=args.proxy_corr,
                        per_trip=not args.no_per_trip, min_speed_mps=args.min_speed,
                        responses=args.responses)


def should_stream(logs, mode: str = "auto") -> bool:
    """Stream the logs? ``yes``/``no``, or ``auto``: more than STREAM_ROWS rows (Parquet
    metadata) or a CSV larger than STREAM_CSV_BYTES."""
    if mode != "auto":
        return mode == "yes"
    from sumo_drvpw.data.stream import plan

    rows, csv_bytes = 0, 0
    for part in plan(logs):
        if part.path.lower().endswith(".csv"):
            csv_bytes += Path(part.path).stat().st_size
        rows += part.rows
    return rows > STREAM_ROWS or csv_bytes > STREAM_CSV_BYTES


def run(logs, vehicle=None, equation=None, out=".", opt=None, figures=True, progress=None, measured=None,
        read_options=None, stream: str = "no", target: str = "wheel"):
    """Load, trace and write every output; returns the DiagnoseResult.

    ``stream``: ``no`` (all logs in memory), ``yes`` (batches of whole trips, bounded
    memory: :func:`sumo_drvpw.fit.diagnose.stream_run.diagnose_stream`) or ``auto``.
    ``details["resources"]`` of the result holds rows, seconds and peak RSS [MB]."""
    import time

    from sumo_drvpw.data.measured import load_measured, resolve_equations
    from sumo_drvpw.fit.diagnose import diagnose
    from sumo_drvpw.fit.engine import _progress, peak_rss_mb
    from sumo_drvpw.model.equations import SPEC_EQUATIONS, load_equation
    from sumo_drvpw.model.vehicles import load_vehicle

    t0 = time.perf_counter()
    if measured is None and should_stream(logs, stream):
        from sumo_drvpw.data.stream import plan
        from sumo_drvpw.fit.diagnose.stream_run import diagnose_stream

        veh = load_vehicle(vehicle) if vehicle else None
        eq = None
        if equation:
            eq = resolve_equations([equation], veh)[0] if equation in SPEC_EQUATIONS else load_equation(equation)
        bar = _progress(sum(p.rows for p in plan(logs)) or None, "rows")
        try:
            res = diagnose_stream(logs, veh, eq, opt, read_options, target=target, progress=progress,
                                  bar=bar.update)
        finally:
            bar.close()
        from sumo_drvpw.cli import note_counts

        note_counts(res.details.get("reader_counts", {}))
        write_outputs(res, out, figures=False)
    else:
        m = measured if measured is not None else load_measured(logs, vehicle, read_options, target=target)
        if measured is None:
            from sumo_drvpw.cli import note_counts

            note_counts(m.counts)
        eq = None
        if equation:
            eq = resolve_equations([equation], m.vehicle)[0] if equation in SPEC_EQUATIONS else load_equation(equation)
        res = diagnose(m, eq, opt, progress=progress)
        res.details["resources"] = {"rows": int(res.details["samples"]["rows"]), "streamed": False}
        write_outputs(res, out, figures=figures)
    r = res.details.setdefault("resources", {})
    r.update(seconds=time.perf_counter() - t0, peak_rss_mb=peak_rss_mb())
    return res


def resource_line(res) -> str:
    """One line: rows, seconds, rows/s and peak RSS of a diagnose run."""
    r = res.details.get("resources", {})
    rows, secs = r.get("rows", 0), r.get("seconds", float("nan"))
    how = (f"streamed, {r['passes']} passes over the prepared batches"
           + (" (on disk)" if r.get("batches_on_disk") else "")) if "passes" in r else "in memory"
    return (f"diagnose: {rows:,} rows in {secs:.1f} s ({rows / secs:,.0f} rows/s, {how}), "
            f"peak RSS {r.get('peak_rss_mb', float('nan')):,.0f} MB")


def main(args) -> int:
    import sys

    from sumo_drvpw.errors import UserError

    opt = options_from_args(args)
    try:
        opt.check()
    except UserError as e:  # the library names the option; the user typed a flag
        msg = str(e)
        for field in ("validation", "block_s", "folds", "alpha", "min_gain", "max_findings", "max_nan"):
            msg = msg.replace(f"diagnose option {field} ", f"--{field.replace('_', '-')} ")
        msg = msg.replace("diagnose option min_speed_mps ", "--min-speed ")
        raise UserError(msg) from None
    progress = None if args.quiet else (lambda s: print(s, file=sys.stderr))
    from sumo_drvpw.cli import output_set
    from sumo_drvpw.cli import read_options

    target = _target(args)
    if target != "wheel":  # issue #12 §3: the loop closed on an energy chain
        return _chain_main(args, target, progress)

    try:
        with output_set(args, args.out, [args.logs, args.vehicle, args.equation]) as tmp:
            res = run(args.logs, args.vehicle, args.equation, tmp, opt, figures=not args.no_figures,
                      progress=progress, read_options=read_options(args, [args.equation] if args.equation else ()),
                      stream=args.stream)
    except UserError as e:  # a message about the data that names none of the inputs: name the logs
        named = [str(x) for x in (*args.logs, args.vehicle, args.equation) if x]
        for opt_name, flag in (("include", "--signals"), ("exclude", "--exclude")):  # as the user typed it
            if str(e).startswith(f"diagnose option {opt_name}: "):
                raise UserError(str(e).replace(f"diagnose option {opt_name}: ", f"{flag}: ", 1)) from None
        if any(n in str(e) for n in named) or str(e).startswith("--"):
            raise
        raise UserError(f"{', '.join(map(str, args.logs))}: {e}") from None
    r = res.report
    print(f"baseline held-out RMSE {r['baseline']['metrics']['rmse_w']:.1f} W; "
          f"{len(r['findings'])} finding(s)")
    for f in r["findings"]:
        share = ("" if f["energy_share"] is None
                 else f", energy share {100 * f['energy_share']:.2f} %")
        print(f"  + {f['term']}: {f['effect']} (RMSE {f['metrics_before']['rmse_w']:.1f} → "
              f"{f['metrics_after']['rmse_w']:.1f} W{share})")
    print(f"final held-out RMSE {r['final']['metrics']['rmse_w']:.1f} W; wrote {Path(args.out) / 'trace.json'}")
    fix = correction_flags(r["findings"], res.equation.measurement)
    if fix:
        veh = f" --vehicle {args.vehicle}" if args.vehicle else ""
        print("measurement-side findings belong in the data, not in coefficients: calibrate the equation for "
              f"SUMO with  sumo-drvpw calibrate {' '.join(map(str, args.logs))}{veh} {fix} --out EQ.toml  "
              "(the equation keeps them in its [measurement]; compare reads new logs the same way)")
    print(resource_line(res), file=sys.stderr)
    return 0


def correction_flags(findings, measurement) -> str:
    """The calibrate options that correct, in the data, the measurement-side findings of a
    trace: the power lag (the traced equation's whole [measurement] lag), the accelerometer
    grade, the air density at altitude. '' when there are none."""
    terms = [f["term"] for f in findings]
    flags = []
    lag = measurement.power_lag_s if measurement is not None else 0.0
    if any(f.get("kind") == "timing" for f in findings) and lag:
        flags.append(f"--power-lag {lag:g}")
    if "[grade_accelerometer]" in terms:
        flags.append("--grade-source fused")
    if any(t.startswith("[air_density_altitude]") for t in terms):
        flags.append("--air-density altitude")
    if flags and measurement is not None and measurement.exclude_dropouts:
        flags.append("--exclude-dropouts")
    return " ".join(flags)


def _target(args) -> str:
    """--target, else battery/fuel when the equation's chain predicts it, else wheel."""
    if getattr(args, "target", None):
        return args.target
    from sumo_drvpw.model.equations import SPEC_EQUATIONS

    if args.equation and args.equation not in SPEC_EQUATIONS:
        from sumo_drvpw.model.equations import load_equation

        pred = load_equation(args.equation).predicts
        return pred if pred in ("battery", "fuel") else "wheel"
    return "wheel"


def chain_notes(eq, files) -> list[str]:
    """What to read a chain trace's figures with: the warnings the declared chain was
    calibrated with, and the logs among ``files`` it was calibrated on (its own parameters
    have seen them: 'before' there is in sample, and 'after' is held out for the findings
    only)."""
    from sumo_drvpw.data.paths import files_in_common
    from sumo_drvpw.report.comparison import calibration_warnings

    notes = calibration_warnings(eq.name, {"chain": eq.chain.to_dict()})
    logs = [str(x) for x in (eq.chain.provenance or {}).get("logs") or []]  # (relative to the equation's
    here = [str(Path(eq.path).parent / x) for x in logs if eq.path and not Path(x).is_absolute()]  # folder;
    # files written before 2026-11-29 name them as calibrate was given them: from the working folder)
    seen = files_in_common(logs + here, files)
    if seen:
        notes.append(f"the declared chain was calibrated on {len(seen)} of these {len(files)} log file(s) "
                     f"({', '.join(map(str, seen[:3]))}{' …' if len(seen) > 3 else ''}): its parameters have seen "
                     "them, so 'before' is in sample there and 'after' is held out for the findings only; "
                     "trace logs it was not calibrated on to judge it")
    return notes


def _chain_main(args, target, progress) -> int:
    from sumo_drvpw.cli import output_set
    from sumo_drvpw.cli import read_options
    from sumo_drvpw.data.measured import load_measured
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.fit.chain_linear import ChainTraceOptions, check_chain_equation, trace_chain
    from sumo_drvpw.model.equations import load_equation
    from sumo_drvpw.report.chain_trace import write_chain_outputs

    if not args.equation:
        raise UserError(f"--target {target} needs --equation with an energy chain predicting {target}")
    streamed = should_stream(args.logs, args.stream)
    eq = load_equation(args.equation)
    check_chain_equation(eq, target)
    opt = ChainTraceOptions(block_s=args.block_s, folds=args.folds, alpha=args.alpha, min_gain=args.min_gain,
                            max_findings=args.max_findings, validation=args.validation,
                            include=_globs(args.signals), exclude=_globs(args.exclude))
    from sumo_drvpw.cli import note_counts
    from sumo_drvpw.data.powertrain import measured_fuel
    from sumo_drvpw.fit.trip_energy import with_trace_fuel_volumes

    with output_set(args, args.out, [args.logs, args.vehicle, args.equation]) as tmp:
        ro = read_options(args, [args.equation])
        if streamed:  # batches of whole trips in bounded memory (fit/chain_trace_stream.py)
            res, veh = _chain_streamed(args, eq, target, opt, ro, progress)
            files = res.files
        else:
            m = load_measured(args.logs, args.vehicle, ro, target=target)
            note_counts(m.counts)
            res = trace_chain(m, eq, opt, progress=progress)
            from sumo_drvpw.fit.trip_energy import with_trace_left_out

            with_trace_left_out(res, m)
            veh, files = m.vehicle, m.log.files
        res.report["notes"] = chain_notes(eq, files)
        with_trace_fuel_volumes(res.report, measured_fuel(veh, ro.fuel))  # a fuel target's litres
        write_chain_outputs(res, tmp)
    r = res.report
    from sumo_drvpw.report.comparison import unknown_input_lines

    for x in unknown_input_lines(r["declared_equation"], r.get("chain_unknown_inputs"), r["n_samples"]):
        print("note: " + x)
    for x in r["notes"]:
        print(("warning: " if "calibration warned" in x else "note: ") + x)
    print(f"{target}: declared chain RMSE {r['baseline']['metrics']['rmse_w']:.1f} W, per-trip net energy "
          f"{100 * r['baseline']['trip_net_energy']['mean_abs_error']:.1f} %; {len(r['findings'])} finding(s)")
    for f in r["findings"]:
        print(f"  + {f['term']}: {f['reading']} (held-out block energy error −{100 * f['energy_gain']:.1f} %)")
    print(f"after (held out): RMSE {r['final']['metrics']['rmse_w']:.1f} W, per-trip net energy "
          f"{100 * r['final']['trip_net_energy']['mean_abs_error']:.1f} %; wrote {Path(args.out) / 'trace.json'}")
    if streamed:
        import sys

        from sumo_drvpw.fit.engine import peak_rss_mb

        rs = r["resources"]
        print(f"diagnose: {rs['rows']:,} rows streamed, {rs['passes']} passes over the prepared batches"
              f"{' (on disk)' if rs['batches_on_disk'] else ''}, peak RSS {peak_rss_mb():,.0f} MB", file=sys.stderr)
    return 0


def _chain_streamed(args, eq, target, opt, ro, progress):
    """The chain trace streamed (:func:`sumo_drvpw.fit.chain_trace_stream.trace_chain_stream`):
    (result, vehicle); the reader's counts said."""
    from sumo_drvpw.cli import note_counts
    from sumo_drvpw.data.stream import plan
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.fit.chain_trace_stream import trace_chain_stream
    from sumo_drvpw.fit.engine import _progress
    from sumo_drvpw.model.vehicles import load_vehicle

    veh = load_vehicle(args.vehicle) if args.vehicle else None
    bar = _progress(sum(p.rows for p in plan(args.logs)) or None, "rows")
    try:
        res = trace_chain_stream(args.logs, veh, eq, target, opt, ro, progress=progress, bar=bar.update)
    except UserError as e:
        if "traced in memory only" in str(e):  # (the library names no flag)
            raise UserError(f"--stream {args.stream}: {e}; give --stream no") from None
        raise
    finally:
        bar.close()
    note_counts(res.counts)
    return res, veh
