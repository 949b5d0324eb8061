"""Energy chain: evaluator by hand calculation, TOML round trip, measured targets, calibration
recovering planted chains, bounds."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings, strategies as st

import corpus
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.chain import calibrate_battery
from sumo_drvpw.fit.chain_fuel import calibrate_fuel
from sumo_drvpw.model.chain import EnergyChain, corrected_fuel_power
from sumo_drvpw.model.chain_toml import chain_from_dict
from sumo_drvpw.model.constants import CABIN_WARMUP_TAU_S, FUEL_COLD_START_TAU_S, FUELS
from sumo_drvpw.model.equations import equation_from_dict, load_equation, save_equation


# ------------------------------------------------------------------ evaluator by hand

def test_battery_traction_recuperation_and_standstill_auxiliary_by_hand():
    ch = EnergyChain(predicts="battery", traction_efficiency=0.8, recuperation_efficiency=0.6,
                     aux_power_w=400.0, loads={"heater_power_w": 1.0})
    p = np.array([20_000.0, -10_000.0, 0.0])
    v = np.array([15.0, 10.0, 0.0])
    out = ch.evaluate(p, v, dt_s=2.0, signals={"heater_power_w": np.array([0.0, 0.0, 2500.0])})
    # traction 20 kW / 0.8 = 25 kW; recuperation 0.6 · (−10 kW) = −6 kW; standstill: aux only
    np.testing.assert_allclose(out["traction_w"], [25_000.0, 0.0, 0.0])
    np.testing.assert_allclose(out["recuperated_w"], [0.0, -6_000.0, 0.0])
    np.testing.assert_allclose(out["auxiliary_w"], [400.0, 400.0, 2900.0])
    np.testing.assert_allclose(out["power_w"], [25_400.0, -5_600.0, 2900.0])
    np.testing.assert_allclose(out["auxiliary_j"], [800.0, 800.0, 5800.0])
    # terms sum to the net
    np.testing.assert_allclose(out["traction_w"] + out["recuperated_w"] + out["auxiliary_w"], out["power_w"])


def test_recuperation_limit_sends_the_rest_to_friction_brakes():
    ch = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.7,
                     recuperation_limit_w=30_000.0)
    p = np.array([-10_000.0, -50_000.0])
    out = ch.evaluate(p, np.array([10.0, 20.0]))
    # below the limit: 0.7·(−10 kW); beyond: 0.7·(−30 kW) and 20 kW to the friction brakes
    np.testing.assert_allclose(out["recuperated_w"], [-7_000.0, -21_000.0])
    np.testing.assert_allclose(out["friction_brake_w"], [0.0, -20_000.0])
    no_limit = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.7)
    np.testing.assert_allclose(no_limit.evaluate(p, np.array([10.0, 20.0]))["recuperated_w"],
                               [-7_000.0, -35_000.0])


def test_hvac_term_by_hand():
    ch = EnergyChain(predicts="battery", hvac={"column": "ambient_c", "setpoint_c": 21.0,
                                               "heating_w_per_k": 100.0, "cooling_w_per_k": 50.0})
    out = ch.evaluate(np.zeros(3), np.zeros(3), signals={"ambient_c": np.array([1.0, 21.0, 31.0])})
    np.testing.assert_allclose(out["auxiliary_w"], [2000.0, 0.0, 500.0])


def test_hvac_with_an_unknown_temperature_books_no_hvac():
    """NaN temperature is unknown: no HVAC (as the term grammar's 'cold'), not the heating of
    0 °C (which would book 21 K × 100 W/K = 2.1 kW here)."""
    ch = EnergyChain(predicts="battery", aux_power_w=300.0,
                     hvac={"column": "ambient_c", "setpoint_c": 21.0, "heating_w_per_k": 100.0,
                           "cooling_w_per_k": 50.0})
    out = ch.evaluate(np.zeros(2), np.zeros(2), signals={"ambient_c": np.array([np.nan, 11.0])})
    np.testing.assert_allclose(out["auxiliary_w"], [300.0, 1300.0])


def test_efficiency_table_interpolates_over_speed_and_power():
    ch = chain_from_dict({"predicts": "battery", "traction_efficiency": {
        "speed_mps": [0.0, 20.0], "power_w": [0.0, 40_000.0], "values": [[0.6, 0.8], [0.8, 0.9]]}})
    out = ch.evaluate(np.array([20_000.0, 80_000.0]), np.array([10.0, 50.0]))
    # bilinear at the centre: mean of the four corners (0.6+0.8+0.8+0.9)/4 = 0.775; beyond
    # both ends: clamped to the corner 0.9
    np.testing.assert_allclose(out["traction_w"], [20_000.0 / 0.775, 80_000.0 / 0.9])


def test_fuel_willans_line_with_engine_off_by_hand():
    ch = EnergyChain(predicts="fuel", idle_fuel_power_w=5_000.0, marginal_efficiency=0.4,
                     engine_off_below_w=3_000.0, engine_on_above_mps=19.0, fuel="gasoline")
    p = np.array([2_000.0, 20_000.0, 0.0, -5_000.0])
    v = np.array([10.0, 15.0, 20.0, 5.0])
    out = ch.evaluate(p, v, dt_s=1.0)
    # engine off below 3 kW (unless v > 19 m/s); on: 5 kW + P/0.4
    np.testing.assert_array_equal(out["engine_on"], [False, True, True, False])
    np.testing.assert_allclose(out["power_w"], [0.0, 55_000.0, 5_000.0, 0.0])
    g = FUELS["gasoline"]
    lps = 55_000.0 / g["lhv_j_per_kg"] / g["density_kg_per_l"]
    np.testing.assert_allclose(out["fuel_lps"][1], lps)
    np.testing.assert_allclose(out["co2_kgps"][1], 55_000.0 / g["lhv_j_per_kg"] * g["co2_kg_per_kg"])
    # 1 L of petrol: 0.745 kg → 2.36 kg CO₂ (EPA: 8887 g per US gallon = 2.35 kg/L)
    assert g["density_kg_per_l"] * g["co2_kg_per_kg"] == pytest.approx(8.887 / 3.785411784, rel=0.01)


def test_overrun_fuel_cut_off_by_hand(tmp_path):
    """fuel_cut_below_w: rolling with a driving power below it, the injection is cut (no
    fuel, aux included); standing, the engine idles whatever the power; a hybrid's engine-off
    and forced-on rules apply first. Round-trips through the file; refused on a battery chain."""
    ch = EnergyChain(predicts="fuel", idle_fuel_power_w=4_000.0, marginal_efficiency=0.4,
                     engine_off_below_w=-np.inf, aux_power_w=2_000.0, fuel_cut_below_w=0.0, fuel="diesel")
    p = np.array([-3_000.0, -3_000.0, 0.0, 10_000.0, -1.0])
    v = np.array([10.0, 0.0, 10.0, 10.0, 0.05])   # the last: below STANDSTILL_MPS (0.1 m/s), standing
    out = ch.evaluate(p, v, dt_s=1.0)
    np.testing.assert_array_equal(out["engine_on"], [False, True, True, True, True])
    # fuelled: 4 kW idle + (max(P, 0) + 2 kW aux)/0.4
    np.testing.assert_allclose(out["power_w"], [0.0, 9_000.0, 9_000.0, 34_000.0, 9_000.0])
    hyb = EnergyChain(predicts="fuel", idle_fuel_power_w=4_000.0, marginal_efficiency=0.4,
                      engine_off_below_w=3_000.0, engine_on_above_mps=19.0, fuel_cut_below_w=0.0)
    np.testing.assert_array_equal(hyb.engine_on(np.array([-5_000.0, 1_000.0, 5_000.0]),
                                                np.array([25.0, 25.0, 5.0])), [False, True, True])
    eq = equation_from_dict({"equation": {"name": "c"}, "terms": {"acc": 1.0}, "chain": ch.to_dict()})
    save_equation(eq, tmp_path / "c.toml")
    assert load_equation(tmp_path / "c.toml").chain == ch and ch.to_dict()["fuel_cut_below_w"] == 0.0
    assert "fuel_cut_below_w" not in EnergyChain(predicts="fuel").to_dict()
    with pytest.raises(UserError, match="'fuel_cut_below_w' cuts an engine's fuel: only for predicts"):
        equation_from_dict({"equation": {"name": "b"}, "terms": {"acc": 1.0},
                            "chain": {"predicts": "battery", "fuel_cut_below_w": 0.0}}, "b.toml")


def test_cold_start_is_a_fixed_volume_per_start_by_hand(tmp_path):
    """A cold start's fuel, energy and CO₂ follow from its litres through the fuel's
    constants; the per-sample evaluation is unchanged (a cold start is per trip, not a
    power); the key round-trips through the equation file; a battery chain has none."""
    import dataclasses

    ch = EnergyChain(predicts="fuel", idle_fuel_power_w=4_000.0, marginal_efficiency=0.35,
                     engine_off_below_w=-np.inf, fuel="diesel", cold_start_fuel_l=0.05)
    d = FUELS["diesel"]
    cs = ch.cold_start()
    assert cs["fuel_l"] == 0.05
    assert cs["fuel_j"] == pytest.approx(0.05 * d["density_kg_per_l"] * d["lhv_j_per_kg"], rel=1e-12)
    assert cs["co2_kg"] == pytest.approx(0.05 * d["density_kg_per_l"] * d["co2_kg_per_kg"], rel=1e-12)
    p, v = np.array([0.0, 8_000.0, -3_000.0]), np.array([0.0, 12.0, 9.0])
    warm = dataclasses.replace(ch, cold_start_fuel_l=0.0)
    np.testing.assert_array_equal(ch.evaluate(p, v, 1.0)["fuel_l"], warm.evaluate(p, v, 1.0)["fuel_l"])
    assert warm.cold_start() == {"fuel_l": 0.0, "fuel_j": 0.0, "co2_kg": 0.0, "battery_j": 0.0}
    assert EnergyChain(predicts="battery").cold_start()["fuel_l"] == 0.0
    eq = equation_from_dict({"equation": {"name": "d"}, "terms": {"acc": 1.0}, "chain": ch.to_dict()})
    save_equation(eq, tmp_path / "d.toml")
    assert load_equation(tmp_path / "d.toml").chain == ch
    assert "cold_start_fuel_l" not in warm.to_dict()
    # colder: V_ref + s·(T_ref − T); warmer than the reference: V_ref
    cold = dataclasses.replace(ch, cold_start_fuel_l_per_k=0.003, cold_start_ref_c=23.9)
    assert cold.cold_start(-6.1)["fuel_l"] == pytest.approx(0.05 + 0.003 * 30.0, rel=1e-12)
    assert cold.cold_start(30.0)["fuel_l"] == cold.cold_start(None)["fuel_l"] == 0.05
    assert cold.cold_start(-6.1)["fuel_j"] == pytest.approx(0.14 * d["density_kg_per_l"] * d["lhv_j_per_kg"])
    eq = equation_from_dict({"equation": {"name": "c"}, "terms": {"acc": 1.0}, "chain": cold.to_dict()})
    assert eq.chain == cold and cold.to_dict()["cold_start_ref_c"] == 23.9


def test_warm_running_fuel_factor_by_hand(tmp_path):
    """``running_fuel_per_k``: the fuel power (idle and load) times 1 + r·(T_ref − T)⁺ at
    the air temperature ``ambient_c``; none above the reference, where the temperature is
    unknown (NaN) or not logged; the chain reads the column and names it when unknown; the
    key round-trips and only a fuel chain may carry it."""
    import dataclasses

    warm = EnergyChain(predicts="fuel", idle_fuel_power_w=4_000.0, marginal_efficiency=0.35,
                       engine_off_below_w=-np.inf, fuel="gasoline")
    ch = dataclasses.replace(warm, running_fuel_per_k=0.003, cold_start_ref_c=23.9)
    p, v = np.array([0.0, 8_000.0, 8_000.0, 8_000.0]), np.array([0.0, 12.0, 12.0, 12.0])
    t = {"ambient_c": np.array([-6.1, -6.1, 30.0, np.nan])}
    base = warm.evaluate(p, v, 1.0)["power_w"]
    np.testing.assert_allclose(base, [4_000.0, 4_000.0 + 8_000.0 / 0.35, 4_000.0 + 8_000.0 / 0.35,
                                      4_000.0 + 8_000.0 / 0.35])
    np.testing.assert_allclose(ch.evaluate(p, v, 1.0, t)["power_w"], base * [1.09, 1.09, 1.0, 1.0], rtol=1e-12)
    np.testing.assert_allclose(ch.evaluate(p, v, 1.0, t)["fuel_l"], warm.evaluate(p, v, 1.0)["fuel_l"]
                               * [1.09, 1.09, 1.0, 1.0], rtol=1e-12)
    np.testing.assert_array_equal(ch.evaluate(p, v, 1.0)["power_w"], base)  # no temperature column
    assert ch.signals == {"ambient_c"} and warm.signals == set()
    assert ch.unknown_inputs(t, 4)["ambient_c"]["read_as"].startswith("the reference temperature")
    eq = equation_from_dict({"equation": {"name": "w"}, "terms": {"acc": 1.0}, "chain": ch.to_dict()})
    save_equation(eq, tmp_path / "w.toml")
    assert load_equation(tmp_path / "w.toml").chain == ch and ch.to_dict()["cold_start_ref_c"] == 23.9
    assert "running_fuel_per_k" not in warm.to_dict()


def test_soc_correction_removes_a_battery_swing():
    # a trip that drained 1 MJ from the battery burnt 1 MJ·k less fuel: corrected fuel adds it back
    fuel = np.full(10, 20_000.0)
    bat = np.full(10, 100_000.0 / 10)  # 10 kW discharge for 10 s... = 100 kJ
    np.testing.assert_allclose(corrected_fuel_power(fuel, bat, 2.5).sum(), 200_000.0 + 250_000.0)


# ------------------------------------------------------------------ as data

def test_chain_round_trips_through_the_equation_file(tmp_path):
    doc = {"equation": {"name": "ev"}, "terms": {"acc": 1.05, "roll": 0.009, "aero_rho": 0.6},
           "chain": {"predicts": "battery", "traction_efficiency": {"speed_mps": [0.0, 30.0],
                                                                    "values": [0.85, 0.9]},
                     "recuperation_efficiency": 0.7, "recuperation_limit_w": 40_000.0,
                     "aux_power_w": 350.0, "loads": {"heater_power_w": 1.0, "aircon_power_w": 0.9},
                     "hvac": {"setpoint_c": 20.0, "heating_w_per_k": 80.0}}}
    eq = equation_from_dict(doc)
    save_equation(eq, tmp_path / "ev.toml")
    back = load_equation(tmp_path / "ev.toml")
    assert back.chain == eq.chain and back.predicts == "battery"
    assert back.chain.signals == {"heater_power_w", "aircon_power_w", "ambient_c"}
    assert load_equation("drvpw_prius3").predicts in ("wheel", "powertrain_output")  # no chain


@pytest.mark.parametrize("chain, msg", [
    ({"predicts": "tank"}, "predicts must be one of"),
    ({"traction_efficiency": 1.2}, "'traction_efficiency' must be in (0, 1]"),
    ({"recuperation_efficiency": 0.0}, "must be in (0, 1]"),
    ({"aux_power_w": -5.0}, "'aux_power_w' must be ≥ 0"),
    ({"aux_power_w": float("inf")}, "'aux_power_w' must be ≥ 0 and finite, got inf"),
    ({"predicts": "battery", "cold_start_fuel_l": 0.05}, "only for predicts = \"fuel\""),
    ({"predicts": "fuel", "cold_start_fuel_l": -0.05}, "'cold_start_fuel_l' must be ≥ 0"),
    ({"predicts": "fuel", "cold_start_fuel_l_per_k": -1e-3}, "'cold_start_fuel_l_per_k' must be ≥ 0"),
    ({"predicts": "fuel", "cold_start_ref_c": 297.0}, "'cold_start_ref_c' must be an air temperature"),
    ({"predicts": "battery", "running_fuel_per_k": 0.003}, "only for predicts = \"fuel\""),
    ({"predicts": "fuel", "running_fuel_per_k": 0.3}, "'running_fuel_per_k' is a share of the fuel per kelvin"),
    ({"predicts": "fuel", "running_fuel_per_k": -0.003}, "'running_fuel_per_k' must be ≥ 0"),
    ({"loads": {"heater_power_w": -1.0}}, "loads.heater_power_w"),
    ({"fuel": "kerosene"}, "fuel must be one of"),
    ({"efficiency": 0.9}, "unknown key(s) ['efficiency']"),
    ({"traction_efficiency": {"speed_mps": [0, 10], "values": [0.9]}}, "shape"),
])
def test_bad_chain_is_a_user_error_naming_the_key(chain, msg):
    with pytest.raises(UserError) as e:
        equation_from_dict({"equation": {"name": "x"}, "terms": {"acc": 1.0}, "chain": chain}, "f.toml")
    assert msg in str(e.value) and "f.toml" in str(e.value)


def test_missing_load_column_is_a_user_error():
    ch = EnergyChain(loads={"heater_power_w": 1.0})
    with pytest.raises(UserError, match="heater_power_w"):
        ch.evaluate(np.zeros(2), np.zeros(2), signals={})


# ------------------------------------------------------------------ calibration

def _drive(n=20_000, seed=1):
    """A random but physical drive: speed, road-load driving power, loads, temperature."""
    rng = np.random.default_rng(seed)
    v = np.clip(np.cumsum(rng.normal(0, 0.3, n)) % 30.0, 0.0, None)
    a = rng.normal(0, 0.8, n)
    p = 1500.0 * v * a + 180.0 * v + 0.35 * v ** 3
    p[rng.random(n) < 0.08] = 0.0  # standstill samples
    heater = np.where(rng.random(n) < 0.5, rng.uniform(0, 4000, n), 0.0)
    temp = rng.uniform(-5, 30, n)
    dt = rng.uniform(0.05, 0.15, n)
    return rng, v, p, heater, temp, dt


def test_calibration_recovers_a_planted_battery_chain_within_2_percent():
    rng, v, p, heater, temp, dt = _drive()
    plant = EnergyChain(predicts="battery", traction_efficiency=0.88, recuperation_efficiency=0.72,
                        recuperation_limit_w=None, aux_power_w=450.0, loads={"heater_power_w": 0.95},
                        hvac={"column": "ambient_c", "setpoint_c": 20.0, "heating_w_per_k": 30.0,
                              "cooling_w_per_k": 40.0})
    sig = {"heater_power_w": heater, "ambient_c": temp}
    meas = plant.evaluate(p, v, signals=sig)["power_w"] + rng.normal(0, 300.0, p.size)
    fit = calibrate_battery(p, v, meas, dt, sig, loads=["heater_power_w"],
                            hvac={"column": "ambient_c", "setpoint_c": 20.0}, limit=None)
    c = fit.chain
    assert c.traction_efficiency == pytest.approx(0.88, rel=0.02)
    assert c.recuperation_efficiency == pytest.approx(0.72, rel=0.02)
    assert c.aux_power_w == pytest.approx(450.0, rel=0.02)
    assert c.loads["heater_power_w"] == pytest.approx(0.95, rel=0.02)
    assert c.hvac["heating_w_per_k"] == pytest.approx(30.0, rel=0.02)
    assert c.hvac["cooling_w_per_k"] == pytest.approx(40.0, rel=0.02)
    # uncertainties reported, and the truth within 4 standard errors
    for k, truth in (("traction_efficiency", 0.88), ("aux_power_w", 450.0)):
        se = fit.parameters[k]["std_err"]
        assert se is not None and abs(fit.parameters[k]["value"] - truth) < 4 * se + 1e-9
    assert "reading" in fit.parameters["traction_efficiency"]


def test_calibration_recovers_a_planted_cabin_warm_up():
    """Trips of 20 min whose cabins start at different temperatures: the battery power holds
    steady heating over the ambient temperature plus a warm-up W·(T_set − T_cab,0)⁺·e^(−t/τ)/τ.
    With that rate as a regressor the fit recovers W and the steady heating within 2 %, and the
    chain books W·ΔT at a cold start; without it the steady heating absorbs part of it."""
    rng = np.random.default_rng(4)
    trips, per, tau, w_true = 40, 1200, 300.0, 120e3
    t = np.tile(np.arange(per, dtype=float), trips)
    amb = np.repeat(rng.uniform(-5, 15, trips), per)
    cab0 = np.where(np.repeat(rng.random(trips) < 0.6, per), amb, 20.0)  # 40 % start with a warm cabin
    v = np.clip(10 + 5 * np.sin(t / 60.0) + rng.normal(0, 0.5, t.size), 0, None)
    p = 400.0 * v + 0.4 * v ** 3 + rng.normal(0, 2000.0, t.size)
    rate = np.maximum(20.0 - cab0, 0.0) * np.exp(-t / tau) / tau
    plant = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.7, aux_power_w=300.0,
                        hvac={"column": "ambient_c", "setpoint_c": 20.0, "heating_w_per_k": 80.0,
                              "cooling_w_per_k": 0.0})
    meas = plant.evaluate(p, v, signals={"ambient_c": amb})["power_w"] + w_true * rate + rng.normal(0, 200.0, t.size)
    hv = {"column": "ambient_c", "setpoint_c": 20.0}
    fit = calibrate_battery(p, v, meas, 1.0, {"ambient_c": amb}, hvac=hv, limit=None, warmup_rate=rate)
    assert fit.chain.hvac["warmup_j_per_k"] == pytest.approx(w_true, rel=0.02)
    assert fit.chain.hvac["heating_w_per_k"] == pytest.approx(80.0, rel=0.02)
    assert fit.chain.cold_start(5.0)["battery_j"] == pytest.approx(15.0 * fit.chain.hvac["warmup_j_per_k"])
    assert fit.chain.cold_start(None)["battery_j"] == 0.0 and "kJ per K" in fit.parameters["hvac.warmup_j_per_k"]["reading"]
    without = calibrate_battery(p, v, meas, 1.0, {"ambient_c": amb}, hvac=hv, limit=None)
    assert without.chain.hvac["heating_w_per_k"] > 85.0 and "warmup_j_per_k" not in without.chain.hvac


def test_samples_with_an_unknown_load_stay_out_of_the_fit():
    """A load logged on part of the data only (the i3's heater V·I is missing on 16 trips):
    where it is NaN the battery power still holds the heater's draw, so those samples are
    left out and counted — read as 0 they would bias the auxiliary power (negative control)."""
    rng, v, p, heater, temp, dt = _drive()
    plant = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.75,
                        aux_power_w=500.0, loads={"heater_w": 1.0})
    meas = plant.evaluate(p, v, signals={"heater_w": heater})["power_w"] + rng.normal(0, 200.0, p.size)
    logged = heater.copy()
    logged[: p.size // 2] = np.nan          # the first half: heater running, not logged
    fit = calibrate_battery(p, v, meas, dt, {"heater_w": logged}, loads=["heater_w"], limit=None)
    assert fit.unknown_input_samples == p.size // 2 and fit.n == p.size - p.size // 2
    assert fit.chain.aux_power_w == pytest.approx(500.0, rel=0.03)
    assert "unknown" in fit.summary()
    zero = calibrate_battery(p, v, meas, dt, {"heater_w": np.nan_to_num(logged)}, loads=["heater_w"],
                             limit=None)
    assert zero.unknown_input_samples == 0 and zero.chain.aux_power_w > 700.0   # the bias avoided


def test_calibration_finds_a_planted_recuperation_limit():
    rng, v, p, heater, temp, dt = _drive(seed=2)
    brake = -p[p < 0]
    lim = float(np.quantile(brake, 0.9))  # a grid point of the profile
    plant = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.7,
                        recuperation_limit_w=lim, aux_power_w=300.0)
    meas = plant.evaluate(p, v)["power_w"] + rng.normal(0, 200.0, p.size)
    fit = calibrate_battery(p, v, meas, dt)
    assert fit.chain.recuperation_limit_w == pytest.approx(lim, rel=1e-9)
    assert fit.chain.recuperation_efficiency == pytest.approx(0.7, rel=0.02)
    assert fit.chain.traction_efficiency == pytest.approx(0.9, rel=0.02)
    # without a limit in the data, the profile keeps none
    plant.recuperation_limit_w = None
    meas = plant.evaluate(p, v)["power_w"] + rng.normal(0, 200.0, p.size)
    assert calibrate_battery(p, v, meas, dt).chain.recuperation_limit_w is None


def test_calibration_recovers_a_planted_fuel_chain_with_soc_swings():
    """A power-split hybrid: below 5 kW the battery drives (engine off, no fuel); with the
    engine on the battery assists (> 0) or is charged (< 0) by up to 30 % of the demand, the
    engine delivering P − P_bat. Against the SOC-corrected fuel, fuel + P_bat/η_m, that is
    the charge-sustaining line: recovered, threshold included. The plain form (driving
    below the threshold unfuelled), fitted on the same log, is not the target's form: its
    idle fuel and threshold come out wrong."""
    rng, v, p, heater, temp, dt = _drive(seed=3)
    plant = EnergyChain(predicts="fuel", idle_fuel_power_w=4_000.0, marginal_efficiency=0.36,
                        engine_off_below_w=5_000.0, charge_sustaining=True, aux_power_w=400.0)
    on = plant.engine_on(p, v)
    pos = np.maximum(p, 0)
    assist = np.where(on, rng.uniform(-0.3, 0.3, p.size) * pos, pos + 400.0)  # off: the battery carries all
    fuel = np.where(on, 4_000.0 + (pos + 400.0 - assist) / 0.36, 0.0)
    fuel = fuel + rng.normal(0, 200.0, p.size) * on
    fit = calibrate_fuel(p, v, fuel, dt, battery_w=assist)
    assert fit.chain.charge_sustaining
    assert fit.chain.marginal_efficiency == pytest.approx(0.36, rel=0.02)
    assert fit.chain.idle_fuel_power_w == pytest.approx(4_000.0, rel=0.02)
    assert fit.chain.aux_power_w == pytest.approx(400.0, rel=0.05)  # standing, the battery carries it
    assert fit.chain.engine_off_below_w == 5_000.0
    assert "charge-sustaining" in fit.parameters["engine_off_below_w"]["reading"]
    target = corrected_fuel_power(fuel, assist, 1 / 0.36)
    assert fit.chain.evaluate(p, v)["power_w"] @ dt == pytest.approx(target @ dt, rel=1e-3)
    plain = calibrate_fuel(p, v, fuel, dt, battery_w=assist, charge_sustaining=False)
    assert not plain.chain.charge_sustaining and plain.chain.engine_off_below_w != 5_000.0
    assert abs(plain.chain.idle_fuel_power_w / 4_000.0 - 1) > 0.3 and plain.chain.aux_power_w == 0.0
    # a trip that only charges the battery (and drives on it below the threshold): without
    # the correction η_m comes out biased
    charge = np.where(on, -0.2 * pos, pos)  # (no auxiliary draw)
    fuel_c = np.where(on, 4_000.0 + (pos - charge) / 0.36, 0.0)
    corrected = calibrate_fuel(p, v, fuel_c, dt, battery_w=charge)
    naive = calibrate_fuel(p, v, fuel_c, dt, battery_w=None)
    assert corrected.chain.marginal_efficiency == pytest.approx(0.36, rel=0.01)
    assert naive.chain.marginal_efficiency == pytest.approx(0.30, rel=0.02)
    # and its reading says the battery's share below the threshold is not in the log
    assert naive.chain.engine_off_below_w > 0
    assert "NOT IDENTIFIED: the log has no hybrid-battery power" in naive.parameters["engine_off_below_w"]["reading"]
    assert "NOT IDENTIFIED" not in corrected.parameters["engine_off_below_w"]["reading"]
    # a conventional engine with overrun fuel cut-off: declared, it is kept and the line
    # recovered; left out, the unfuelled overrun samples pull the idle fuel down
    cut = EnergyChain(predicts="fuel", idle_fuel_power_w=4_000.0, marginal_efficiency=0.36,
                      engine_off_below_w=-np.inf, fuel_cut_below_w=0.0)
    fuel_cut = cut.evaluate(p, v)["power_w"] + rng.normal(0, 200.0, p.size) * cut.engine_on(p, v)
    kept = calibrate_fuel(p, v, fuel_cut, dt, engine_off=-np.inf, fuel_cut_below_w=0.0)
    assert kept.chain.fuel_cut_below_w == 0.0
    assert kept.chain.idle_fuel_power_w == pytest.approx(4_000.0, rel=0.02)
    assert kept.chain.marginal_efficiency == pytest.approx(0.36, rel=0.02)
    blind = calibrate_fuel(p, v, fuel_cut, dt, engine_off=-np.inf)
    assert blind.chain.fuel_cut_below_w is None and blind.chain.idle_fuel_power_w < 3_500.0


@settings(max_examples=25, deadline=None)
@given(eta_t=st.floats(0.3, 1.0), eta_r=st.floats(0.0, 1.0), aux=st.floats(-2000.0, 2000.0),
       seed=st.integers(0, 10_000))
def test_constrained_parameters_stay_in_bounds(eta_t, eta_r, aux, seed):
    """Whatever the data (even unphysical: η_r = 0, negative auxiliary, noise), the fit stays
    in (0, 1] for efficiencies and ≥ 0 for powers and gains."""
    rng = np.random.default_rng(seed)
    n = 2000
    v = rng.uniform(0, 30, n)
    p = rng.normal(0, 20_000, n)
    heater = rng.uniform(0, 3000, n)
    meas = (np.maximum(p, 0) / eta_t + eta_r * np.minimum(p, 0) + aux - 0.5 * heater
            + rng.normal(0, 5000, n))
    fit = calibrate_battery(p, v, meas, np.full(n, 0.1), {"heater_power_w": heater},
                            loads=["heater_power_w"])
    c = fit.chain
    assert 0 < c.traction_efficiency <= 1 and 0 < c.recuperation_efficiency <= 1
    assert c.aux_power_w >= 0 and c.loads["heater_power_w"] >= 0
    assert c.recuperation_limit_w is None or c.recuperation_limit_w >= 0
    # the fitted chain writes and reads back as valid data
    chain_from_dict(c.to_dict())


# ------------------------------------------------------------------ measured targets

def _log(tmp_path, **cols):
    from sumo_drvpw.data.measured import load_measured

    n = 50
    df = pd.DataFrame({"time_s": np.arange(n) * 0.5, "speed_mps": np.linspace(0, 10, n),
                       "mass_kg": 1500.0, **{k: np.full(n, v) for k, v in cols.items()}})
    f = tmp_path / "log.csv"
    df.to_csv(f, index=False)
    return lambda target: load_measured([f], None, target=target)


def test_measured_battery_and_fuel_targets(tmp_path):
    load = _log(tmp_path, battery_voltage_v=350.0, battery_current_a=20.0, fuel_rate_gps=1.5)
    m = load("battery")
    np.testing.assert_allclose(m.power_w, 7000.0)
    assert m.target == "battery"
    f = load("fuel")
    np.testing.assert_allclose(f.power_w, 1.5e-3 * FUELS["gasoline"]["lhv_j_per_kg"])
    np.testing.assert_allclose(f.battery_w, 7000.0)
    with pytest.raises(UserError, match="target must be one of"):
        load("tank")


def test_fuel_target_from_volume_flow_and_missing_columns(tmp_path):
    load = _log(tmp_path, fuel_flow_rate_hour_lph=3.6)
    g = FUELS["gasoline"]
    np.testing.assert_allclose(load("fuel").power_w, 3.6 * g["density_kg_per_l"] / 3600 * g["lhv_j_per_kg"])
    with pytest.raises(UserError, match="battery_voltage_v"):
        load("battery")


def test_fuel_target_from_an_app_computed_flow_and_an_ambiguous_pair(tmp_path):
    """Car Scanner's 'Calculated instant fuel rate (L/h)' (from the MAF) is a fuel flow
    too; of two, the one named 'fuel…' is used; two of the same standing say which."""
    g = FUELS["gasoline"]
    want = 2.4 * g["density_kg_per_l"] / 3600 * g["lhv_j_per_kg"]
    np.testing.assert_allclose(_log(tmp_path, calculated_instant_fuel_rate_lph=2.4)("fuel").power_w, want)
    both = _log(tmp_path, calculated_instant_fuel_rate_lph=9.9, fuel_flow_rate_hour_lph=2.4)("fuel")
    np.testing.assert_allclose(both.power_w, want)
    with pytest.raises(UserError, match="several could be: calculated_instant_fuel_rate_lph, "
                                        "estimated_fuel_flow_lph"):
        _log(tmp_path, calculated_instant_fuel_rate_lph=2.4, estimated_fuel_flow_lph=2.5)("fuel")


def test_fuel_target_from_a_petrol_engines_mass_air_flow(tmp_path):
    """No fuel flow logged, but the mass air flow (OBD PID 0x10) with the fuel trims of two
    banks and the commanded λ: ṁ_f = MAF / AFR_st × (1 + mean over banks of (short + long)
    / 100) / λ — by hand; a diesel's air flow gives no fuel; AFR_st from the carbon
    fraction behind the CO₂ factor (14.59, textbooks 14.6–14.7)."""
    from sumo_drvpw.model.constants import AFR_STOICH_GASOLINE

    assert AFR_STOICH_GASOLINE == pytest.approx(14.59, abs=0.01)
    g = FUELS["gasoline"]
    load = _log(tmp_path, mass_air_flow_rate_gps=20.0, fuel_trim_bank_1_short_term_pct=4.0,
                fuel_trim_bank_1_long_term_pct=-2.0, short_term_fuel_trim_bank_2_pct=6.0,
                long_term_fuel_trim_bank_2_pct=0.0, commanded_equivalence_ratio=0.9)
    m = load("fuel")
    want = 20.0e-3 / AFR_STOICH_GASOLINE * (1 + (2.0 + 6.0) / 2 / 100) / 0.9 * g["lhv_j_per_kg"]
    np.testing.assert_allclose(m.power_w, want, rtol=1e-12)
    assert m.source.startswith("ESTIMATE: fuel from the mass air flow mass_air_flow_rate_gps")
    # a logged fuel flow wins over the estimate
    np.testing.assert_allclose(_log(tmp_path, mass_air_flow_rate_gps=20.0, fuel_rate_gps=1.0)("fuel").power_w,
                               1e-3 * g["lhv_j_per_kg"])
    from sumo_drvpw.data.powertrain import measured_fuel_power

    log = _log(tmp_path, mass_air_flow_rate_gps=20.0)("fuel").log
    with pytest.raises(UserError, match="'mass_air_flow_rate_gps' is an air flow, and a diesel engine's fuel"):
        measured_fuel_power(log, fuel="diesel")
    with pytest.raises(UserError, match="several air flows: mass_air_flow_rate_gps, mass_air_flow_sensor_a_gps"):
        _log(tmp_path, mass_air_flow_rate_gps=20.0, mass_air_flow_sensor_a_gps=20.5)("fuel")


def test_cli_calibrates_a_conventional_engine_from_its_air_flow(tmp_path, capsys):
    """A petrol car's OBD log with only its mass air flow and fuel trims: a planted Willans
    line with the engine running throughout (idle 9 kW of fuel, η 0.33) is recovered by
    calibrate --target fuel through the air-flow estimate, engine always on."""
    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.model.constants import AFR_STOICH_GASOLINE

    rng = np.random.default_rng(11)
    df = corpus.sine_trips(rng, 5000, 11.0)
    road = corpus.road_equation(tmp_path)
    x = from_frame(df).inputs()
    plant = EnergyChain(predicts="fuel", idle_fuel_power_w=9000.0, marginal_efficiency=0.33,
                        engine_off_below_w=-np.inf)
    kgps = plant.evaluate(load_equation(road).power(x), x.v)["power_w"] / FUELS["gasoline"]["lhv_j_per_kg"]
    trim = rng.normal(0, 3, len(df))
    df["fuel_trim_bank_1_short_term_pct"] = trim
    df["maf_gps"] = kgps * 1000 * AFR_STOICH_GASOLINE / (1 + trim / 100)
    log = tmp_path / "obd.csv"
    df.to_csv(log, index=False)
    out = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(log), "--target", "fuel", "--equation", str(road),
                     "--out", str(out)]) == 0
    ch = load_equation(out).chain
    assert ch.engine_off_below_w == -np.inf
    assert ch.marginal_efficiency == pytest.approx(0.33, rel=1e-3)
    assert ch.idle_fuel_power_w == pytest.approx(9000.0, rel=1e-3)


# ------------------------------------------------------------------ command line

def _planted_battery_log(tmp_path):
    """Two trips with a known road load and a planted chain; battery V·I from it."""
    rng = np.random.default_rng(7)
    frames = []
    plant = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.7,
                        aux_power_w=500.0, loads={"heater_power_w": 1.0})
    for trip in ("T1", "T2"):
        n = 6000
        t = np.arange(n) * 0.1
        v = np.clip(12 + 10 * np.sin(t / 25.0) + rng.normal(0, 0.05, n), 0, None)
        v[:300] = 0.0  # a standstill start: auxiliary only
        heater = np.where(t > 200, 2000.0, 0.0)
        frames.append(pd.DataFrame({"trip_id": trip, "time_s": t, "speed_mps": v, "mass_kg": 1500.0,
                                    "heater_power_w": heater}))
    df = pd.concat(frames, ignore_index=True)
    road = tmp_path / "road.toml"
    road.write_text('[equation]\nname = "road"\n[terms]\nacc = 1.0\nv1 = 150.0\nv3 = 0.35\n', encoding="utf-8")
    from sumo_drvpw.data.log import from_frame

    x = from_frame(df).inputs()  # inputs as the reader derives them (acceleration from speed)
    p = load_equation(road).power(x)
    bat = plant.evaluate(p, x.v, signals={"heater_power_w": df["heater_power_w"].to_numpy()})["power_w"]
    df["battery_voltage_v"] = 360.0
    df["battery_current_a"] = bat / 360.0
    f = tmp_path / "log.csv"
    df.to_csv(f, index=False)
    return f, road


def test_cli_calibrate_battery_then_compare_uses_the_chain(tmp_path, capsys):
    import json

    from sumo_drvpw.cli import main as cli_main

    log, road = _planted_battery_log(tmp_path)
    eq = tmp_path / "chain.toml"
    assert cli_main(["calibrate", str(log), "--target", "battery", "--equation", str(road),
                     "--load", "heater_power_w", "--out", str(eq)]) == 0
    ch = load_equation(eq).chain
    assert ch.predicts == "battery" and ch.traction_efficiency == pytest.approx(0.9, rel=0.02)
    assert ch.aux_power_w == pytest.approx(500.0, rel=0.02) and ch.std_err
    out = tmp_path / "cmp"
    assert cli_main(["compare", str(log), "--equation", str(eq), "--out", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text(encoding="utf-8"))["equations"]["chain"]
    assert rep["predicts"] == "battery"
    trips = rep["trip_net_energy"]["trips"]
    assert set(trips) == {"T1", "T2"}
    for t in trips.values():  # the planted chain is recovered: per-trip battery energy within 1 %
        assert abs(t["error"]) < 0.01
    # the report's traction ratio is the battery's too (it was the terms' wheel traction over
    # the measured battery traction: 0.75 on i3 logs); the terms' total stays under energy_j
    te = rep["trip_energy"]["trips"]
    p_bat = sum(t["predicted_j"] for t in te.values())
    assert rep["predicted_traction_energy_j"] == pytest.approx(p_bat, rel=1e-9)
    assert rep["traction_energy_ratio"] == pytest.approx(p_bat / rep["measured_traction_energy_j"], rel=1e-9)
    assert abs(rep["traction_energy_ratio"] - 1.0) < 0.01
    assert rep["energy_j"]["total"] < 0.95 * p_bat  # the wheel needs less than the battery gives
    md = (out / "report.md").read_text(encoding="utf-8")
    assert f"{p_bat / 3.6e6:.3f}" in md and "the target's (the chain's battery or fuel power)" in md
    # a chain beside an equation without one (a rehearsal: the battery target dropped without
    # a word): compared at the wheels, and said, on the console and in the report's context
    capsys.readouterr()
    for engine in ([], ["--engine", "memory"]):
        mixed = tmp_path / f"mixed{len(engine)}"
        assert cli_main(["compare", str(log), "--equation", str(eq), "--equation", str(road),
                         "--out", str(mixed)] + engine) == 0
        said = capsys.readouterr().out
        assert "note: the equations predict different targets" in said and "--target battery" in said
        assert json.loads((mixed / "report.json").read_text(encoding="utf-8"))["settings"]["target"] == "wheel"
        assert "**target**: the equations predict different targets" in (mixed / "report.md").read_text(encoding="utf-8")
    # an equation at the powertrain output (drvpw_prius3) is a driving power: no such note
    assert cli_main(["compare", str(log), "--equation", str(road), "--equation", "drvpw_prius3",
                     "--out", str(tmp_path / "po")]) == 0
    assert "different targets" not in capsys.readouterr().out
    # a driving-power comparison of a log without a driving-power source is refused (exit 2)
    assert cli_main(["compare", str(log), "--equation", str(eq), "--target", "fuel",
                     "--out", str(tmp_path / "f")]) == 2
    assert "fuel-flow column" in capsys.readouterr().err
    assert not (tmp_path / "f").exists()


# ------------------------------------------------------------------ SUMO accounts

def _city_sumocfg():
    """The city scenario's SUMO config (package data, or the repo's scenarios/ folder)."""
    from pathlib import Path

    repo = Path(__file__).resolve().parent.parent
    for p in (repo / "sumo_drvpw" / "sim" / "builtin" / "scenarios" / "city.sumocfg",
              repo / "scenarios" / "city.sumocfg"):
        if p.is_file():
            return p
    pytest.skip("city scenario not found")


def _chain_equations():
    fuel_eq = load_equation("drvpw_prius3")
    fuel_eq.chain = EnergyChain(predicts="fuel", idle_fuel_power_w=5000.0, marginal_efficiency=0.36,
                                engine_off_below_w=4000.0)
    bev = equation_from_dict({"equation": {"name": "bev"}, "terms": {"acc": 1.05, "grade": 1.0, "roll": 0.009,
                                                                       "aero_rho": 0.6},
                              "chain": {"predicts": "battery", "traction_efficiency": 0.9,
                                        "recuperation_efficiency": 0.7, "recuperation_limit_w": 20000.0,
                                        "aux_power_w": 500.0}})
    return [fuel_eq, bev]


@pytest.mark.parametrize("scenario", ["city", "highway"])
def test_run_scenario_reports_battery_and_fuel_per_class(tmp_path, scenario):
    """`run_scenario` with chain equations writes kWh/km and L/100 km per class; vehicle,
    edge and class tables balance; auxiliary energy = 500 W × time in the network."""
    pytest.importorskip("libsumo")
    import pandas as pd_

    from pathlib import Path

    from sumo_drvpw.sim import run_scenario

    repo = Path(__file__).resolve().parent.parent
    path = next((p for p in (repo / "sumo_drvpw" / "sim" / "builtin" / "scenarios" / f"{scenario}.toml",
                             repo / "scenarios" / f"{scenario}.toml") if p.is_file()), None)
    if path is None:
        pytest.skip(f"scenario {scenario} not found")
    res = run_scenario(path, tmp_path / "out", equations=_chain_equations(), end=150.0,
                       figures=False, edgedata=True, period=60.0)
    cls = res.summary["chain"]["classes"]
    assert {r["equation"] for r in cls} == {"drvpw_prius3", "bev"}
    for r in cls:
        if r["equation"] == "bev":
            assert 0.05 < r["net_kwh_per_km"] < 1.0
        else:
            assert 1.0 < r["fuel_l_per_100km"] < 40.0
    tabs = {k: pd_.read_csv(tmp_path / "out" / f"chain_{k}.csv") for k in ("vehicles", "edges", "classes")}
    for col in ("net_kwh", "auxiliary_kwh", "fuel_l", "co2_kg"):
        tot = [t[col].sum() for t in tabs.values()]
        np.testing.assert_allclose(tot, tot[0], rtol=1e-9, atol=1e-12)
    # edgeData: the intervals' battery and fuel per edge add up to the run's totals
    import xml.etree.ElementTree as ET

    root = ET.parse(tmp_path / "out" / "edgedata.xml").getroot()
    assert len(root.findall("interval")) >= 3
    for attr, col, eq in (("bev_battery_net_kwh", "net_kwh", "bev"), ("drvpw_prius3_fuel_l", "fuel_l", "drvpw_prius3")):
        xml_sum = sum(float(e.get(attr)) for e in root.iter("edge"))
        c = tabs["classes"]
        assert xml_sum == pytest.approx(c[c["equation"] == eq][col].sum(), rel=1e-4, abs=1e-5)
    led = res.ledger
    bev_rows = tabs["vehicles"][tabs["vehicles"]["equation"] == "bev"]
    t_in = dict(zip(led.veh_ids, led.chain.vehicle_time(led.n_veh)[:, led.chain.booked("bev")]))
    np.testing.assert_allclose(bev_rows["auxiliary_kwh"], 500.0 * bev_rows["key"].map(t_in) / 3.6e6,
                               rtol=1e-9)


def test_cold_starts_are_booked_once_per_departing_vehicle(tmp_path):
    """A real SUMO run (city, 150 s) with and without ``cold_start``: every vehicle the fuel
    chain books burns its cold_start_fuel_l more as it decays over the first minutes, V ·
    (1 − e^(−T/τ)) for T seconds booked (a short trip takes part of a warm-up, not all of it:
    a 66-s hop booked a whole one, found by a sweep), reported as cold_start_l; the battery
    chain's accounts are unchanged; vehicle, edge, class and edgeData totals agree; off, no
    cold-start column appears."""
    pytest.importorskip("libsumo")
    import dataclasses
    import xml.etree.ElementTree as ET

    from sumo_drvpw.sim import run_scenario

    cfg = _city_sumocfg()
    eqs = _chain_equations()
    eqs[0].chain = dataclasses.replace(eqs[0].chain, cold_start_fuel_l=0.07)
    path = cfg.with_suffix(".toml")
    tabs, summ = {}, {}
    for on in (False, True):
        res = run_scenario(path, tmp_path / str(on), equations=eqs, end=150.0, figures=False,
                           edgedata=True, cold_start=on)
        summ[on] = res.summary["chain"]["cold_start"]
        tabs[on] = {k: pd.read_csv(tmp_path / str(on) / f"chain_{k}.csv") for k in ("vehicles", "edges", "classes")}
    fuel = {on: tabs[on]["vehicles"].query("equation == 'drvpw_prius3'").set_index("key") for on in tabs}
    assert len(fuel[True]) > 20 and fuel[True].index.equals(fuel[False].index)
    booked_s = res.vehicles.query("equation == 'drvpw_prius3'").set_index("vehicle")["time_s"]
    share = 1.0 - np.exp(-fuel[True].index.map(booked_s).to_numpy(float) / FUEL_COLD_START_TAU_S)
    assert share.min() < 0.5 < share.max()  # trips cut by the run's end and short ones
    np.testing.assert_allclose(fuel[True]["fuel_l"] - fuel[False]["fuel_l"], 0.07 * share, rtol=1e-9)
    np.testing.assert_allclose(fuel[True]["cold_start_l"], 0.07 * share, rtol=1e-12)
    g = FUELS["gasoline"]
    np.testing.assert_allclose(fuel[True]["co2_kg"] - fuel[False]["co2_kg"],
                               0.07 * share * g["density_kg_per_l"] * g["co2_kg_per_kg"], rtol=1e-9)
    bev = {on: tabs[on]["vehicles"].query("equation == 'bev'").reset_index(drop=True) for on in tabs}
    pd.testing.assert_frame_equal(bev[True].drop(columns="cold_start_l"), bev[False])
    assert "cold_start_l" not in tabs[False]["vehicles"] and bev[True]["cold_start_l"].isna().all()
    for col in ("fuel_l", "cold_start_l"):
        tot = [t[col].sum() for t in tabs[True].values()]
        np.testing.assert_allclose(tot, tot[0], rtol=1e-9)
    assert summ[True] == {**summ[True], "booked": True, "vehicles": len(fuel[True])}
    assert summ[True]["fuel_l_per_start"] == {"drvpw_prius3": 0.07}
    assert summ[False]["booked"] is False and summ[False]["vehicles"] == 0
    root = ET.parse(tmp_path / "True" / "edgedata.xml").getroot()
    xml_sum = sum(float(e.get("drvpw_prius3_cold_start_l", 0.0)) for e in root.iter("edge"))
    assert xml_sum == pytest.approx(0.07 * share.sum(), rel=1e-5)
    # a share of the departures starts cold: that share of the litres, at every departure
    half = run_scenario(path, tmp_path / "half", equations=eqs, end=150.0, figures=False, edgedata=False,
                        cold_start=0.5)
    veh = pd.read_csv(tmp_path / "half" / "chain_vehicles.csv").query("equation == 'drvpw_prius3'")
    np.testing.assert_allclose(veh["cold_start_l"], 0.035 * share, rtol=1e-12)
    assert half.summary["chain"]["cold_start"]["share"] == 0.5
    # in the cold: the run's air temperature sets each start's litres (V_ref + s·(T_ref − T))
    eqs[0].chain = dataclasses.replace(eqs[0].chain, cold_start_fuel_l_per_k=0.003, cold_start_ref_c=23.9)
    res = run_scenario(path, tmp_path / "cold", equations=eqs, end=150.0, figures=False, edgedata=False,
                       cold_start=True, air_temperature_c=-6.1)
    veh = pd.read_csv(tmp_path / "cold" / "chain_vehicles.csv").query("equation == 'drvpw_prius3'")
    np.testing.assert_allclose(veh["cold_start_l"], (0.07 + 0.003 * 30.0) * share, rtol=1e-12)
    assert res.summary["chain"]["cold_start"]["fuel_l_per_start"]["drvpw_prius3"] == pytest.approx(0.16)
    assert not any("no air temperature" in w for w in res.summary["warnings"])
    # a warm engine in the cold: every step's fuel × (1 + r·30 K), the cold starts unchanged
    eqs[0].chain = dataclasses.replace(eqs[0].chain, running_fuel_per_k=0.002)
    res = run_scenario(path, tmp_path / "cold_run", equations=eqs, end=150.0, figures=False, edgedata=False,
                       cold_start=True, air_temperature_c=-6.1)
    run = pd.read_csv(tmp_path / "cold_run" / "chain_vehicles.csv").query("equation == 'drvpw_prius3'")
    assert run["key"].tolist() == veh["key"].tolist()
    np.testing.assert_allclose(run["fuel_l"] - run["cold_start_l"], (veh["fuel_l"] - veh["cold_start_l"]) * 1.06,
                               rtol=1e-9)
    np.testing.assert_allclose(run["cold_start_l"], veh["cold_start_l"], rtol=1e-12)
    assert res.summary["chain"]["warm_running"]["drvpw_prius3"]["factor"] == pytest.approx(1.06)
    # the city scenario's own air (20 °C): 3.9 K below the reference; a run that gives no air
    # temperature reads the default air's 20 °C, as the HVAC and cold starts do, and says so
    res = run_scenario(path, tmp_path / "city_air", equations=eqs, end=150.0, figures=False, edgedata=False)
    assert res.summary["chain"]["warm_running"]["drvpw_prius3"]["factor"] == pytest.approx(1 + 0.002 * 3.9)
    from sumo_drvpw.sim.chain import chain_ledger
    led = chain_ledger(eqs, 3)
    q = led.book(np.array([0]), np.array([1]), np.array([10.0]), 1.0, np.array([[5_000.0, 5_000.0]]))
    q_warm = chain_ledger([dataclasses.replace(eqs[0], chain=dataclasses.replace(eqs[0].chain, running_fuel_per_k=0.0)),
                           eqs[1]], 3).book(np.array([0]), np.array([1]), np.array([10.0]), 1.0,
                                            np.array([[5_000.0, 5_000.0]]))
    np.testing.assert_allclose(q[0, :3], q_warm[0, :3] * (1 + 0.002 * 3.9), rtol=1e-12)  # fuel_j, fuel_l, co2
    assert led.air_temperature_assumed


def _warm_part(res, keys) -> np.ndarray:
    """The part of a whole cold start each vehicle ``keys`` books over its T seconds booked
    under drvpw_prius3 in run ``res``: 1 − e^(−T/τ) (sim/chain.py)."""
    t = res.vehicles.query("equation == 'drvpw_prius3'").set_index("vehicle")["time_s"]
    return 1.0 - np.exp(-pd.Index(keys).map(t).to_numpy(float) / FUEL_COLD_START_TAU_S)


def test_cold_start_shares_by_vtype_and_vclass(tmp_path):
    """A real SUMO run (city network, two vTypes of one vClass, 150 s): a vType's own
    ``cold_start`` replaces the run's (through traffic 0, the rest cold), a vClass's share
    applies where the run's is off; the summary counts the departures and their shares;
    vehicle and class totals agree."""
    pytest.importorskip("libsumo")
    import dataclasses

    from sumo_drvpw.sim import run_scenario

    b = _city_sumocfg().parent
    net = (b.parent / "networks" / "city.net.xml").resolve()
    rou = tmp_path / "two.rou.xml"
    rou.write_text('<routes>\n'
                   '  <flow id="local" type="prius3" from="c00c10" to="c34c44" begin="0" end="100" period="10"/>\n'
                   '  <flow id="through" type="prius3_hw" from="c40c30" to="c04c14" begin="0" end="100" period="10"/>\n'
                   '</routes>\n', encoding="utf-8")
    eqs = _chain_equations()
    eqs[0].chain = dataclasses.replace(eqs[0].chain, cold_start_fuel_l=0.07)

    def run(name, extra, add=b / "prius3.vtype.xml"):
        sc = tmp_path / f"{name}.toml"
        sc.write_text(f'equations = ["drvpw_prius3"]\n[sumo]\nnet = "{net.as_posix()}"\n'
                      f'routes = ["{rou.as_posix()}"]\nadditional = ["{add.as_posix()}"]\n'
                      f'end = 150\n{extra}', encoding="utf-8")
        res = run_scenario(sc, tmp_path / name, equations=eqs, figures=False, edgedata=False)
        veh = pd.read_csv(tmp_path / name / "chain_vehicles.csv").query("equation == 'drvpw_prius3'")
        cls = pd.read_csv(tmp_path / name / "chain_classes.csv").query("equation == 'drvpw_prius3'")
        assert veh["cold_start_l"].sum() == pytest.approx(cls["cold_start_l"].sum(), rel=1e-9)
        # per whole cold start: each vehicle booked the part 1 − e^(−T/τ) of its T seconds
        veh["cold_start_l"] /= _warm_part(res, veh["key"])
        return veh.assign(through=veh["key"].str.startswith("through")), res.summary["chain"]["cold_start"]

    veh, summ = run("by_vtype", "[vehicles]\ncold_start = true\n[vtypes.prius3_hw]\ncold_start = 0\n")
    assert veh["through"].sum() >= 5 and (~veh["through"]).sum() >= 5
    np.testing.assert_allclose(veh.loc[~veh["through"], "cold_start_l"], 0.07, rtol=1e-12)
    assert (veh.loc[veh["through"], "cold_start_l"] == 0).all()
    assert summ["vehicles"] == (~veh["through"]).sum() == summ["expected_cold_starts"]
    assert summ["share_by_vtype"] == {"prius3_hw": 0.0} and summ["booked"] is True
    veh, summ = run("by_vclass", "[vclasses.passenger]\ncold_start = 0.5\n")  # the run's share: off
    np.testing.assert_allclose(veh["cold_start_l"], 0.035, rtol=1e-12)
    assert summ["vehicles"] == len(veh) and summ["expected_cold_starts"] == pytest.approx(0.5 * len(veh))
    assert summ["share"] == 0.0 and summ["share_by_vclass"] == {"passenger": 0.5}
    # the vType's own param in the route files; the scenario's [vtypes] wins over it
    add = tmp_path / "types.add.xml"
    add.write_text((b / "prius3.vtype.xml").read_text(encoding="utf-8").replace(
        'speedFactor="normc(0.85,0.06,0.72,1.0)"/>',
        'speedFactor="normc(0.85,0.06,0.72,1.0)"><param key="drvpw.cold_start" value="0.25"/></vType>'),
        encoding="utf-8")
    veh, summ = run("by_param", "[vehicles]\ncold_start = true\n", add)
    np.testing.assert_allclose(veh.loc[veh["through"], "cold_start_l"], 0.0175, rtol=1e-12)
    np.testing.assert_allclose(veh.loc[~veh["through"], "cold_start_l"], 0.07, rtol=1e-12)
    assert summ["share_by_vtype"] == {"prius3_hw": 0.25}
    veh, _ = run("param_and_scenario", "[vtypes.prius3_hw]\ncold_start = 1\n", add)
    np.testing.assert_allclose(veh.loc[veh["through"], "cold_start_l"], 0.07, rtol=1e-12)
    assert (veh.loc[~veh["through"], "cold_start_l"] == 0).all()  # the run's share: off
    add.write_text(add.read_text(encoding="utf-8").replace('value="0.25"', 'value="often"'), encoding="utf-8")
    with pytest.raises(UserError, match=r"types.add.xml: vType 'prius3_hw': drvpw.cold_start .*'often'"):
        run("bad_param", "", add)


def test_cold_start_shares_of_single_vehicles_and_flows(tmp_path):
    """A real SUMO run (city, 150 s) whose route file gives single vehicles and a flow their
    own ``drvpw.cold_start`` param: each books its own share, over the vType's and the run's;
    a flow's share reaches every vehicle ``<flow>.<n>``; vehicles without one keep their
    vType's. Replayed from the run's FCD with the same route files, every vehicle books the
    same litres. A bad value is refused with its file and vehicle."""
    pytest.importorskip("libsumo")
    import dataclasses

    from sumo_drvpw.sim import run_scenario
    from sumo_drvpw.sim.fcd import process_fcd

    b = _city_sumocfg().parent
    net = (b.parent / "networks" / "city.net.xml").resolve()
    rou = tmp_path / "own.rou.xml"
    rou.write_text('<routes>\n'  # sorted by departure, as SUMO reads them
                   '  <flow id="local" type="prius3" from="c00c10" to="c34c44" begin="0" end="100" period="10">'
                   '<param key="drvpw.cold_start" value="0.5"/></flow>\n'
                   '  <flow id="through" type="prius3_hw" from="c40c30" to="c04c14" begin="0" end="100" period="10"/>\n'
                   '  <vehicle id="home.a" type="prius3" depart="0"><route edges="c00c10 c10c20"/>'
                   '<param key="drvpw.cold_start" value="true"/></vehicle>\n'
                   '  <trip id="errand" type="prius3" depart="5" from="c10c20" to="c20c30">'
                   '<param key="drvpw.cold_start" value="0.4"/></trip>\n'
                   '</routes>\n', encoding="utf-8")
    eqs = _chain_equations()
    eqs[0].chain = dataclasses.replace(eqs[0].chain, cold_start_fuel_l=0.07)
    sc = tmp_path / "own.toml"
    sc.write_text(f'equations = ["drvpw_prius3"]\n[sumo]\nnet = "{net.as_posix()}"\n'
                  f'routes = ["{rou.as_posix()}"]\nadditional = ["{(b / "prius3.vtype.xml").as_posix()}"]\n'
                  'end = 150\n[vtypes.prius3]\ncold_start = 0\n[vtypes.prius3_hw]\ncold_start = 0.25\n',
                  encoding="utf-8")
    res = run_scenario(sc, tmp_path / "live", equations=eqs, figures=False, edgedata=False,
                       options=["--fcd-output", str(tmp_path / "fcd.xml"), "--precision", "6"])
    veh = pd.read_csv(tmp_path / "live" / "chain_vehicles.csv").query("equation == 'drvpw_prius3'")
    litres = veh.set_index("key")["cold_start_l"]
    part = pd.Series(_warm_part(res, litres.index), index=litres.index)
    expect = {k: 0.07 * part[k] * (1.0 if k == "home.a" else 0.4 if k == "errand" else
                                   0.5 if k.startswith("local.") else 0.25) for k in litres.index}
    assert {"home.a", "errand"} <= set(litres.index)
    assert sum(k.startswith("local.") for k in litres.index) >= 5
    assert sum(k.startswith("through.") for k in litres.index) >= 5
    np.testing.assert_allclose(litres, pd.Series(expect)[litres.index], rtol=1e-12)
    summ = res.summary["chain"]["cold_start"]
    assert summ["own_share_vehicles"] == 2 and summ["own_share_flows"] == 1
    assert summ["expected_cold_starts"] == pytest.approx(sum(expect[k] / part[k] for k in expect) / 0.07)
    # the FCD replay reads the same route files: the same shares, vehicle by vehicle
    process_fcd(tmp_path / "fcd.xml", scenario=sc, out_dir=tmp_path / "fcd", equations=eqs, end=150,
                figures=False)
    rep = pd.read_csv(tmp_path / "fcd" / "chain_vehicles.csv").query("equation == 'drvpw_prius3'")
    pd.testing.assert_series_equal(rep.set_index("key")["cold_start_l"].sort_index(), litres.sort_index())
    rou.write_text(rou.read_text(encoding="utf-8").replace('value="0.4"', 'value="1.5"'), encoding="utf-8")
    with pytest.raises(UserError, match=r"own.rou.xml: trip 'errand': drvpw.cold_start .*'1.5'"):
        run_scenario(sc, tmp_path / "bad", equations=eqs, figures=False, edgedata=False)


def test_cabin_warm_up_is_booked_at_cold_departures(tmp_path):
    """A battery chain's cabin warm-up (``[chain.hvac] warmup_j_per_k``): a real SUMO run
    (city, 150 s, air at 0 °C) with cold starts on and off. Each booked vehicle's auxiliary
    and net energy grow by warmup × (20 − 0) K × (1 − e^(−T/300 s)) over its T seconds (the
    warm-up as it decays: a 66-s hop booked a whole one, 32 kW, found by a sweep); traction and recuperation do not
    change; a share books that share; the summary gives the kWh per start; the TOML round
    trip keeps the key, and a fuel chain may not carry it."""
    pytest.importorskip("libsumo")
    import dataclasses

    from sumo_drvpw.sim import run_scenario

    path = _city_sumocfg().with_suffix(".toml")
    eqs = _chain_equations()
    hv = {"column": "ambient_c", "setpoint_c": 20.0, "heating_w_per_k": 100.0, "cooling_w_per_k": 0.0,
          "warmup_j_per_k": 60000.0}
    eqs[1].chain = dataclasses.replace(eqs[1].chain, hvac=hv)
    assert chain_from_dict(eqs[1].chain.to_dict()).hvac == hv
    with pytest.raises(UserError, match="warmup_j_per_k.*only for predicts"):
        chain_from_dict({"predicts": "fuel", "hvac": hv})
    veh, summ = {}, {}
    for share in (0.0, 1.0, 0.5):
        res = run_scenario(path, tmp_path / str(share), equations=eqs, end=150.0, figures=False, edgedata=False,
                           cold_start=share, air_temperature_c=0.0)
        summ[share] = res.summary["chain"]["cold_start"]
        veh[share] = pd.read_csv(tmp_path / str(share) / "chain_vehicles.csv").query(
            "equation == 'bev'").set_index("key")
    per_start = 60000.0 * 20.0 / 3.6e6
    assert len(veh[1.0]) > 20 and veh[1.0].index.equals(veh[0.0].index)
    t = res.vehicles.query("equation == 'bev'").set_index("vehicle")["time_s"]
    part = 1.0 - np.exp(-veh[1.0].index.map(t).to_numpy(float) / CABIN_WARMUP_TAU_S)
    assert part.min() < 0.3 and part.max() < 0.5  # 150 s: no trip takes half its warm-up
    for share in (1.0, 0.5):
        for col in ("auxiliary_kwh", "net_kwh"):
            np.testing.assert_allclose(veh[share][col] - veh[0.0][col], share * per_start * part, rtol=1e-9)
        for col in ("traction_kwh", "recuperated_kwh"):
            np.testing.assert_allclose(veh[share][col], veh[0.0][col], rtol=1e-12)
    assert summ[1.0]["battery_kwh_per_start"] == {"bev": pytest.approx(per_start)}
    assert summ[1.0]["vehicles"] == len(veh[1.0]) and summ[0.0]["booked"] is False


@settings(max_examples=40, deadline=None)
@given(shares=st.lists(st.sampled_from([0.0, 0.25, 0.5, 1.0]), min_size=1, max_size=12),
       air=st.floats(-30.0, 40.0), steps=st.integers(1, 4), seed=st.integers(0, 2 ** 16))
def test_cold_start_shares_book_share_times_one_start(shares, air, steps, seed):
    """ChainLedger without SUMO: vehicles departing with any shares book, over any steps on
    any edges, share × one cold start × (1 − e^(−T/τ)) for T seconds booked — litres for the
    fuel chain (τ = 505/3 s), the cabin's warm-up for the battery chain (auxiliary and net,
    τ = 300 s) — and, once the trip is long, the whole share × one cold start; vehicle and
    edge totals agree; the counts are the vehicles with a share > 0 and the sum of the shares."""
    from sumo_drvpw.sim.chain import ChainLedger

    fuel = EnergyChain(predicts="fuel", idle_fuel_power_w=4000.0, marginal_efficiency=0.35,
                       engine_off_below_w=-np.inf, cold_start_fuel_l=0.06, cold_start_fuel_l_per_k=0.003)
    bat = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.7, aux_power_w=300.0,
                      hvac={"column": "ambient_c", "setpoint_c": 20.0, "heating_w_per_k": 50.0,
                            "cooling_w_per_k": 0.0, "warmup_j_per_k": 80e3})
    n, n_edges = len(shares), 5

    def run(on):
        led = ChainLedger(["f", "b"], [fuel, bat], n_edges, signal_values={"ambient_c": air},
                          cold_start=1.0 if on else 0.0)
        if on:
            led.start(np.arange(n), shares)
        r = np.random.default_rng(seed)
        for _ in range(steps):
            led.book(np.arange(n), r.integers(0, n_edges, n), r.uniform(0, 20, n), 0.5,
                     r.normal(0, 2e4, (n, 2)))
        return led

    def check(on, off, t_s):
        d = on.vehicle_totals(n) - off.vehicle_totals(n)
        sh = np.asarray(shares)
        part_f, part_b = (1.0 - np.exp(-t_s / tau) for tau in (FUEL_COLD_START_TAU_S, CABIN_WARMUP_TAU_S))
        np.testing.assert_allclose(d[:, 0, 7], sh * fuel.cold_start(air)["fuel_l"] * part_f, rtol=1e-9, atol=1e-15)
        np.testing.assert_allclose(d[:, 0, 5], d[:, 0, 7], rtol=1e-9, atol=1e-15)
        warm = sh * bat.cold_start(air)["battery_j"] * part_b
        for q in (2, 3):
            np.testing.assert_allclose(d[:, 1, q], warm, rtol=1e-8, atol=1e-6)  # a difference of MJ
        np.testing.assert_allclose(d[:, 1, :2], 0.0, atol=1e-6)
        np.testing.assert_allclose(on.edge.sum(axis=0), on.vehicle_totals(n).sum(axis=0), rtol=1e-9, atol=1e-6)
        assert on.cold_starts == int((sh > 0).sum()) and on.cold_starts_expected == pytest.approx(sh.sum())

    on, off = run(True), run(False)
    check(on, off, 0.5 * steps)
    for led in (on, off):  # then a long stretch at rest: the whole cold start, and no more
        for _ in range(2):
            led.book(np.arange(n), np.zeros(n, np.int64), np.zeros(n), 10 * CABIN_WARMUP_TAU_S, np.zeros((n, 2)))
    check(on, off, np.inf)


@settings(max_examples=60, deadline=None)
@given(own=st.dictionaries(st.sampled_from(["a", "b.1", "f.2"]), st.sampled_from([0.0, 0.3, 1.0]), max_size=3),
       flows=st.dictionaries(st.sampled_from(["f", "g", "b"]), st.sampled_from([0.0, 0.6, 1.0]), max_size=3),
       vtypes=st.dictionaries(st.sampled_from(["car", "van"]), st.sampled_from([0.0, 0.2]), max_size=2),
       vclasses=st.dictionaries(st.sampled_from(["passenger", "delivery"]), st.sampled_from([0.0, 0.7]),
                                max_size=2),
       run_share=st.sampled_from([0.0, 0.4, 1.0]),
       vid=st.sampled_from(["a", "b.1", "f.2", "f.x", "g.10", "h", "g"]),
       vtype=st.sampled_from(["car", "van", "bus"]), vclass=st.sampled_from(["passenger", "delivery", "bus"]))
def test_a_vehicles_share_is_its_most_specific_one(own, flows, vtypes, vclasses, run_share, vid, vtype, vclass):
    """ChainLedger.share_of: the vehicle's own param, else its flow's (ids ``<flow>.<n>``,
    n digits only), else its vType's, else its vClass's, else the run's share; cold starts
    are on exactly when any of these is above 0."""
    from sumo_drvpw.sim.chain import ChainLedger

    fuel = EnergyChain(predicts="fuel", idle_fuel_power_w=4000.0, marginal_efficiency=0.35,
                       engine_off_below_w=-np.inf, cold_start_fuel_l=0.06)
    led = ChainLedger(["f"], [fuel], 2, cold_start=run_share, cold_start_vtypes=vtypes,
                      cold_start_vclasses=vclasses, cold_start_vehicles=own, cold_start_flows=flows)
    head, _, tail = vid.rpartition(".")
    if vid in own:
        want = own[vid]
    elif head and tail.isdigit() and head in flows:
        want = flows[head]
    elif vtype in vtypes:
        want = vtypes[vtype]
    else:
        want = vclasses.get(vclass, run_share)
    assert led.share_of(vtype, vclass, vid) == want
    assert led.share_of(vtype, vclass) == (vtypes[vtype] if vtype in vtypes else vclasses.get(vclass, run_share))
    every = [run_share, *own.values(), *flows.values(), *vtypes.values(), *vclasses.values()]
    assert led.cold_start_on == any(x > 0 for x in every)


def test_sumo_run_chain_accounts_balance():
    """A real SUMO run (city scenario, 150 s): chain energy per vehicle = Σ over its steps;
    vehicle, edge and class totals agree; auxiliary energy accrues while standing."""
    libsumo = pytest.importorskip("libsumo")
    from sumo_drvpw.model.terms import Inputs
    from sumo_drvpw.sim.chain import QUANTITIES, ChainLedger

    cfg = _city_sumocfg()
    eqs = _chain_equations()
    fuel_eq = eqs[0]
    libsumo.start(["sumo", "-c", str(cfg), "--end", "150",
                   "--no-step-log", "true", "--no-warnings", "true"])
    try:
        dt = libsumo.simulation.getDeltaT()
        n_edges = len(libsumo.edge.getIDList())  # internal edges included
        led = ChainLedger([e.name for e in eqs], [e.chain for e in eqs], n_edges=n_edges)
        vix, eix, classes, edges = {}, {}, [], []
        prev_v: dict[str, float] = {}
        direct = {}
        stood = np.zeros(0)
        while libsumo.simulation.getTime() < 150:
            libsumo.simulationStep()
            ids = libsumo.vehicle.getIDList()
            if not ids:
                continue
            for vid in ids:
                if vid not in vix:
                    vix[vid] = len(vix)
                    classes.append(libsumo.vehicle.getVehicleClass(vid) + ("_odd" if len(vix) % 2 else ""))
            road = [libsumo.vehicle.getRoadID(v) for v in ids]
            for r in road:
                if r not in eix:
                    eix[r] = len(eix)
                    edges.append(r)
            v = np.array([libsumo.vehicle.getSpeed(x) for x in ids])
            a = (v - np.array([prev_v.get(x, 0.0) for x in ids])) / dt
            th = np.radians([libsumo.vehicle.getSlope(x) for x in ids])
            n = len(ids)
            x = Inputs(v=v, a=a, theta=th, wind=np.zeros(n), mass=np.full(n, 1625.0), rho=np.full(n, 1.2041))
            p = np.column_stack([e.power(x) for e in eqs])
            vi = np.array([vix[i] for i in ids])
            q = led.expand(led.book(vi, np.array([eix[r] for r in road]), v, dt, p))
            for j, i in enumerate(vi):
                direct[i] = direct.get(i, 0.0) + q[j]
            stood = np.concatenate([stood, np.zeros(len(vix) - stood.size)])
            stood[vi] += dt * (v == 0.0)
            prev_v = dict(zip(ids, v))
    finally:
        libsumo.close()
    nv = len(vix)
    assert nv > 20 and stood.sum() > 0  # vehicles came, and some stood
    tot = led.vehicle_totals(nv)
    np.testing.assert_allclose(tot, np.stack([direct[i] for i in range(nv)]), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(led.edge.sum(axis=0), tot.sum(axis=0), rtol=1e-9, atol=1e-6)
    cls = led.class_totals(classes)
    assert len(cls) == 2
    np.testing.assert_allclose(sum(cls.values()), tot.sum(axis=0), rtol=1e-9, atol=1e-6)
    # battery: auxiliary = 500 W × time in the network, standing included; net = sum of parts
    k = {q: j for j, q in enumerate(QUANTITIES)}
    np.testing.assert_allclose(tot[:, 1, k["auxiliary_j"]], 500.0 * led.vehicle_time(nv)[:, led.booked("bev")], rtol=1e-12)
    np.testing.assert_allclose(tot[:, 1, k["traction_j"]] + tot[:, 1, k["recuperated_j"]]
                               + tot[:, 1, k["auxiliary_j"]], tot[:, 1, k["net_j"]], rtol=1e-9, atol=1e-6)
    # fuel: litres and CO₂ from the fuel energy through the fuel's constants
    g = FUELS["gasoline"]
    np.testing.assert_allclose(tot[:, 0, k["fuel_l"]],
                               tot[:, 0, k["fuel_j"]] / g["lhv_j_per_kg"] / g["density_kg_per_l"], rtol=1e-12)
    one = led.vehicle(0)  # what a TraCI script reads during a run
    assert set(one) == {fuel_eq.name, "bev"} and set(one["bev"]) == {"traction_j", "recuperated_j",
                                                                    "auxiliary_j", "net_j"}
    assert one["bev"]["net_j"] == pytest.approx(tot[0, 1, k["net_j"]])
    rep = led.report(list(vix), classes, edges)
    per_class = [r for r in rep["classes"] if r["equation"] == "bev"]
    assert all(0.05 < r["net_kwh_per_km"] < 1.0 for r in per_class)  # a car: 50–1000 Wh/km
    fuel_rows = [r for r in rep["classes"] if r["equation"] == fuel_eq.name]
    assert all(1.0 < r["fuel_l_per_100km"] < 40.0 for r in fuel_rows)


def test_fixed_parameters_stay_and_the_rest_is_recovered():
    """Closing the loop from a dynamometer: efficiencies held at the dyno's, the road's
    auxiliary power found; a fixed name that is not a parameter is a UserError."""
    rng, v, p, heater, temp, dt = _drive(seed=4)
    plant = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.8,
                        aux_power_w=450.0)
    meas = plant.evaluate(p, v)["power_w"] + rng.normal(0, 300.0, p.size)
    fit = calibrate_battery(p, v, meas, dt, limit=None,
                            fixed={"traction_efficiency": 0.9, "recuperation_efficiency": 0.8})
    assert fit.chain.traction_efficiency == 0.9 and fit.chain.recuperation_efficiency == 0.8
    assert fit.parameters["traction_efficiency"]["fixed"] and fit.parameters["aux_power_w"]["std_err"]
    assert fit.chain.aux_power_w == pytest.approx(450.0, rel=0.02)
    # held at a wrong value, the free parameter moves to compensate (what the road "adds")
    wrong = calibrate_battery(p, v, meas, dt, limit=None, fixed={"traction_efficiency": 0.95})
    assert wrong.chain.aux_power_w > 450.0
    with pytest.raises(UserError, match="cannot fix"):
        calibrate_battery(p, v, meas, dt, fixed={"marginal_efficiency": 0.3})


# ------------------------------------------------------------------ real data

def test_real_prius2_fuel_chain_is_physical_and_soc_corrected(shared_data):
    """Prius Gen 2 (shared data): the fuel chain fitted on the measured P_PTdrv has a
    petrol engine's marginal efficiency; the held-out trip's fuel is within 20 %; litres
    per 100 km of the measured trips are a Prius's (4–8)."""
    from sumo_drvpw.validation.chain import prius2_study

    r = prius2_study(shared_data)
    for f in r["fits"].values():
        assert 0.3 < f["chain"]["marginal_efficiency"]["value"] < 0.45
        assert f["chain"]["idle_fuel_power_w"]["value"] > 0
    for row in r["rows"]:
        assert 4.0 < row["measured_l_per_100km"] < 8.0
        assert abs(row["error"]) < 0.2
        # SOC correction: a trip that charged the battery (energy < 0) burnt fuel for it
        assert (row["measured_corrected_l"] < row["measured_l"]) == (row["battery_kwh"] < 0)


def test_accountant_energy_reports_the_chain_during_the_run():
    """`Accountant.energy(vehicle)` carries the chain's running battery/fuel totals; at the
    end of the run they equal the vehicle's row of the chain table, converted from kWh/L."""
    pytest.importorskip("libsumo")
    from sumo_drvpw.sim import Accountant, close_sumo, start_sumo
    from sumo_drvpw.sim.chain import KWH
    from sumo_drvpw.sim.scenario import load_scenario

    from pathlib import Path

    sc = load_scenario(Path(__file__).resolve().parent.parent / "scenarios" / "city.toml", end=120)
    conn = start_sumo(sc.sumo_args)
    probe, during = None, []
    try:
        acc = Accountant(conn, equations=_chain_equations(), scenario=sc.path, figures=False)
        conn.addStepListener(acc)
        while conn.simulation.getTime() < 120 - 1e-9:
            conn.simulationStep()
            ids = conn.vehicle.getIDList()
            probe = probe or (ids[0] if ids else None)
            if probe in ids:
                during.append(acc.energy(probe)["bev"]["chain"]["auxiliary_j"])
        final = acc.energy(probe)
        res = acc.result()
    finally:
        close_sumo(conn)
    assert len(during) > 10 and np.all(np.diff(during) >= 0) and during[-1] > 0  # 500 W accrues
    rows = res.ledger.chain.table(res.ledger.chain.vehicle_totals(res.ledger.n_veh),
                                  res.ledger.chain.vehicle_dist(res.ledger.n_veh), list(res.ledger.veh_ids))
    bev = next(r for r in rows if r["key"] == probe and r["equation"] == "bev")
    fuel = next(r for r in rows if r["key"] == probe and r["equation"] == "drvpw_prius3")
    assert final["bev"]["chain"]["net_j"] == pytest.approx(bev["net_kwh"] * KWH, rel=1e-12)
    assert final["drvpw_prius3"]["chain"]["fuel_l"] == pytest.approx(fuel["fuel_l"], rel=1e-12)


# ------------------------------------------------------------------ recuperation limit, SUMO side by side

def test_profile_recuperation_limit_recovers_a_planted_friction_blend():
    """The motor recuperates max(P_wheel, −25 kW) (+ noise); the profile keeps a limit within
    the grid's spacing of 25 kW. Without a planted limit none is kept (BIC)."""
    from sumo_drvpw.fit.chain import profile_recuperation_limit

    rng = np.random.default_rng(3)
    p = -rng.gamma(2.0, 9000.0, 20_000)          # braking powers, many beyond 25 kW
    y = np.maximum(p, -25_000.0) + rng.normal(0, 300.0, p.size)
    r = profile_recuperation_limit(p, y, 0.1)
    grid = [g["recuperation_limit_w"] for g in r["profile"] if g["recuperation_limit_w"] is not None]
    assert r["recuperation_limit_w"] is not None
    # the chosen limit is the grid point nearest 25 kW
    assert r["recuperation_limit_w"] == min(grid, key=lambda g: abs(g - 25_000.0))
    free = profile_recuperation_limit(p, p + rng.normal(0, 300.0, p.size), 0.1)
    assert free["recuperation_limit_w"] is None
    # traction samples are not braking samples: they do not count
    assert profile_recuperation_limit(np.abs(p), np.abs(p), 0.1)["n"] == 0


def test_chain_vtype_params_map_the_chain_onto_sumo_parameters():
    """Hand mapping: η_t → propulsionEfficiency, η_r → recuperationEfficiency, P_aux,0 + the
    extra load → constantPowerIntake, the limit → maximumRecuperationPower; the road load as
    export.py maps it (aero c → A·C_d = 2c/ρ_SUMO); a log-only term is listed as missing."""
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.sim.export import RHO_SUMO, energy_model_params
    from sumo_drvpw.validation.chain_sumo import chain_vtype_params

    eq = Equation("x", {"acc": 1.1, "grade": 1.0, "aero": 0.3, "roll": 0.01, "[ambient_c]*v^2": -0.1})
    ch = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.8,
                     aux_power_w=500.0, recuperation_limit_w=40_000.0)
    p, missing = chain_vtype_params(eq, ch, 1500.0, 2.0, extra_aux_w=250.0, at_motor_shaft=True)
    assert p["propulsionEfficiency"] == 0.9 and p["recuperationEfficiency"] == 0.8
    assert p["constantPowerIntake"] == pytest.approx(750.0)
    assert p["maximumRecuperationPower"] == 40_000.0 and p["gearEfficiency"] == 1.0
    assert p["airDragCoefficient"] * p["frontSurfaceArea"] == pytest.approx(2 * 0.3 / RHO_SUMO)
    assert p["rotatingMass"] == pytest.approx(0.1 * 1500.0) and p["rollDragCoefficient"] == 0.01
    assert any("[ambient_c]*v^2" in m for m in missing)
    # the road load exactly as sim/export.py maps it
    ref, _ = energy_model_params(eq, 1500.0, 2.0)
    for k in ("mass", "frontSurfaceArea", "airDragCoefficient", "rollDragCoefficient", "rotatingMass"):
        assert p[k] == pytest.approx(ref[k])


def test_sumo_energy_model_books_the_chain_parameters(tmp_path):
    """A real emissionsDrivingCycle run with the mapped parameters: 1000 W more constant
    intake adds 1000 W × every second of the time line, the 50 standing seconds included
    (in this tool SUMO 1.28's Energy model books the intake at standstill too)."""
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.validation.chain_sumo import chain_vtype_params, sumo_battery_kwh, sumo_tool

    if sumo_tool("emissionsDrivingCycle") is None:
        pytest.skip("SUMO's emissionsDrivingCycle is not installed")
    t = np.arange(0.0, 200.0, 0.5)
    v = np.clip(np.minimum(t, 150.0 - t) * 0.5, 0.0, 15.0)   # up, cruise, down, then 50 s standing
    eq = Equation("x", {"acc": 1.1, "grade": 1.0, "aero": 0.3, "roll": 0.01})
    out = {}
    for aux in (0.0, 1000.0):
        ch = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.8,
                         aux_power_w=aux)
        p, _ = chain_vtype_params(eq, ch, 1500.0, 2.0)
        d = tmp_path / str(int(aux))
        d.mkdir()
        out[aux] = sumo_battery_kwh(t, v, np.zeros_like(t), d, p)["sumo_energy_chain"]["kwh"]
    sec = pd.Series(v).groupby(np.floor(t).astype(int)).mean()
    assert int((sec == 0).sum()) > 40    # the standing seconds exist
    assert (out[1000.0] - out[0.0]) * 3.6e6 == pytest.approx(1000.0 * sec.size, rel=0.01)


def test_sumo_phemlight5_petrol_class_burns_fuel_at_idle(tmp_path):
    """PHEMlight5 PC_EU4_G through emissionsDrivingCycle: litres > 0 for a standing minute
    (idle fuel), more when driving; litres = mg / 1e6 / density."""
    from sumo_drvpw.validation.chain_sumo import sumo_fuel_l, sumo_tool

    if sumo_tool("emissionsDrivingCycle") is None:
        pytest.skip("SUMO's emissionsDrivingCycle is not installed")
    t = np.arange(0.0, 60.0)
    rho = FUELS["gasoline"]["density_kg_per_l"]
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    idle = sumo_fuel_l(t, np.zeros_like(t), np.zeros_like(t), tmp_path / "a", rho)["sumo_phemlight5_pc_eu4_g"]["l"]
    drive = sumo_fuel_l(t, np.full_like(t, 15.0), np.zeros_like(t), tmp_path / "b", rho)["sumo_phemlight5_pc_eu4_g"]["l"]
    assert 0.005 < idle < 0.05          # about 0.5–2 L/h idle for a petrol car
    assert drive > 2 * idle


def test_i3_study_reads_with_the_library_corrections_fused_grade_and_rho_at_altitude():
    """validation.chain_i3.I3_MEASUREMENT through the library's reader corrections
    (data.corrections.apply_measurement, as `calibrate --grade-source fused --air-density
    altitude --exclude-dropouts`): ρ × p(h)/p0 (standard atmosphere); the grade's fast part
    from the accelerometer (a planted 20-s undulation the logged grade lacks is recovered),
    its slow part from the logged grade (a 2° mounting pitch of the accelerometer does not
    enter); nothing held by the logger, so nothing is left out."""
    import copy
    from types import SimpleNamespace

    from sumo_drvpw.data.corrections import apply_measurement
    from sumo_drvpw.data.log import ReadOptions
    from sumo_drvpw.model.air import pressure_at_altitude_kpa
    from sumo_drvpw.model.constants import G, P_STD_KPA
    from sumo_drvpw.model.terms import Inputs
    from sumo_drvpw.validation.chain_i3 import I3_MEASUREMENT

    t = np.arange(0.0, 600.0, 0.1)
    n = t.size
    sin_true = 0.04 * np.sin(2 * np.pi * t / 20.0)
    a = 0.2 * np.sin(2 * np.pi * t / 50.0)
    v = 10.0 + 0.2 * 50.0 / (2 * np.pi) * (1 - np.cos(2 * np.pi * t / 50.0))
    imu = a + G * (sin_true + np.sin(np.radians(2.0)))
    h = np.full(n, 500.0)
    df = pd.DataFrame({"trip_id": "T", "time_s": t, "elevation_m": h, "speed_mps": v,
                       "imu_accel_mps2": imu})
    log = SimpleNamespace(df=df, counts={}, options=ReadOptions(), describe=lambda: "T")
    x = Inputs(v, a, np.zeros(n), np.zeros(n), np.full(n, 1500.0), np.full(n, 1.2),
               {"imu_accel_mps2": imu})
    p, xc, ok = apply_measurement(log, copy.copy(x), np.ones(n), np.ones(n, bool), I3_MEASUREMENT)
    assert ok.all() and log.counts["excluded_dropouts"] == 0
    np.testing.assert_allclose(xc.rho, 1.2 * pressure_at_altitude_kpa(h) / P_STD_KPA)
    assert xc.rho[0] < 1.2 * 0.95                      # ~6 % less air at 500 m
    s = np.sin(xc.theta)[600:-600]                     # away from the trip's ends
    assert np.corrcoef(s, sin_true[600:-600])[0, 1] > 0.95
    assert abs(np.mean(s)) < 0.002                     # the pitch bias stays out
    assert np.all(x.theta == 0.0) and np.all(x.rho == 1.2)   # the input is not modified


def test_sumo_cycle_steps_of_a_dropout_are_not_booked():
    """validation.chain_sumo._kept_steps: the 1-s steps of emissionsDrivingCycle's output whose
    second holds a sample left out of the measured energy (a logger dropout) are not booked;
    nothing is dropped without a mask."""
    from sumo_drvpw.validation.chain_sumo import _kept_steps

    t = 100.0 + np.arange(0, 10, 0.25)                 # 10 s at 4 Hz, starting at t = 100 s
    drop = (t >= 103.0) & (t < 105.5)                  # seconds 3, 4 and 5 touched
    keep = _kept_steps(t, 10, drop)
    assert list(np.flatnonzero(~keep)) == [3, 4, 5]
    assert _kept_steps(t, 10, None).all() and _kept_steps(t, 10, np.zeros(t.size, bool)).all()


# ------------------------------------------------------------------ published road load

def test_roadload_spec_is_the_vehicle_files_a_b_c_by_hand():
    """'roadload_spec': F = A + B·v + C·v² of the vehicle file ([road_load], e.g. the JLU
    dynamometer's A 179.4 N, B 1.008 N/(m/s), C 0.30456 N/(m/s)²) plus m·a."""
    from sumo_drvpw.data.measured import resolve_equations
    from sumo_drvpw.model.terms import Inputs
    from sumo_drvpw.model.vehicles import load_vehicle

    veh = load_vehicle("jlu_bev")
    eq = resolve_equations(["roadload_spec"], veh)[0]
    x = Inputs(np.array([10.0, 20.0]), np.array([0.0, 1.0]), np.zeros(2), np.zeros(2),
               np.full(2, 1919.0), np.full(2, 1.2), {})
    # 10 m/s cruise: (179.4 + 10.08 + 30.456)·10 = 2199.36 W; 20 m/s at 1 m/s²: + 1919·20
    want = [2199.36, (179.4 + 1.008 * 20 + 0.30456 * 400) * 20 + 1919.0 * 20]
    np.testing.assert_allclose(eq.power(x), want, rtol=1e-12)
    # the Prius files write A, B, C as f0_N, f1_N_per_mps, f2_N_per_mps2: read as well
    p3 = load_vehicle("prius3")
    assert resolve_equations(["roadload_spec"], p3)[0].terms["v1"] == p3.road_load["f0_N"]
    with pytest.raises(UserError, match=r"\[road_load\] lacks 'a_n' or 'f0_N'"):
        resolve_equations(["roadload_spec"], load_vehicle("bmw_i3"))
    with pytest.raises(UserError, match="needs a vehicle"):
        resolve_equations(["roadload_spec"])


def test_cli_dyno_chain_on_the_published_road_load(tmp_path, capsys):
    """`calibrate --target battery --equation roadload_spec` on a log with battery V·I only
    (a dynamometer): the planted chain (η_t 0.9, η_r 0.7, 500 W, heater gain 1) is recovered
    on the vehicle's A + B·v + C·v²; a negative coefficient in the vehicle file is exit 2."""
    from sumo_drvpw.cli import main as cli_main

    log, _ = _planted_battery_log(tmp_path)       # its road load: acc 1, v1 150, v3 0.35
    veh = tmp_path / "dyno_car.toml"
    veh.write_text('[vehicle]\nname = "dyno_car"\nmass_kg = 1500\n[powertrain]\ntype = "battery"\n'
                   '[road_load]\na_n = 150.0\nb_n_per_mps = 0.0\nc_n_per_mps2 = 0.35\n', encoding="utf-8")
    eq = tmp_path / "chain.toml"
    assert cli_main(["calibrate", str(log), "--vehicle", str(veh), "--target", "battery",
                     "--equation", "roadload_spec", "--load", "heater_power_w", "--out", str(eq)]) == 0
    ch = load_equation(eq).chain
    assert ch.traction_efficiency == pytest.approx(0.9, rel=0.02)
    assert ch.aux_power_w == pytest.approx(500.0, rel=0.02)
    assert load_equation(eq).terms == {"acc": 1.0, "grade": 1.0, "v1": 150.0, "v2": 0.0, "v3": 0.35}
    veh.write_text(veh.read_text(encoding="utf-8").replace("c_n_per_mps2 = 0.35", "c_n_per_mps2 = -0.35"), encoding="utf-8")
    capsys.readouterr()
    assert cli_main(["calibrate", str(log), "--vehicle", str(veh), "--target", "battery",
                     "--equation", "roadload_spec", "--out", str(tmp_path / "bad.toml")]) == 2
    assert "road_load.c_n_per_mps2 = -0.35" in capsys.readouterr().err
    # without --equation the road load was fitted on the battery power itself (the chain's
    # own target; on the JLU road trips η_t 0.974, IMPLAUSIBLE): refused, one line
    veh.write_text(veh.read_text(encoding="utf-8").replace("c_n_per_mps2 = -0.35", "c_n_per_mps2 = 0.35"), encoding="utf-8")
    assert cli_main(["calibrate", str(log), "--vehicle", str(veh), "--target", "battery",
                     "--out", str(tmp_path / "none.toml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "logs no driving power" in err[0] and "--equation" in err[0], err
    assert not (tmp_path / "none.toml").exists()


def test_i3_cabin_start_and_warm_up_rate_by_hand():
    """validation.chain_i3: a trip's cabin start temperature is its sensor's first 10 s, or
    the air temperature where the sensor reads its 10 °C floor (a cold-soaked cabin); the
    warm-up rate decays with τ and integrates over a trip of T seconds to
    (T_set − T_start)⁺ · (1 − e^(−T/τ)), as a SUMO run books it."""
    import types

    from sumo_drvpw.validation.chain_i3 import WARMUP_TAU_S, cabin_start_c, warmup_rate

    t = np.r_[np.arange(0, 900, 0.5), np.arange(0, 600, 0.5)]
    trips = np.array(["a"] * 1800 + ["b"] * 1200)
    cab = np.where(trips == "a", 10.0, 21.5)
    amb = np.where(trips == "a", 2.0, 4.0)
    log = types.SimpleNamespace(df=pd.DataFrame({"time_s": t, "dt_s": 0.5}))
    mb = types.SimpleNamespace(inputs=types.SimpleNamespace(signals={"cabin_temp_c": cab, "ambient_c": amb}))
    start = cabin_start_c(log, mb, trips)
    assert start == {"a": 2.0, "b": 21.5}
    rate = warmup_rate(log, trips, start, 20.0)
    assert float(rate[trips == "a"] @ np.full(1800, 0.5)) == pytest.approx(
        18.0 * (1.0 - np.exp(-900.0 / WARMUP_TAU_S)), rel=1e-12)
    assert not rate[trips == "b"].any()
    a = rate[trips == "a"]
    assert a[600] / a[0] == pytest.approx(np.exp(-300.0 / WARMUP_TAU_S), rel=1e-12)  # t = 300 s


def test_i3_battery_equation_for_sumo_studies_runs_in_sumo(tmp_path):
    """docs/energy-chain/bmw_i3_battery.toml — calibrated on the TUM i3 trips by
    `python -m sumo_drvpw.validation.chain` in the form a SUMO study can run (cold drag,
    HVAC over the ambient temperature) — in a real SUMO run of the city scenario at the i3's
    mass: per-class kWh/km within what an i3 draws in town (about 0.13–0.20 kWh/km at the
    battery in real driving; 0.08–0.40 allowed for a 150-s city excerpt); at 20 °C (the
    set-point) the auxiliary energy is the constant power × time in the network, at 0 °C it
    adds heating_w_per_k × 20 K × that time, exactly; vehicle and class totals agree."""
    pytest.importorskip("libsumo")
    from pathlib import Path

    import pandas as pd_

    from sumo_drvpw.model.vehicles import load_vehicle
    from sumo_drvpw.sim import run_scenario

    repo = Path(__file__).resolve().parent.parent
    eq_path = repo / "docs" / "energy-chain" / "bmw_i3_battery.toml"
    ch = load_equation(eq_path).chain
    assert ch.predicts == "battery" and ch.hvac["setpoint_c"] == 20.0
    assert 0.0 < ch.recuperation_efficiency < 1.0          # no lossless generator in SUMO
    cfg = repo / "sumo_drvpw" / "sim" / "builtin" / "scenarios" / "city.sumocfg"
    mass = load_vehicle("bmw_i3").mass_kg
    aux, t_in = {}, {}
    for temp in (0.0, 20.0):
        sc = tmp_path / f"i3_{temp:g}.toml"
        sc.write_text(f'equations = ["{eq_path}"]\n[sumo]\nconfig = "{cfg}"\nbegin = 0\nend = 150\n'
                      f'[vtypes.prius3]\nmass_kg = {mass}\n'
                      f'[air]\ntemperature_c = {temp}\n[outputs]\nfigures = false\nedgedata = false\n', encoding="utf-8")
        out = tmp_path / f"out{temp:g}"
        res = run_scenario(sc, out)
        cls = [r for r in res.summary["chain"]["classes"] if r["equation"] == "bmw_i3_battery"]
        assert cls and all(0.08 < r["net_kwh_per_km"] < 0.40 for r in cls), cls
        veh = pd_.read_csv(out / "chain_vehicles.csv")
        classes = pd_.read_csv(out / "chain_classes.csv")
        assert veh["net_kwh"].sum() == pytest.approx(classes["net_kwh"].sum(), rel=1e-9)
        aux[temp] = veh["auxiliary_kwh"].sum()
        led = res.ledger
        t_in[temp] = float(np.sum(led.chain.veh_time[:led.n_veh]))
    assert t_in[0.0] == pytest.approx(t_in[20.0], rel=1e-12)       # the same traffic
    assert aux[20.0] == pytest.approx(ch.aux_power_w * t_in[20.0] / 3.6e6, rel=1e-9)
    heat = ch.hvac["heating_w_per_k"] * 20.0 * t_in[0.0] / 3.6e6
    assert aux[0.0] - aux[20.0] == pytest.approx(heat, rel=1e-9)


def test_cli_chain_road_load_obeys_the_physical_constraints(tmp_path, capsys):
    """`calibrate --target battery` without --equation calibrates the road load under the
    chain as `calibrate` does, physics included: on a log whose grade is attenuated (the
    logger's grade carries noise as large as the grade itself, as coarse elevation gives) the
    free grade coefficient reads about 0.5 and the constrained fit (grade = 1) is used and
    said (the free fit was written before)."""
    import pandas as pd

    from sumo_drvpw.cli import main

    rng = np.random.default_rng(3)
    n = 12000
    t = np.arange(n) * 0.5
    v = np.clip(14 + 9 * np.sin(t / 45) + 3 * np.sin(t / 7) + rng.normal(0, 0.05, n), 0, None)
    a = np.gradient(v, t)
    theta = 0.04 * np.sin(t / 130) + 0.02 * np.sin(t / 31)
    m = 1500.0
    p = 1.05 * m * v * a + m * 9.81 * v * np.sin(theta) + 0.35 * v ** 3 + 0.012 * m * 9.81 * v
    batt = np.where(p > 0, p / 0.92, p * 0.92) + 600.0
    df = pd.DataFrame({"time_s": t, "speed_mps": v, "mass_kg": m, "power_w": p + rng.normal(0, 200, n),
                       "grade_rad": theta + rng.normal(0, theta.std(), n), "battery_voltage_v": 350.0,
                       "battery_current_a": batt / 350.0})
    f = tmp_path / "log.csv"
    df.to_csv(f, index=False)
    out = tmp_path / "ev.toml"
    assert main(["calibrate", str(f), "--target", "battery", "--out", str(out)]) == 0
    said = capsys.readouterr().out
    assert "physically constrained fit used" in said and "grade" in said
    eq = load_equation(out)
    assert eq.terms["grade"] == pytest.approx(1.0)
    assert "physically constrained" in eq.chain.provenance["road_load"]
    assert eq.chain.traction_efficiency == pytest.approx(0.92, abs=0.01)


def test_compare_says_where_a_chain_load_is_unknown(tmp_path, capsys):
    """A declared load unknown (NaN) on one trip: compare predicts there without it (no
    draw) and says so — in report.json (samples, trip, how it is read), report.md and on
    the console — instead of booking an unknown load as a zero one unremarked."""
    import json

    from sumo_drvpw.cli import main as cli_main

    log, road = _planted_battery_log(tmp_path)
    eq = tmp_path / "chain.toml"
    assert cli_main(["calibrate", str(log), "--target", "battery", "--equation", str(road),
                     "--load", "heater_power_w", "--out", str(eq)]) == 0
    df = pd.read_csv(log)
    t2 = (df["trip_id"] == "T2").to_numpy()
    df.loc[t2, "heater_power_w"] = np.nan            # the heater not logged on trip T2
    part = tmp_path / "part.csv"
    df.to_csv(part, index=False)
    capsys.readouterr()
    out = tmp_path / "cmp"
    assert cli_main(["compare", str(part), "--equation", str(eq), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    rep = json.loads((out / "report.json").read_text(encoding="utf-8"))["equations"]["chain"]
    u = rep["chain_unknown_inputs"]["heater_power_w"]
    assert u["trips"] == ["T2"] and u["read_as"] == "no load"
    assert 0 < u["samples"] <= int(t2.sum())
    assert "'heater_power_w' unknown (NaN)" in said and "T2" in said
    assert "'heater_power_w' unknown (NaN)" in (out / "report.md").read_text(encoding="utf-8")
    # read as no load: trip T2's net battery energy is under-predicted by the heater's
    errs = rep["trip_net_energy"]["trips"]
    assert abs(errs["T1"]["error"]) < 0.01 and errs["T2"]["error"] < -0.05
    # a log with the load known everywhere: nothing to say
    assert cli_main(["compare", str(log), "--equation", str(eq), "--out", str(tmp_path / "c2")]) == 0
    assert "chain_unknown_inputs" not in json.loads((tmp_path / "c2" / "report.json").read_text(encoding="utf-8"))[
        "equations"]["chain"]


def test_fuel_chain_says_when_its_engine_off_is_not_identified_at_city_speeds():
    """A fuel chain calibrated on highway driving only cannot know whether the engine runs
    at city speeds: its engine-off reading says so; the same chain calibrated on mixed
    driving does not. (The shared Prius Gen-2 logs, 21 % of their time below 50 km/h, are
    not flagged.)"""
    rng = np.random.default_rng(11)
    n = 8000
    dt = np.full(n, 0.5)
    for v0, flagged in ((27.0, True), (12.0, False)):
        v = np.clip(v0 + 6 * np.sin(np.arange(n) / 60.0) + rng.normal(0, 0.3, n), 0, None)
        a = np.gradient(v, 0.5)
        p = 1400 * v * a + 0.35 * v ** 3 + 150 * v
        fuel = np.where(p > 5_000.0, 4_000.0 + np.maximum(p, 0) / 0.36, 0.0)
        reading = calibrate_fuel(p, v, fuel, dt).parameters["engine_off_below_w"]["reading"]
        assert ("NOT IDENTIFIED at city speeds" in reading) == flagged, (v0, reading)


def test_config_with_sumos_emissions_device_puts_its_energy_beside_the_chains(tmp_path):
    """A SUMO config that enables the emissions device (and writes tripinfo) gets SUMO's
    per-vehicle electricity and fuel beside the chains' without being asked: the battery
    chain's kWh against SUMO's electricity (Energy-model EVs), the fuel chain's litres
    against SUMO's fuel (HBEFA petrol cars, mg at the chain fuel's density); the config's
    tripinfo stays, in OUT/sumo/; vehicles flushed during the run are in the comparison
    (flush_vehicles=2); outputs.sumo_device = false turns it off."""
    pytest.importorskip("libsumo")
    import pandas as pd_

    from pathlib import Path

    from sumo_drvpw.model.constants import FUELS
    from sumo_drvpw.sim import run_scenario
    from sumo_drvpw.sim.run import read_tripinfo_emissions

    repo = Path(__file__).resolve().parent.parent
    net = repo / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"
    (tmp_path / "r.rou.xml").write_text("""<routes>
    <vType id="ev" vClass="passenger" emissionClass="Energy/unknown" mass="1600"/>
    <vType id="petrol" vClass="passenger" emissionClass="HBEFA4/PC_petrol_Euro-4" mass="1400"/>
    <flow id="e" type="ev" begin="0" end="60" period="10" departSpeed="0"><route edges="c00c10 c10c20 c20c30"/></flow>
    <flow id="p" type="petrol" begin="0" end="60" period="10" departSpeed="0"><route edges="c00c10 c10c20 c20c30"/></flow>
</routes>
""", encoding="utf-8")
    (tmp_path / "c.sumocfg").write_text(f"""<configuration>
    <input><net-file value="{net}"/><route-files value="r.rou.xml"/></input>
    <output><tripinfo-output value="ti.xml"/></output>
    <emissions><device.emissions.probability value="1"/></emissions>
    <time><begin value="0"/><end value="400"/><step-length value="0.5"/></time>
    <report><no-warnings value="true"/></report>
</configuration>
""", encoding="utf-8")
    fuel_eq, bev = _chain_equations()
    (tmp_path / "s.toml").write_text('equations = ["x"]\n[sumo]\nconfig = "c.sumocfg"\n'
                                     '[outputs]\nfigures = false\n', encoding="utf-8")
    out = tmp_path / "o"
    res = run_scenario(tmp_path / "s.toml", out, equations=[fuel_eq, bev], flush_vehicles=2)
    assert (out / "sumo" / "ti.xml").is_file() and not (tmp_path / "ti.xml").exists()
    assert not any("replaced" in w for w in res.summary["warnings"])
    dev = read_tripinfo_emissions(out / "sumo" / "ti.xml")
    ev_ids = set(dev.vehicle[dev.vehicle.str.startswith("e")])
    petrol = set(dev.vehicle[dev.vehicle.str.startswith("p")])
    assert len(ev_ids) >= 5 and len(petrol) >= 5
    cmp = pd_.read_csv(out / "sumo_device.csv").set_index("equation")
    chain = pd_.read_csv(out / "chain_vehicles.csv", dtype={"key": str})
    assert set(chain.key) >= ev_ids | petrol          # flushed and held vehicles alike
    b = cmp.loc["bev"]
    assert b["quantity"].startswith("battery kWh") and b["vehicles"] == len(ev_ids)
    ours = chain[(chain.equation == "bev") & chain.key.isin(ev_ids)].net_kwh.sum()
    sumo = dev[dev.vehicle.isin(ev_ids)].sumo_electricity_wh.sum() / 1e3
    assert b["ours"] == pytest.approx(ours, rel=1e-9) and b["sumo"] == pytest.approx(sumo, rel=1e-9)
    assert 0.3 < b["ratio"] < 3.0
    # the ratio split: the chain's auxiliary energy (500 W over every second booked, standing
    # included) over SUMO's total, and the rest; they add up to the ratio
    t_ev = pd_.read_parquet(out / "vehicles.parquet").query("equation == 'bev'")
    t_ev = t_ev[t_ev.vehicle.isin(ev_ids)].time_s.sum()
    assert b["ours_auxiliary"] == pytest.approx(500.0 * t_ev / 3.6e6, rel=1e-9)
    assert b["ratio_auxiliary"] == pytest.approx(b["ours_auxiliary"] / sumo, rel=1e-9)
    assert b["ratio_rest"] == pytest.approx((ours - b["ours_auxiliary"]) / sumo, rel=1e-9)
    assert b["ratio_auxiliary"] + b["ratio_rest"] == pytest.approx(b["ratio"], rel=1e-12)
    assert "model difference" in b["note"] and "constantPowerIntake" in b["note"]
    assert res.summary["sumo_device"][list(cmp.index).index("bev")]["ratio_rest"] == pytest.approx(b["ratio_rest"])
    f = cmp.loc["drvpw_prius3"]
    assert f["quantity"].startswith("fuel L") and f["vehicles"] == len(petrol)
    ours = chain[(chain.equation == "drvpw_prius3") & chain.key.isin(petrol)].fuel_l.sum()
    sumo = dev[dev.vehicle.isin(petrol)].sumo_fuel_mg.sum() / 1e6 / FUELS["gasoline"]["density_kg_per_l"]
    assert f["ours"] == pytest.approx(ours, rel=1e-9) and f["sumo"] == pytest.approx(sumo, rel=1e-9)
    assert 0.2 < f["ratio"] < 5.0
    assert pd_.isna(f["ours_auxiliary"]) and pd_.isna(f["ratio_rest"])   # no split for fuel
    v = pd_.read_parquet(out / "vehicles.parquet")
    assert "sumo_electricity_wh" in v and v.vehicle.isin(ev_ids | petrol).all()
    # the same tripinfo gzipped reads alike (a config may name it ti.xml.gz)
    import gzip

    with gzip.open(tmp_path / "ti.xml.gz", "wb") as g:
        g.write((out / "sumo" / "ti.xml").read_bytes())
    pd_.testing.assert_frame_equal(read_tripinfo_emissions(tmp_path / "ti.xml.gz"), dev)
    # asked not to: no comparison, the config's tripinfo still kept
    (tmp_path / "s.toml").write_text('equations = ["x"]\n[sumo]\nconfig = "c.sumocfg"\n'
                                     '[outputs]\nfigures = false\nsumo_device = false\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o2", equations=[fuel_eq, bev])
    assert not (tmp_path / "o2" / "sumo_device.csv").exists()
    assert (tmp_path / "o2" / "sumo" / "ti.xml").is_file()
    # a window no vehicle drives in: an empty comparison with its header (a traceback,
    # KeyError 'vehicle', and a 1-byte file before; found by a sweep)
    (tmp_path / "s.toml").write_text('equations = ["x"]\n[sumo]\nconfig = "c.sumocfg"\n'
                                     '[outputs]\nfigures = false\n', encoding="utf-8")
    res = run_scenario(tmp_path / "s.toml", tmp_path / "o3", equations=[fuel_eq, bev], begin=300, end=400)
    assert res.summary["vehicles"] == 0
    empty = pd_.read_csv(tmp_path / "o3" / "sumo_device.csv")
    assert len(empty) == 0 and list(empty.columns) == ["equation", "quantity", "vehicles", "ours", "sumo", "ratio",
                                                "ours_auxiliary", "ratio_auxiliary", "ratio_rest", "note"]


def test_engine_off_minus_inf_round_trips_and_bad_values_are_refused(tmp_path):
    from sumo_drvpw.model.equations import load_equation, save_equation

    text = ('[equation]\nname = "c"\n[terms]\nacc = 1.0\n[chain]\npredicts = "fuel"\n'
            'idle_fuel_power_w = 8000.0\nmarginal_efficiency = 0.35\nengine_off_below_w = {}\nfuel = "gasoline"\n')
    (tmp_path / "c.toml").write_text(text.format("-inf"), encoding="utf-8")
    eq = load_equation(tmp_path / "c.toml")
    out = eq.chain.evaluate(np.array([-5000.0, 0.0, 7000.0]), np.array([10.0, 0.0, 10.0]), dt_s=1.0)
    assert out["engine_on"].all()  # braking and standing: the engine idles
    assert out["power_w"] == pytest.approx([8000.0, 8000.0, 8000.0 + 7000.0 / 0.35])
    save_equation(eq, tmp_path / "c2.toml")
    assert load_equation(tmp_path / "c2.toml").chain.engine_off_below_w == -np.inf
    for bad in ("inf", "nan", '"never"'):
        (tmp_path / "b.toml").write_text(text.format(bad), encoding="utf-8")
        with pytest.raises(UserError, match="engine_off_below_w"):
            load_equation(tmp_path / "b.toml")


@pytest.mark.parametrize("left_out", ["fuel", "marginal_efficiency", "idle_fuel_power_w", "engine_off_below_w"])
def test_a_fuel_chain_without_an_engine_s_keys_is_refused_naming_them(tmp_path, capsys, left_out):
    """A fuel chain that predicts (a run, compare, diagnose) must say its fuel, η_m, idle fuel
    and engine-off threshold: the defaults (petrol, η_m = 1, no idle fuel, off at rest)
    describe no engine; one that declares a calibration's fuel cut-off need not. Before (rehearsal
    2026-11-29: a diesel bus's chain with only predicts and the efficiencies) the run booked
    26.9 L/100 km of petrol from a 100 %-efficient engine without a word."""
    from sumo_drvpw.cli import main
    from sumo_drvpw.model.equations import load_equation

    keys = {"fuel": '"diesel"', "marginal_efficiency": "0.42", "idle_fuel_power_w": "20000.0",
            "engine_off_below_w": "-inf"}
    text = ('[equation]\nname = "bus"\n[terms]\nacc = 1.0\nv1 = 900.0\n[chain]\npredicts = "fuel"\n'
            'traction_efficiency = 0.85\n' + "".join(f"{k} = {v}\n" for k, v in keys.items() if k != left_out))
    (tmp_path / "bus.toml").write_text(text, encoding="utf-8")
    with pytest.raises(UserError, match=rf"bus\.toml \[chain\]: predicts = \"fuel\" needs '{left_out}'"):
        load_equation(tmp_path / "bus.toml").chain.evaluate(np.ones(3), np.ones(3))
    rc = main(["run", "city", "--equation", str(tmp_path / "bus.toml"), "--out", str(tmp_path / "o"), "--end", "5"])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and left_out in err, err
    assert not (tmp_path / "o").exists()
    # a declaration for calibrate (its fuel cut-off kept) reads: the chain is not used to predict
    assert load_equation(tmp_path / "bus.toml").chain.missing == (left_out,)
    (tmp_path / "bus.toml").write_text(text + f"{left_out} = {keys[left_out]}\n", encoding="utf-8")
    assert load_equation(tmp_path / "bus.toml").chain.fuel == "diesel"


def test_fuel_calibration_finds_a_conventional_engine():
    """A planted engine that runs throughout (fuel at idle, at stops and while braking):
    the profiled engine-off threshold is -inf and the line is recovered."""
    from sumo_drvpw.fit.chain_fuel import calibrate_fuel

    rng = np.random.default_rng(3)
    n = 4000
    v = np.clip(12 + 8 * np.sin(np.arange(n) / 40) + rng.normal(0, 1, n), 0, None)
    v[::97] = 0.0
    p = 400 * v + 0.4 * v ** 3 + 1500 * v * rng.normal(0, 0.4, n)
    fuel = 9000.0 + np.maximum(p, 0) / 0.36
    fit = calibrate_fuel(p, v, fuel, 1.0, engine_on_above_mps=None)
    assert fit.chain.engine_off_below_w == -np.inf
    assert fit.chain.marginal_efficiency == pytest.approx(0.36, rel=1e-6)
    assert fit.chain.idle_fuel_power_w == pytest.approx(9000.0, rel=1e-6)
    assert "always on" in fit.parameters["engine_off_below_w"]["reading"]


def test_builtin_i3_battery_is_the_validations_deliverable():
    """The built-in bmw_i3_battery (a bare SUMO config's electric cars) is the file the chain
    validation writes for SUMO studies (docs/energy-chain/bmw_i3_battery.toml): the same
    document, so the figures of docs/energy-chain-validation.md are its figures."""
    import tomllib
    from pathlib import Path

    from sumo_drvpw.model.equations import BUILTIN_DIR

    docs = Path(__file__).resolve().parents[1] / "docs" / "energy-chain" / "bmw_i3_battery.toml"
    with open(docs, "rb") as a, open(BUILTIN_DIR / "bmw_i3_battery.toml", "rb") as b:
        assert tomllib.load(a) == tomllib.load(b)
    eq = load_equation("bmw_i3_battery")
    assert eq.predicts == "battery" and "evehicle" in eq.vclasses and eq.chain.hvac["setpoint_c"] == 20.0


def test_i3_logged_load_deliverable_through_the_cli(shared_data, tmp_path, capsys):
    """docs/energy-chain/bmw_i3_battery_logged.toml (python -m sumo_drvpw.validation.chain):
    a battery chain with the heater and A/C logs at gain 1 and the closed loop's
    [measurement]; imported and compared through the CLI on three shared trips (summer with
    the heater's V·I, summer without, winter), it reproduces per trip the battery-energy
    errors the validation wrote for the pipeline fitted on every trip, and says which trip
    lacks the heater's log."""
    import json
    from pathlib import Path

    from sumo_drvpw.cli import main as cli_main

    repo = Path(__file__).resolve().parent.parent
    eq_file = repo / "docs" / "energy-chain" / "bmw_i3_battery_logged.toml"
    eq = load_equation(eq_file)
    assert eq.predicts == "battery" and eq.chain.loads == {"heater_electric_w": 1.0, "aircon_power_w": 1.0}
    assert eq.measurement is not None and eq.measurement.grade == "fused"
    ref = json.loads((repo / "docs" / "energy-chain-validation.json").read_text(encoding="utf-8"))
    ref = ref["bmw_i3"]["kfold"]["in_sample"]["errors"]
    trips = ["TripA23", "TripA13", "TripB17"]
    src = [str(shared_data / "bmw_i3_tum" / f"{t}.csv") for t in trips]
    assert cli_main(["import", "bmw-i3-tum", *src, "--out", str(tmp_path / "i3.parquet")]) == 0
    capsys.readouterr()
    assert cli_main(["compare", str(tmp_path / "i3.parquet"), "--vehicle", "bmw_i3", "--equation", str(eq_file),
                     "--out", str(tmp_path / "cmp")]) == 0
    said = capsys.readouterr()
    said = said.out + said.err
    note = next(line for line in said.splitlines() if "'heater_electric_w' unknown" in line)
    assert "TripA13" in note and "TripA23" not in note and "TripB17" not in note
    rep = json.loads((tmp_path / "cmp" / "report.json").read_text(encoding="utf-8"))
    got = rep["equations"]["bmw_i3_battery_logged"]["trip_net_energy"]["trips"]
    for t in trips:
        assert got[t]["error"] == pytest.approx(ref[t], abs=1e-6), t
    assert abs(ref["TripA13"]) > 0.2  # the trip without heater V·I: its heater is missing


def test_jlu_road_deliverable_through_the_cli(shared_data, tmp_path):
    """docs/energy-chain/jlu_bev_road_battery.toml: the dyno chain with what the road adds
    (diagnose's battery tracer on all six shared road trips); imported and compared through
    the CLI on two of the trips, it reproduces their committed in-sample battery-energy
    errors."""
    import json
    from pathlib import Path

    from sumo_drvpw.cli import main as cli_main

    repo = Path(__file__).resolve().parent.parent
    eq_file = repo / "docs" / "energy-chain" / "jlu_bev_road_battery.toml"
    eq = load_equation(eq_file)
    assert eq.predicts == "battery" and eq.terms["grade"] == 1.0
    ref = json.loads((repo / "docs" / "energy-chain-validation.json").read_text(encoding="utf-8"))
    ref = ref["jlu"]["deliverable"]["in_sample"]
    trips = ["001", "021"]
    src = [str(shared_data / "jlu_bev_road" / f"{t}.parquet") for t in trips]
    assert cli_main(["import", "jlu-road", *src, "--out", str(tmp_path / "jlu.parquet")]) == 0
    assert cli_main(["compare", str(tmp_path / "jlu.parquet"), "--vehicle", "jlu_bev", "--equation", str(eq_file),
                     "--out", str(tmp_path / "cmp")]) == 0
    rep = json.loads((tmp_path / "cmp" / "report.json").read_text(encoding="utf-8"))
    got = rep["equations"]["jlu_bev_road_battery"]["trip_net_energy"]["trips"]
    for t in trips:
        assert got[t]["error"] == pytest.approx(ref[t], abs=1e-6), t


def test_prius2_fuel_deliverable_through_the_cli(shared_data, tmp_path):
    """docs/energy-chain/prius2_fuel.toml (both shared trips): imported and compared through
    the CLI, each trip's fuel error (the battery's energy change taken off the prediction)
    is the committed in-sample one."""
    import json
    from pathlib import Path

    from sumo_drvpw.cli import main as cli_main

    repo = Path(__file__).resolve().parent.parent
    eq_file = repo / "docs" / "energy-chain" / "prius2_fuel.toml"
    eq = load_equation(eq_file)
    assert eq.predicts == "fuel" and 0.25 < eq.chain.marginal_efficiency < 0.5
    ref = json.loads((repo / "docs" / "energy-chain-validation.json").read_text(encoding="utf-8"))
    ref = ref["prius2"]["deliverable"]["in_sample"]
    assert cli_main(["import", "torquepro-prius2", str(shared_data / "prius_gen2_torquepro"),
                     "--out", str(tmp_path / "p2.parquet")]) == 0
    assert cli_main(["compare", str(tmp_path / "p2.parquet"), "--vehicle", "prius2", "--equation", str(eq_file),
                     "--out", str(tmp_path / "cmp")]) == 0
    rep = json.loads((tmp_path / "cmp" / "report.json").read_text(encoding="utf-8"))
    got = rep["equations"]["prius2_fuel"]["trip_net_energy"]["trips"]
    assert set(got) == set(ref) == {"From_CdA_Act", "To_CdA_Act"}
    for t in ref:
        assert got[t]["error"] == pytest.approx(ref[t], abs=1e-6), t


def test_a_traci_script_says_which_added_vehicle_starts_cold(tmp_path):
    """Accountant.set_cold_start in a user's own libsumo loop: a vehicle the script adds
    (vehicle.add) and says starts cold books one cold start (0.07 L), the scenario's own
    vehicles none (the run's share is 0); saying it after the departure, a share outside
    0–1, or for a run without an energy chain is a ValueError."""
    pytest.importorskip("libsumo")
    import dataclasses
    from pathlib import Path

    from sumo_drvpw.sim import Accountant, close_sumo, start_sumo
    from sumo_drvpw.sim.scenario import load_scenario

    city = Path(__file__).resolve().parent.parent / "scenarios" / "city.toml"
    eqs = _chain_equations()
    eqs[0].chain = dataclasses.replace(eqs[0].chain, cold_start_fuel_l=0.07)
    sc = load_scenario(city, end=120)
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, equations=eqs[:1], scenario=city)
        conn.addStepListener(acc)
        conn.route.add("r_added", ["c00c10", "c10c20"])
        conn.vehicle.add("added", "r_added", typeID="prius3", depart="now")
        acc.set_cold_start("added", True)
        with pytest.raises(ValueError, match="0–1"):
            acc.set_cold_start("later", 1.5)
        while conn.simulation.getTime() < 120 - 1e-9:
            conn.simulationStep()
        with pytest.raises(ValueError, match="departed already"):
            acc.set_cold_start("added", 0.5)
        res = acc.result()
        bare = Accountant(conn, equations=["vsp_ldv1999"], scenario=city)
        with pytest.raises(ValueError, match="no energy chain"):
            bare.set_cold_start("x", 1.0)
    finally:
        close_sumo(conn)
    res.write(tmp_path / "o")
    veh = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv").query("equation == 'drvpw_prius3'").set_index("key")
    assert len(veh) > 5 and veh.loc["added", "cold_start_l"] == pytest.approx(
        0.07 * _warm_part(res, ["added"])[0], rel=1e-12)
    assert (veh.drop(index="added")["cold_start_l"] == 0).all()
    assert res.summary["chain"]["cold_start"]["vehicles"] == 1


def test_a_flipped_battery_current_is_refused_not_fitted(tmp_path, capsys):
    """Found by the second metamorphic sweep: JLU and i3 logs with the current's sign flipped
    calibrated to η_t = 1, η_r = 0.001, auxiliary 0 W, R² −2.87, and exit 0. The battery power
    must rise with the driving power; falling, the log is refused, asking about the sign."""
    import pandas as pd

    from sumo_drvpw.cli import main as cli_main

    log, road = _planted_battery_log(tmp_path)
    df = pd.read_csv(log)
    df["battery_current_a"] = -df["battery_current_a"]
    flipped = tmp_path / "flipped.csv"
    df.to_csv(flipped, index=False)
    out = tmp_path / "chain.toml"
    assert cli_main(["calibrate", str(flipped), "--target", "battery", "--equation", str(road),
                     "--load", "heater_power_w", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "is the current's sign flipped?" in err and "flipped.csv" in err and "current_positive" in err
    assert "its mapping's scale = -1 on battery_current_a" in err  # (the import's fix, too: a rehearsal)
    assert not out.exists()
    # the log as logged still calibrates
    assert cli_main(["calibrate", str(log), "--target", "battery", "--equation", str(road),
                     "--load", "heater_power_w", "--out", str(out)]) == 0
    # compare and diagnose read the same target: they booked +200…+400 % per trip and took
    # driving for charging, exit 0 (found by a sweep on unseen logs); now the same refusal
    for cmd in (["compare", str(flipped), "--equation", str(out), "--target", "battery", "--out",
                 str(tmp_path / "cmp")],
                ["diagnose", str(flipped), "--equation", str(out), "--target", "battery", "--out",
                 str(tmp_path / "dg")]):
        assert cli_main(cmd) == 2
        err = capsys.readouterr().err
        assert "is the current's sign flipped?" in err and "flipped.csv" in err, err
        assert not (tmp_path / cmd[-1]).exists()
    assert cli_main(["compare", str(log), "--equation", str(out), "--target", "battery", "--out",
                     str(tmp_path / "cmp")]) == 0


def test_no_cold_start_fuel_while_a_start_stop_engine_is_off():
    """A start-stop system's engine off (sim/shutoff.py): no fuel, the cold start's decaying
    part included (it was booked on top of the zeroed fuel: 0.021 L in 60 s switched off;
    found by a review); the battery chain's cabin warm-up goes on (its auxiliaries run)."""
    from sumo_drvpw.sim.chain import ChainLedger

    fuel = EnergyChain(predicts="fuel", idle_fuel_power_w=4000.0, marginal_efficiency=0.35, cold_start_fuel_l=0.07,
                       engine_off_below_w=-np.inf)  # a conventional engine: idles when on
    bat = EnergyChain(predicts="battery", aux_power_w=300.0, hvac={"column": "ambient_c", "setpoint_c": 20.0,
                                                                   "heating_w_per_k": 0.0, "cooling_w_per_k": 0.0,
                                                                   "warmup_j_per_k": 80e3})
    led = ChainLedger(["f", "b"], [fuel, bat], 2, cold_start=1.0, signal_values={"ambient_c": 0.0})
    led.start(np.arange(2))
    off = np.array([True, False])
    for _ in range(60):
        led.book(np.arange(2), np.zeros(2, np.int64), np.zeros(2), 1.0, np.zeros((2, 2)), engine_off=off)
    tot = led.vehicle_totals(2)
    part = 1.0 - np.exp(-60.0 / FUEL_COLD_START_TAU_S)
    assert tot[0, 0, 5] == 0.0 and tot[1, 0, 5] == pytest.approx(4000.0 * 60 / 43.2e6 / 0.745 + 0.07 * part)
    warm = 80e3 * 20.0 * (1.0 - np.exp(-60.0 / CABIN_WARMUP_TAU_S))
    assert tot[0, 1, 2] == pytest.approx(300.0 * 60 + warm) == tot[1, 1, 2]


def test_a_battery_chain_that_recuperates_nothing_is_flagged(tmp_path, capsys):
    """Rehearsal on a public Nissan Leaf log: `calibrate --target battery` fitted a
    recuperation efficiency of 0.001 (at its bound) and called it "low: friction braking or
    a recuperation limit dominates", no warning; SUMO runs then booked no recuperation for
    an electric car. Planted: the battery V·I of a chain returning 0.7 of braking is not
    flagged; the same V·I with only the auxiliaries' draw while braking (a battery that
    never takes energy back) is, in the console's warnings and in the equation's [chain.provenance] warnings."""
    from sumo_drvpw.cli import main as cli_main

    from sumo_drvpw.data.log import from_frame

    log, road = _planted_battery_log(tmp_path)
    df = pd.read_csv(log)
    braking = load_equation(road).power(from_frame(df).inputs()) < 0
    clipped = tmp_path / "clipped.csv"  # while braking only the auxiliaries draw: nothing returns
    df.assign(battery_current_a=np.where(braking, (500.0 + df["heater_power_w"]) / 360.0,
                                         df["battery_current_a"])).to_csv(clipped, index=False)
    for f, flagged in ((log, False), (clipped, True)):
        eq = tmp_path / f"{f.stem}.toml"
        assert cli_main(["calibrate", str(f), "--target", "battery", "--equation", str(road),
                         "--load", "heater_power_w", "--out", str(eq)]) == 0
        said = capsys.readouterr().out
        chain = load_equation(eq).chain
        assert (chain.recuperation_efficiency < 0.15) == flagged
        hit = "IMPLAUSIBLE for a car that recuperates"
        assert ("warning: energy chain recuperation_efficiency" in said and hit in said) == flagged, said
        assert any(hit in w for w in chain.provenance.get("warnings", [])) == flagged


def test_standstill_auxiliary_is_drawn_below_the_standstill_speed_only_by_hand():
    """A battery chain's ``standstill_aux_w`` (model/chain.py: + P_stand·[v < v_stand],
    v_stand = STANDSTILL_MPS = 0.1 m/s) adds to the auxiliary power only while the vehicle
    stands: at 0 and 0.05 m/s, not at exactly 0.1 m/s (the threshold moves) nor at 15 m/s.
    By hand with P_aux 400 W, P_stand 300 W, η_t 0.8 and no driving power where it stands:
    auxiliary 700, 700, 400, 400 W; the moving sample at 8 kW draws 8/0.8 = 10 kW + 400 W."""
    from sumo_drvpw.model.constants import STANDSTILL_MPS

    ch = EnergyChain(predicts="battery", traction_efficiency=0.8, recuperation_efficiency=0.6,
                     aux_power_w=400.0, standstill_aux_w=300.0)
    v = np.array([0.0, 0.05, STANDSTILL_MPS, 15.0])
    p = np.array([0.0, 0.0, 0.0, 8_000.0])
    out = ch.evaluate(p, v, dt_s=2.0)
    np.testing.assert_allclose(out["auxiliary_w"], [700.0, 700.0, 400.0, 400.0])
    np.testing.assert_allclose(out["power_w"], [700.0, 700.0, 400.0, 10_400.0])
    np.testing.assert_allclose(out["auxiliary_j"], [1400.0, 1400.0, 800.0, 800.0])


def test_ledger_evaluates_each_chain_only_on_the_vehicles_it_books(monkeypatch):
    """A bare SUMO config books a dozen built-in chains, each for one kind of vehicle (petrol
    cars, diesel trucks, electric cars …); the ledger evaluated every chain on every vehicle in
    every step and zeroed what did not apply: DLR's port_lübeck (2026-11-29, cProfile) 42,744
    chain evaluations over 3,562 steps, 12 a step, for the 3 chains that booked anything, and
    60 edge bincounts a step — 18.6 of its 44.6 s of stepping. Now a chain is evaluated only
    on the vehicles it applies to, and not at all in a step without one; the quantities are
    those of evaluating every vehicle and zeroing the others."""
    from sumo_drvpw.sim.chain import ChainLedger

    eqs = [load_equation(n) for n in ("epa_gasoline_car", "bmw_i3_battery", "moves_single_unit_truck_diesel")]
    calls = []
    real = EnergyChain.evaluate

    def counted(self, p, *a, **k):
        calls.append((self, len(np.atleast_1d(p))))
        return real(self, p, *a, **k)

    rng = np.random.default_rng(4)
    n, dt = 7, 1.0
    v = rng.uniform(0, 20, n)
    p = rng.normal(0, 2e4, (n, 3))
    app = np.zeros((n, 3))
    app[:4, 0] = 1.0  # four petrol cars, three trucks, no electric car in this step
    app[4:, 2] = 1.0
    eidx = rng.integers(0, 3, n)
    ref = ChainLedger([e.name for e in eqs], [e.chain for e in eqs], n_edges=3)
    want = ref.expand(ref.book(np.arange(n), eidx, v, dt, p)) * app[:, :, None]
    led = ChainLedger([e.name for e in eqs], [e.chain for e in eqs], n_edges=3)
    monkeypatch.setattr(EnergyChain, "evaluate", counted)
    got = led.expand(led.book(np.arange(n), eidx, v, dt, p, app=app))
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)
    assert sorted(k for _, k in calls) == [3, 4]
    assert all(c is not eqs[1].chain for c, _ in calls)
    per_edge = np.stack([want[eidx == k].sum(axis=0) for k in range(3)])
    np.testing.assert_allclose(led.edge, per_edge, rtol=1e-12, atol=0)
    np.testing.assert_allclose(led.veh[:n], want, rtol=1e-12, atol=0)
