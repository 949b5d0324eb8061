"""The built-in combination truck's chain against two measured class-8 trucks: what explains its
per-trip error (docs/hdv-fuel.md, 'What explains the per-trip error').

    .venv/bin/python scripts/hdv_measured.py FEAD/VT-Dataset [--report docs/hdv-fuel.md]

FEAD/VT-Dataset: the folder holding ``veh002_all.csv`` and ``veh003_all.csv`` of
github.com/Torreskai0722/FEAD (no licence stated: read where they lie, never copied into the
repository). The study is ``sumo_drvpw/validation/hdv_measured.py`` (about 30 s, one
process); its result goes into the report's JSON under ``measured.explained`` and the report
is rendered again from that JSON (its other sections are not recomputed). Without
``--report`` the result is printed as JSON and nothing is written.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("folder", type=Path, help="the folder of veh002_all.csv and veh003_all.csv")
    ap.add_argument("--report", type=Path, help="the report to update (its JSON beside it: docs/hdv-fuel.json)")
    args = ap.parse_args(argv)
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.fileio import plain, write_json, write_text
    from sumo_drvpw.validation.hdv_fuel_report import render
    from sumo_drvpw.validation.hdv_measured import study

    t0 = time.perf_counter()
    try:
        js = args.report.with_suffix(".json") if args.report else None
        res = json.loads(js.read_text(encoding="utf-8")) if js else None
        if js and not (res or {}).get("measured"):
            raise UserError(f"{js}: no 'measured' section to explain (the comparison's table is made first)")
        out = study(args.folder)
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    except (OSError, ValueError) as e:
        print(f"error: {args.report}: {e}", file=sys.stderr)
        return 2
    out["command"] = "python scripts/hdv_measured.py FEAD/VT-Dataset" + (f" --report {args.report}" if args.report else "")
    out["seconds"] = round(time.perf_counter() - t0)
    if not args.report:
        print(json.dumps(plain(out), indent=1, ensure_ascii=False))
        return 0
    res["measured"]["explained"] = out
    write_json(js, plain(res))
    write_text(args.report, render(plain(res)))
    print(f"wrote {args.report} and {js} ({out['seconds']} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
