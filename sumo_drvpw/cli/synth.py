"""`sumo-drvpw synth`: a synthetic 8 Hz Prius3-like test-track log with declared truth.

``--plant`` adds effects the declared equation lacks (for testing ``diagnose``), and
``--trips`` writes several trips (seeds seed … seed+N−1) into one log.
"""

from __future__ import annotations

from sumo_drvpw.errors import UserError

#: --plant names: the one table of planted effects (sumo_drvpw.synth.effects.PLANTS), without
#: log-power, which the synthetic log needs no plant for — its keys written out so that the
#: command line does not import the synthesizer to build its help (0.4 s);
#: tests/test_synth.py keeps the two equal
PLANT_NAMES = ("ac", "cold-tyres", "speed-quadratic", "trip-mass", "distractors", "pedal", "power-lag",
               "recuperation-efficiency", "recuperation-limit", "altitude-air", "attenuated-grade",
               "battery-standstill-aux")


def configure(p):
    p.add_argument("--out", required=True, help="output log (.parquet, or .csv plus .truth.json)")
    p.add_argument("--minutes", type=float, default=15.0, help="duration of each trip [min] (default 15)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--trips", type=int, default=1, help="number of trips (default 1)")
    p.add_argument("--truth", default="drvpw_prius3", help="truth equation, name or file (default drvpw_prius3)")
    p.add_argument("--vehicle", default="prius3", help="vehicle (power-split) name or file (default prius3)")
    p.add_argument("--plant", default="", metavar="EFFECT,...",
                   help=f"undeclared effects to plant: {', '.join(PLANT_NAMES)} (comma list)")


#: the longest synthetic drive one command writes [min] (a week: 4.8 M samples at 8 Hz,
#: about a GB in memory while generated) and the most trips
MAX_MINUTES, MAX_TRIPS = 7 * 24 * 60, 10_000
MIN_MINUTES = 0.005  # 2 samples at 8 Hz: fewer than a derivative needs crashed


def main(args) -> int:
    from sumo_drvpw.synth.track import SynthOptions, synthesize, write_synth

    if not MIN_MINUTES <= args.minutes <= MAX_MINUTES:
        raise UserError(f"--minutes must be from {MIN_MINUTES:g} to {MAX_MINUTES:g} (a week of driving per trip), "
                        f"got {args.minutes}")
    if args.seed < 0:
        raise UserError(f"--seed must be ≥ 0, got {args.seed}")
    if not 1 <= args.trips <= MAX_TRIPS:
        raise UserError(f"--trips must be from 1 to {MAX_TRIPS}, got {args.trips}")
    if args.minutes * args.trips > MAX_MINUTES:
        raise UserError(f"--minutes × --trips must be at most {MAX_MINUTES:g} minutes of driving (8 Hz: "
                        f"{MAX_MINUTES * 480:,.0f} samples), got {args.minutes * args.trips:g}")
    if not str(args.out).lower().endswith((".parquet", ".csv")):
        raise UserError(f"--out {args.out}: give a .parquet or .csv file name")
    names = [s.strip() for s in args.plant.split(",") if s.strip()]
    bad = [s for s in names if s not in PLANT_NAMES]
    if bad:
        raise UserError(f"--plant: unknown effect {bad[0]!r} (known: {', '.join(PLANT_NAMES)})")
    from sumo_drvpw.cli import existing_paths
    from sumo_drvpw.fileio import check_output_path

    inputs = existing_paths(args.truth, args.vehicle)
    check_output_path(args.out, inputs, "file")
    if str(args.out).lower().endswith(".csv"):
        from pathlib import Path

        check_output_path(Path(args.out).with_suffix(".truth.json"), inputs, "file")
    _check_power_split(args.vehicle)
    from sumo_drvpw.synth.effects import PLANTS

    effects = tuple(PLANTS[s]() for s in names)
    kw = dict(minutes=args.minutes, truth=args.truth, vehicle=args.vehicle)
    if args.trips == 1:
        df, truth = synthesize(SynthOptions(seed=args.seed, **kw), effects=effects)
    else:
        from sumo_drvpw.synth.effects import synth_trips

        df, truths = synth_trips(args.trips, seed=args.seed, effects=effects, **kw)
        truth = dict(truths[0], trips=[{"trip_id": f"synth-{i + 1}", "seed": t["seed"]}
                                       for i, t in enumerate(truths)])
    write_synth(df, truth, args.out)
    print(f"wrote {args.out}: {len(df)} samples, {args.trips} trip(s) × {args.minutes:g} min at 8 Hz, "
          f"truth {truth['equation']}" + (f", planted: {', '.join(names)}" if names else ""))
    return 0


#: vehicle-file keys the synthetic power-split signals need (``[powertrain]``)
POWER_SPLIT_KEYS = ("sun_teeth", "ring_teeth", "final_drive", "wheel_radius_m")


def _check_power_split(spec) -> None:
    """The vehicle must be a power-split hybrid with the gear data the synthesizer uses."""
    from sumo_drvpw.model.vehicles import load_vehicle

    veh = load_vehicle(spec)
    where = veh.path or spec
    if veh.powertrain_type != "power_split":
        raise UserError(f"--vehicle {spec} ({where}): synth writes power-split (THS) signals and needs "
                        f"a [powertrain] type = \"power_split\" vehicle, got {veh.powertrain_type!r} "
                        "(e.g. prius3, prius2)")
    missing = [k for k in POWER_SPLIT_KEYS if k not in veh.powertrain]
    if missing:
        raise UserError(f"--vehicle {spec} ({where}): [powertrain] lacks {', '.join(missing)}, "
                        "needed for the synthetic power-split signals")
