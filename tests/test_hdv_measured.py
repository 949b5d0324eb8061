"""What explains the combination truck chain's per-trip error on measured trucks
(sumo_drvpw/validation/hdv_measured.py, scripts/hdv_measured.py, docs/hdv-fuel.md).

By hand: the carbon balance of a CO₂/CO/HC flow and Gillespie's mass factor at a gear.
Planted effects, on synthetic logs in the FEAD files' layout (two trucks, slow stop-and-go and
fast phases, an engine speed from a gear schedule): a fuel burnt at another mass than the
study books is found as that mass on every trip and by the mass fitted on the other truck; a
fuel that pays the rotating inertia at the logged gear is booked exactly by that hypothesis
and by no other; a carbon balance that reads a set share low is found as that line; a
Willans line under a noisy driving power is flattened on 1-s samples and found on long blocks.
The committed report's section is the rendering of its JSON.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.validation import hdv_measured as H

REPO = Path(__file__).resolve().parents[1]
MPH = 0.44704


def test_carbon_balance_by_hand():
    """3.158 g of CO₂ is 1 g of diesel; 28.0101 g of CO carries the carbon of 44.0095 g of CO₂;
    hydrocarbons count as fuel."""
    assert H.carbon_balance_gps([3.158], [0.0], [0.0])[0] == pytest.approx(1.0)
    assert H.carbon_balance_gps([0.0], [28.0101], [0.0])[0] == pytest.approx(44.0095 / 3.158)
    assert H.carbon_balance_gps([3.158], [0.0], [0.25])[0] == pytest.approx(1.25)


def test_rotating_mass_factor_by_hand():
    """1,500 rpm at 10 m/s on the 0.501-m tyre is gear ratio 7.87; at 28 t the truck's inertias
    (S60 engine 1,394 kg × 5/9 × 0.075² = 4.36 kg·m², 18 wheels of 80 kg as solid cylinders 181 kg·m²)
    add (181 + 4.36 × 7.87²)/(28,000 × 0.501²) = 0.0641; a car's shares 0.04 + 0.0025 × 7.87² =
    0.195; standing or creeping (below 2 m/s) 1."""
    n = 1500 * 2 * np.pi / 60 * 0.501 / 10
    eng, wheels = 4.2 * 332 * (1 / 3 + 2 / 9) * 0.075**2, 18 * 80 * 0.501**2 / 2
    got = H.rotating_mass_factor([1500.0, 1500.0, 0.0], [10.0, 1.0, 0.0])
    assert got[0] == pytest.approx(1 + (wheels + eng * n**2) / (28000 * 0.501**2)) and got[0] == pytest.approx(1.0641, abs=1e-4)
    assert list(got[1:]) == [1.0, 1.0]
    car = H.rotating_mass_factor([1500.0], [10.0], car=True)
    assert car[0] == pytest.approx(1.04 + 0.0025 * n**2)
    assert H.speed_gear_factor([10.0, 40.0, 1.0], 1500.0, 3.0, 20.0)[0] == pytest.approx(got[0])
    assert H.speed_gear_factor([40.0], 1500.0, 3.0, 20.0)[0] == pytest.approx(1 + (wheels + eng * 9) / (28000 * 0.501**2))


def _phase(kind: str, rng) -> tuple[np.ndarray, np.ndarray]:
    """Speed [mph] and engine speed [rpm] of one phase: 'slow' stop-and-go in low gears (to 25 mph),
    'fast' a highway cruise near 58 mph; a standing minute at each end."""
    if kind == "slow":
        cyc = np.r_[np.linspace(0, 25, 20), np.full(30, 25.0), np.linspace(25, 0, 15), np.zeros(10)]
        v = np.tile(cyc, 5)
    else:
        v = np.r_[np.linspace(0, 58, 90), 58 + 1.5 * np.sin(np.arange(400) / 25.0), np.linspace(58, 0, 60)]
    v = np.r_[np.zeros(60), v, np.zeros(60)] + 0.0 * rng.random()
    ratio = np.where(v < 12, 14.0, np.where(v < 30, 7.0, 2.9))  # engine rev per wheel rev, by speed
    rpm = np.where(v > 2, np.maximum(650.0, v * MPH / 0.49 * ratio * 60 / (2 * np.pi)), 650.0)
    return v, np.minimum(rpm, 2000.0)


def _fead(folder: Path, seed: int = 1) -> None:
    """Two trucks' files in the FEAD layout, fuel and CO₂ placeholders (0.5 g/s)."""
    rng = np.random.default_rng(seed)
    for f in H.FILES:
        rows = []
        for k, kind in enumerate(("slow", "fast", "slow", "fast", "slow"), start=1):
            v, rpm = _phase(kind, rng)
            elev = 300 + 4 * np.sin(np.arange(v.size) / 90.0) + (k % 2) * np.cumsum(v) * MPH * 0.004
            rows.append(pd.DataFrame({"CO2 (g/s)": 0.5, "CO (g/s)": 0.0, "HC (g/s)": 0.0, "NOx (g/s)": 0.1,
                                      "vel (mph)": v, "fuel (g/s)": 0.5, "engine (rpm)": rpm,
                                      "elevation (m)": elev, "phase_num": k}))
        pd.concat(rows, ignore_index=True).to_csv(folder / f, index=False)


def _plant(folder: Path, fuel_gps_of, co2_share: float = 1.0) -> None:
    """Write ``fuel_gps_of(log)`` (per sample, the rows as the study reads them) as each file's
    fuel, and its carbon at ``co2_share`` of it as CO₂."""
    log = H.read_trucks(folder)
    fuel = fuel_gps_of(log)
    files = log.df["trip_id"].astype(str).str.split("-").str[0].to_numpy()
    for f in H.FILES:
        raw = pd.read_csv(folder / f)
        got = fuel[files == Path(f).stem]
        assert got.size == len(raw)
        raw["fuel (g/s)"] = got
        raw["CO2 (g/s)"] = got * 3.158 * co2_share
        raw.to_csv(folder / f, index=False)


def _booked_gps(log, mass_kg, **kw):
    from sumo_drvpw.model.equations import load_equation

    eq = load_equation(H.EQUATION)
    dt = log.df["dt_s"].to_numpy(float)
    x = H.at_mass(log.inputs(), mass_kg)
    return H.booked_l(eq, x, dt, **kw) * 832.0 / dt   # L per sample → g/s


def test_a_fuel_burnt_at_another_mass_is_found_as_that_mass(tmp_path):
    """Fuel booked at 31 t (the study books 28): every trip's implied mass is 31 t, the mass fitted
    on either truck is 31 t and books the other's trips exactly; the carbon balance planted at
    1/1.2 of the fuel is found as ECU = 0 + 1.2 × carbon."""
    _fead(tmp_path)
    _plant(tmp_path, lambda log: _booked_gps(log, 31000.0), co2_share=1 / 1.2)
    r = H.study(tmp_path)
    masses = [t["implied_mass_t"] for t in r["per_trip"]]
    assert masses and all(m == pytest.approx(31.0, abs=0.1) for m in masses), masses
    fitted = [h for h in r["hypotheses"] if h["hypothesis"].startswith("one mass")]
    assert len(fitted) == 2 and all("31.0 t" in h["hypothesis"] and h["mean_abs_pct"] < 0.2 for h in fitted)
    assert r["mean_abs_pct"] > 3.0          # the built-in at 28 t is off
    for s in r["signal"].values():
        assert s["line"][1] == pytest.approx(1.2, abs=1e-3) and s["line"][0] == pytest.approx(0.0, abs=1e-3)
        assert s["ecu_l"] == pytest.approx(1.2 * s["carbon_balance_l"], rel=1e-2)


def test_a_fuel_that_pays_the_rotating_inertia_is_found_by_that_hypothesis_alone(tmp_path):
    """Fuel booked with the truck's rotating inertia at the logged gear: that hypothesis books every
    trip (mean |error| ~0), the built-in under-books the slow trips, the mass, grade, cap and a
    car's inertia do not explain it, the speed-only gear halves the error, and the implied masses
    part with the trips' speed."""
    _fead(tmp_path)

    def inertia(log):
        x = log.inputs()
        return _booked_gps(log, H.MASS_KG, factor=H.rotating_mass_factor(log.df["engine_rpm"].to_numpy(float), x.v))

    _plant(tmp_path, inertia)
    r = H.study(tmp_path)
    by = {h["hypothesis"]: h for h in r["hypotheses"]}
    assert by["rotating inertia at the logged gear: the truck's (ADVISOR's engine and wheels)"]["mean_abs_pct"] < 0.2
    assert by["the built-in"]["slow_pct"] < -2.0 and by["the built-in"]["mean_abs_pct"] > 1.5
    others = [h for n, h in by.items() if n.startswith(("one mass", "elevation", "the S60's rated", "rotating inertia at "
                                                            "the logged gear: a passenger"))]
    assert len(others) == 7 and all(h["mean_abs_pct"] > 0.8 for h in others)
    by_speed = [h for n, h in by.items() if n.startswith("rotating inertia, gear from speed alone")]
    assert len(by_speed) == 2 and all(h["mean_abs_pct"] < by["the built-in"]["mean_abs_pct"] / 2 for h in by_speed)
    slow = [t["implied_mass_t"] for t in r["per_trip"] if t["mean_kmh"] < 40]
    fast = [t["implied_mass_t"] for t in r["per_trip"] if t["mean_kmh"] >= 40]
    assert min(slow) > max(fast) + 0.5


def test_a_fuel_through_a_better_driveline_is_found_by_that_hypothesis(tmp_path):
    """Fuel booked through ADVISOR's 0.92 gearbox instead of the built-in's 0.80: the built-in books
    every moving trip high, the driveline hypothesis books them all, the inertia's does not."""
    import dataclasses

    from sumo_drvpw.model.equations import load_equation

    _fead(tmp_path)
    ch = dataclasses.replace(load_equation(H.EQUATION).chain, traction_efficiency=H.ADVISOR_GEARBOX)
    _plant(tmp_path, lambda log: _booked_gps(log, H.MASS_KG, chain=ch))
    r = H.study(tmp_path)
    def by(start):
        return next(h for h in r["hypotheses"] if h["hypothesis"].startswith(start))

    assert by("driveline 0.92 (ADVISOR")["mean_abs_pct"] < 0.2
    assert by("the built-in")["slow_pct"] > 3.0 and by("the built-in")["fast_pct"] > 3.0
    assert by("rotating inertia at the logged gear: the truck's")["mean_abs_pct"] > by("the built-in")["mean_abs_pct"]


def test_a_noisy_driving_power_flattens_the_per_sample_line():
    """A planted line (30 kW at zero output, η 0.42) under a 1-Hz driving power with 80 kW of
    noise: on 1-s samples the fitted line is flatter with more zero-output fuel; on 60-s blocks
    it is the planted one within a few per cent."""
    rng = np.random.default_rng(3)
    n = 36000
    true_p = np.clip(np.repeat(rng.uniform(20e3, 300e3, n // 120), 120) + 20e3 * rng.standard_normal(n), 1e3, None)
    fuel = 30e3 + true_p / 0.8 / 0.42
    seen = true_p + 80e3 * rng.standard_normal(n)
    trips, v = np.repeat(np.arange(10).astype(str), n // 10), np.full(n, 20.0)
    z1, e1 = H.block_line(fuel, seen, v, trips, 1, 0.8)
    z60, e60 = H.block_line(fuel, seen, v, trips, 60, 0.8)
    assert e1 > 0.5 and z1 > 60e3
    assert e60 == pytest.approx(0.42, rel=0.05) and z60 == pytest.approx(30e3, abs=8e3)


def test_the_script_writes_the_section_and_refuses_a_report_without_the_comparison(tmp_path, capsys):
    """scripts/hdv_measured.py puts the study under the JSON's measured.explained and renders the
    report from the JSON; a report without a 'measured' section is one line, exit 2, nothing
    written; a folder without the files is one line naming the file."""
    from script_module import load_script

    script = load_script("hdv_measured")
    _fead(tmp_path)
    _plant(tmp_path, lambda log: _booked_gps(log, 30000.0))
    committed = json.loads((REPO / "docs" / "hdv-fuel.json").read_text(encoding="utf-8"))
    rep = tmp_path / "hdv.md"
    rep.with_suffix(".json").write_text(json.dumps(committed), encoding="utf-8")
    assert script.main([str(tmp_path), "--report", str(rep)]) == 0
    res = json.loads(rep.with_suffix(".json").read_text(encoding="utf-8"))
    assert res["check"] == committed["check"] and res["measured"]["groups"] == committed["measured"]["groups"]
    ex = res["measured"]["explained"]
    assert ex["trips"] == len(ex["per_trip"]) and "### What explains the per-trip error" in rep.read_text("utf-8")
    bare = tmp_path / "bare.md"
    bare.with_suffix(".json").write_text(json.dumps({"check": {}}), encoding="utf-8")
    capsys.readouterr()
    assert script.main([str(tmp_path), "--report", str(bare)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no 'measured' section" in err[0] and not bare.exists()
    assert script.main([str(tmp_path / "nowhere")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "veh002_all.csv" in err[0]


def test_the_committed_section_is_the_rendering_of_its_json():
    """docs/hdv-fuel.md's 'What explains' section is the JSON's: a hypothesis's figures changed
    there change the table."""
    from sumo_drvpw.validation.hdv_fuel_report import render

    res = json.loads((REPO / "docs" / "hdv-fuel.json").read_text(encoding="utf-8"))
    md = render(res)
    assert "### What explains the per-trip error" in md and md == (REPO / "docs" / "hdv-fuel.md").read_text("utf-8")
    h = res["measured"]["explained"]["hypotheses"][-1]
    h.update(mean_abs_pct=4.2, helped=40, hurt=1)
    assert f"| {h['hypothesis']} | 4.2 % |" in render(res) and "40 / 1 of" in render(res)
