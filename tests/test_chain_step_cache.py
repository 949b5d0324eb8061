"""The chain booking's per-step overhead at a few vehicles a step (sim/chain.py, model/chain.py):
what does not change between steps is built once per ledger, work the step does not need is
not done, and what is booked is the same as the plain computation (benchmarks/run_ratio.py
measures the run; no timing here)."""

from __future__ import annotations

import numpy as np

from sumo_drvpw.model.chain import EnergyChain, Table
from sumo_drvpw.model.constants import FUELS
from sumo_drvpw.sim.chain import ChainLedger


def _fuel(**kw) -> EnergyChain:
    return EnergyChain(**{"predicts": "fuel", "idle_fuel_power_w": 4000.0, "marginal_efficiency": 0.35,
                          "engine_off_below_w": 0.0, **kw})


def test_a_fuel_chain_evaluates_its_engine_state_and_efficiency_table_once(monkeypatch):
    """A fuel chain's step evaluates whether the engine runs once (what it pays for is that, or
    everything for a charge-sustaining hybrid) and its η_t table once, also where a hybrid's
    braking energy is given back; the fuel power is the module's Willans line by hand."""
    eta = Table(values=np.array([0.8, 0.9, 0.92]), speed_mps=np.array([0.0, 10.0, 30.0]))
    counts = {"eta": 0, "on": 0}
    real_call, real_on = Table.__call__, EnergyChain.engine_on

    def call(self, v, p):
        counts["eta"] += 1
        return real_call(self, v, p)

    def on(self, p, v):
        counts["on"] += 1
        return real_on(self, p, v)

    monkeypatch.setattr(Table, "__call__", call)
    monkeypatch.setattr(EnergyChain, "engine_on", on)
    p = np.array([-30000.0, -5000.0, 0.0, 2000.0, 9000.0, 40000.0])
    v = np.array([12.0, 3.0, 0.0, 5.0, 15.0, 25.0])
    for cs, rt in ((False, 0.0), (True, 0.64)):
        ch = _fuel(traction_efficiency=eta, aux_power_w=500.0, engine_off_below_w=8000.0, charge_sustaining=cs,
                   recuperation_round_trip=rt, recuperation_limit_w=20000.0)
        counts.update(eta=0, on=0)
        pf = ch.evaluate(p, v)["power_w"]
        assert counts == {"eta": 1, "on": 1}, (cs, counts)
        e = np.interp(v, [0.0, 10.0, 30.0], [0.8, 0.9, 0.92])
        running = p > 8000.0
        want = (np.where(running, 4000.0, 0.0) + np.where(running | cs, (np.maximum(p, 0) / e + 500.0) / 0.35, 0.0)
                + rt * np.maximum(np.minimum(p, 0.0), -20000.0) / e / 0.35)
        np.testing.assert_allclose(pf, want, rtol=1e-12)
        assert FUELS[ch.fuel]["lhv_j_per_kg"] > 0
