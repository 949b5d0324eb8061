"""Time and peak memory of `import car-scanner` on a long-layout OBD-app log, against
pandas reading the same file (the baseline, measured in the same run).

Usage: .venv/bin/python benchmarks/import_async.py [--hours 10] [--pids 50] [--repeats 3]

Data: a Car Scanner long-layout CSV written here (``"SECONDS";"PID";"VALUE";"UNITS";
"LATITUDE";"LONGTITUDE"``), ``--pids`` values polled in turn every 26 ms — about 138,000
rows an hour, the rate of a real export of about 50 PIDs — one of them the vehicle speed.
Each repeat runs in a fresh process, which reports its own peak RSS (``VmHWM``): the
import (``sumo_drvpw.data.adapters.read``) and, as baseline, ``pandas.read_csv`` of the
same file with the same separator (no conversion). Last line:
``time_ratio=<import / read_csv, medians> rss_ratio=<import / read_csv, medians> rows=<N>``
(target: time ≤ 3, memory ≤ 3: putting the channels onto the speed samples costs about
what reading the file costs). Not part of the test suite.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


def write_log(path: Path, hours: float, pids: int) -> int:
    import numpy as np

    n = int(hours * 3600 / 0.026)
    t = 40000.0 + np.arange(n) * 0.026
    k = np.arange(n) % pids
    names = np.array([f"PID {i}" for i in range(pids - 1)] + ["Vehicle speed"])
    units = np.where(k == pids - 1, "km/h", "V")
    val = (np.arange(n) % 1000) / 20.0
    with open(path, "w", encoding="utf-8") as f:
        f.write('"SECONDS";"PID";"VALUE";"UNITS";"LATITUDE";"LONGTITUDE";\n')
        for i in range(0, n, 100_000):
            s = slice(i, i + 100_000)
            f.writelines(f'"{a:.3f}";"{b}";"{c:.2f}";"{d}";"49.1";"18.7";\n'
                         for a, b, c, d in zip(t[s], names[k[s]], val[s], units[s]))
    return n


def child(kind: str, path: str) -> None:
    t0 = time.perf_counter()
    if kind == "import":
        from sumo_drvpw.data.adapters import read

        df, _ = read("car-scanner", path)
    else:
        import pandas as pd

        df = pd.read_csv(path, sep=";")
    took = time.perf_counter() - t0
    rss = 0.0
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            rss = int(line.split()[1]) / 1024.0
    print(json.dumps({"kind": kind, "s": took, "rss_mb": rss, "rows": len(df)}))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=10.0)
    ap.add_argument("--pids", type=int, default=50)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        child(*a.child)
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.csv"
        n = write_log(path, a.hours, a.pids)
        print(f"{n} rows, {path.stat().st_size / 1e6:.0f} MB")
        res = {"import": [], "read_csv": []}
        for _ in range(a.repeats):
            for kind in ("read_csv", "import"):  # interleaved: the same load for both
                r = subprocess.run([sys.executable, __file__, "--child", kind, str(path)],
                                   capture_output=True, text=True, check=True)
                res[kind].append(json.loads(r.stdout.strip().splitlines()[-1]))
        med = {k: (statistics.median(x["s"] for x in v), statistics.median(x["rss_mb"] for x in v))
               for k, v in res.items()}
        for k, (s, m) in med.items():
            print(f"{k}: {s:.2f} s, peak RSS {m:.0f} MB (medians of {a.repeats})")
        print(f"time_ratio={med['import'][0] / med['read_csv'][0]:.2f} "
              f"rss_ratio={med['import'][1] / med['read_csv'][1]:.2f} rows={n}")


if __name__ == "__main__":
    main()
