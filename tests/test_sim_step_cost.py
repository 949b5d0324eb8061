"""A step's fixed cost: what a SUMO step books does not scale with the network's size nor
with equations no vehicle of the step books (benchmarks/run_ratio.py measures the run)."""

from __future__ import annotations

import numpy as np

from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.sim.chain import ChainLedger


def test_chain_book_works_on_the_steps_edges_only(monkeypatch):
    """ChainLedger.book adds each booked column over the edges of the step's vehicles, not
    over an array as long as the network (13,000 edges in a port scenario: most of a step
    of five vehicles); the totals are those of a per-edge sum over every edge."""
    fuel = EnergyChain(predicts="fuel", idle_fuel_power_w=4000.0, marginal_efficiency=0.35)
    bat = EnergyChain(predicts="battery", aux_power_w=300.0)
    n_edges, rng = 50_000, np.random.default_rng(3)
    led = ChainLedger(["f", "b"], [fuel, bat], n_edges)
    want_edge = np.zeros((n_edges, 2, 8))
    lengths = []
    real = np.bincount

    def spy(x, weights=None, minlength=0):
        lengths.append(minlength)
        return real(x, weights, minlength)

    monkeypatch.setattr(np, "bincount", spy)
    for _ in range(30):
        n = 4
        vidx, eidx = np.arange(n), rng.choice([7, 7, 123, 49_999, 2], n)
        full = led.expand(led.book(vidx, eidx, rng.uniform(0, 20, n), 0.5, rng.normal(0, 2e4, (n, 2))))
        for i, e in enumerate(eidx):  # the step's quantities, summed on their edges
            want_edge[e] += full[i]
    assert max(lengths) <= 4, f"bincount over {max(lengths)} bins for 4 vehicles"
    np.testing.assert_allclose(led.edge, want_edge, rtol=1e-12, atol=1e-9)

