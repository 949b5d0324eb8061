"""A sweep of runs with energy-chain equations puts their litres and kWh side by side
(``chain_runs.csv``), as ``runs.csv`` does the driving energy. Real SUMO runs."""

from __future__ import annotations

import pytest

from sumo_drvpw.cli import main as cli_main

pytest.importorskip("libsumo")


def test_sweep_with_a_fuel_chain_writes_the_litres_of_every_run_side_by_side(tmp_path):
    """`run city highway --equation epa_gasoline_car`: chain_runs.csv holds, per scenario,
    each run's chain_classes.csv rows (litres, CO2, L/100 km per vClass). Before (2026-11-27
    rehearsal: a winter and a summer run of a hilly Bologna scenario with the EPA petrol and
    i3 battery chains), the sweep's side-by-side table had only the driving energy: the
    seasons' litres and kWh were in each run's own folder only."""
    import pandas as pd

    out = tmp_path / "runs"
    code = cli_main(["run", "city", "highway", "--equation", "epa_gasoline_car", "--end", "60",
                     "--no-figures", "--no-progress", "--out", str(out)])
    assert code == 0
    both = pd.read_csv(out / "chain_runs.csv")
    assert list(both.columns[:3]) == ["scenario", "key", "equation"]
    assert set(both.scenario) == {"city", "highway"}
    for n in ("city", "highway"):
        own = pd.read_csv(out / n / "chain_classes.csv")
        mine = both[both.scenario == n].drop(columns="scenario").reset_index(drop=True)
        assert len(own) > 0 and (own.fuel_l > 0).all()
        pd.testing.assert_frame_equal(mine[list(own.columns)], own, check_dtype=False, rtol=1e-12)


def test_co2_per_km_is_the_co2_mass_over_the_distance(tmp_path):
    """chain_classes.csv and chain_vehicles.csv of a run with a petrol chain: co2_g_per_km is
    1000·co2_kg / distance_km (grams of CO₂, not litres, per km), and co2_kg is the litres'
    mass times petrol's CO₂ per kg (constants.FUELS: 0.745 kg/L × 3.169 kg/kg, 2.36 kg/L),
    fuel_l_per_100km 100·fuel_l / distance_km."""
    import pandas as pd

    from sumo_drvpw.model.constants import FUELS
    from sumo_drvpw.sim import run_scenario

    run_scenario("highway", tmp_path / "o", end=60, equations=["epa_gasoline_car"], figures=False)
    petrol = FUELS["gasoline"]
    for name in ("chain_classes.csv", "chain_vehicles.csv"):
        t = pd.read_csv(tmp_path / "o" / name)
        t = t[t.distance_km > 0]
        assert len(t) > 0 and (t.fuel_l > 0).all(), name
        pd.testing.assert_series_equal(t.co2_g_per_km, 1000.0 * t.co2_kg / t.distance_km,
                                       check_names=False, rtol=1e-6)
        pd.testing.assert_series_equal(t.co2_kg, t.fuel_l * petrol["density_kg_per_l"] * petrol["co2_kg_per_kg"],
                                       check_names=False, rtol=1e-6)
        pd.testing.assert_series_equal(t.fuel_l_per_100km, 100.0 * t.fuel_l / t.distance_km,
                                       check_names=False, rtol=1e-6)
