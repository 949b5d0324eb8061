"""A battery chain calibrated with ``--equation`` on a log that has a measured driving power
(motor torque × speed) is fitted on the measured power, not on the equation's: the command
says so. Found on a public LeafSpy log of a 2020 Nissan Leaf (ericthobbs/TripViewer @
a58aa42, examples/Log.csv, docs/adapters.md): its `Torque Nm` × `RPM` is 0.77 of the
battery's V·I at 65 mph, so `--equation roadload_spec` (the EPA road load) gave exactly the
chain the measured power gives — traction efficiency 1, 2.65 kW of auxiliary power — while
the warning blamed the road load, which the fit had not used."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

MASS, RATIO, RADIUS = 1500.0, 8.0, 0.3


def _log(tmp_path, torque_reads: float = 0.8):
    """1-Hz rides of a single-motor car on the road load ``rl`` below; its logged motor
    torque reads ``torque_reads`` of the true (a sensor reading low, as the Leaf's), the
    battery's V·I is the true power through η 0.9 plus 300 W."""
    rng = np.random.default_rng(5)
    v = np.concatenate([np.concatenate([np.arange(0, top, 1.0), np.full(60, top), np.arange(top, 0, -1.5),
                                        np.zeros(10)]) for top in rng.uniform(10, 30, 12)])
    t = np.arange(v.size, dtype=float)
    p = MASS * np.gradient(v, t) * v + 150.0 * v + 0.4 * v ** 3
    w = v / RADIUS * RATIO  # motor speed [rad/s]
    tq = np.where(w > 0, torque_reads * p / np.maximum(w, 1e-9), 0.0)
    bat = np.where(p > 0, p / 0.9, 0.6 * p) + 300.0
    pd.DataFrame({"time_s": t, "speed_mps": v, "motor_torque_nm": tq, "motor_speed_rpm": w * 60 / (2 * np.pi),
                  "battery_voltage_v": 360.0, "battery_current_a": bat / 360.0}).to_parquet(tmp_path / "r.parquet")
    (tmp_path / "veh.toml").write_text(
        f'[vehicle]\nname = "v"\nmass_kg = {MASS}\n[powertrain]\ntype = "single_motor"\ngear_ratio = {RATIO}\n'
        f'wheel_radius_m = {RADIUS}\n[battery]\ncurrent_positive = "discharge"\n', encoding="utf-8")
    (tmp_path / "rl.toml").write_text('[equation]\nname = "rl"\n[terms]\nv1 = 150.0\nv3 = 0.4\nacc = 1.0\n',
                                      encoding="utf-8")


@pytest.mark.parametrize("engine", ["memory", "local"])
def test_the_chain_says_it_is_fitted_on_the_measured_power(tmp_path, capsys, engine):
    from sumo_drvpw.cli import main as cli_main

    _log(tmp_path)
    rc = cli_main(["calibrate", str(tmp_path / "r.parquet"), "--target", "battery", "--vehicle",
                   str(tmp_path / "veh.toml"), "--equation", str(tmp_path / "rl.toml"), "--engine", engine,
                   "--out", str(tmp_path / "o.toml")])
    out = capsys.readouterr().out
    assert rc == 0
    note = [ln for ln in out.splitlines() if ln.startswith("note: the chain is fitted on")]
    assert len(note) == 1, out
    assert "measured driving power (single motor" in note[0] and f"not on --equation {tmp_path / 'rl.toml'}" in note[0]
    # what it warns of: the chain took the sensor's 0.8 into its efficiency (0.9 × 0.8)
    import tomllib

    chain = tomllib.loads((tmp_path / "o.toml").read_text(encoding="utf-8"))["chain"]
    assert chain["traction_efficiency"] == pytest.approx(0.72, abs=0.02)


def test_no_note_without_an_equation_or_a_measured_power(tmp_path, capsys):
    """The stepwise road load fitted on the same measured power (no --equation), or a log
    with battery V·I alone: the chain's input is what the equation is fitted on; no note."""
    from sumo_drvpw.cli._scale import chain_input_note

    assert chain_input_note(None, "single motor (motor torque × motor speed)") is None
    assert chain_input_note("roadload_spec", None) is None


@pytest.mark.parametrize("engine", ["memory", "local"])
@pytest.mark.parametrize("equation", [False, True])
def test_an_implausible_traction_efficiency_on_a_measured_power_blames_it_not_the_road_load(tmp_path, capsys,
                                                                                           engine, equation):
    """A battery chain fitted on a measured driving power (motor torque × speed) whose torque
    reads 0.6 of the true: η_t = 0.9 × 0.6 = 0.54, IMPLAUSIBLE for a BEV. No road load was in
    that fit, so the warning names the measured power it was fitted on (its sensor's scale or
    timing), not 'the road load is off' — which it said before, with or without --equation
    (the 2020 Leaf's LeafSpy τ·ω: η_t 1 'the road load is off', docs/adapters.md). The same
    chain fitted on an equation's power keeps the road-load text (test_chain_checks.py)."""
    import tomllib

    from sumo_drvpw.cli import main as cli_main

    _log(tmp_path, torque_reads=0.6)
    rc = cli_main(["calibrate", str(tmp_path / "r.parquet"), "--target", "battery", "--vehicle",
                   str(tmp_path / "veh.toml"), "--engine", engine, "--out", str(tmp_path / "o.toml")]
                  + (["--equation", str(tmp_path / "rl.toml")] if equation else []))
    out = capsys.readouterr().out
    assert rc == 0
    chain = tomllib.loads((tmp_path / "o.toml").read_text(encoding="utf-8"))["chain"]
    assert chain["traction_efficiency"] == pytest.approx(0.54, abs=0.02)
    said = [ln for ln in out.splitlines() if ln.startswith("warning: energy chain traction_efficiency")]
    assert len(said) == 1, out
    assert "IMPLAUSIBLE for a BEV" in said[0] and "the road load is off" not in said[0]
    assert "measured driving power" in said[0] and "not a road load's power" in said[0]
