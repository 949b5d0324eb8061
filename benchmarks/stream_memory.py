"""Benchmark: peak memory of the streamed (default) `calibrate`, `compare` and `diagnose` on wide logs.

Logs: (a) the 50 BMW i3 trips of the shared data imported to Parquet
(``sumo-drvpw import bmw-i3-tum DATA --out i3.parquet``: 652,765 rows, 68 columns; left
out when ``--i3`` is absent) and (b) a synthetic wide log: four 30-min trips of the
package's virtual track (``synth_trips``, Prius 3 power-split signals, so a measured
driving power), tiled under new trip ids to ``--rows`` rows, with ``--extra`` float columns
beside them (values of two decimals, as a logger writes them), as a fleet log carries.
Both are made in child processes into a temporary folder deleted afterwards.

Commands, each in a fresh child process (its own peak RSS: ``VmHWM``, see
``chain_memory.py``), ``--engine local`` (the default):
``calibrate LOG --vehicle V --out cal.toml`` (driving power, stepwise),
``compare LOG --vehicle V --equation cal.toml --equation vsp_ldv1999`` (driving power) and,
on the i3 log, ``compare LOG --vehicle bmw_i3 --equation docs/energy-chain/bmw_i3_battery_logged.toml``
(battery target: the chain's inputs are found by name, so every column is read) and
``diagnose LOG --vehicle V [--equation drvpw_prius3] --stream yes`` (the streamed residual
tracer; the Prius logs with the declared drvpw_prius3, the others calibrated on the spot
on the first-look sample); ``--commands`` picks some of them.
This tree's code runs against ``--baseline REV`` (``git archive`` of that commit),
interleaved, ``--repeat`` times; medians are reported with the ratio baseline/this. With
``--narrow ROWS`` a narrow log of that many rows (``benchmarks/scale.py``'s fleet log:
8 columns, power_w and mass_kg, no vehicle) is run too: the time a value-bounded batch
costs where the width did not matter. Every
number of the two equations and of the two report.json files is compared (max. relative
difference; percentiles and counts must be equal).

    .venv/bin/python benchmarks/stream_memory.py --baseline REV [--rows 1e6] [--extra 150] [--narrow 1e7] [--repeat 2] [--commands diagnose]

Last line: ``<log>_<command>_mb=<this> <log>_<command>_ratio=<baseline/this> …``.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from chain_memory import max_rel_diff, numbers, run_once  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
WIDE = r"""
import sys
import numpy as np, pandas as pd, pyarrow as pa, pyarrow.parquet as pq
from sumo_drvpw.synth.effects import synth_trips
rows, extra, out = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
base, _ = synth_trips(n_trips=4, minutes=30.0, seed=3)
base = base.drop(columns=["phase"])   # a text column per row
rng = np.random.default_rng(7)
writer, done, i = None, 0, 0
while done < rows:
    d = base.iloc[:rows - done].copy()
    d["trip_id"] = d["trip_id"] + f"-{i}"
    d = d[d["trip_id"].map(d["trip_id"].value_counts()) > 100]   # no stub of a trip at the cut
    if d.empty:
        break
    x = np.round(rng.normal(20.0, 5.0, (len(d), extra)), 2)
    d = pd.concat([d.reset_index(drop=True),
                   pd.DataFrame(x, columns=[f"sensor_{j:03d}" for j in range(extra)])], axis=1)
    t = pa.Table.from_pandas(d, preserve_index=False)
    writer = writer or pq.ParquetWriter(out, t.schema)
    writer.write_table(t, row_group_size=1_000_000)
    done += len(d)
    i += 1
writer.close()
print(done, len(d.columns))
"""


def make_wide(rows: int, extra: int, path: Path) -> tuple[int, int]:
    r = subprocess.run([sys.executable, "-c", WIDE, str(rows), str(extra), str(path)], cwd=ROOT,
                       capture_output=True, text=True, check=True)
    n, c = r.stdout.split()
    return int(n), int(c)


NARROW = r"""
import sys
from pathlib import Path
sys.path.insert(0, sys.argv[3])
from scale import generate
print(generate(Path(sys.argv[2]), int(float(sys.argv[1])), 10_000_000))
"""


def make_narrow(rows: int, folder: Path) -> int:
    folder.mkdir()
    r = subprocess.run([sys.executable, "-c", NARROW, str(rows), str(folder), str(Path(__file__).parent)],
                       cwd=ROOT, capture_output=True, text=True, check=True)
    return int(r.stdout.split()[-1])


def make_i3(src: Path, path: Path) -> tuple[int, int]:
    subprocess.run([sys.executable, "-m", "sumo_drvpw", "import", "bmw-i3-tum", str(src), "--out", str(path)],
                   cwd=ROOT, capture_output=True, text=True, check=True)
    import pyarrow.parquet as pq

    f = pq.ParquetFile(path)
    return f.metadata.num_rows, len(f.schema_arrow.names)


def json_numbers(x, key: str = "") -> dict:
    """Every number of a JSON document by key path."""
    out = {}
    if isinstance(x, dict):
        for k, v in x.items():
            out.update(json_numbers(v, f"{key}/{k}"))
    elif isinstance(x, list):
        for i, v in enumerate(x):
            out.update(json_numbers(v, f"{key}[{i}]"))
    elif isinstance(x, (int, float)) and not isinstance(x, bool):
        out[key] = float(x)
    return out


def report_numbers(folder: Path) -> dict:
    """Every number of a report.json by key path (the calibrated equation's name made neutral)."""
    doc = json.loads((folder / "report.json").read_text())
    out = json_numbers(doc.get("equations", {})) | json_numbers({"n_samples": doc.get("n_samples")})
    return {re.sub(r"cal_\w+?_\d+", "CAL", k): v for k, v in out.items()}


def trace_numbers(folder: Path) -> dict:
    """Every number of a diagnose trace.json by key path."""
    return json_numbers(json.loads((folder / "trace.json").read_text()))


def exact_parts(a: dict, b: dict) -> int:
    """Counts and percentiles that differ (they must not: same samples, same reservoir)."""
    bad = 0
    for k in a:
        if re.search(r"(/n|_n|samples|median_w|p5_w|p95_w)$", k) and not (
                a[k] == b.get(k) or (math.isnan(a[k]) and math.isnan(b.get(k, 0.0)))):
            bad += 1
    return bad


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--baseline", metavar="REV", required=True, help="git revision of the code to compare with")
    ap.add_argument("--rows", default="1e6", help="rows of the synthetic wide log")
    ap.add_argument("--extra", type=int, default=150, help="extra float columns of the synthetic log")
    ap.add_argument("--i3", default=str(ROOT.parent / "shared" / "data" / "bmw_i3_tum"),
                    help="the TUM i3 trips (left out when absent)")
    ap.add_argument("--narrow", default="0",
                    help="rows of a narrow log (benchmarks/scale.py's, without --vehicle) to time too (0: none)")
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--commands", default="calibrate,compare,compare_battery,diagnose",
                    help="commands to run, comma-separated (default: all)")
    ap.add_argument("--tmp", default=None, help="folder for the temporary logs")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="stream_memory_", dir=args.tmp))
    try:
        base = tmp / "baseline"
        base.mkdir()
        arch = subprocess.run(["git", "-C", str(ROOT), "archive", args.baseline, "sumo_drvpw"],
                              capture_output=True, check=True).stdout
        subprocess.run(["tar", "-x", "-C", str(base)], input=arch, check=True)
        trees = {"baseline": base, "this": ROOT}
        logs = {}
        if Path(args.i3).is_dir():
            logs["i3"] = (tmp / "i3.parquet", "bmw_i3")
            n, c = make_i3(Path(args.i3), logs["i3"][0])
            print(f"i3: {n:,} rows, {c} columns", flush=True)
        logs["wide"] = (tmp / "wide.parquet", "prius3")
        n, c = make_wide(int(float(args.rows)), args.extra, logs["wide"][0])
        print(f"wide: {n:,} rows, {c} columns ({logs['wide'][0].stat().st_size / 1e6:.0f} MB Parquet)", flush=True)
        if float(args.narrow) > 0:
            logs["narrow"] = (tmp / "narrow", None)
            n = make_narrow(int(float(args.narrow)), logs["narrow"][0])
            print(f"narrow: {n:,} rows (benchmarks/scale.py's fleet log, 8 columns)", flush=True)
        battery = ROOT / "docs" / "energy-chain" / "bmw_i3_battery_logged.toml"
        tail = []
        for name, (log, veh) in logs.items():
            cmds = ["calibrate", "compare"] + (["compare_battery"] if name == "i3" and battery.exists() else []) \
                + ["diagnose"]
            cmds = [c for c in cmds if c in args.commands.split(",")]
            if "compare" in cmds and "calibrate" not in cmds:
                cmds.insert(0, "calibrate")  # compare compares the equation it calibrates
            res = {(c, t): [] for c in cmds for t in trees}
            outs = {}
            for r in range(args.repeat):
                for tree_name, tree in trees.items():  # interleaved: the same load for both
                    cal = tmp / f"cal_{tree_name}_{r}.toml"
                    for cmd in cmds:
                        out = tmp / f"{name}_{cmd}_{tree_name}_{r}"
                        car = ["--vehicle", veh] if veh else []
                        if cmd == "calibrate":
                            argv = ["calibrate", str(log), *car, "--out", str(cal)]
                        elif cmd == "diagnose":
                            eq = ["--equation", "drvpw_prius3"] if veh == "prius3" else []
                            argv = ["diagnose", str(log), *car, *eq, "--stream", "yes", "--out", str(out)]
                        elif cmd == "compare":
                            argv = ["compare", str(log), *car, "--equation", str(cal),
                                    "--equation", "vsp_ldv1999", "--out", str(out)]
                        else:
                            argv = ["compare", str(log), *car, "--equation", str(battery),
                                    "--out", str(out)]
                        load = os.getloadavg()[0]
                        mb, wall = run_once(tree, argv)
                        res[cmd, tree_name].append((mb, wall))
                        outs[cmd, tree_name] = cal if cmd == "calibrate" else out
                        print(f"  {name} {cmd:<15} {tree_name:<8} run {r + 1}: peak RSS {mb:,.0f} MB, "
                              f"{wall:.1f} s (load {load:.1f})", flush=True)
            for cmd in cmds:
                med = {t: (statistics.median(x[0] for x in res[cmd, t]),
                           statistics.median(x[1] for x in res[cmd, t])) for t in trees}
                ratio = med["baseline"][0] / med["this"][0]
                if cmd == "calibrate":
                    diff, bad = max_rel_diff(numbers(outs[cmd, "baseline"]), numbers(outs[cmd, "this"])), 0
                elif cmd == "diagnose":
                    a, b = trace_numbers(outs[cmd, "baseline"]), trace_numbers(outs[cmd, "this"])
                    diff, bad = max_rel_diff(a, b), sum(a.get(k) != b.get(k) for k in set(a) ^ set(b))
                else:
                    a, b = report_numbers(outs[cmd, "baseline"]), report_numbers(outs[cmd, "this"])
                    diff = max_rel_diff(a, b)
                    bad = exact_parts(a, b)
                print(f"{name} {cmd}: peak RSS {med['baseline'][0]:,.0f} MB before, {med['this'][0]:,.0f} MB "
                      f"now (ratio {ratio:.2f}); wall {med['baseline'][1]:.1f} / {med['this'][1]:.1f} s; "
                      f"numbers: max. rel. difference {diff:.1e}, counts/percentiles differing: {bad}")
                tail.append(f"{name}_{cmd}_mb={med['this'][0]:.0f} {name}_{cmd}_ratio={ratio:.2f}")
        print(" ".join(tail))
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


if __name__ == "__main__":
    main()
