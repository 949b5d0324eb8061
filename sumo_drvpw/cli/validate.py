"""`sumo-drvpw validate`: the validation report on the shared real data."""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.cli import add_force, output_set


def configure(p):
    p.add_argument("--data", default=None, metavar="DIR",
                   help="folder of the shared data (default: $SUMO_DRVPW_DATA, else <repo>/../shared/data)")
    p.add_argument("--out", default="validation-out", metavar="DIR",
                   help="folder for figures and summary.json, written whole or not at all; the "
                        "report is <DIR>.md beside it (default validation-out → validation-out.md; "
                        "the repository's docs are regenerated with --out docs/validation --force --chain)")
    p.add_argument("--chain", action="store_true",
                   help="also the energy-chain study: battery and fuel energy per held-out trip "
                        "beside SUMO's Energy model, MMPEVEM and PHEMlight5 (about 1–2 min more)")
    add_force(p)


def main(args) -> int:
    from sumo_drvpw.validation import report_path, resolve_data, run_validation

    data = resolve_data(args.data)
    if args.chain:
        from sumo_drvpw.validation.chain import FOLDERS

        resolve_data(args.data, FOLDERS)
    out = Path(args.out)
    cmd = (f"sumo-drvpw validate --data {args.data or data} --out {args.out}"
           + (" --chain" if args.chain else ""))
    with output_set(args, out, [data]) as tmp:  # tmp has out's name: links in the report hold
        summary = run_validation(data, tmp, command=cmd, chain=args.chain)
    print(f"wrote {report_path(out)}, {out / 'summary.json'} and "
          f"{len(summary['figures'])} figures in {summary['run']['seconds']:.1f} s")
    return 0
