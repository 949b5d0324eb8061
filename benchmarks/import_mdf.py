"""Time and peak memory of `import columns` on an ASAM MDF 4 logger file, against asammdf
putting the same channels onto the speed's time base itself (the baseline, same run).

Usage: .venv/bin/python benchmarks/import_mdf.py [--hours 10] [--channels 12] [--repeats 3]

Data: an MF4 written here: the speed at 10 Hz (km/h) and ``--channels`` other channels,
each in its own channel group as loggers write them — measured values (float) at 10, 20,
50 and 100 Hz in turn (those faster than the speed averaged over each speed interval by the
import, interpolated by the baseline), every fourth an integer state at 2 Hz. Each repeat runs in a fresh
process, which reports its own peak RSS (``VmHWM``): the import
(``sumo_drvpw.data.adapters.read("columns", …)`` with a mapping naming every channel) and,
as baseline, ``asammdf.MDF(path).to_dataframe(channels=…, raster="VehSpd")`` (asammdf's own
resampling onto the speed channel's time stamps, no unit conversion, no checks). Last line:
``time_ratio=<import / to_dataframe, medians> rss_ratio=<…> rows=<speed samples>``
(target: time ≤ 2, memory ≤ 2). Not part of the test suite.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from _child import compare, parse, report

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


def child(kind: str, path: str, channels: str) -> None:
    channels = int(channels)
    t0 = time.perf_counter()
    if kind == "import":
        from sumo_drvpw.data.adapters import read

        mapping = Path(path).with_suffix(".toml")
        df, _ = read("columns", path, mapping)
    else:
        from asammdf import MDF

        with MDF(path) as mdf:
            df = mdf.to_dataframe(channels=["VehSpd", *names(channels)], raster="VehSpd")
    report(kind, time.perf_counter() - t0, len(df))


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=10.0)
    ap.add_argument("--channels", type=int, default=12)
    a = parse(ap, child, 3)
    if a is None:
        return
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "log.mf4"
        n = write_mf4(path, a.hours, a.channels)
        path.with_suffix(".toml").write_text(
            '[columns.VehSpd]\nname = "speed_mps"\n'
            + "".join(f'[columns.{c}]\nname = "{c.lower()}"\n' for c in names(a.channels)))
        print(f"{n} speed samples, {a.channels} other channels, {path.stat().st_size / 1e6:.0f} MB")
        compare(__file__, "to_dataframe", "import", [str(path), str(a.channels)], a.repeats, n)

if __name__ == "__main__":
    main()
