"""A conventional engine that idles at stops is fitted as one (fit/chain_fuel.py
``idles_at_stops``): the fuel chain's engine-off profile keeps only an engine that runs at
standstill when the log shows fuel flowing on most of the standing time.

Why: on Argonne's D3 dynamometer tests of a 2018 Toyota Camry (docs/d3-camry.md) one fold
of the calibration read the conventional car as an engine that stops at P ≤ 0 with a
1.8 kW auxiliary draw paid at the margin: the charge-sustaining template took up the
higher fuel of an engine in gear than at idle. The planted engine below does the same:
5 kW of fuel at idle, 8 kW + P/η when moving."""

from __future__ import annotations

import tomllib

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.fit.chain_fuel import calibrate_fuel, idles_at_stops, standing_sums

IDLE_W, GEAR_W, ETA = 5_000.0, 8_000.0, 0.33
MASS, F0, F2 = 1500.0, 150.0, 0.4


def _stop_and_go(seed=4, dt=0.5):
    """Trips of accelerate – cruise – brake – stand 20 s, at 2 Hz: speed, driving power."""
    rng = np.random.default_rng(seed)
    v = []
    for _ in range(60):
        top = rng.uniform(8.0, 30.0)
        up = np.arange(0.0, top, rng.uniform(0.8, 2.0) * dt)
        down = np.arange(top, 0.0, -rng.uniform(0.8, 2.5) * dt)
        v += [up, np.full(int(rng.uniform(20, 120) / dt), top), down, np.zeros(int(20 / dt))]
    v = np.concatenate(v)
    t = np.arange(v.size) * dt
    a = np.gradient(v, t)
    p = MASS * a * v + F0 * v + F2 * v ** 3
    return rng, t, v, p


def _fuel(rng, v, p):
    moving = v > 0.05
    fuel = np.where(moving, GEAR_W + np.maximum(p, 0.0) / ETA, IDLE_W)
    return fuel + rng.normal(0, 300.0, v.size)


def test_an_engine_idling_at_stops_is_fitted_as_one(monkeypatch):
    rng, t, v, p = _stop_and_go()
    fuel, dt = _fuel(rng, v, p), np.full(v.size, 0.5)
    stand = standing_sums(v, fuel, dt, np.ones(v.size, bool))
    assert stand[0] > 1000 and idles_at_stops(stand)
    fit = calibrate_fuel(p, v, fuel, dt)
    assert fit.chain.engine_off_below_w == -np.inf and not fit.chain.charge_sustaining
    assert {r["engine_off_below_w"] for r in fit.profile} == {-np.inf}
    reading = fit.parameters["engine_off_below_w"]["reading"]
    assert "idling at stops (fuel flowing on 100% of" in reading
    assert fit.parameters["engine_off_below_w"]["how"].startswith("fixed")
    # the premise: without the rule the profile prefers an engine that stops at P ≤ 0 with
    # an auxiliary draw paid at the margin (idle fuel while moving, the draw standing)
    import sumo_drvpw.fit.chain_fuel as chain_fuel

    with monkeypatch.context() as m:
        m.setattr(chain_fuel, "IDLES_AT_STOPS_SHARE", 2.0)
        blind = calibrate_fuel(p, v, fuel, dt)
    assert blind.chain.engine_off_below_w >= 0 and blind.chain.charge_sustaining
    assert blind.chain.aux_power_w > 500.0
    moving = v > 0.05
    # an engine that stops where the car stands keeps the profile (a hybrid's)
    off = np.where(moving, fuel, 0.0)
    assert not idles_at_stops(standing_sums(v, off, dt, np.ones(v.size, bool)))
    assert len({r["engine_off_below_w"] for r in calibrate_fuel(p, v, off, dt).profile}) > 1


@pytest.mark.parametrize("engine", ["memory", "local"])
def test_calibrate_fits_an_idling_engine_as_one_in_memory_and_streamed(tmp_path, engine):
    """The same through `calibrate --target fuel`, in memory and streamed (the standing
    sums add over batches): the equation file's engine never stops, and its reading says
    why."""
    from sumo_drvpw.cli import main as cli_main

    rng, t, v, p = _stop_and_go(seed=5)
    fuel_w = _fuel(rng, v, p)
    lph = fuel_w / (42.5e6 * 0.745) * 3600.0  # any petrol: the structure, not the numbers
    pd.DataFrame({"time_s": t, "speed_mps": v, "fuel_rate_lph": lph, "mass_kg": MASS}).to_parquet(
        tmp_path / "log.parquet")
    (tmp_path / "rl.toml").write_text(f'[equation]\nname = "rl"\n[terms]\nv1 = {F0}\nv3 = {F2}\nacc = 1.0\n')
    out = tmp_path / f"{engine}.toml"
    assert cli_main(["calibrate", str(tmp_path / "log.parquet"), "--target", "fuel", "--equation",
                     str(tmp_path / "rl.toml"), "--engine", engine, "--out", str(out)]) == 0
    chain = tomllib.loads(out.read_text())["chain"]
    assert chain["engine_off_below_w"] == -np.inf and not chain.get("charge_sustaining", False)
    assert "idling at stops" in chain["reading"]["engine_off_below_w"]
