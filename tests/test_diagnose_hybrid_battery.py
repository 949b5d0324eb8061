"""``diagnose --target fuel`` of a hybrid whose chain carries a battery (fit/chain_linear.py): a
window (``battery_usable_j``) or a plug-in's charge-depleting start (``[chain.depleting]``) is
carried through each trip with the samples' durations, and an effect planted on top is found."""

from __future__ import annotations

import numpy as np
import pytest

from sumo_drvpw.data.log import from_frame
from sumo_drvpw.data.measured import measure
from sumo_drvpw.fit.chain_linear import gains, linearised_columns, trace_chain
from sumo_drvpw.model.chain_toml import chain_from_dict
from sumo_drvpw.model.constants import FUELS
from sumo_drvpw.model.equations import Equation, load_equation
from sumo_drvpw.model.vehicles import load_vehicle
from sumo_drvpw.synth.effects import BatteryLog, synth_trips
from sumo_drvpw.synth.track import Noise

#: a hybrid whose engine runs throughout and whose battery takes at most 3 kW: its braking credit
#: (≤ 0.64 × 3 kW / (0.95 × 0.38) = 5.3 kW) below its idle fuel, so the fuel it books, like a
#: measured one, is never negative
HYBRID = {"predicts": "fuel", "fuel": "gasoline", "traction_efficiency": 0.95, "aux_power_w": 300.0,
          "idle_fuel_power_w": 6000.0, "marginal_efficiency": 0.38, "engine_off_below_w": float("-inf"),
          "charge_sustaining": True, "recuperation_round_trip": 0.64, "recuperation_limit_w": 3000.0,
          "battery_usable_j": 60e3}
#: a plug-in battery that lasts part of each 10-minute trip
PLUG_IN = {**HYBRID, "depleting": {"usable_j": 0.6e6, "traction_efficiency": 0.85, "recuperation_efficiency": 0.6}}


@pytest.fixture(scope="module")
def trips():
    df, _ = synth_trips(n_trips=6, minutes=10.0, seed=3, effects=(BatteryLog(noise_w=100.0),),
                        noise=Noise(process_w=50.0, process_rel=0.002))
    return df.drop(columns=["battery_voltage_v", "battery_current_a"])


def _fuel_log(df, chain_doc: dict, plant_w: float, seed: int = 5):
    """The trips' measured fuel from ``chain_doc`` with ``plant_w`` more engine load, ±3 % noise."""
    veh = load_vehicle("prius3")
    truth = load_equation("drvpw_prius3")
    x = measure(from_frame(df.assign(fuel_rate_gps=0.0), veh, name="x"), veh, "fuel")
    plant = Equation("plant", dict(truth.terms), truth.mass_kg,
                     chain=chain_from_dict({**chain_doc, "aux_power_w": chain_doc["aux_power_w"] + plant_w}))
    xi = x.inputs.with_mass(truth.mass_kg) if truth.mass_kg else x.inputs
    pf = plant.chain.evaluate(plant.power(xi), xi.v, x.log.df["dt_s"].to_numpy(float), xi.signals, xi.trip)["power_w"]
    pf = pf * (1.0 + np.random.default_rng(seed).normal(0, 0.03, pf.size)).clip(0.0)
    d = df.assign(fuel_rate_gps=pf / FUELS["gasoline"]["lhv_j_per_kg"] * 1000.0)
    return measure(from_frame(d, veh, name="synth-fuel"), veh, "fuel"), truth


@pytest.mark.parametrize("doc", [HYBRID, PLUG_IN], ids=["window", "plug-in"])
def test_a_planted_engine_load_is_found_through_the_battery(trips, doc):
    """1500 W more engine load than declared: found as aux_power_w within 10 %; nothing planted,
    nothing found. The plug-in's fuel is zero while it drives on its battery, so its gain is
    zero there."""
    found = {}
    for plant in (0.0, 1500.0):
        m, truth = _fuel_log(trips, doc, plant)
        res = trace_chain(m, Equation("declared", dict(truth.terms), truth.mass_kg, chain=chain_from_dict(doc)))
        found[plant] = {f["term"]: f["coefficient"] for f in res.report["findings"]}
    assert found[0.0] == {}
    assert list(found[1500.0]) == ["aux_power_w"]
    assert found[1500.0]["aux_power_w"] == pytest.approx(1500.0, rel=0.1)


def test_the_gains_follow_the_battery(trips):
    """The window: braking while it is full credits nothing (g_wheel 0 there), where it has
    room η_rt/(η_t·η_m); the plug-in on its battery: no fuel per W (g 0), once spent its fuel
    chain's (g_aux 1/η_m); the columns sum to the chain's fuel where it is linear."""
    m, truth = _fuel_log(trips, PLUG_IN, 0.0)
    eq = Equation("declared", dict(truth.terms), truth.mass_kg, chain=chain_from_dict(PLUG_IN))
    dt = m.log.df["dt_s"].to_numpy(float)
    p = eq.power(m.inputs.with_mass(eq.mass_kg))
    out = eq.chain.evaluate(p, m.inputs.v, dt, m.inputs.signals, m.inputs.trip)
    gw, ga = gains(eq.chain, p, m.inputs.v, m.inputs.signals, dt, m.inputs.trip)
    on_battery = out["spent_j"] < PLUG_IN["depleting"]["usable_j"] - 1e3
    assert on_battery.any() and (~on_battery).any()
    assert np.all(gw[on_battery & (p > 0)] == 0.0) and np.all(ga[on_battery] == 0.0)
    full = out["spent_j"] >= PLUG_IN["depleting"]["usable_j"]
    # spent for 5 samples at least (±1 W moves the sample that spends the last joule)
    spent = full & np.r_[np.zeros(5, bool), full[:-5]] & (p > 1.0) & (p < 30e3)
    np.testing.assert_allclose(ga[spent], 1 / 0.38, rtol=1e-6)
    cols, off = linearised_columns(eq, m.inputs, dt)
    total = sum(cols.values()) + off
    lin = spent | on_battery & (p > 1.0)
    np.testing.assert_allclose(total[lin], out["power_w"][lin], rtol=1e-6, atol=1e-3)


def test_diagnose_streamed_and_in_memory_find_it_alike(trips, tmp_path):
    """``diagnose --target fuel`` of the windowed hybrid, streamed (batches of whole trips) and in
    memory: the same finding, to 1 W."""
    import json

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.model.equations import save_equation

    m, truth = _fuel_log(trips, HYBRID, 1500.0)
    trips.assign(fuel_rate_gps=m.power_w / FUELS["gasoline"]["lhv_j_per_kg"] * 1000.0).to_csv(tmp_path / "log.csv",
                                                                                               index=False)
    save_equation(Equation("declared", dict(truth.terms), truth.mass_kg, chain=chain_from_dict(HYBRID)),
                  tmp_path / "eq.toml")
    found = {}
    for mode in ("no", "yes"):
        out = tmp_path / mode
        assert cli_main(["diagnose", str(tmp_path / "log.csv"), "--vehicle", "prius3", "--target", "fuel",
                         "--equation", str(tmp_path / "eq.toml"), "--stream", mode, "--out", str(out)]) == 0
        rep = json.loads((out / "trace.json").read_text(encoding="utf-8"))
        found[mode] = {f["term"]: f["coefficient"] for f in rep["findings"]}
    assert list(found["no"]) == list(found["yes"]) == ["aux_power_w"]
    assert found["yes"]["aux_power_w"] == pytest.approx(found["no"]["aux_power_w"], abs=1.0)
    assert found["no"]["aux_power_w"] == pytest.approx(1500.0, rel=0.1)
