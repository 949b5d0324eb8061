"""``sumo-drvpw run SCENARIO... --out DIR``: apply equations to every vehicle of SUMO runs.

One scenario: its outputs in DIR. Several (``run a.toml b.toml --jobs 2``): one SUMO per
process, each scenario's outputs in ``DIR/<scenario name>/`` and all of them side by side in
``DIR/runs.csv`` (per scenario, equation and road class: traction energy [kWh] and
energy per distance [Wh/km], the vehicles the equation booked and those of the scenario), and,
with energy-chain equations, their litres and kWh per vClass in ``DIR/chain_runs.csv``. ``--engine dask`` runs each scenario as one task on a Dask
cluster (``--scheduler ADDRESS``, else a local cluster of ``--workers N`` processes). A scenario is a TOML file or a built-in name (``city``,
``highway``: ``sumo_drvpw/sim/builtin/scenarios``).
"""

from __future__ import annotations

import argparse
import math
import sys

from sumo_drvpw.cli import (add_cold_start, add_force, check_air_temperature, check_period,
                            cold_start_override, output_set, sumo_time_arg)
from sumo_drvpw.cli._scale import add_engine_arguments, check_engine_arguments
from sumo_drvpw.errors import UserError


def configure(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", nargs="+",
                        help="scenario TOML file(s), SUMO config(s) as they are (X.sumocfg: every vehicle by "
                             "the built-in equations made for its vClass), or built-in name(s) (docs/scenario.md)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument("--jobs", type=int, default=1, metavar="N",
                        help="run up to N scenarios at once, one SUMO process each (default 1)")
    parser.add_argument("--begin", type=sumo_time_arg, help="override sumo.begin [s, or h:m:s]")
    parser.add_argument("--end", type=sumo_time_arg, help="override sumo.end [s, or h:m:s]")
    parser.add_argument("--equation", action="append", metavar="NAME_OR_FILE",
                        help="evaluate these equations instead of the scenario's (repeatable; "
                             "vtype_energy: each Energy/… vType by its own SUMO Energy-model parameters)")
    parser.add_argument("--traci", action="store_true",
                        help="use traci instead of libsumo (slower; allows --gui)")
    parser.add_argument("--gui", action="store_true", help="watch in sumo-gui (implies --traci)")
    parser.add_argument("--trace", action="store_true",
                        help="also write trace.parquet (per vehicle-step power per term)")
    parser.add_argument("--period", type=float, metavar="S",
                        help="edgeData interval [s] (default: the scenario's, else the whole run)")
    parser.add_argument("--air-temperature", type=float, metavar="C",
                        help="air temperature [°C], replacing the scenario's [air] (ρ from it at the "
                             "scenario's pressure, else 101.325 kPa); the equations' cold terms and "
                             "the energy chains' HVAC, cold starts and warm-engine fuel read it")
    add_cold_start(parser, "during the run")
    parser.add_argument("--no-figures", action="store_true", help="skip the figures")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")
    add_engine_arguments(parser, ("local", "dask"),
                         "local: this machine, --jobs processes (default); dask: one task per "
                         "scenario, one SUMO per task, on a Dask cluster (pip install "
                         "'sumo-drvpw[dask]'; the workers write into --out: on a cluster of "
                         "other machines a shared filesystem)")
    add_force(parser)


def _overrides(args) -> dict:
    o = {}
    for key in ("begin", "end", "period"):
        if getattr(args, key) is not None:
            o[key] = getattr(args, key)
    if args.end is not None and not (args.end > (args.begin if args.begin is not None else 0.0)):
        raise UserError(f"--end {args.end:g} must be after " + (f"--begin {args.begin:g}" if args.begin is not None
                                                               else "the start (0 s)"))
    check_period(args.period)
    t = getattr(args, "air_temperature", None)
    check_air_temperature(t)
    if t is not None:
        o["air_temperature_c"] = t
    cold_start_override(args, o)
    if args.equation:
        o["equations"] = args.equation
    if args.traci or args.gui:
        o["connection"] = "traci"
    if args.gui:
        o["gui"] = True
    if args.trace:
        o["trace"] = True
    if args.no_figures:
        o["figures"] = False
    if args.no_progress or len(args.scenario) > 1:
        o["progress"] = False
    return o


def _run_one(scenario: str, out: str, overrides: dict) -> dict:
    """One scenario in this process; returns its summary (picklable for --jobs)."""
    from sumo_drvpw.sim import run_scenario
    from sumo_drvpw.sim.scenario_paths import scenario_path

    return run_scenario(scenario_path(scenario), out, **overrides).summary


def _run_many(args, scen: list[str], outs: list, overrides: dict) -> list[dict]:
    from sumo_drvpw.sim.run import run_scenarios

    return run_scenarios(scen, outs, overrides, engine=args.engine, jobs=args.jobs,
                         scheduler=args.scheduler, workers=args.workers)


def _print_summary(s: dict, out, label: str = "", replaced: bool = False) -> None:
    """``replaced``: --equation replaced the scenario's equations (a vClass then unbooked
    had one in the scenario or among a bare config's class equations)."""
    for w in s.get("warnings", []):
        print(f"warning: {label}{w}", file=sys.stderr)
    print(f"{label}{s['steps']} steps, {s['vehicles']} vehicles, "
          f"{s['slope_corrected_samples']} slope-corrected samples; outputs in {out}")
    skipped = dict(s.get("skipped", {}).get("by_vclass", {}))
    persons = skipped.pop("pedestrian", 0)
    if skipped:
        hint = ""
        if replaced:
            from sumo_drvpw.sim.resolver import builtin_equations_for

            made = {c: builtin_equations_for(c) for c in skipped}
            hint = (" — with --equation only the equations given are applied: repeat it with one made for"
                    " these vClasses" + (" (built-in: " + "; ".join(
                        f"{c}: {', '.join(m)}" for c, m in made.items() if m) + ")"
                        if any(made.values()) else ""))
        print("  not booked (no equation for the vClass): "
              + ", ".join(f"{c} {n}" for c, n in skipped.items()) + hint)
    if persons:
        print(f"  persons (walking or riding; never booked themselves): {persons}")
    idle = []
    for name, eq in s["equations"].items():
        if not any(d > 0 for d in eq.get("distance_m", {}).values()) and eq.get("vclasses"):
            idle.append(name)  # made for classes no vehicle of this run had
            continue
        parts = ", ".join(f"{c} {d['total'] / 3.6e6:.3f} kWh" for c, d in eq["energy_j"].items()
                          if d["total"] > 0)
        also = {"wheel": "", "powertrain_output": " (at the powertrain output)",
                "battery": "; its battery energy per class below", "fuel": "; its fuel per class below"}
        print(f"  {name}: traction of its terms {parts or '0'}{also.get(eq.get('predicts', 'wheel'), '')}")
    # a vtype_energy equation books its own vType only: idle when no vehicle of it ran
    unused = [n[len("vtype_energy."):] for n in idle if n.startswith("vtype_energy.")]
    idle = [n for n in idle if not n.startswith("vtype_energy.")]
    if idle:
        print(f"  booked no vehicle (none of their vClasses, or of their fuel): {', '.join(idle)}")
    if unused:
        print(f"  vtype_energy: no vehicle of vType {', '.join(unused)} ran")
    tp = s.get("teleports") or {}
    if tp.get("count"):  # SUMO put cars back on a lane at speed: energy apart from driving
        print(f"  teleports: {tp['count']} vehicles put back on a lane (not driven, not in the energies "
              "above): " + (", ".join(f"{n} kinetic {tp['kinetic_j'][n] / 3.6e6:+.3f} kWh, potential "
                                     f"{tp['potential_j'][n] / 3.6e6:+.3f} kWh" for n in tp["kinetic_j"]
                                     if n not in idle and max(abs(tp['kinetic_j'][n]), abs(tp['potential_j'][n])) >= 1800.0)
                            or "under 0.0005 kWh for every equation"))  # (those booking none of them: not listed)
    # a vType's own Energy-model equation books vehicles another battery chain books too
    also = ((s.get("assumptions") or {}).get("vtype_energy") or {}).get("also_booked_by", {})
    for r in (s.get("chain") or {}).get("classes", []):  # battery kWh or fuel L per class
        if not r.get("distance_km"):
            continue
        if "fuel_l" in r:
            cold = f" (cold starts {r['cold_start_l']:.2f} L)" if "cold_start_l" in r else ""
            # the distance beside the per-km figure: a class that barely moved (a shuttle
            # idling at its stop) reads 1,000 L/100 km, which is true but not a consumption
            print(f"  {r['equation']} fuel, {r['key']}: {r['fuel_l']:.2f} L{cold} over "
                  f"{_km(r['distance_km'])} km, {r['fuel_l_per_100km']:.2f} L/100 km, "
                  f"CO₂ {r['co2_kg']:.1f} kg"
                  # a plug-in hybrid's battery, spent before its fuel (model/chain_plugin.py)
                  + (f"; battery net {r['net_kwh']:.2f} kWh ({r['net_kwh_per_km']:.3f} kWh/km)"
                     if isinstance(r.get("net_kwh"), (int, float)) and math.isfinite(r["net_kwh"]) else ""))
        else:
            print(f"  {r['equation']} battery, {r['key']}: net {r['net_kwh']:.2f} kWh over "
                  f"{_km(r['distance_km'])} km ({r['net_kwh_per_km']:.3f} kWh/km; auxiliary "
                  f"{r['auxiliary_kwh']:.2f} kWh)"
                  + (f" — its vType's own parameters, for vehicles {' and '.join(also[r['equation']])} books "
                     "too: an alternative, not more vehicles" if also.get(r["equation"]) else ""))


def _km(km: float) -> str:
    """A distance for the console: 32,912 not 3.29e+04; 3 significant digits below 100 km."""
    return f"{km:,.0f}" if km >= 100 else f"{km:.3g}"


def _names(scenarios: list[str]) -> list[str]:
    from pathlib import Path

    out, used = [], {}
    for s in scenarios:
        stem = Path(s).stem if s.endswith((".toml", ".sumocfg")) else s
        used[stem] = used.get(stem, 0) + 1
        out.append(stem if used[stem] == 1 else f"{stem}_{used[stem]}")
    return out


def _equation_vehicles(out_dir) -> dict[str, int]:
    """Vehicles each equation booked in one scenario's outputs (its rows of vehicles.parquet)."""
    import pyarrow.parquet as pq

    path = out_dir / "vehicles.parquet"
    if not path.is_file():
        return {}
    counts = pq.read_table(path, columns=["equation"]).column("equation").value_counts()
    return {str(c["values"]): int(c["counts"]) for c in counts.to_pylist()}


def _combined(summaries: dict[str, dict], out_dirs: dict):
    """One row per scenario × equation × road class: traction energy and Wh/km; ``vehicles``
    the vehicles the equation booked in that scenario (on any road class), and
    ``scenario_vehicles`` all the scenario accounted."""
    import pandas as pd

    rows = []
    for scen, s in summaries.items():
        booked = _equation_vehicles(out_dirs[scen])
        for eq, d in s["equations"].items():
            for cls, e in d["energy_j"].items():
                m = d.get("distance_m", {}).get(cls, 0.0)
                rows.append({"scenario": scen, "equation": eq, "predicts": d.get("predicts"),
                             "class": cls, "vehicles": booked.get(eq, 0),
                             "scenario_vehicles": s["vehicles"],
                             "traction_kwh": e["total"] / 3.6e6,
                             "recuperable_kwh": d["recuperable_energy_j"][cls]["total"] / 3.6e6,
                             "distance_km": m / 1000.0,
                             "traction_whpkm": e["total"] / m / 3.6 if m > 0 else float("nan")})
    return pd.DataFrame(rows)


def _combined_chains(summaries: dict[str, dict]):
    """Each run's energy-chain rows per vClass (its ``chain_classes.csv``: litres, CO2 and
    L/100 km, or battery kWh and kWh/km) under a ``scenario`` column; None when no run
    had a chain equation."""
    import pandas as pd

    rows = [{"scenario": scen, **r} for scen, s in summaries.items()
            for r in (s.get("chain") or {}).get("classes", [])]
    return pd.DataFrame(rows) if rows else None


def main(args: argparse.Namespace) -> int:
    from pathlib import Path

    from sumo_drvpw.errors import UserError
    from sumo_drvpw.fileio import write_text

    if args.jobs < 1:
        raise UserError(f"--jobs must be ≥ 1, got {args.jobs}")
    check_engine_arguments(args)
    dask = args.engine == "dask"
    if dask and args.jobs != 1:
        raise UserError("--jobs goes with --engine local; with --engine dask the cluster's "
                        "workers (--workers N) run the scenarios")
    if dask and args.gui:
        raise UserError("--gui watches a run on this machine (not with --engine dask)")
    overrides = _overrides(args)
    scen = list(args.scenario)
    inputs = [s for s in scen if Path(s).exists()]
    meta: dict = {}
    if len(scen) == 1:
        with output_set(args, args.out, inputs, meta=meta) as tmp:
            s = _run_many(args, scen, [tmp], overrides)[0] if dask else \
                _run_one(scen[0], str(tmp), overrides)
            meta["interrupted"] = bool(s.get("interrupted"))
        _print_summary(s, args.out, replaced=bool(args.equation))
        if s.get("interrupted"):
            print("interrupted: outputs cover the simulated part")
            return 130
        return 0
    if args.gui:
        raise UserError("--gui watches one scenario at a time")
    names = _names(scen)
    with output_set(args, args.out, inputs, meta=meta) as tmp:
        summaries = dict(zip(names, _run_many(args, scen, [tmp / n for n in names], overrides)))
        write_text(tmp / "runs.csv", _combined(summaries, {n: tmp / n for n in names}).to_csv(index=False))
        chains = _combined_chains(summaries)
        if chains is not None:  # the chains' litres and kWh per vClass, run beside run
            write_text(tmp / "chain_runs.csv", chains.to_csv(index=False))
        meta["scenarios"] = dict(zip(names, scen))
        meta["interrupted"] = any(s.get("interrupted") for s in summaries.values())
    for n, s in summaries.items():
        _print_summary(s, Path(args.out) / n, f"[{n}] ", replaced=bool(args.equation))
    print(f"all runs side by side: {Path(args.out) / 'runs.csv'}"
          + (f"; their litres and kWh per vClass: {Path(args.out) / 'chain_runs.csv'}" if chains is not None else ""))
    if meta["interrupted"]:  # one after the other: the sweep ended in the interrupted scenario
        left = [n for n in names if n not in summaries]
        print(f"interrupted: outputs cover the simulated part of [{list(summaries)[-1]}]"
              + (f"; not run: {', '.join(left)}" if left else ""))
        return 130
    return 0
