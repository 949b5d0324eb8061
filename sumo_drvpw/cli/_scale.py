"""Engine flags and the streamed paths of `calibrate` and `compare` (issue #14).

``--engine local`` (default) streams the logs batch by batch of whole trips in bounded
memory; ``--engine dask`` runs the same reduction on a Dask cluster (``--scheduler
ADDRESS``, else a local cluster of ``--workers N`` processes); ``--engine memory`` reads
everything at once (the reference path the streamed results are tested against).
"""

from __future__ import annotations

import sys
from functools import partial
from pathlib import Path

from sumo_drvpw.errors import NoDrivingPower, UserError

ENGINES = ("local", "dask", "memory")
#: the most processes a local Dask cluster is started with (a billion were started until memory ran out)
MAX_WORKERS = 256


def add_engine_arguments(p, engines=ENGINES, engine_help: str | None = None) -> None:
    """--engine, --scheduler, --workers (``engines``/``engine_help``: a command's own choices,
    e.g. ``run``'s local process pool or Dask)."""
    g = p.add_argument_group("scale (bounded memory, Dask)")
    g.add_argument("--engine", choices=engines, default="local",
                   help=engine_help or
                   "local: stream the logs trip by trip in bounded memory (default); dask: the "
                   "same on a Dask cluster (pip install 'sumo-drvpw[dask]'); memory: read all at once")
    g.add_argument("--scheduler", metavar="ADDRESS",
                   help="Dask scheduler of an existing cluster, e.g. tcp://host:8786 "
                        "(--engine dask; default: a local cluster)")
    g.add_argument("--workers", type=int, metavar="N",
                   help="worker processes of the local Dask cluster (default: one per CPU)")


def check_engine_arguments(args) -> None:
    """The flags go together: --scheduler and --workers only with --engine dask."""
    engine = getattr(args, "engine", "local")
    if engine != "dask":
        for flag in ("scheduler", "workers"):
            if getattr(args, flag, None) is not None:
                raise UserError(f"--{flag} goes with --engine dask (got --engine {engine})")
    workers = getattr(args, "workers", None)
    if workers is not None and not 1 <= workers <= MAX_WORKERS:
        raise UserError(f"--workers must be from 1 to {MAX_WORKERS} (processes of a local cluster; a larger "
                        f"cluster: --scheduler ADDRESS), got {workers}")
    if engine == "dask":
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise UserError("--engine dask needs Dask: pip install 'sumo-drvpw[dask]'") from None


def _run(args, make, vehicle):
    from sumo_drvpw.fit.engine import run

    from sumo_drvpw.cli import read_options

    # a column named twice: the reader checks each file's header as it reads it
    # trip ids in two files: checked by the engine on the ids it reads (no extra pass)
    return run(args.logs, make, vehicle, options=read_options(args, _equations(args)), engine=args.engine,
               scheduler=args.scheduler, workers=args.workers)


def _equations(args) -> list:
    """The --equation(s) of a command, whose [measurement] the logs are read with."""
    eqs = getattr(args, "equation", None)
    return [eqs] if isinstance(eqs, str) else list(eqs or ())


def _measurement(args):
    """The corrections :func:`_run` reads the logs with (no note: the read said it)."""
    from sumo_drvpw.cli._measurement import measurement_options

    return measurement_options(args, _equations(args), say=False)


def _context(st, vehicle, n_used: int) -> dict:
    """What :meth:`sumo_drvpw.data.measured.Measured.context` reports, from streamed sums."""
    counts = dict(st.counts)
    counts["files"] = len(st.files)
    return {"logs": st.files, "vehicle": vehicle.name if vehicle else None,
            "power_source": st.source, "samples": st.rows, "usable": counts.get("usable", n_used),
            "counts": counts}


def fit_road_load(args, st, cands, veh, name: str, provenance: dict):
    """The stepwise road load of streamed statistics (``st``, a CalibrationStats), refused
    where the in-memory path refuses it and physically constrained as it is; its summary
    and notes printed. Returns (equation, the physics note or '', the CalibrationResult)."""
    from sumo_drvpw.fit.stream import calibrate_from_stats
    from sumo_drvpw.cli.calibrate import MOVING_MPS

    if st.mass_n == 0:
        from sumo_drvpw.data.log import exclusions

        raise UserError(f"{', '.join(map(str, args.logs))}: no usable sample among {st.counts.get('rows', 0)} "
                        f"rows (excluded: {exclusions(st.counts)}; any other row lacks a finite measured "
                        "power or input)")
    from sumo_drvpw.cli.calibrate import check_identified

    where = st.files[0] if len(st.files) == 1 else f"{len(st.files)} files"
    if len(st.speeds) < 2:  # the in-memory path's identifiability check, from streamed sums
        raise UserError(f"{where}: speed takes {len(st.speeds)} distinct value(s) above "
                        f"{MOVING_MPS:g} m/s on the usable samples; {', '.join(cands)} cannot be "
                        "identified (they need the speed to vary); calibrate on a log with varying speed")
    res = calibrate_from_stats(st, args.p_enter, args.p_remove)

    check_identified(res, ", ".join(map(str, args.logs)))
    eq = res.to_equation(name, provenance=provenance)
    print(res.summary(physics=False))  # (the physics: apply_physics_gram says, below)
    from sumo_drvpw.fit.physical import apply_physics_gram, constraints_of  # issue #11 §3

    try:
        eq, note = apply_physics_gram(eq, st.gram()[0], st.rho_sum / st.mass_n,
                                      constraints=constraints_of(args.candidates))
    except UserError as e:  # about the data: name them
        raise UserError(f"{where}: {e}") from None
    if note:
        print(note)
        from sumo_drvpw.cli.calibrate import hint_grade_source, log_columns

        hint_grade_source(note, log_columns(args.logs), _measurement(args))
    from sumo_drvpw.cli.calibrate import say_physics

    say_physics(eq, veh, st.rho_sum / st.mass_n if st.mass_n else None)
    return eq, note, res


def calibrate_streamed(args, cands, out: Path, inputs) -> int:
    """`calibrate` (driving power) through the streaming engines; same outputs."""
    from sumo_drvpw.data.measured import resolve_equations
    from sumo_drvpw.data.powertrain import terms_predict_of
    from sumo_drvpw.data.trips import signature_texts
    from sumo_drvpw.fit.stream import CalibrationStats
    from sumo_drvpw.fit.stream_compare import CompareStats
    from sumo_drvpw.model.vehicles import load_vehicle

    veh = load_vehicle(args.vehicle) if args.vehicle else None
    from sumo_drvpw.cli.calibrate import MOVING_MPS, say_battery_power

    st, info = _run(args, partial(CalibrationStats, tuple(cands), moving_mps=MOVING_MPS), veh)
    from sumo_drvpw.cli import note_counts

    if st.mass_n:
        note_counts(st.counts)
    say_battery_power(st.source)
    eq, note, res = fit_road_load(args, st, cands, veh, args.name or out.stem, {
        "logs": st.files, "vehicle": veh.path if veh else None, "power_source": st.source,
        "candidates_spec": args.candidates, "trip_signatures": signature_texts(st.signatures)})
    eq.terms_predict = terms_predict_of(st.source)  # (the P_PTdrv of a power-split: its output)
    from sumo_drvpw.cli.calibrate import declare_measurement

    declare_measurement(eq, _measurement(args))
    lines = [info.line()]

    def report(tmp):
        from sumo_drvpw.cli.calibrate import report_specs
        from sumo_drvpw.report.comparison import write_comparison_report

        specs, skipped = report_specs(veh, args.compare_with)
        eqs = [eq] + [e for e in resolve_equations(specs, veh) if e.name != eq.name]
        cs, info2 = _run(args, partial(CompareStats, eqs, eq.name), veh)
        ctx = _context(st, veh, res.n)
        if skipped:
            ctx["not compared"] = skipped
        ctx["calibration"] = {
            "equation": eq.name, "terms": eq.terms, "std_err": eq.std_err,
            "p_values": eq.p_values, "r2": res.r2, "n": res.n, "selection_trace": res.trace,
            "settings": res.settings, "beta_mass_free": eq.metrics.get("beta_mass_free"),
            "reference_mass_kg": res.reference_mass_kg,
            "dropped_candidates": [f"{d['term']} dropped: {d['reason']}" for d in res.dropped]}
        write_comparison_report(cs.comparison(), tmp,
                                f"Calibration of {eq.name} against classic VSP", ctx)
        lines.append(info2.line() + " (report pass)")

    from sumo_drvpw.cli.calibrate import write_equation

    write_equation(args, eq, out, inputs, report, st.mass_sum / st.mass_n)  # (the log's mean mass)
    for ln in lines:
        print(ln, file=sys.stderr)
    return 0


def compare_streamed(args, tmp: Path, title: str, target: str = "wheel", target_note: str | None = None,
                     in_sample: list[str] | None = None):
    """`compare` through the streaming engines (``target``: driving power, or the energy
    chains' battery or fuel power; ``target_note``: why, in the report's context;
    ``in_sample``: the files' in-sample notes said, to which those of the trips are added,
    printed and in the report's context): writes the report into ``tmp`` and returns the
    comparison (whose ``to_json`` covers every sample)."""
    from sumo_drvpw.data.measured import resolve_equations
    from sumo_drvpw.fit.stream_compare import CompareStats
    from sumo_drvpw.model.vehicles import load_vehicle
    from sumo_drvpw.report.comparison import write_comparison_report

    veh = load_vehicle(args.vehicle) if args.vehicle else None
    eqs = resolve_equations(args.equation, veh)
    cs, info = _run(args, partial(CompareStats, eqs, None, target=target), veh)
    from sumo_drvpw.cli import note_counts

    note_counts(cs.counts)
    if in_sample is not None:
        from sumo_drvpw.cli.compare import in_sample_trips

        more = in_sample_trips(eqs, cs.signatures, args.logs)
        for line in more:
            print("note: " + line)
        in_sample = in_sample + more
    try:
        comp = cs.comparison()
    except UserError as e:  # no usable sample: name the logs
        raise UserError(f"{', '.join(map(str, args.logs))}: {e}") from None
    from sumo_drvpw.data.powertrain import measured_fuel

    from sumo_drvpw.cli import chains_fuel

    comp.measured_fuel = measured_fuel(veh, chains_fuel(args.equation))  # what the log's fuel flow was read as
    ctx = _context(cs, veh, cs.n)
    if target_note:
        ctx["target"] = target_note
    if in_sample:
        ctx["in sample"] = in_sample
    write_comparison_report(comp, tmp, title, ctx)
    print(info.line(), file=sys.stderr)
    return comp


def compare_main(args, in_sample: list[str] | None = None) -> int | None:
    """`compare` through the streaming engines, local or Dask (driving power, or battery or
    fuel power through the equations' chains); None for ``--engine memory`` (read in memory).
    ``in_sample``: the files' in-sample notes (cli/compare.in_sample_lines)."""
    from sumo_drvpw.cli import output_set
    from sumo_drvpw.cli.compare import print_summary

    if getattr(args, "engine", "memory") == "memory":
        return None
    from sumo_drvpw.cli.compare import compare_target

    target, note = compare_target(args)
    what = {"wheel": "driving", "battery": "battery", "fuel": "fuel"}[target]
    with output_set(args, args.out, [args.logs, args.vehicle, args.equation]) as tmp:
        comp = compare_streamed(args, tmp, f"Equations against measured {what} power", target, note,
                                in_sample)
    print_summary(comp.to_json(trips=False), args.out)
    return 0


def calibrate_chain_streamed(args, out: Path, inputs, hvac) -> int:
    """`calibrate --target battery|fuel` through the streaming engines (constant
    efficiencies): the same equation as the in-memory path (fit/chain_stream.py). With
    ``--engine dask`` and no scheduler, one local cluster serves every pass over the logs."""
    if args.engine != "dask" or args.scheduler is not None:
        return _chain_streamed(args, out, inputs, hvac)
    import argparse

    from sumo_drvpw.fit.engine import dask_client

    with dask_client(None, args.workers) as client:
        shared = argparse.Namespace(**{**vars(args), "scheduler": client.scheduler.address, "workers": None})
        return _chain_streamed(shared, out, inputs, hvac)


def _chain_streamed(args, out: Path, inputs, hvac) -> int:
    from sumo_drvpw.cli import note_counts
    from sumo_drvpw.cli.calibrate import MOVING_MPS, declare_measurement
    from sumo_drvpw.data.measured import resolve_equations
    from sumo_drvpw.data.trips import signature_texts
    from sumo_drvpw.fit.chain_checks import check_chain
    from sumo_drvpw.fit.chain_stream import ChainSpec, ChainStats, calibrate_chain_streamed as fit_chain
    from sumo_drvpw.model.vehicles import load_vehicle

    veh = load_vehicle(args.vehicle) if args.vehicle else None
    eq = resolve_equations([args.equation], veh, predicting=False)[0] if args.equation else None
    cands = None
    if eq is None:
        from sumo_drvpw.fit.calibrate import resolve_candidates

        cands = tuple(resolve_candidates(args.candidates))
    fuel = veh.powertrain.get("fuel", "gasoline") if veh is not None else "gasoline"
    from sumo_drvpw.fit.chain import declared_fuel_cut
    from sumo_drvpw.fit.chain_fuel import engine_off_for

    cut = declared_fuel_cut(eq) if args.target == "fuel" else None  # declared: kept
    engine = {}
    if args.target == "fuel":
        from sumo_drvpw.fit.chain_fuel import declared_engine

        engine = declared_engine(eq)  # a moving zero-output fuel fitted, a rated output kept

    spec = ChainSpec(args.target, eq, tuple(args.load), hvac, cands, MOVING_MPS, fuel, cut,
                     engine_off_for(veh, False, getattr(args, "engine_off", "profile")), **engine,  # (battery: at the fit)
                     fixed=getattr(args, "fix_values", None))
    infos = []

    def reduce(make):
        st, info = _run(args, make, veh)
        infos.append(info)
        return st

    # one process: the scan keeps what the battery chain's later passes read (no re-reading)
    st = reduce(partial(ChainStats, spec, keep=args.engine == "local"))
    note_counts(st.counts)
    st.check_inputs()
    if hvac and hvac["column"] not in st.seen:
        raise UserError(f"--hvac {args.hvac}: {st.where} has no column '{hvac['column']}'")
    src = st.measured_input
    if eq is not None:
        road = f"road-load equation {eq.name} ({eq.path or 'built in'})"
    else:
        if src is None:
            if st.wheel_error:  # as in memory: the driving power's own refusal (the CLI adds --equation)
                raise NoDrivingPower(st.wheel_error)
            raise UserError(f"--target {args.target}: {st.where} logs no driving power (power_w, motor "
                            "torque, the power-split signals), only battery V·I, so the road load cannot be "
                            "told apart from the chain's losses; give its road load with --equation (e.g. "
                            "roadload_spec, the vehicle's published A + B·v + C·v², or an equation calibrated "
                            "on logs with a driving power)")
        eq, note, _ = fit_road_load(args, st.road, cands, veh, args.name or out.stem, {
            "logs": st.road.files, "power_source": st.road.source, "candidates_spec": args.candidates,
            "trip_signatures": signature_texts(st.road.signatures)})
        road = f"road-load equation calibrated stepwise on {st.road.source}" + (
            " (physically constrained: the free fit was implausible)" if note else "")
    chain_input = f"driving power of {eq.name}" if src is None else f"measured driving power ({src})"
    fit = fit_chain(reduce, st)
    check_chain(fit, veh, None, None, None, ranges=st.fitted_ranges(), where=st.where, counts=st.counts,
                hvac_trips=st.hvac_trips, measured=src is not None)
    eq.name = args.name or out.stem
    replace_chain(eq, fit.chain)
    eq.chain.provenance = {**fit.chain.provenance, "logs": st.files, "target": st.source, "road_load": road,
                           "chain_input": chain_input, "vehicle": veh.path if veh else None,
                           "trip_signatures": signature_texts(st.signatures),
                           **({"fixed": spec.fixed} if spec.fixed else {})}
    eq.chain.reading = {k: p.get("reading", "") for k, p in fit.parameters.items()}
    declare_measurement(eq, _measurement(args))
    if note := chain_input_note(args.equation, src):
        print(note)
    print(fit.summary())
    for w in fit.warnings:
        print(f"warning: {w}")
    def report(tmp):
        from sumo_drvpw.fit.stream_compare import CompareStats
        from sumo_drvpw.report.comparison import write_comparison_report

        cs = reduce(partial(CompareStats, [eq], None, target=args.target))
        ctx = _context(cs, veh, cs.n)
        ctx["calibration"] = {"equation": eq.name, "chain": fit.parameters, "r2": fit.r2,
                              "n": fit.n, "road_load": road}
        write_comparison_report(cs.comparison(), tmp, f"Energy chain of {eq.name} against measured "
                                f"{args.target} power", ctx)

    from sumo_drvpw.cli.calibrate import write_equation

    # the log's mean mass over its usable rows, with or without a road load fitted on it (as in memory)
    write_equation(args, eq, out, inputs, report, st.mass_sum / st.mass_n if st.mass_n else None)
    for info in infos:
        print(info.line(), file=sys.stderr)
    return 0


def replace_chain(eq, chain) -> None:
    """``eq.chain = chain`` (a calibrated chain on top of road-load equation ``eq``); where
    ``eq``'s own chain was SUMO's MMPEVEM motor (its description names it), says so on the
    console and in the description, which would otherwise claim a motor the file lacks."""
    if getattr(eq.chain, "motor", None) is not None:
        print(f"note: the chain of --equation {eq.path or eq.source or eq.name} was SUMO's MMPEVEM motor "
              "(loss map, limits, battery): the calibrated chain replaces it, its road load stays")
        eq.description = f"road load of: {eq.description}; its MMPEVEM motor replaced by the calibrated chain"
    eq.chain = chain


def chain_input_note(equation: str | None, src: str | None) -> str | None:
    """The line a chain calibration prints when ``--equation`` names a road load but the log
    has a measured driving power ``src``: the chain is fitted on ``src``, and `compare` and
    SUMO runs apply it to the equation's power, so a sensor that reads low or high (LeafSpy's
    Leaf motor torque: its τ·ω about 0.77 of the battery's V·I at cruise) goes into the
    efficiencies and auxiliary power, not into a road load said to be 'off'."""
    if not equation or src is None:
        return None
    return (f"note: the chain is fitted on the log's measured driving power ({src}), not on --equation "
            f"{equation}'s; compare and SUMO runs apply it to {equation}'s power, so where the two differ "
            "its efficiencies and auxiliary power carry the difference (an implausible one may be the "
            "measured power's, not the road load's); to fit the chain on the equation, import the log "
            "without the measured power's columns")
