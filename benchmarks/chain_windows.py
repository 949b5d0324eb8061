"""Time of a fuel chain's windows for the ATTENUATED check's three lengths (10, 30, 60 s;
fit/chain_windows.py): the splits found once per trip and chopped per length (``trip_runs`` then
``chop``, as ``windowed_lines`` and ``window_designs`` do), against the baseline measured in the
same run, ``window_ids`` called once per length (each finding the splits again, as before
2026-11-30). Both give the same windows (checked).

Usage: .venv/bin/python benchmarks/chain_windows.py [--trips 200] [--minutes 25] [--repeats 7]

Data: random driving power, speed, fuel and usability at 1 Hz in trips of ``--minutes``. Last
line: ``time_ratio=<once / per length, medians> samples=<N>``. Not part of the test suite.
"""

from __future__ import annotations

import argparse
import statistics
import time


def main() -> None:
    import numpy as np

    from sumo_drvpw.fit.chain_windows import DILUTION_WINDOWS_S, chop, trip_runs, window_ids

    ap = argparse.ArgumentParser()
    ap.add_argument("--trips", type=int, default=200)
    ap.add_argument("--minutes", type=float, default=25.0)
    ap.add_argument("--repeats", type=int, default=7)
    a = ap.parse_args()
    rng = np.random.default_rng(0)
    trip = np.repeat(np.arange(a.trips), int(a.minutes * 60))
    n = trip.size
    p, v = rng.normal(2e3, 2e4, n), np.where(rng.random(n) < 0.1, 0.0, 15.0)
    fuel, ok = np.where(rng.random(n) < 0.1, 0.0, 5e4), rng.random(n) > 0.01

    def per_length():
        return [window_ids(p, v, fuel, 1.0, ok, trip, ws) for ws in DILUTION_WINDOWS_S]

    def once():
        runs = trip_runs(p, v, fuel, 1.0, ok, trip)
        return [chop(runs, ws) for ws in DILUTION_WINDOWS_S]

    assert all(np.array_equal(x, y) for x, y in zip(per_length(), once()))
    base, new = [], []
    for _ in range(a.repeats):
        t0 = time.perf_counter()
        per_length()
        base.append(time.perf_counter() - t0)
        t0 = time.perf_counter()
        once()
        new.append(time.perf_counter() - t0)
    mb, mn = statistics.median(base), statistics.median(new)
    print(f"per length {mb * 1e3:.1f} ms, once {mn * 1e3:.1f} ms (medians of {a.repeats})")
    print(f"time_ratio={mn / mb:.3f} samples={n}")


if __name__ == "__main__":
    main()
