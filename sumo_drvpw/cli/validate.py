"""`sumo-drvpw validate`: the validation report on the shared real data."""

from __future__ import annotations

from pathlib import Path


def configure(p):
    p.add_argument("--data", default=None, metavar="DIR",
                   help="folder of the shared data (default: $SUMO_DRVPW_DATA, else <repo>/../shared/data)")
    p.add_argument("--out", default="docs/validation", metavar="DIR",
                   help="folder for figures and summary.json; the report is <DIR>.md beside it "
                        "(default docs/validation → docs/validation.md)")


def main(args) -> int:
    from sumo_drvpw.validation.study import report_path, resolve_data, run_validation

    data = resolve_data(args.data)
    out = Path(args.out)
    cmd = f"sumo-drvpw validate --data {args.data or data} --out {args.out}"
    summary = run_validation(data, out, command=cmd)
    print(f"wrote {report_path(out)}, {out / 'summary.json'} and "
          f"{len(summary['figures'])} figures in {summary['run']['seconds']:.1f} s")
    return 0
