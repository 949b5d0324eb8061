"""``sumo-drvpw fcd FCD_FILE --net NET [--scenario S.toml] --out DIR``: book a finished SUMO
run from its FCD output (XML, .xml.gz, Parquet, CSV, or partitioned Parquet: a folder or a
glob of parts) and write what ``run`` writes. The replay holds the FCD columns in memory
(the ledger only the vehicles present); it runs on this machine (no ``--engine``)."""

from __future__ import annotations

import argparse

from sumo_drvpw.cli import add_force, output_set


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("fcd", metavar="FCD_FILE",
                        help="SUMO --fcd-output file (.xml, .xml.gz, .parquet, .csv), or "
                             "partitioned Parquet FCD: a folder or a quoted glob ('fcd/*.parquet'); "
                             "--precision 6 keeps speeds exact")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--net", metavar="NET", help="the network the FCD was recorded on "
                        "(default: the scenario's)")
    parser.add_argument("--scenario", metavar="S.toml",
                        help="scenario for equations, vTypes (masses, vClasses) and options")
    parser.add_argument("--vtypes", action="append", metavar="FILE",
                        help="route/additional file(s) with the vTypes (default: the scenario's)")
    parser.add_argument("--equation", action="append", metavar="NAME_OR_FILE",
                        help="evaluate these equations instead of the scenario's (repeatable)")
    parser.add_argument("--begin", type=float, help="ignore timesteps before this [s]")
    parser.add_argument("--end", type=float, help="stop at this simulation time [s]")
    parser.add_argument("--period", type=float, metavar="S", help="edgeData interval [s]")
    parser.add_argument("--no-figures", action="store_true", help="skip the figures")
    add_force(parser)


def main(args: argparse.Namespace) -> int:
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.sim.fcd import process_fcd

    if args.scenario is None and args.net is None:
        raise UserError("give --net (the network of the FCD) or --scenario")
    if args.scenario is None and not args.equation:
        raise UserError("give --equation NAME (repeatable) or --scenario")
    overrides = {}
    if args.end is not None:
        overrides["end"] = args.end
    if args.period is not None:
        overrides["period"] = args.period
    if args.no_figures:
        overrides["figures"] = False
    with output_set(args, args.out, [args.fcd, args.net, args.scenario, args.vtypes]) as tmp:
        res = process_fcd(args.fcd, net=args.net, scenario=args.scenario, out_dir=tmp,
                          equations=args.equation, vtype_files=args.vtypes,
                          begin_s=args.begin, **overrides)
    from sumo_drvpw.cli.run import _print_summary

    _print_summary(res.summary, args.out)
    return 0
