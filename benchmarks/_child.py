"""What the import benchmarks share: each measurement in a fresh process that reports its
own time and peak RSS, the candidate and its baseline interleaved (the same machine load
for both), medians and their ratio."""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path


def report(kind: str, seconds: float, rows: int) -> None:
    """A child's last line: its kind, time, rows and peak RSS (``VmHWM``, MB)."""
    rss = 0.0
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            rss = int(line.split()[1]) / 1024.0
    print(json.dumps({"kind": kind, "s": seconds, "rss_mb": rss, "rows": rows}))


def parse(ap: argparse.ArgumentParser, child, nargs: int):
    """The benchmark's arguments plus ``--repeats`` and the hidden ``--child KIND ARG…``
    that :func:`compare` passes (``nargs`` values); called as a child, run ``child(*those)``
    and return None, else return the arguments."""
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--child", nargs=nargs, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        child(*a.child)
        return None
    return a


def compare(script: str, baseline: str, candidate: str, args: list[str], repeats: int, rows: int) -> None:
    """Run ``script --child KIND *args`` for the baseline and the candidate in turn,
    ``repeats`` times; print the medians and ``time_ratio=… rss_ratio=… rows=…``."""
    res = {candidate: [], baseline: []}
    for _ in range(repeats):
        for kind in (baseline, candidate):  # interleaved: the same load for both
            r = subprocess.run([sys.executable, script, "--child", kind, *args],
                               capture_output=True, text=True, check=True)
            res[kind].append(json.loads(r.stdout.strip().splitlines()[-1]))
    if len({x["rows"] for v in res.values() for x in v}) != 1:
        print(f"row counts differ: { {k: v[0]['rows'] for k, v in res.items()} }")
    med = {k: (statistics.median(x["s"] for x in v), statistics.median(x["rss_mb"] for x in v))
           for k, v in res.items()}
    for k, (s, m) in med.items():
        print(f"{k}: {s:.2f} s, peak RSS {m:.0f} MB (medians of {repeats})")
    print(f"time_ratio={med[candidate][0] / med[baseline][0]:.2f} "
          f"rss_ratio={med[candidate][1] / med[baseline][1]:.2f} rows={rows}")
