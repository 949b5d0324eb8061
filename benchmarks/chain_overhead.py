"""Per-step cost of the energy chain's accounts against the road-load ledger's, in-process.

Usage: .venv/bin/python benchmarks/chain_overhead.py [--vehicles 1000 5000] [--steps 200]
       [--repeats 5]

For N vehicles on 2000 edges and two equations (one battery chain with a recuperation
limit, one fuel chain), random speeds, accelerations and edges per step, it times:

- ``ledger``: ``EquationSet.category_powers`` + ``Ledger.book`` (what the SUMO loop does
  per step without chains);
- ``ledger+chain``: the same plus ``ChainLedger.book`` (what it does with chains).

Prints the median of ``--repeats`` runs of ``--steps`` steps per variant, and the final
line ``chain_overhead_ratio=<(ledger+chain)/ledger at the largest N>``. No SUMO involved:
the ratio is the chain's share of the plug-in's own arithmetic (SUMO's stepping, which
dominates a real run, comes on top of both). Not part of the test suite.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.model.equations import equation_from_dict, load_equation
from sumo_drvpw.model.terms import Inputs
from sumo_drvpw.sim.chain import ChainLedger
from sumo_drvpw.sim.ledger import EquationSet, Ledger


def equations():
    fuel = load_equation("drvpw_prius3")
    fuel.chain = EnergyChain(predicts="fuel", idle_fuel_power_w=5000.0, marginal_efficiency=0.36,
                             engine_off_below_w=4000.0)
    bev = equation_from_dict({"equation": {"name": "bev"},
                              "terms": {"acc": 1.05, "grade": 1.0, "roll": 0.009, "aero_rho": 0.6},
                              "chain": {"predicts": "battery", "traction_efficiency": 0.9,
                                        "recuperation_efficiency": 0.7,
                                        "recuperation_limit_w": 30000.0, "aux_power_w": 500.0}})
    return [fuel, bev]


def run(n: int, steps: int, chain: bool, seed: int = 0) -> float:
    rng = np.random.default_rng(seed)
    eqs = equations()
    eqset = EquationSet(eqs)
    n_edges = 2000
    led = Ledger(n_edges, len(eqs), capacity=n)
    for i in range(n):
        led.add_vehicle(f"v{i}", "car", 1500.0, np.ones(len(eqs)), True, "passenger")
    cl = ChainLedger([e.name for e in eqs], [e.chain for e in eqs], n_edges) if chain else None
    vidx = np.arange(n)
    edge = rng.integers(0, n_edges, n)
    inputs = [Inputs(v=rng.uniform(0, 30, n), a=rng.normal(0, 1, n), theta=rng.normal(0, 0.02, n),
                     wind=np.zeros(n), mass=np.full(n, 1500.0), rho=np.full(n, 1.2))
              for _ in range(8)]
    t0 = time.perf_counter()
    for s in range(steps):
        x = inputs[s % 8]
        if s % 10 == 0:  # a tenth of the vehicles change edge every 10 steps
            ch = rng.random(n) < 0.1
            edge[ch] = rng.integers(0, n_edges, int(ch.sum()))
        pc = eqset.category_powers(x)
        led.book(vidx, edge, x.v, 0.5, pc)
        if cl is not None:
            cl.book(vidx, edge, x.v, 0.5, pc.sum(axis=2), app=led.veh_app[vidx])
    return time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, nargs="+", default=[1000, 5000])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args(argv)
    ratio = float("nan")
    for n in a.vehicles:
        times = {"ledger": [], "ledger+chain": []}
        for r in range(a.repeats):  # variants interleaved
            times["ledger"].append(run(n, a.steps, False, r))
            times["ledger+chain"].append(run(n, a.steps, True, r))
        med = {k: float(np.median(v)) for k, v in times.items()}
        ratio = med["ledger+chain"] / med["ledger"]
        print(f"N={n}: ledger {1e3 * med['ledger'] / a.steps:.3f} ms/step, ledger+chain "
              f"{1e3 * med['ledger+chain'] / a.steps:.3f} ms/step, ratio {ratio:.2f}")
    print(f"chain_overhead_ratio={ratio:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
