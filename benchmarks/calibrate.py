"""Benchmark: stepwise calibration of 10 million samples (target ≤ 20 s, ≤ 2 GB peak RSS).

Builds 10 M samples in memory (speed, acceleration, grade, wind, mass, density and a
measured power whose truth is Table 3 Indt var. 1 plus noise), then times
``calibrate()`` — the chunked sufficient statistics, forward–backward selection and the
final statsmodels OLS — over the Indt var. 2 candidates (eight terms), repeated and
reported as the median. Peak RSS is the whole process's (data included).

    .venv/bin/python benchmarks/calibrate.py [--samples N] [--repeat R]

Final line: ``samples_per_s=<number> peak_rss_mb=<number>``.
"""

import argparse
import resource
import statistics
import time

import numpy as np

from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
from sumo_drvpw.model.equations import load_equation
from sumo_drvpw.model.terms import Inputs


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--samples", type=int, default=10_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--candidates", default="indt-var-2")
    args = ap.parse_args()
    n = args.samples
    rng = np.random.default_rng(0)
    # mass and density constant, as DriveLog.inputs() gives them for a log without a
    # mass column (read-only broadcast views, no memory)
    x = Inputs(v=rng.uniform(0, 45, n), a=rng.normal(0, 1, n), theta=rng.normal(0, 0.03, n),
               wind=rng.normal(0, 2, n), mass=np.broadcast_to(1625.0, (n,)), rho=np.broadcast_to(1.2, (n,)))
    truth = load_equation("drvpw_prius3")
    y = np.empty(n)
    for lo in range(0, n, 1_000_000):  # chunked so the data's own temporaries stay small
        sl = slice(lo, min(lo + 1_000_000, n))
        y[sl] = truth.power(x.take(sl)) + rng.normal(0, 1500, sl.stop - sl.start)
    data_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    times = []
    res = None
    for _ in range(args.repeat):
        res = None  # one calibration's memory at a time: the last result (its data) let go
        t0 = time.perf_counter()
        res = calibrate(x, y, CANDIDATES[args.candidates])
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"candidates={args.candidates} selected={','.join(res.terms)} r2={res.r2:.4f}")
    print(f"runs_s={','.join(f'{t:.2f}' for t in times)} median_s={med:.2f} (target <= 20 s)")
    print(f"peak_rss_mb={peak_mb:.0f} (target <= 2048; of which the in-memory data {data_mb:.0f})")
    print(f"samples_per_s={n / med:.0f} peak_rss_mb={peak_mb:.0f}")


if __name__ == "__main__":
    main()
