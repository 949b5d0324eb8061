"""data.charging: external charging inside a drive log (energy into the battery while the car
stands) is left out of battery-target fits and per-trip energies, and counted."""

import json

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.data.charging import CHARGE_MIN_S, charging_mask
from sumo_drvpw.model.equations import load_equation


def test_mask_by_hand():
    t = np.arange(0.0, 200.0, 1.0)
    v = np.full(200, 10.0)
    p = np.full(200, 5000.0)
    v[20:80] = 0.0
    p[20:80] = -20000.0      # 60 s standing, 20 kW flowing in: a charger
    v[100:110] = 0.0
    p[100:110] = -20000.0    # 10 s: too short to be a charging session
    v[130:190] = 0.0
    p[130:190] = 400.0       # 60 s standing, drawing 400 W: auxiliaries, not charging
    m = charging_mask(p, v, t, np.zeros(200, int))
    assert np.flatnonzero(m).tolist() == list(range(20, 80))


def test_median_decides_and_a_stretch_never_crosses_a_trip():
    t = np.r_[np.arange(0.0, 40.0), np.arange(0.0, 40.0)]
    codes = np.r_[np.zeros(40, int), np.ones(40, int)]
    v = np.zeros(80)
    p = np.full(80, -3000.0)
    p[5] = 9e9                       # one spike inside a charging stretch does not decide
    p[40:] = np.where(np.arange(40) < 25, 300.0, -3000.0)   # trip 2: mostly auxiliaries
    m = charging_mask(p, v, t, codes)
    assert m[:40].all() and not m[40:].any()
    # two 20-s halves of one standing minute in different trips are two short stretches
    t2 = np.r_[np.arange(0.0, 20.0), np.arange(20.0, 40.0)]
    assert not charging_mask(np.full(40, -5000.0), np.zeros(40), t2, np.r_[np.zeros(20), np.ones(20)]).any()
    assert CHARGE_MIN_S > 20.0
    # unknown speed is not standing; empty input
    assert not charging_mask(np.full(60, -5000.0), np.full(60, np.nan), np.arange(60.0), np.zeros(60)).any()
    assert charging_mask([], [], [], []).size == 0


def _with_charging_stop(tmp_path):
    """The planted battery log of test_chain (chain η_t 0.9, η_r 0.7, 500 W auxiliary,
    heater as a load), trip T2 starting with a 300-s fast-charging stop (−50 kW) before its
    standstill start (the car leaves the charger and drives off)."""
    from test_chain import _planted_battery_log

    f, road = _planted_battery_log(tmp_path)
    df = pd.read_csv(f)
    first = int(df.index[df["trip_id"] == "T2"][0])
    n = 3000
    stop = pd.DataFrame({"trip_id": "T2", "time_s": np.arange(n) * 0.1, "speed_mps": 0.0,
                         "mass_kg": 1500.0, "heater_power_w": 0.0,
                         "battery_voltage_v": 360.0, "battery_current_a": -50000.0 / 360.0})
    t2 = df.loc[first:].copy()
    t2["time_s"] += n * 0.1
    out = pd.concat([df.loc[:first - 1], stop, t2], ignore_index=True)
    g = tmp_path / "with_charging.csv"
    out.to_csv(g, index=False)
    return g, road, n


def test_battery_fit_and_trip_energy_leave_a_charging_stop_out(tmp_path):
    from sumo_drvpw.cli import main

    log, road, n = _with_charging_stop(tmp_path)
    eq = tmp_path / "chain.toml"
    assert main(["calibrate", str(log), "--target", "battery", "--equation", str(road),
                 "--load", "heater_power_w", "--out", str(eq)]) == 0
    ch = load_equation(eq).chain
    assert ch.aux_power_w == pytest.approx(500.0, rel=0.05)      # planted 500 W
    assert ch.traction_efficiency == pytest.approx(0.9, rel=0.03)
    out = tmp_path / "cmp"
    assert main(["compare", str(log), "--equation", str(eq), "--out", str(out)]) == 0
    rep = json.loads((out / "report.json").read_text(encoding="utf-8"))
    trips = rep["equations"]["chain"]["trip_net_energy"]["trips"]
    assert trips["T2"]["measured_j"] > 0                     # 4 kWh charged would make it negative
    assert abs(trips["T2"]["error"]) < 0.02
    # the charger's 300 s and the 30 s of standing that join them (one standstill stretch)
    assert n <= _count(rep) <= n + 300
    assert "excluded_charging: " in (out / "report.md").read_text(encoding="utf-8")


def _count(rep) -> int:
    """excluded_charging wherever the report keeps its counts."""
    found = []

    def walk(o):
        if isinstance(o, dict):
            for k, v in o.items():
                if k == "excluded_charging":
                    found.append(v)
                walk(v)
        elif isinstance(o, list):
            for v in o:
                walk(v)
    walk(rep)
    return max(found) if found else -1


def test_without_the_rule_the_charging_stop_spoils_the_fit(tmp_path, monkeypatch):
    """The negative control: with the threshold out of reach the same log teaches the chain a
    negative auxiliary power (the test above can fail)."""
    import sumo_drvpw.data.charging as charging
    from sumo_drvpw.cli import main

    monkeypatch.setattr(charging, "CHARGE_MIN_W", 1e12)
    monkeypatch.setattr(charging.charging_mask, "__defaults__", (1e12, CHARGE_MIN_S))
    log, road, _ = _with_charging_stop(tmp_path)
    eq = tmp_path / "chain.toml"
    rc = main(["calibrate", str(log), "--target", "battery", "--equation", str(road),
               "--load", "heater_power_w", "--out", str(eq)])
    assert rc != 0 or abs(load_equation(eq).chain.aux_power_w - 500.0) > 100.0


def test_a_hybrid_charging_at_standstill_from_its_engine_is_kept():
    """In a power-split hybrid, or a log with fuel flow, energy into the battery at standstill
    may come from the engine: not a charger, not left out."""
    from types import SimpleNamespace

    from sumo_drvpw.data.measured import _has_engine

    df = pd.DataFrame({"speed_mps": [0.0]})
    assert _has_engine(SimpleNamespace(df=df), SimpleNamespace(powertrain_type="power_split"))
    assert _has_engine(SimpleNamespace(df=df.assign(fuel_rate_gps=0.1)), None)
    assert not _has_engine(SimpleNamespace(df=df), SimpleNamespace(powertrain_type="single_motor"))
    assert not _has_engine(SimpleNamespace(df=df), None)
