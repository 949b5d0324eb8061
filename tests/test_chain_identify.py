"""The driving power a log must reach for a chain's efficiency to be told (fit/chain_checks.py
``identify_drive_w``) scales with the vehicle's mass: 2 kW is a 1.5 t car creeping, but more than a
94 kg e-scooter with its rider draws at 25 km/h, and a 30 t truck's creep.

Why: a calibration of a Xiaomi scooter's battery chain on its real rides (DualEMobilityData, 94 kg with
its rider, peaks of a few hundred W at the wheels) was refused as 'standing, idling or creeping only'."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.fit.chain_checks import IDENTIFY_DRIVE_W, identify_drive_w


def _rides(mass, top_mps, seed=2):
    """Rides at 1 Hz — accelerate at 0.5 m/s², cruise, brake, stand — of a vehicle of ``mass``
    [kg]; the driving power of v1 = 0.01·m·g, v3 = 0.3, and the battery's V·I through η 0.85/0.6
    plus 20 W, with noise."""
    rng = np.random.default_rng(seed)
    v = np.concatenate([np.concatenate([np.arange(0, top, 0.5), np.full(120, top), np.arange(top, 0, -1.0),
                                        np.zeros(20)]) for top in rng.uniform(0.6, 1.0, 20) * top_mps])
    t = np.arange(v.size, dtype=float)
    f0 = 0.01 * mass * 9.81
    p = mass * np.gradient(v, t) * v + f0 * v + 0.3 * v ** 3
    bat = np.where(p > 0, p / 0.85, 0.6 * p) + 20.0 + rng.normal(0, 0.01 * max(p.max(), 1.0), v.size)
    return t, v, p, bat, f0


def _calibrate(tmp_path, mass, top_mps, capsys):
    from sumo_drvpw.cli import main as cli_main

    t, v, p, bat, f0 = _rides(mass, top_mps)
    pd.DataFrame({"time_s": t, "speed_mps": v, "battery_voltage_v": 36.0, "battery_current_a": bat / 36.0}
                 ).to_parquet(tmp_path / "ride.parquet")
    (tmp_path / "veh.toml").write_text(f'[vehicle]\nname = "v"\nmass_kg = {mass}\n[powertrain]\ntype = "battery"\n',
                                       encoding="utf-8")
    (tmp_path / "rl.toml").write_text(f'[equation]\nname = "rl"\n[terms]\nv1 = {f0}\nv3 = 0.3\nacc = 1.0\n',
                                      encoding="utf-8")
    out = tmp_path / "o.toml"
    rc = cli_main(["calibrate", str(tmp_path / "ride.parquet"), "--target", "battery", "--vehicle",
                   str(tmp_path / "veh.toml"), "--equation", str(tmp_path / "rl.toml"), "--out", str(out)])
    return rc, capsys.readouterr().err.strip(), out, p


def test_a_scooter_that_drives_is_calibrated(tmp_path, capsys):
    """94 kg at up to 25 km/h: driving power peaks well under 2 kW but far above its 125 W."""
    rc, err, out, p = _calibrate(tmp_path, 94.0, 25 / 3.6, capsys)
    assert identify_drive_w(type("V", (), {"mass_kg": 94.0})) < p.max() < IDENTIFY_DRIVE_W
    assert rc == 0, err
    assert out.exists()


def test_a_truck_that_only_creeps_is_refused(tmp_path, capsys):
    """30 t creeping at up to 5 km/h: above 2 kW, yet far below the power a 30 t truck drives
    with — refused in one line naming its threshold per kg, no output."""
    rc, err, out, p = _calibrate(tmp_path, 30000.0, 5 / 3.6, capsys)
    assert IDENTIFY_DRIVE_W < p.max() < identify_drive_w(type("V", (), {"mass_kg": 30000.0}))
    assert rc == 2 and len(err.splitlines()) == 1 and "ride.parquet" in err
    assert "never above 40 kW (1.33 W/kg of its 30000 kg)" in err
    assert not out.exists()


@pytest.mark.parametrize("mass", [None, 0.0, float("nan")])
def test_without_a_mass_the_car_threshold_stays(mass):
    assert identify_drive_w(None if mass is None else type("V", (), {"mass_kg": mass})) == IDENTIFY_DRIVE_W
