"""A calibrated energy chain says when its parameters are implausible or extrapolated
(fit/chain_checks.py): zero-output fuel against a car's idle fuel, a power-split hybrid's
engine-on rule, and the driving power and speed it was fitted on, kept for SUMO runs."""

import numpy as np
import pytest

import corpus
from sumo_drvpw.fit.chain_checks import engine_off_note, fuel_l_per_h, idle_fuel_note
from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.model.constants import FUELS
from sumo_drvpw.model.equations import load_equation


def test_zero_output_fuel_in_litres_per_hour_and_its_bounds():
    # 12.893 kW of petrol: 12893 / 43.2e6 J/kg / 0.745 kg/L · 3600 s/h = 1.442 L/h
    assert fuel_l_per_h(12893.0) == pytest.approx(12893.0 / 43.2e6 / 0.745 * 3600.0)
    assert fuel_l_per_h(12893.0) == pytest.approx(1.442, abs=1e-3)
    assert "IMPLAUSIBLE" in idle_fuel_note(20000.0, 0.0, "gasoline", None)        # 2.24 L/h
    assert "IMPLAUSIBLE" in idle_fuel_note(20000.0, -np.inf, "gasoline", None)
    assert "IMPLAUSIBLE" not in idle_fuel_note(8000.0, -np.inf, "gasoline", None)  # 0.89 L/h
    # 3 kW (0.34 L/h): too little for an engine idling at stops, not for one switched off there
    assert "IMPLAUSIBLE" in idle_fuel_note(3000.0, -np.inf, "gasoline", None)
    assert "IMPLAUSIBLE" not in idle_fuel_note(3000.0, 0.0, "gasoline", None)
    # a power-split hybrid running its engine at any positive driving power
    assert "IMPLAUSIBLE" in engine_off_note(0.0, "power_split", 1.44)
    assert "1.44 L/h" in engine_off_note(0.0, "power_split", 1.44)
    assert engine_off_note(5000.0, "power_split", 1.44) == ""
    assert engine_off_note(0.0, "direct", 1.44) == ""


def _planted_fuel_log(tmp_path, plant: EnergyChain):
    """Two trips with a known road load; the fuel flow [L/h] of a planted Willans chain."""
    from sumo_drvpw.data.log import from_frame

    df = corpus.sine_trips(np.random.default_rng(5), 4000, 12.0)
    road = corpus.road_equation(tmp_path)
    x = from_frame(df).inputs()
    p = load_equation(road).power(x)
    g = FUELS["gasoline"]
    fuel_w = plant.evaluate(p, x.v)["power_w"]
    df["fuel_flow_rate_hour_lph"] = fuel_w / g["lhv_j_per_kg"] / g["density_kg_per_l"] * 3600.0
    log = tmp_path / "fuel.csv"
    df.to_csv(log, index=False)
    return log, road, p


def _calibrate(tmp_path, capsys, plant, *extra):
    from sumo_drvpw.cli import main as cli_main

    log, road, p = _planted_fuel_log(tmp_path, plant)
    out = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(log), "--target", "fuel", "--equation", str(road),
                     "--out", str(out), *extra]) == 0
    return load_equation(out), capsys.readouterr().out, p


def test_an_implausible_zero_output_fuel_is_said_and_kept(tmp_path, capsys):
    # 20 kW of fuel at zero output (2.24 L/h): more than a 4.6-L sedan idles on
    plant = EnergyChain(predicts="fuel", idle_fuel_power_w=20000.0, marginal_efficiency=0.35,
                        engine_off_below_w=-np.inf)
    eq, out, p = _calibrate(tmp_path, capsys, plant)
    assert eq.chain.idle_fuel_power_w == pytest.approx(20000.0, rel=1e-2)
    assert "warning: energy chain idle_fuel_power_w" in out and "2.24 L/h; IMPLAUSIBLE" in out
    assert any("idle_fuel_power_w" in w for w in eq.chain.provenance["warnings"])
    assert "IMPLAUSIBLE" in eq.chain.reading["idle_fuel_power_w"]
    # the driving power and speed it was fitted on, for SUMO runs (Equation.validity)
    from sumo_drvpw.data.measured import load_measured

    m = load_measured([tmp_path / "fuel.csv"], None, target="fuel")
    fitted = p[m.usable]  # the reader leaves out acceleration outliers
    lo, hi = eq.chain.provenance["power_range_w"]
    assert lo == pytest.approx(float(fitted.min()), rel=1e-6) and hi == pytest.approx(float(fitted.max()), rel=1e-6)
    assert eq.validity()[2] == (lo, hi)
    assert eq.chain.provenance["speed_range_mps"][0] == 0.0


def test_a_plausible_chain_has_no_warning(tmp_path, capsys):
    plant = EnergyChain(predicts="fuel", idle_fuel_power_w=8000.0, marginal_efficiency=0.35,
                        engine_off_below_w=-np.inf)  # 0.89 L/h idling
    eq, out, _ = _calibrate(tmp_path, capsys, plant)
    assert "warning: energy chain" not in out
    assert "warnings" not in eq.chain.provenance and "power_range_w" in eq.chain.provenance


def test_a_power_split_hybrid_whose_engine_never_rests_at_light_load(tmp_path, capsys):
    # the engine runs at any positive driving power: no electric driving, as no Prius does
    plant = EnergyChain(predicts="fuel", idle_fuel_power_w=9000.0, marginal_efficiency=0.38,
                        engine_off_below_w=0.0)
    eq, out, _ = _calibrate(tmp_path, capsys, plant, "--vehicle", "prius2")
    assert eq.chain.engine_off_below_w == 0.0
    assert "warning: energy chain engine_off_below_w = 0: " in out
    assert "IMPLAUSIBLE for a power-split hybrid" in eq.chain.reading["engine_off_below_w"]
