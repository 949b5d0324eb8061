"""`roadload_spec` on a road log: the published A + B·v + C·v² with the grade's potential
energy (coefficient 1), so a battery chain calibrated on a hilly road log on it finds the
planted efficiencies — without the grade the descents' recuperation went unexplained and
η_r fell to its bound (a real LeafSpy log in Wales: 0.001, 0.47 with the grade)."""

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.model.equations import load_equation


def _hilly_battery_log(tmp_path):
    """Two trips over a hilly road (grade ±6 %), 10 Hz; battery V·I from a planted chain
    on the true road load acc 1, grade 1, v1 150 N, v3 0.35 N/(m/s)² at 1500 kg."""
    rng = np.random.default_rng(11)
    frames = []
    for trip in ("T1", "T2"):
        n = 9000
        t = np.arange(n) * 0.1
        v = np.clip(14 + 6 * np.sin(t / 40.0) + rng.normal(0, 0.03, n), 0, None)
        v[:200] = 0.0
        grade = 0.06 * np.sin(t / 55.0 + (0.0 if trip == "T1" else 1.3))
        frames.append(pd.DataFrame({"trip_id": trip, "time_s": t, "speed_mps": v, "mass_kg": 1500.0,
                                    "grade_rad": grade}))
    df = pd.concat(frames, ignore_index=True)
    truth = tmp_path / "truth.toml"
    truth.write_text('[equation]\nname = "truth"\n[terms]\nacc = 1.0\ngrade = 1.0\nv1 = 150.0\nv3 = 0.35\n',
                     encoding="utf-8")
    from sumo_drvpw.data.log import from_frame

    x = from_frame(df).inputs()
    p = load_equation(truth).power(x)
    plant = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.65,
                        aux_power_w=400.0)
    bat = plant.evaluate(p, x.v)["power_w"]
    df["battery_voltage_v"] = 360.0
    df["battery_current_a"] = bat / 360.0
    log = tmp_path / "road.csv"
    df.to_csv(log, index=False)
    veh = tmp_path / "car.toml"
    veh.write_text('[vehicle]\nname = "car"\nmass_kg = 1500\n[powertrain]\ntype = "battery"\n'
                   '[battery]\ncurrent_positive = "discharge"\n'
                   '[road_load]\na_n = 150.0\nb_n_per_mps = 0.0\nc_n_per_mps2 = 0.35\n', encoding="utf-8")
    return log, veh


def test_roadload_spec_carries_the_grade_by_hand():
    """P = m·v·a + m·g·v·sin θ + A·v + B·v² + C·v³ (JLU dyno A, B, C): the grade term is
    m·g·v·sin θ at coefficient 1, 0 on a flat road."""
    from sumo_drvpw.data.measured import resolve_equations
    from sumo_drvpw.model.constants import G
    from sumo_drvpw.model.terms import Inputs
    from sumo_drvpw.model.vehicles import load_vehicle

    eq = resolve_equations(["roadload_spec"], load_vehicle("jlu_bev"))[0]
    assert eq.terms["grade"] == 1.0
    theta = np.array([0.0, 0.05])
    x = Inputs(np.array([10.0, 10.0]), np.zeros(2), theta, np.zeros(2), np.full(2, 1919.0), np.full(2, 1.2), {})
    flat = (179.4 + 1.008 * 10 + 0.30456 * 100) * 10
    np.testing.assert_allclose(eq.power(x), [flat, flat + 1919.0 * G * 10 * np.sin(0.05)], rtol=1e-12)


def test_battery_chain_on_roadload_spec_finds_the_planted_efficiencies_on_a_hilly_road(tmp_path):
    from sumo_drvpw.cli import main as cli_main

    log, veh = _hilly_battery_log(tmp_path)
    out = tmp_path / "chain.toml"
    assert cli_main(["calibrate", str(log), "--vehicle", str(veh), "--target", "battery",
                     "--equation", "roadload_spec", "--out", str(out)]) == 0
    eq = load_equation(out)
    ch = eq.chain
    got = (ch.traction_efficiency, ch.recuperation_efficiency, ch.aux_power_w)
    assert got == pytest.approx((0.9, 0.65, 400.0), rel=0.03)
    assert eq.terms["grade"] == 1.0   # written with the equation: SUMO books the climbs too
