"""`sumo-drvpw synth`: a synthetic 8 Hz Prius3-like test-track log with declared truth."""

from __future__ import annotations

from ..errors import UserError


def configure(p):
    p.add_argument("--out", required=True, help="output log (.parquet, or .csv plus .truth.json)")
    p.add_argument("--minutes", type=float, default=15.0, help="log duration [min] (default 15)")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--truth", default="drvpw_prius3", help="truth equation, name or file (default drvpw_prius3)")
    p.add_argument("--vehicle", default="prius3", help="vehicle (power-split) name or file (default prius3)")


def main(args) -> int:
    from ..synth import SynthOptions, synthesize, write_synth

    if not args.minutes > 0:
        raise UserError(f"--minutes must be > 0, got {args.minutes}")
    if not str(args.out).lower().endswith((".parquet", ".csv")):
        raise UserError(f"--out {args.out}: give a .parquet or .csv file name")
    df, truth = synthesize(SynthOptions(minutes=args.minutes, seed=args.seed, truth=args.truth,
                                        vehicle=args.vehicle))
    write_synth(df, truth, args.out)
    print(f"wrote {args.out}: {len(df)} samples, {args.minutes:g} min at 8 Hz, truth {truth['equation']}")
    return 0
