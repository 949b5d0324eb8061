"""``sumo-drvpw fcd FCD_FILE [--net NET] [--scenario S.toml] --out DIR``: book a finished SUMO
run from its FCD output (XML, .xml.gz, Parquet, CSV, or partitioned Parquet: a folder or a
glob of parts) and write what ``run`` writes. The file is streamed in blocks of rows (memory:
one block and the vehicles running, whatever the file's length). ``--engine dask`` splits the
vehicles into buckets (``--buckets``, default one per worker), one task each on a Dask
cluster (``--scheduler ADDRESS``, else a local cluster of ``--workers N`` processes); the
results are the local engine's summed."""

from __future__ import annotations

import argparse

from sumo_drvpw.cli import (add_cold_start, add_force, check_air_temperature, check_period,
                            cold_start_override, output_set, sumo_time_arg)
from sumo_drvpw.cli._parser import path_arg
from sumo_drvpw.cli._scale import add_engine_arguments, check_engine_arguments


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("fcd", metavar="FCD_FILE", type=path_arg,
                        help="SUMO --fcd-output file (.xml, .xml.gz, .parquet, .csv), or "
                             "partitioned Parquet FCD: a folder or a quoted glob ('fcd/*.parquet'); "
                             "--precision 6 keeps speeds exact")
    parser.add_argument("--out", required=True, metavar="DIR", type=path_arg, help="output directory")
    parser.add_argument("--net", metavar="NET", type=path_arg, help="the network the FCD was recorded on "
                        "(default: the scenario's, else the one the XML FCD's header names)")
    parser.add_argument("--scenario", metavar="S.toml|X.sumocfg", type=path_arg,
                        help="scenario (or the run's SUMO config) for equations, vTypes (masses, "
                             "vClasses) and options")
    parser.add_argument("--vtypes", action="append", metavar="FILE", type=path_arg,
                        help="route/additional file(s) with the vTypes (default: the scenario's, else "
                             "those the XML FCD's header names)")
    parser.add_argument("--equation", action="append", metavar="NAME_OR_FILE", type=path_arg,
                        help="evaluate these equations instead of the scenario's (repeatable; "
                             "default without a scenario: the built-in equations of every vClass)")
    parser.add_argument("--begin", type=sumo_time_arg, help="ignore timesteps before this [s, or h:m:s]")
    parser.add_argument("--end", type=sumo_time_arg, help="stop at this simulation time [s, or h:m:s] (default: the recording's last timestep, whatever end the scenario or its config gives)")
    parser.add_argument("--period", type=float, metavar="S", help="edgeData interval [s]")
    parser.add_argument("--air-temperature", type=float, metavar="C",
                        help="air temperature [°C] of the recorded run, replacing the scenario's [air] "
                             "(as run's option: the cold terms, HVAC, cold starts, warm-engine fuel)")
    add_cold_start(parser, "in the FCD")
    parser.add_argument("--no-figures", action="store_true", help="skip the figures")
    parser.add_argument("--no-progress", action="store_true",
                        help="no progress bar (timesteps replayed, on a terminal)")
    add_engine_arguments(parser, ("local", "dask"),
                         "local: stream the FCD on this machine in bounded memory (default); "
                         "dask: the vehicles split into buckets, one task each on a Dask cluster "
                         "(each task streams the whole file; pip install 'sumo-drvpw[dask]'; the "
                         "workers write into --out: on a cluster of other machines a shared "
                         "filesystem)")
    parser.add_argument("--buckets", type=int, metavar="K",
                        help="--engine dask: vehicle buckets, one task each (default: one per "
                             "worker)")
    add_force(parser)


def main(args: argparse.Namespace) -> int:
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.sim.fcd import process_fcd

    from pathlib import Path

    if not any(c in str(args.fcd) for c in "*?[") and not Path(args.fcd).exists():  # (a glob: said by the reader)
        raise UserError(f"FCD file not found: {args.fcd}")
    if args.scenario is None and (args.net is None or args.vtypes is None):
        _recorded_inputs(args)
    if args.scenario is None and args.net is None:
        from sumo_drvpw.sim.fcd_read import (configs_beside, configs_writing, fcd_parts, header_options,
                                             iter_fcd_blocks)

        next(iter(iter_fcd_blocks(args.fcd)), None)  # a file it cannot read says so first, naming it
        msg = "give --net (the network of the FCD) or --scenario"
        # a header-less FCD (Parquet, CSV): the SUMO configs beside it that may have run it
        if Path(args.fcd).is_file() and not fcd_parts(args.fcd) and header_options(args.fcd) is None:
            writers = [c for c, _, _ in configs_writing(args.fcd)]
            cfgs = [] if writers else configs_beside(args.fcd)

            def names(cs):
                return ", ".join(c.name for c in cs[:3]) + (", …" if len(cs) > 3 else "")
            if len(writers) > 1:
                msg += f"; SUMO configs beside {args.fcd} write it ({names(writers)}): --scenario the one that ran it"
            elif cfgs:
                msg += (f"; no SUMO config beside {args.fcd} writes it ({names(cfgs)}: an --fcd-output on SUMO's "
                        "command line?): " + (f"if it ran it, --scenario {cfgs[0]}" if len(cfgs) == 1
                                              else "if one of them ran it, --scenario it"))
        raise UserError(msg)
    replaced = bool(args.equation)  # the user's equations replace the scenario's
    if args.scenario is None and not args.equation:  # as `run X.sumocfg` does
        from sumo_drvpw.sim.scenario import CONFIG_EQUATIONS

        args.equation = list(CONFIG_EQUATIONS)
        print("note: no --equation or --scenario: every vehicle by the built-in equations made for its "
              "vClass (" + ("vClasses from the route and additional files" if args.vtypes
                            else "no vType file: every vehicle a passenger car; --vtypes gives the "
                                 "run's route files") + ")")
    check_engine_arguments(args)
    if args.buckets is not None and args.engine != "dask":
        raise UserError(f"--buckets goes with --engine dask (got --engine {args.engine})")
    if args.buckets is not None and args.buckets < 1:
        raise UserError(f"--buckets must be at least 1, got {args.buckets}")
    if args.end is not None:  # as `run` refuses an empty time window
        if args.begin is not None and args.end <= args.begin:
            raise UserError(f"--end {args.end:g} must be after --begin {args.begin:g}")
        if args.begin is None and args.end <= 0:
            raise UserError(f"--end {args.end:g} must be after the start of the run (0; for "
                            "FCD recorded from an earlier time give --begin)")
    overrides = {}
    if args.end is not None:
        overrides["end"] = args.end
    check_period(args.period)
    if args.period is not None:
        overrides["period"] = args.period
    check_air_temperature(args.air_temperature)
    if args.air_temperature is not None:
        overrides["air_temperature_c"] = args.air_temperature
    if args.no_figures:
        overrides["figures"] = False
    if args.no_progress:
        overrides["progress"] = False
    cold_start_override(args, overrides)
    meta: dict = {}
    # the recording's own route files: the replay finds them again, and records those gone
    vtypes = None if getattr(args, "vtypes_recorded", False) else args.vtypes
    with output_set(args, args.out, [args.fcd, args.net, args.scenario, args.vtypes], meta=meta) as tmp:
        if args.engine == "dask":
            from sumo_drvpw.sim.fcd_dask import process_fcd_dask

            res = process_fcd_dask(args.fcd, tmp, net=args.net, scenario=args.scenario,
                                   equations=args.equation, vtype_files=vtypes,
                                   begin_s=args.begin, buckets=args.buckets,
                                   scheduler=args.scheduler, workers=args.workers, **overrides)
        else:
            res = process_fcd(args.fcd, net=args.net, scenario=args.scenario, out_dir=tmp,
                              equations=args.equation, vtype_files=vtypes,
                              begin_s=args.begin, **overrides)
        meta["interrupted"] = bool(res.summary.get("interrupted"))
    from sumo_drvpw.cli.run import _print_summary

    _print_summary(res.summary, args.out, replaced=replaced)
    if meta["interrupted"]:  # as run: the replayed part is written, marked interrupted
        print("interrupted: outputs cover the replayed part")
        return 130
    return 0


def _recorded_inputs(args: argparse.Namespace) -> None:
    """Without --scenario: the network (unless --net) and the route and additional files
    (unless --vtypes) of the run that recorded the FCD, as its header names them
    (:func:`sumo_drvpw.sim.fcd_read.run_inputs`: else the one SUMO config beside it that
    writes it), each said in a note; a route or additional file found nowhere in a note with
    the options that give it (the replay warns of it, in summary.json too: its vTypes are
    unknown)."""
    from sumo_drvpw.sim.fcd_read import run_inputs

    rec = run_inputs(args.fcd)
    if rec is None:
        return
    how, src = "from the run that recorded the FCD (its header)", "the FCD's header"
    if "config" in rec:  # no header: the SUMO config beside it that writes it
        how, src = f"from the SUMO config that writes the FCD ({rec['config']})", f"the config {rec['config'].name}"
    want = {"net-file": args.net is None, "route-files": args.vtypes is None,
            "additional-files": args.vtypes is None}
    took = []
    if args.net is None and rec["net"] is not None:
        args.net = str(rec["net"])
        took.append(f"network {rec['net']}")
    if args.vtypes is None and rec["files"]:
        args.vtypes = [str(f) for f in rec["files"]]
        args.vtypes_recorded = True
        took.append("vTypes and stops from " + ", ".join(str(f) for f in rec["files"]))
    if took:
        print(f"note: {how}: " + "; ".join(took)
              + " (--net, --vtypes or --scenario choose others)")
    missing = [v for k, v in rec["missing"] if want[k]]
    if missing:  # (without a network refused next, in one line: "give --net"; else warned at the end)
        print(f"note: {src} names {', '.join(missing)}, not found beside the FCD "
              f"(looked in {', '.join(str(p) for p in rec['looked_in'])}); give --vtypes (and --net) for its vTypes")
