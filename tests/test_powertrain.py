"""Power-split driving power (seed paper Eq. 5-12) against hand calculations."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numpy.testing import assert_allclose

from sumo_drvpw.errors import UserError
from sumo_drvpw.data.powertrain import battery_power, planetary_mg1_speed, power_split_power

# simple ratios so every case is checkable by hand: k_r = 2, k_c = 1, k_f = 4 (k = 8)
GEAR = dict(sun_teeth=30, ring_teeth=78, mg2_reduction=2.0, counter_ratio=1.0, final_drive=4.0)
NO_INERTIA = {}


def ps(ice_w=0.0, ice_dw=0.0, mg1_w=0.0, mg1_dw=0.0, mg1_tq=0.0, mg2_w=0.0, mg2_tq=0.0, wh_dw=0.0,
       inertia=NO_INERTIA):
    return power_split_power(ice_w, ice_dw, mg1_w, mg1_dw, mg1_tq, mg2_w, mg2_tq, wh_dw,
                             inertia=inertia, **GEAR)


def test_engine_only_steady_state():
    # τ_MG1 = −30 N·m reacts the engine: τ_C = (108/30)·30 = 108 N·m, ring gets 78/108 of it
    # = 78 N·m, wheels 4·78 = 312 N·m; ω_MG2 = 800 rad/s → ω_wh = 800/8 = 100 rad/s → 31.2 kW.
    ice_w, ring_w = 200.0, 400.0
    mg1_w = planetary_mg1_speed(ice_w, ring_w, 30, 78)
    assert mg1_w == pytest.approx((108 * 200 - 78 * 400) / 30)  # = −320 rad/s
    out = ps(ice_w=ice_w, mg1_w=mg1_w, mg1_tq=-30.0, mg2_w=800.0)
    assert out["ice_torque_nm"] == pytest.approx(108.0)
    assert out["wheel_torque_nm"] == pytest.approx(312.0)
    assert out["wheel_speed"] == pytest.approx(100.0)
    assert out["power_w"] == pytest.approx(31_200.0)
    # power balance: engine 108·200 = 21.6 kW plus MG1 (−30)·(−320) = +9.6 kW motoring
    assert out["power_w"] == pytest.approx(108 * 200 + (-30) * mg1_w)


def test_ev_only_is_mg2_shaft_power():
    out = ps(mg2_w=500.0, mg2_tq=100.0)
    assert out["power_w"] == pytest.approx(50_000.0)  # τ·ω of MG2, engine and MG1 idle


def test_regeneration_is_negative():
    out = ps(mg2_w=500.0, mg2_tq=-80.0)
    assert out["power_w"] == pytest.approx(-40_000.0)


def test_acceleration_with_inertia():
    # J at the wheel = I_R·(k_c k_f)² + I_MG2·(k_r k_c k_f)² + I_wh = 0.01·16 + 0.03·64 + 3 = 5.08
    # τ_wh = 8·100 − 2·5.08 = 789.84 N·m; ω_wh = 400/8 = 50 rad/s → P = 39 492 W
    inertia = {"ring": 0.01, "mg2": 0.03, "wheels": 3.0}
    out = ps(mg2_w=400.0, mg2_tq=100.0, wh_dw=2.0, inertia=inertia)
    assert out["wheel_torque_nm"] == pytest.approx(789.84)
    assert out["power_w"] == pytest.approx(39_492.0)


def test_engine_inertia_stays_with_the_engine():
    # accelerating the engine at 100 rad/s² with I_ice = 0.18 needs 18 N·m more engine torque,
    # but the ring still receives R/(R+S) of the carrier's net torque 108 N·m
    base = ps(ice_w=200.0, mg1_tq=-30.0, mg2_w=800.0)
    acc = ps(ice_w=200.0, ice_dw=100.0, mg1_tq=-30.0, mg2_w=800.0, inertia={"ice": 0.18})
    assert acc["ice_torque_nm"] == pytest.approx(126.0)
    assert acc["power_w"] == pytest.approx(base["power_w"])


def test_mg1_inertia_term():
    # MG1 accelerating at 50 rad/s² with I_MG1 + I_S = 0.02 + 0.01: τ_C = 3.6·(1.5 + 30) = 113.4
    out = ps(mg1_dw=50.0, mg1_tq=-30.0, mg2_w=800.0, inertia={"mg1": 0.02, "sun": 0.01})
    assert out["ice_torque_nm"] == pytest.approx(113.4)
    assert out["wheel_torque_nm"] == pytest.approx(4 * 78 / 108 * 113.4)


@settings(max_examples=200, deadline=None)
@given(ice=st.floats(0, 600), ring=st.floats(0, 600), t1=st.floats(-200, 200), t2=st.floats(-300, 300))
def test_steady_state_power_balance(ice, ring, t1, t2):
    """Without accelerations, wheel power = engine + MG1 + MG2 mechanical power (no losses)."""
    mg1 = planetary_mg1_speed(ice, ring, 30, 78)
    mg2 = ring * GEAR["mg2_reduction"]
    out = ps(ice_w=ice, mg1_w=mg1, mg1_tq=t1, mg2_w=mg2, mg2_tq=t2)
    engine = out["ice_torque_nm"] * ice
    assert out["power_w"] == pytest.approx(engine + t1 * mg1 + t2 * mg2, rel=1e-9, abs=1e-6)


def test_battery_sign_conventions():
    assert_allclose(battery_power([300.0], [10.0], "discharge"), [3000.0])
    assert_allclose(battery_power([300.0], [10.0], "charge"), [-3000.0])
    with pytest.raises(UserError, match="current_positive"):
        battery_power([1.0], [1.0], "sideways")


def test_measured_power_on_synthetic_signals_matches_truth():
    """Inverse (synth) then forward (measured_power) reproduces the truth power without noise."""
    from sumo_drvpw.model.equations import load_equation
    from sumo_drvpw.synth.track import Noise, SynthOptions, synthesize
    from sumo_drvpw.data.measured import load_measured
    import tempfile
    from pathlib import Path
    from sumo_drvpw.synth.track import write_synth

    quiet = Noise(speed_mps=0, airspeed_mps=0, torque_nm=0, speed_rpm=0, imu_mps2=0, gps_elevation_m=0,
                  process_w=0, process_rel=0)
    df, truth = synthesize(SynthOptions(minutes=4, seed=3, noise=quiet))
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "q.parquet"
        write_synth(df, truth, p)
        from sumo_drvpw.data.log import ReadOptions

        # unsmoothed derivatives: the inverse model used exact central differences
        m = load_measured([p], "prius3", ReadOptions(accel_window_s=0.0))
    eq = load_equation("drvpw_prius3")
    pred = eq.power(m.inputs)
    u = m.usable & (m.inputs.v > 1.0)
    # only the rounding of logged speeds to whole rpm separates the two
    err = pred[u] - m.power_w[u]
    assert np.sqrt(np.mean(err ** 2)) < 50.0
    assert abs(np.mean(err)) < 10.0
