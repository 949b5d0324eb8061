"""Run the bad-input corpus through the CLI as a user does (one child process per case).

    .venv/bin/python scripts/bad_input_corpus.py [--jobs 2] [--only TEXT] [--json FILE]

Each case of ``tests/corpus.py`` gets an empty temporary folder with its input files; the
child runs ``python -m sumo_drvpw ARGS`` there; the folder is hashed before and after.
Prints, per class, how many cases were refused cleanly (exit 2, one line naming the
culprit, nothing written, inputs unchanged) or accepted cleanly (the few good inputs
among them, e.g. standstill noise), and every other outcome: traceback, warning, accepted
(a bad input let through), refused (a good one refused), input changed, output written,
message (culprit not named / not one line / not exit 2). Exit 1 if any case failed.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from collections import Counter, defaultdict
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO / "tests"))

import corpus  # noqa: E402

GOOD = ("refused cleanly", "accepted cleanly")


def _run_one(c: corpus.Case) -> tuple[str, str, str]:
    with tempfile.TemporaryDirectory(prefix="corpus-") as t:
        d = Path(t)
        mounted = None
        try:
            if c.needs == "shared" and not corpus.SHARED.is_dir():
                return c.id, "skipped", "no shared data"
            if c.needs == "root":
                if os.geteuid() != 0:
                    return c.id, "skipped", "needs root (read-only tmpfs)"
                mounted = d / "ro"
                mounted.mkdir()
                subprocess.run(["mount", "-t", "tmpfs", "-o", "ro,size=64k", "tmpfs", str(mounted)],
                               check=True, capture_output=True)
            outcome, detail = corpus.run_subprocess(c, d, sys.executable)
            return c.id, outcome, detail
        except Exception as e:  # noqa: BLE001 - a broken case is reported, not fatal
            return c.id, "case error", repr(e)[:200]
        finally:
            if mounted is not None:
                subprocess.run(["umount", str(mounted)], check=False, capture_output=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--jobs", type=int, default=2, help="cases run at once (default 2)")
    ap.add_argument("--only", default="", help="run only cases whose class/name contains this")
    ap.add_argument("--json", help="also write the outcomes here")
    a = ap.parse_args(argv)
    cases = [c for c in corpus.CASES if a.only in c.id]
    with ThreadPoolExecutor(max_workers=a.jobs) as ex:
        results = list(ex.map(_run_one, cases))
    per = defaultdict(Counter)
    for c, (cid, outcome, _) in zip(cases, results):
        per[c.cls][outcome] += 1
    outcomes = sorted({o for cnt in per.values() for o in cnt}, key=lambda o: (o not in GOOD, o))
    w = max(len(k) for k in per)
    print(f"{'class':<{w}}  cases  " + "  ".join(outcomes))
    for cls, cnt in per.items():
        print(f"{cls:<{w}}  {sum(cnt.values()):>5}  " + "  ".join(f"{cnt.get(o, 0):>{len(o)}}" for o in outcomes))
    tot = Counter()
    for cnt in per.values():
        tot.update(cnt)
    print(f"{'total':<{w}}  {sum(tot.values()):>5}  " + "  ".join(f"{tot.get(o, 0):>{len(o)}}" for o in outcomes))
    bad = [(cid, o, d) for cid, o, d in results if o not in GOOD and o != "skipped"]
    for cid, o, d in bad:
        print(f"  {o}: {cid}: {d}")
    if a.json:
        Path(a.json).write_text(json.dumps([{"case": cid, "outcome": o, "detail": d}
                                            for cid, o, d in results], indent=1) + "\n")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
