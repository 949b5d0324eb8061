"""An energy chain's efficiency table (model/chain_values.Table) evaluated as a run's chain
evaluates it every step: this checkout's call against a fresh scipy interpolator per call
(the table's evaluation before it kept its interpolator), interleaved, medians of
``--repeats`` rounds of ``--calls`` calls on ``--vehicles`` vehicles, and their ratio. Results
must be bit-identical (checked). Not part of the test suite.

    .venv/bin/python benchmarks/chain_tables.py --repeats 5
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np


def fresh(table, v, p):
    """The table's value as it was computed before: an interpolator built per call."""
    from scipy.interpolate import RegularGridInterpolator

    axes, pts = [], []
    if table.speed_mps is not None:
        axes.append(table.speed_mps)
        pts.append(np.clip(np.asarray(v, float), table.speed_mps[0], table.speed_mps[-1]))
    if table.power_w is not None:
        axes.append(table.power_w)
        pts.append(np.clip(np.abs(np.asarray(p, float)), table.power_w[0], table.power_w[-1]))
    f = RegularGridInterpolator(tuple(axes), table.values, method="linear")
    return f(np.stack(np.broadcast_arrays(*pts), axis=-1))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--vehicles", type=int, default=5)
    a = ap.parse_args(argv)
    from sumo_drvpw.model.chain_values import Table

    rng = np.random.default_rng(1)
    table = Table(rng.uniform(0.7, 0.95, (6, 9)), np.linspace(0, 40, 6), np.linspace(0, 8e4, 9))
    v, p = rng.uniform(0, 45, a.vehicles), rng.normal(0, 3e4, a.vehicles)
    assert np.array_equal(table(v, p), fresh(table, v, p))
    times: dict[str, list[float]] = {"fresh": [], "table": []}
    for _ in range(a.repeats):
        for name, f in (("fresh", lambda: fresh(table, v, p)), ("table", lambda: table(v, p))):
            t = time.perf_counter()
            for _ in range(a.calls):
                f()
            times[name].append((time.perf_counter() - t) / a.calls * 1e6)
    med = {k: statistics.median(x) for k, x in times.items()}
    for k, x in times.items():
        print(f"{k:6s} median {med[k]:.1f} µs per call {[round(t, 1) for t in x]}")
    print(f"table_ratio={med['table'] / med['fresh']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
