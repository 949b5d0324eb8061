"""Generate docs/closing-the-loop.md: the loop closed on real data, proven on held-out trips.

    .venv/bin/python scripts/closing_the_loop.py --data ../shared/data --out docs

The study — how the trips are split, what is fitted and chosen on the training trips only,
how the held-out trips are scored — is :mod:`sumo_drvpw.validation.closing_the_loop` (its
docstring is the method; the grade choices GRADE_CHOICES and SELECTION_ENERGIES in
``closing_the_loop_fit``). This command takes the options, runs the study (each run's tracer
report and closed-loop equation under ``<out>/closing-the-loop/``) and writes the Markdown
``<out>/closing-the-loop.md`` (scripts/closing_the_loop_report.py).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

CMD = ".venv/bin/python scripts/closing_the_loop.py --data ../shared/data --out docs"


def command_line(argv) -> str:
    """The command this run was started with, as the report's header shows it (the
    documented regeneration, CMD, when it was that one)."""
    import shlex

    return ".venv/bin/python scripts/closing_the_loop.py" + ("".join(" " + shlex.quote(a) for a in argv))


def main(argv=None) -> int:
    """Run the loop and write the report; bad input (a data folder an adapter refuses) is one
    line on stderr, exit 2, nothing written."""
    from sumo_drvpw.errors import UserError

    try:
        return _main(sys.argv[1:] if argv is None else list(argv))
    except UserError as e:
        print(f"closing_the_loop.py: error: {e}", file=sys.stderr)
        return 2


def _main(argv) -> int:
    from sumo_drvpw.validation import closing_the_loop as study
    from sumo_drvpw.validation import closing_the_loop_fit as fits

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get(
        "SUMO_DRVPW_DATA", str(Path(__file__).resolve().parents[2] / "shared" / "data")))
    ap.add_argument("--out", default="docs")
    ap.add_argument("--only", default="", help="comma list of i3, prius2, jlu (default: all)")
    ap.add_argument("--grade-choice", choices=fits.GRADE_CHOICES, default=fits.GRADE_CHOICE,
                    help="how the grade source and the physical candidates are chosen (see GRADE_CHOICES)")
    ap.add_argument("--selection-energy", choices=fits.SELECTION_ENERGIES, default=fits.SELECTION_ENERGY,
                    help="the per-trip energy whose error chooses the structure (see SELECTION_ENERGIES)")
    a = ap.parse_args(argv)
    from sumo_drvpw.fileio import write_text

    data, out = Path(a.data), Path(a.out)
    only = {s.strip() for s in a.only.split(",") if s.strip()}
    t0 = time.perf_counter()
    cars = study.run(data, out / "closing-the-loop", only, a.grade_choice, a.selection_energy)
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from closing_the_loop_report import render

    shared = Path(__file__).resolve().parents[2] / "shared" / "data"
    other = None if data.resolve() == shared.resolve() else str(data)
    write_text(out / "closing-the-loop.md", render(cars, time.perf_counter() - t0, command_line(argv),
                                                   other_data=other))
    print(f"wrote {out / 'closing-the-loop.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
