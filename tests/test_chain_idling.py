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
    (tmp_path / "rl.toml").write_text(f'[equation]\nname = "rl"\n[terms]\nv1 = {F0}\nv3 = {F2}\nacc = 1.0\n', encoding="utf-8")
    out = tmp_path / f"{engine}.toml"
    assert cli_main(["calibrate", str(tmp_path / "log.parquet"), "--target", "fuel", "--equation",
                     str(tmp_path / "rl.toml"), "--engine", engine, "--out", str(out)]) == 0
    chain = tomllib.loads(out.read_text(encoding="utf-8"))["chain"]
    assert chain["engine_off_below_w"] == -np.inf and not chain.get("charge_sustaining", False)
    assert "idling at stops" in chain["reading"]["engine_off_below_w"]


@pytest.mark.parametrize("engine", ["memory", "local"])
def test_a_log_that_only_idles_is_refused_not_fitted_to_an_efficiency_at_its_bound(tmp_path, capsys, engine):
    """Half an hour of idling with one creep to 5 km/h (a rehearsal's idling-only log): no
    driving power above 2 kW, so the Willans slope is not identified — the fit put it at its
    bound (100 %) and wrote the file, exit 0. Now exit 2 in one line naming the log, no file."""
    from sumo_drvpw.cli import main as cli_main

    rng = np.random.default_rng(1)
    t = np.arange(0.0, 1800.0, 0.5)
    v = np.zeros(t.size)
    v[1000:1040] = 1.5 * np.sin(np.linspace(0.0, np.pi, 40))
    log = tmp_path / "idle.parquet"
    pd.DataFrame({"time_s": t, "speed_mps": v, "fuel_rate_gps": 0.166 + rng.normal(0, 0.005, t.size),
                  "mass_kg": MASS}).to_parquet(log)
    (tmp_path / "rl.toml").write_text(f'[equation]\nname = "rl"\n[terms]\nv1 = {F0}\nv3 = {F2}\nacc = 1.0\n', encoding="utf-8")
    out = tmp_path / "o.toml"
    assert cli_main(["calibrate", str(log), "--target", "fuel", "--equation", str(tmp_path / "rl.toml"),
                     "--engine", engine, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err and "idle.parquet" in err
    assert "never above 2 kW" in err and "marginal efficiency cannot be told" in err
    assert not out.exists()


@pytest.mark.parametrize("fuel,eta,flagged", [("gasoline", 0.52, True), ("diesel", 0.52, False),
                                              ("gasoline", 0.27, False), ("diesel", 0.27, True)])
def test_the_willans_slope_is_judged_by_the_engine_s_fuel(fuel, eta, flagged):
    """A diesel's marginal efficiency of 0.52 is plausible (the literature's ≈ 0.45), a
    petrol engine's is not, and 0.27 the other way round; the reading names the engine's fuel, not "petrol" for both."""
    from sumo_drvpw.fit.chain_checks import reading

    r = reading("marginal_efficiency", eta, fuel)
    assert ("IMPLAUSIBLE" in r) == flagged
    assert not flagged or f"for a {'petrol' if fuel == 'gasoline' else 'diesel'} engine" in r


@pytest.mark.parametrize("engine", ["memory", "local"])
@pytest.mark.parametrize("declared,want", [("never", -np.inf), ("2000", 2000.0)])
def test_the_engine_off_threshold_can_be_declared(tmp_path, engine, declared, want):
    """A log too short to show its engine idling at stops (under 30 s standing) is profiled
    over every threshold; `--engine-off never` declares the conventional engine that runs
    throughout (or a threshold in W), in memory and streamed alike, and the file says it
    was declared."""
    from sumo_drvpw.cli import main as cli_main

    rng, t, v, p = _stop_and_go(seed=6)
    keep = np.cumsum(v < 0.05) * 0.5 < 25.0  # the log ends 25 s into its stops
    standing = float(0.5 * (v[keep] < 0.05).sum())
    assert standing < 30.0  # too short for the idling rule (IDLING_MIN_STANDING_S)
    lph = _fuel(rng, v, p)[keep] / (42.5e6 * 0.745) * 3600.0
    pd.DataFrame({"time_s": t[keep], "speed_mps": v[keep], "fuel_rate_lph": lph, "mass_kg": MASS}).to_parquet(
        tmp_path / "log.parquet")
    (tmp_path / "rl.toml").write_text(f'[equation]\nname = "rl"\n[terms]\nv1 = {F0}\nv3 = {F2}\nacc = 1.0\n', encoding="utf-8")
    out = tmp_path / f"{engine}.toml"
    assert cli_main(["calibrate", str(tmp_path / "log.parquet"), "--target", "fuel", "--equation",
                     str(tmp_path / "rl.toml"), "--engine", engine, "--engine-off", declared, "--out", str(out)]) == 0
    chain = tomllib.loads(out.read_text(encoding="utf-8"))["chain"]
    assert chain["engine_off_below_w"] == want
    assert chain["reading"]["engine_off_below_w"].endswith("declared, not profiled")


def _short_log(tmp_path, idle_w=IDLE_W):
    """The short log above (under 30 s standing: the idling rule cannot tell) with an equation."""
    rng, t, v, p = _stop_and_go(seed=6)
    keep = np.cumsum(v < 0.05) * 0.5 < 25.0
    fuel = np.where(v > 0.05, _fuel(rng, v, p), idle_w + rng.normal(0, 300.0, v.size))[keep]
    pd.DataFrame({"time_s": t[keep], "speed_mps": v[keep], "fuel_rate_lph": fuel / (42.5e6 * 0.745) * 3600.0,
                  "mass_kg": MASS}).to_parquet(tmp_path / "log.parquet")
    (tmp_path / "rl.toml").write_text(f'[equation]\nname = "rl"\n[terms]\nv1 = {F0}\nv3 = {F2}\nacc = 1.0\n', encoding="utf-8")


@pytest.mark.parametrize("engine", ["memory", "local"])
@pytest.mark.parametrize("battery", [False, True, "logged"], ids=["no-traction-battery", "battery-declared",
                                                                   "battery-logged"])
def test_a_car_without_a_traction_battery_is_not_fitted_as_a_hybrid(tmp_path, engine, battery):
    """A vehicle file of powertrain type 'direct' without a [battery] table, and no battery
    power logged: a car whose engine alone drives it. Its engine-off threshold is profiled
    only over 'never' and 0 W (stops where no driving power is asked), without the
    charge-sustaining form (no battery carries its loads while the engine is off). Before, a
    rehearsal's OBD log of a conventional Seat Leon (under 30 s standing) was fitted as an
    engine off below 5 kW, 'the battery drives', with a 10-kW auxiliary draw. A vehicle file
    that declares its battery keeps the whole profile."""
    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.fit.chain_fuel import CONVENTIONAL_OFF_GRID_W, ENGINE_OFF_GRID_W

    _short_log(tmp_path)
    if battery == "logged":  # a hybrid's battery V·I in the log, no [battery] in its file: a hybrid
        df = pd.read_parquet(tmp_path / "log.parquet")
        df = df.assign(battery_voltage_v=200.0, battery_current_a=np.random.default_rng(2).normal(0, 5, len(df)))
        df.to_parquet(tmp_path / "log.parquet")
    (tmp_path / "car.toml").write_text(
        f'[vehicle]\nname = "car"\nmass_kg = {MASS}\n[powertrain]\ntype = "direct"\nfuel = "gasoline"\n'
        + ('[battery]\ncapacity_kwh = 1.3\n' if battery is True else ""), encoding="utf-8")
    out = tmp_path / f"{engine}.toml"
    assert cli_main(["calibrate", str(tmp_path / "log.parquet"), "--vehicle", str(tmp_path / "car.toml"),
                     "--target", "fuel", "--equation", str(tmp_path / "rl.toml"), "--engine", engine,
                     "--out", str(out)]) == 0
    doc = tomllib.loads(out.read_text(encoding="utf-8"))
    chain = doc["chain"]
    from sumo_drvpw.fit.chain_fuel import engine_off_for, fuel_grid
    from sumo_drvpw.model.vehicles import load_vehicle

    how = engine_off_for(load_vehicle(str(tmp_path / "car.toml")), battery == "logged")
    tried = {c.engine_off_below_w for c in fuel_grid(how)}
    assert tried == set(ENGINE_OFF_GRID_W if battery else CONVENTIONAL_OFF_GRID_W)
    assert engine_off_for(load_vehicle(str(tmp_path / "car.toml")), True) == "profile"  # battery logged
    if battery:
        assert "without a traction battery" not in chain["reading"]["engine_off_below_w"]
    else:
        assert chain["engine_off_below_w"] in CONVENTIONAL_OFF_GRID_W
        assert not chain.get("charge_sustaining", False) and chain.get("aux_power_w", 0.0) == 0.0
        assert "a car without a traction battery" in chain["reading"]["engine_off_below_w"]


@pytest.mark.parametrize("idle_w,flagged", [(IDLE_W, False), (30_000.0, True)])
def test_a_fuel_target_no_idling_engine_burns_at_standstill_is_flagged(idle_w, flagged):
    """The log's own fuel at standstill, 3.4 L/h for a car (a diesel's air flow read as a
    petrol's, a rehearsal's Seat Leon TDI), is beyond any idling engine (2.5× the idle
    band's top): the chain's reading says the target is wrong, not only the fit; a
    plausible idle says nothing."""
    from sumo_drvpw.fit.chain_checks import check_chain
    from sumo_drvpw.model.vehicles import Vehicle

    rng, t, v, p = _stop_and_go(seed=7)
    fuel = np.where(v > 0.05, _fuel(rng, v, p), idle_w + rng.normal(0, 300.0, v.size))
    dt = np.full(v.size, 0.5)
    fit = calibrate_fuel(p, v, fuel, dt, engine_off=-np.inf)
    assert fit.standing is not None and fit.standing[1] > 1000
    check_chain(fit, Vehicle("car", MASS, powertrain={"displacement_l": 1.4}), p, v, np.ones(v.size, bool))
    r = fit.parameters["idle_fuel_power_w"]["reading"]
    assert ("IMPLAUSIBLE TARGET" in r) == flagged, r
    assert any("IMPLAUSIBLE TARGET" in w for w in fit.warnings) == flagged


@pytest.mark.parametrize("idle_w,said", [(IDLE_W, False), (22_000.0, True)])
def test_a_standing_fuel_above_a_car_s_idle_asks_for_the_engine_when_its_size_is_unknown(idle_w, said):
    """Without the engine's displacement the standstill check's band is any car's (up to a
    large engine's cold idle), so a diesel's air flow read as petrol at 3.3 L/h standing
    passed without a word (a rehearsal's KIT Seat Leon, 2026-11-29). Above a 2.0-L car's
    idle it now says to give the displacement (a warning); a plausible idle says nothing."""
    from sumo_drvpw.fit.chain_checks import check_chain
    from sumo_drvpw.model.vehicles import Vehicle

    rng, t, v, p = _stop_and_go(seed=7)
    fuel = np.where(v > 0.05, _fuel(rng, v, p), idle_w + rng.normal(0, 300.0, v.size))
    fit = calibrate_fuel(p, v, fuel, np.full(v.size, 0.5), engine_off=-np.inf)
    check_chain(fit, Vehicle("car", MASS), p, v, np.ones(v.size, bool))
    r = fit.parameters["idle_fuel_power_w"]["reading"]
    assert ("CHECK THE TARGET" in r and "powertrain.displacement_l" in r) == said, r
    assert any("CHECK THE TARGET" in w for w in fit.warnings) == said
    assert "IMPLAUSIBLE TARGET" not in r
