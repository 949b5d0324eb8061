"""``sumo-drvpw run SCENARIO.toml --out DIR``: apply equations to every vehicle of a SUMO run."""

from __future__ import annotations

import argparse
import sys


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", help="scenario TOML file (see sumo_drvpw.sim.scenario)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--begin", type=float, help="override sumo.begin [s]")
    parser.add_argument("--end", type=float, help="override sumo.end [s]")
    parser.add_argument("--equation", action="append", metavar="NAME_OR_FILE",
                        help="evaluate these equations instead of the scenario's (repeatable)")
    parser.add_argument("--traci", action="store_true",
                        help="use traci instead of libsumo (slower; allows --gui)")
    parser.add_argument("--gui", action="store_true", help="watch in sumo-gui (implies --traci)")
    parser.add_argument("--trace", action="store_true",
                        help="also write trace.parquet (per vehicle-step power per term)")
    parser.add_argument("--no-figures", action="store_true", help="skip the figures")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def main(args: argparse.Namespace) -> int:
    from sumo_drvpw.sim import run_scenario

    overrides = {}
    if args.begin is not None:
        overrides["begin"] = args.begin
    if args.end is not None:
        overrides["end"] = args.end
    if args.equation:
        overrides["equations"] = args.equation
    if args.traci or args.gui:
        overrides["connection"] = "traci"
    if args.gui:
        overrides["gui"] = True
    if args.trace:
        overrides["trace"] = True
    if args.no_figures:
        overrides["figures"] = False
    if args.no_progress:
        overrides["progress"] = False
    s = run_scenario(args.scenario, args.out, **overrides)
    for w in s.get("warnings", []):
        print(f"warning: {w}", file=sys.stderr)
    print(f"{s['steps']} steps, {s['vehicles']} vehicles, {s['slope_corrected_samples']} "
          f"slope-corrected samples; outputs in {args.out}")
    for name, eq in s["equations"].items():
        parts = ", ".join(f"{c} {d['total'] / 3.6e6:.3f} kWh" for c, d in eq["energy_j"].items()
                          if d["total"] > 0)
        print(f"  {name}: traction {parts or '0'}")
    if s.get("interrupted"):
        print("interrupted: outputs cover the simulated part")
        return 130
    return 0
