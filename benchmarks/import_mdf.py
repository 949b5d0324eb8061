"""Time and peak memory of `import columns` on an ASAM MDF 4 logger file, against asammdf
putting the same channels onto the speed's time base itself (the baseline, same run).

Usage: .venv/bin/python benchmarks/import_mdf.py [--hours 10] [--channels 12] [--repeats 3]

Data: an MF4 written here: the speed at 10 Hz (km/h) and ``--channels`` other channels,
each in its own channel group as loggers write them — measured values (float) at 10, 20,
50 and 100 Hz in turn, every fourth an integer state at 2 Hz. Each repeat runs in a fresh
process, which reports its own peak RSS (``VmHWM``): the import
(``sumo_drvpw.data.adapters.read("columns", …)`` with a mapping naming every channel) and,
as baseline, ``asammdf.MDF(path).to_dataframe(channels=…, raster="VehSpd")`` (asammdf's own
resampling onto the speed channel's time stamps, no unit conversion, no checks). Last line:
``time_ratio=<import / to_dataframe, medians> rss_ratio=<…> rows=<speed samples>``
(target: time ≤ 2, memory ≤ 2). Not part of the test suite.
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

RATES_HZ = (10.0, 20.0, 50.0, 100.0)


def names(channels: int) -> list[str]:
    return [f"Ch{i:02d}" for i in range(channels)]


def write_mf4(path: Path, hours: float, channels: int) -> int:
    import numpy as np
    from asammdf import MDF, Signal

    span = hours * 3600.0
    mdf = MDF(version="4.10")
    ts = np.arange(0.0, span, 0.1)
    mdf.append([Signal(36.0 + 18.0 * np.sin(0.01 * ts), ts, name="VehSpd", unit="km/h")])
    for i, name in enumerate(names(channels)):
        if i % 4 == 3:
            t = np.arange(0.0, span, 0.5)
            mdf.append([Signal((np.arange(len(t)) // 40 % 6).astype(np.int8), t, name=name, unit="")])
        else:
            t = np.arange(0.0, span, 1.0 / RATES_HZ[i % 4]) + 0.001 * i
            mdf.append([Signal(np.sin(0.003 * t * (i + 1)) * 100.0, t, name=name, unit="A")])
    mdf.save(path, overwrite=True)
    mdf.close()
    return len(ts)


def child(kind: str, path: str, channels: int) -> None:
    t0 = time.perf_counter()
    if kind == "import":
        from sumo_drvpw.data.adapters import read

        mapping = Path(path).with_suffix(".toml")
        df, _ = read("columns", path, mapping)
    else:
        from asammdf import MDF

        with MDF(path) as mdf:
            df = mdf.to_dataframe(channels=["VehSpd", *names(channels)], raster="VehSpd")
    took = time.perf_counter() - t0
    rss = 0.0
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            rss = int(line.split()[1]) / 1024.0
    print(json.dumps({"kind": kind, "s": took, "rss_mb": rss, "rows": len(df)}))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=10.0)
    ap.add_argument("--channels", type=int, default=12)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        child(a.child[0], a.child[1], int(a.child[2]))
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.mf4"
        n = write_mf4(path, a.hours, a.channels)
        path.with_suffix(".toml").write_text(
            '[columns.VehSpd]\nname = "speed_mps"\n'
            + "".join(f'[columns.{c}]\nname = "{c.lower()}"\n' for c in names(a.channels)))
        print(f"{n} speed samples, {a.channels} other channels, {path.stat().st_size / 1e6:.0f} MB")
        res = {"import": [], "to_dataframe": []}
        for _ in range(a.repeats):
            for kind in ("to_dataframe", "import"):  # interleaved: the same load for both
                r = subprocess.run([sys.executable, __file__, "--child", kind, str(path), str(a.channels)],
                                   capture_output=True, text=True, check=True)
                res[kind].append(json.loads(r.stdout.strip().splitlines()[-1]))
        if len({x["rows"] for v in res.values() for x in v}) != 1:
            print(f"row counts differ: { {k: v[0]['rows'] for k, v in res.items()} }")
        med = {k: (statistics.median(x["s"] for x in v), statistics.median(x["rss_mb"] for x in v))
               for k, v in res.items()}
        for k, (s, m) in med.items():
            print(f"{k}: {s:.2f} s, peak RSS {m:.0f} MB (medians of {a.repeats})")
        print(f"time_ratio={med['import'][0] / med['to_dataframe'][0]:.2f} "
              f"rss_ratio={med['import'][1] / med['to_dataframe'][1]:.2f} rows={n}")


if __name__ == "__main__":
    main()
