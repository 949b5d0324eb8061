"""Benchmark: peak memory per row of `calibrate --target battery` (the chain fit, in memory).

Data: a synthetic Prius 3 battery log made with the package's synth module
(``synth_trips`` with the ``BatteryLog`` effect: power-split signals, so the log has a
measured driving power, and battery V·I from a known chain), four 30-min trips at 8 Hz
tiled under new trip ids to ``--sizes`` rows, one Parquet file each, in a temporary
folder deleted afterwards (made in a child process, so this process stays small).

Each size runs ``calibrate LOG --vehicle prius3 --target battery --equation EQ --out …``
(``--equation ''``: the road load calibrated stepwise first) in a fresh child process,
the code of this tree (``--engine memory``: the in-memory chain fit, the default engine's
before the chain fit was streamed) against the code of ``--baseline REV`` (``git archive``
of that commit into a temporary folder), interleaved, ``--repeat`` times each. The child reports
its own peak RSS (``VmHWM`` of /proc/self/status, the high-water mark of the process's
own memory, not carried over from this one) and wall time; medians are reported, with
the peak RSS per row and the ratio baseline/this. The equations both write are compared
(max. relative difference of every number of the [chain] and [terms] tables).

``--streamed`` runs this tree's code twice instead, ``--engine memory`` (the chain fitted
on the arrays kept in memory) against ``--engine local`` (streamed batch by batch,
fit/chain_stream.py), and reports the ratio memory/local of their peak RSS and the
difference of the two equations (with ``--baseline``, the old code runs beside them).

``--compare`` also runs ``compare LOG --equation <the chain just fitted>`` with this tree's
code, ``--engine local`` (streamed: memory flat in rows) against ``--engine memory``.

    .venv/bin/python benchmarks/chain_memory.py --baseline REV [--sizes 1e6,3e6] [--repeat 3] [--compare]
    .venv/bin/python benchmarks/chain_memory.py --streamed [--sizes 1e6,3e6] [--repeat 2]

Last line: ``bytes_per_row_<size>=<this> ratio_<size>=<baseline/this> …`` (``--streamed``:
``bytes_per_row_<size>=<local> streamed_ratio_<size>=<memory/local>``).
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
#: the child: run the CLI of the package found first on sys.path (the cwd), then print its
#: own high-water mark of resident memory
CHILD = r"""
import sys, time
t0 = time.perf_counter()
import sumo_drvpw
from sumo_drvpw.cli import main
rc = main(sys.argv[1:])
hwm = [l for l in open('/proc/self/status') if l.startswith('VmHWM')][0].split()[1]
print(f'CHILD rc={rc} hwm_kb={hwm} wall_s={time.perf_counter() - t0:.3f} pkg={sumo_drvpw.__file__}',
      file=sys.stderr)
"""
MAKE = r"""
import sys
import numpy as np, pandas as pd
from sumo_drvpw.synth.effects import BatteryLog, synth_trips
rows, out = int(sys.argv[1]), sys.argv[2]
base, _ = synth_trips(n_trips=4, minutes=30.0, seed=3, effects=[BatteryLog()])
base = base.drop(columns=["phase"])   # a text column per row: not what the chain reads
k = -(-rows // len(base))
parts = []
for i in range(k):
    d = base.copy()
    d["trip_id"] = d["trip_id"] + f"-{i}"
    parts.append(d)
df = pd.concat(parts, ignore_index=True).iloc[:rows]
df = df[df["trip_id"].map(df["trip_id"].value_counts()) > 100]   # no stub of a trip at the cut
df.to_parquet(out, row_group_size=1_000_000)
print(len(df), len(df.columns))
"""


def make_log(rows: int, path: Path) -> tuple[int, int]:
    r = subprocess.run([sys.executable, "-c", MAKE, str(rows), str(path)], cwd=ROOT,
                       capture_output=True, text=True, check=True)
    n, c = r.stdout.split()
    return int(n), int(c)


def run_once(tree: Path, argv: list[str]) -> tuple[float, float]:
    """(peak RSS [MB], wall [s]) of the CLI run by the package in ``tree``."""
    r = subprocess.run([sys.executable, "-c", CHILD, *argv], cwd=tree, capture_output=True, text=True)
    line = [ln for ln in r.stderr.splitlines() if ln.startswith("CHILD ")]
    if r.returncode != 0 or not line or "rc=0" not in line[-1]:
        raise SystemExit(f"{tree}: sumo-drvpw {' '.join(argv)} failed:\n{r.stderr[-3000:]}")
    kv = dict(x.split("=", 1) for x in line[-1].split()[1:])
    if not Path(kv["pkg"]).resolve().is_relative_to(tree.resolve()):  # the tree's code ran
        raise SystemExit(f"{tree}: the child imported {kv['pkg']}, not this tree's package")
    return int(kv["hwm_kb"]) / 1024.0, float(kv["wall_s"])


def numbers(path: Path) -> dict:
    """Every number of an equation file's [terms] and [chain] tables, by key path."""
    doc = tomllib.loads(path.read_text())
    out = {}

    def walk(x, key):
        if isinstance(x, dict):
            for k, v in x.items():
                if k not in ("provenance", "reading"):
                    walk(v, f"{key}/{k}")
        elif isinstance(x, list):
            for i, v in enumerate(x):
                walk(v, f"{key}[{i}]")
        elif isinstance(x, (int, float)) and not isinstance(x, bool):
            out[key] = float(x)

    walk({"terms": doc.get("terms", {}), "chain": doc.get("chain", {})}, "")
    return out


def max_rel_diff(a: dict, b: dict) -> float:
    if set(a) != set(b):
        return math.inf
    worst = 0.0
    for k in a:
        x, y = a[k], b[k]
        if x == y or (math.isnan(x) and math.isnan(y)):
            continue
        worst = max(worst, abs(x - y) / max(abs(x), abs(y)))
    return worst


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="1e6,3e6", help="rows per log, comma-separated")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--baseline", metavar="REV", help="git revision of the code to compare with")
    ap.add_argument("--equation", default="drvpw_prius3",
                    help="road-load equation under the chain ('': calibrated stepwise first)")
    ap.add_argument("--tmp", default=None, help="folder for the temporary logs")
    ap.add_argument("--streamed", action="store_true",
                    help="this tree with --engine memory against --engine local (streamed)")
    ap.add_argument("--compare", action="store_true",
                    help="also compare the fitted chain on the log, --engine local against memory")
    args = ap.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    tmp = Path(tempfile.mkdtemp(prefix="chain_memory_", dir=args.tmp))
    trees = {"this": ROOT}
    engines = {"this": ["--engine", "memory"]}  # extra arguments per run (the baseline's: none)
    if args.streamed:
        trees = {"memory": ROOT, "local": ROOT}
        engines = {"memory": ["--engine", "memory"], "local": ["--engine", "local"]}
    try:
        if args.baseline:
            base = tmp / "baseline"
            base.mkdir()
            arch = subprocess.run(["git", "-C", str(ROOT), "archive", args.baseline, "sumo_drvpw"],
                                  capture_output=True, check=True).stdout
            subprocess.run(["tar", "-x", "-C", str(base)], input=arch, check=True)
            trees = {"baseline": base, **trees}
            engines["baseline"] = []
        tail = []
        for rows in sizes:
            log = tmp / f"battery_{rows}.parquet"
            n, ncol = make_log(rows, log)
            print(f"{n:,} rows, {ncol} columns ({log.stat().st_size / 1e6:.0f} MB Parquet)", flush=True)
            res = {k: [] for k in trees}
            outs = {}
            for r in range(args.repeat):
                for name, tree in trees.items():  # interleaved: the same load for both
                    out = tmp / f"{name}_{rows}_{r}.toml"
                    argv = ["calibrate", str(log), "--vehicle", "prius3", "--target", "battery",
                            "--out", str(out)] + (["--equation", args.equation] if args.equation else [])
                    argv += engines[name]
                    load = os.getloadavg()[0]
                    mb, wall = run_once(tree, argv)
                    res[name].append((mb, wall))
                    outs[name] = out
                    print(f"  {name:<8} run {r + 1}: peak RSS {mb:,.0f} MB, {wall:.1f} s (load {load:.1f})",
                          flush=True)
            med = {k: (statistics.median(x[0] for x in v), statistics.median(x[1] for x in v))
                   for k, v in res.items()}
            for k, (mb, wall) in med.items():
                print(f"  {k:<8} median: peak RSS {mb:,.0f} MB = {mb * 2**20 / n:,.0f} B/row, {wall:.1f} s")
            this = "local" if args.streamed else "this"
            tail.append(f"bytes_per_row_{rows:.0e}={med[this][0] * 2**20 / n:.0f}")
            if args.streamed:
                ratio = med["memory"][0] / med["local"][0]
                diff = max_rel_diff(numbers(outs["memory"]), numbers(outs["local"]))
                print(f"  peak RSS memory/local (streamed) = {ratio:.2f}; equations: max. rel. difference {diff:.1e}")
                tail.append(f"streamed_ratio_{rows:.0e}={ratio:.2f} streamed_diff_{rows:.0e}={diff:.1e}")
            if "baseline" in med:
                ratio = med["baseline"][0] / med[this][0]
                diff = max_rel_diff(numbers(outs["baseline"]), numbers(outs[this]))
                print(f"  peak RSS baseline/this = {ratio:.2f}; equations: max. rel. difference {diff:.1e}")
                tail.append(f"ratio_{rows:.0e}={ratio:.2f}")
            if args.compare:
                cmp = {"local": [], "memory": []}
                for r in range(args.repeat):
                    for eng in cmp:
                        argv = ["compare", str(log), "--vehicle", "prius3", "--equation",
                                str(outs["local" if args.streamed else "this"]),
                                "--out", str(tmp / f"cmp_{eng}_{rows}_{r}"), "--engine", eng]
                        load = os.getloadavg()[0]
                        mb, wall = run_once(ROOT, argv)
                        cmp[eng].append(mb)
                        print(f"  compare --engine {eng:<6} run {r + 1}: peak RSS {mb:,.0f} MB, {wall:.1f} s "
                              f"(load {load:.1f})", flush=True)
                for eng, v in cmp.items():
                    print(f"  compare --engine {eng:<6} median: peak RSS {statistics.median(v):,.0f} MB")
                    tail.append(f"compare_{eng}_mb_{rows:.0e}={statistics.median(v):.0f}")
            log.unlink()
        print(" ".join(tail))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
