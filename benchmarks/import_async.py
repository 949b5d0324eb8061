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
import tempfile
import time
from pathlib import Path

from _child import compare, parse, report


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
    report(kind, time.perf_counter() - t0, len(df))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=10.0)
    ap.add_argument("--pids", type=int, default=50)
    a = parse(ap, child, 2)
    if a is None:
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.csv"
        n = write_log(path, a.hours, a.pids)
        print(f"{n} rows, {path.stat().st_size / 1e6:.0f} MB")
        compare(__file__, "read_csv", "import", [str(path)], a.repeats, n)


if __name__ == "__main__":
    main()
