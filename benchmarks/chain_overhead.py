"""Per-step cost of the energy chain's accounts against the road-load ledger's, in-process.

Usage: .venv/bin/python benchmarks/chain_overhead.py [--vehicles 1000 5000] [--steps 200]
       [--repeats 5]

For N vehicles on 2000 edges and two equations (one battery chain with a recuperation
limit, one fuel chain), random speeds, accelerations and edges per step, it times:

- ``ledger``: ``EquationSet.category_powers`` + ``Ledger.book`` (what the SUMO loop does
  per step without chains);
- ``ledger+chain``: the same plus ``ChainLedger.book`` (what it does with chains);
- ``ledger+chain+mmpevem``: the same with a third equation, SUMO's shipped BMW i3 on
  MMPEVEM (``vtype_energy``'s equation for it: terms at the step's mean speed, the chain's
  motor with its loss map), booking a tenth of the vehicles (its vType's), as the loop books
  it (inputs at the mean speed, the step's acceleration and grade passed to the chain).

Prints the median of ``--repeats`` runs of ``--steps`` steps per variant, the final lines
``chain_overhead_ratio=<(ledger+chain)/ledger at the largest N>`` and
``mmpevem_overhead_ratio=<(ledger+chain+mmpevem)/(ledger+chain)>``. No SUMO involved:
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


def mmpevem_i3():
    """SUMO's shipped BMW i3 MMPEVEM vType as vtype_energy books it."""
    import xml.etree.ElementTree as ET

    import sumo

    from sumo_drvpw.model.mmpevem import mmpevem_equation

    vt = ET.parse(f"{sumo.SUMO_HOME}/data/emissions/MMPEVEM/BMW_i3.xml").getroot().find("vType")
    return mmpevem_equation("i3_mmpevem", {p.get("key"): p.get("value") for p in vt.findall("param")},
                            float(vt.get("mass")), "BMW_i3.xml")[0]


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


def run(n: int, steps: int, chain: bool, seed: int = 0, mmpevem: bool = False) -> float:
    from dataclasses import replace

    rng = np.random.default_rng(seed)
    eqs = equations() + ([mmpevem_i3()] if mmpevem else [])
    eqset = EquationSet(eqs)
    n_edges = 2000
    led = Ledger(n_edges, len(eqs), capacity=n)
    for i in range(n):  # the MMPEVEM equation books a tenth of the fleet (its vType's)
        app = np.ones(len(eqs))
        app[2:] = float(i % 10 == 0)
        led.add_vehicle(f"v{i}", "car", 1500.0, app, True, "passenger")
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
        v_mean = x.v - 0.25 * x.a
        pc = eqset.category_powers(x, None, replace(x, v=v_mean) if eqset.uses_mean else None)
        led.book(vidx, edge, x.v, 0.5, pc)
        if cl is not None:
            cl.book(vidx, edge, x.v, 0.5, pc.sum(axis=2), app=led.veh_app[vidx], accel=x.a,
                    v_mean=v_mean, grade=x.theta)
    return time.perf_counter() - t0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--vehicles", type=int, nargs="+", default=[1000, 5000])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args(argv)
    ratio = float("nan")
    for n in a.vehicles:
        times = {"ledger": [], "ledger+chain": [], "ledger+chain+mmpevem": []}
        for r in range(a.repeats):  # variants interleaved
            times["ledger"].append(run(n, a.steps, False, r))
            times["ledger+chain"].append(run(n, a.steps, True, r))
            times["ledger+chain+mmpevem"].append(run(n, a.steps, True, r, mmpevem=True))
        med = {k: float(np.median(v)) for k, v in times.items()}
        ratio = med["ledger+chain"] / med["ledger"]
        mratio = med["ledger+chain+mmpevem"] / med["ledger+chain"]
        print(f"N={n}: ledger {1e3 * med['ledger'] / a.steps:.3f} ms/step, ledger+chain "
              f"{1e3 * med['ledger+chain'] / a.steps:.3f} ms/step, ratio {ratio:.2f}; +mmpevem "
              f"{1e3 * med['ledger+chain+mmpevem'] / a.steps:.3f} ms/step, ratio {mratio:.2f}")
    print(f"chain_overhead_ratio={ratio:.3f}")
    print(f"mmpevem_overhead_ratio={mratio:.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
