"""The EPA Test Car List study (sumo_drvpw/validation/epa_fleet.py) and the conventional
engine it needs in the fuel chain (engine_off_below_w = -inf).

Planted: synthetic Test Car List files whose fuel economies come from a known Willans
line (computed here by hand from the road load and the schedule), with hybrids and
electric tests mixed in that the selection must leave out; the study must recover the
line. Real: the shared lists; the built-in equations must be what the study writes.
"""

from __future__ import annotations

import copy

import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import FUELS, G, LB, LBF, MILE, MPH
from sumo_drvpw.validation import epa_fleet as ef

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"

ETA, P_L = 0.33, 4500.0  # the planted line: η and idle fuel power per litre [W/L]
HEADER = ["Model Year", "Vehicle Manufacturer Name", "Represented Test Veh Make",
          "Represented Test Veh Model", "Test Vehicle ID", "Test Veh Configuration #",
          "Test Veh Displacement (L)", "Vehicle Type", "Equivalent Test Weight (lbs.)",
          "Test Procedure Description", "Test Fuel Type Description", "Analytically Derived FE?",
          "RND_ADJ_FE", "FE_UNIT", "FE Bag 1", "FE Bag 2", "FE Bag 3", "FE Bag 4",
          "Target Coef A (lbf)", "Target Coef B (lbf/mph)", "Target Coef C (lbf/mph**2)"]


def _schedules(folder: Path) -> dict[str, np.ndarray]:
    """Small synthetic schedules in FASTSim's format; speeds per second [m/s]."""
    t = np.arange(1370.0)
    udds = np.clip(12 * np.sin(np.pi * t / 120) ** 2 + 4 * np.sin(t / 17), 0, None) * (t % 240 < 200)
    v = {"udds": udds, "hwfet": 22 + 5 * np.sin(np.arange(766) / 60) * (np.arange(766) > 30),
         "us06": np.clip(30 * np.sin(np.pi * np.arange(601) / 600) + 3 * np.sin(np.arange(601) / 7), 0, None)}
    v["hwfet"][:30] = np.linspace(0, 22, 30)
    folder.mkdir(parents=True, exist_ok=True)
    for k, s in v.items():
        pd.DataFrame({"cycSecs": np.arange(len(s)), "cycMps": s, "cycGrade": 0, "cycRoadType": 0}).to_csv(
            folder / f"{k}.csv", index=False)
    return v


def _litres(v: np.ndarray, a_n, b, c, m, disp, eta=ETA, p_l=P_L) -> tuple[float, float]:
    """Fuel [L] and distance [m] of the planted line on schedule v, by hand: 1-s steps at
    the mean speed, m·v̄·Δv the kinetic-energy change, engine running throughout."""
    vm, dv = 0.5 * (v[1:] + v[:-1]), np.diff(v)
    p = (a_n + b * vm + c * vm ** 2) * vm + m * vm * dv
    e_fuel = p_l * disp * len(vm) + np.maximum(p, 0).sum() / eta
    f = FUELS["gasoline"]
    return e_fuel / (f["lhv_j_per_kg"] * f["density_kg_per_l"]), float(vm.sum())


def _mpg(v, *car, **kw) -> float:
    litres, dist = _litres(v, *car, **kw)
    return dist / MILE / (litres / ef.GALLON_L)


def _write_lists(folder: Path, speeds: dict, n: int = 40, seed: int = 1) -> list[dict]:
    """Two model years of planted conventional cars, plus a hybrid (4-bag FTP, too good a
    fuel economy), a plug-in (charge-depleting test) and an electric test to leave out."""
    rng = np.random.default_rng(seed)
    cars = []
    for year in (2015, 2020):
        rows = []
        for i in range(n):
            m = rng.uniform(1200, 2600)
            a_n, b, c = rng.uniform(0.08, 0.13) * m, rng.uniform(-1.0, 6.0), rng.uniform(0.3, 0.7)
            disp = rng.choice([1.5, 2.0, 2.5, 3.5, 5.0])
            typ = "Car" if i % 2 else "Truck"
            base = {"Model Year": year, "Vehicle Manufacturer Name": "maker", "Represented Test Veh Make": "Maker",
                    "Represented Test Veh Model": f"M{i}", "Test Vehicle ID": f"V{year}{i}",
                    "Test Veh Configuration #": 0, "Test Veh Displacement (L)": disp, "Vehicle Type": typ,
                    "Equivalent Test Weight (lbs.)": m / LB, "Test Fuel Type Description": "Tier 2 Cert Gasoline",
                    "Analytically Derived FE?": "No", "FE_UNIT": "MPG", "Target Coef A (lbf)": a_n / LBF,
                    "Target Coef B (lbf/mph)": b * MPH / LBF, "Target Coef C (lbf/mph**2)": c * MPH ** 2 / LBF}
            car = (a_n, b, c, m, disp)
            u = speeds["udds"]
            hot, stab = _mpg(u[:506], *car), _mpg(u[505:1370], *car)
            rows.append(base | {"Test Procedure Description": "Federal fuel 2-day exhaust (w/can load)",
                                "FE Bag 1": hot * 0.8, "FE Bag 2": stab, "FE Bag 3": hot, "RND_ADJ_FE": stab})
            rows.append(base | {"Test Procedure Description": "HWFE", "RND_ADJ_FE": _mpg(speeds["hwfet"], *car)})
            if i % 3 == 0:
                rows.append(base | {"Test Procedure Description": "US06", "RND_ADJ_FE": _mpg(speeds["us06"], *car)})
            if typ == "Car" and i < 30:  # the FTP at −6.7 °C on winter fuel: bag 1 at half the economy
                rows.append(base | {"Test Procedure Description": "Cold CO", "RND_ADJ_FE": stab * 0.9,
                                    "Test Fuel Type Description": "Cold CO Regular (Tier 2)",
                                    "FE Bag 1": hot * 0.5, "FE Bag 2": stab * 0.9, "FE Bag 3": hot * 0.95})
            cars.append({"year": year, "type": typ, "car": car, "name": f"M{i}"})
        hyb = dict(rows[0]) | {"Represented Test Veh Model": "Hybrid thing", "Test Vehicle ID": f"H{year}"}
        rows.append(hyb | {"FE Bag 4": 50.0, "FE Bag 2": 60.0, "FE Bag 3": 55.0, "FE Bag 1": 45.0})
        rows.append(dict(rows[1]) | {"Test Vehicle ID": f"H{year}", "Represented Test Veh Model": "Hybrid thing",
                                     "RND_ADJ_FE": 58.0})
        plug = dict(rows[1]) | {"Represented Test Veh Model": "Q7", "Test Vehicle ID": f"P{year}"}
        rows.append(plug | {"Test Procedure Description": "Charge Depleting Highway", "RND_ADJ_FE": 90.0})
        rows.append(plug | {"RND_ADJ_FE": 70.0})
        rows.append(dict(rows[1]) | {"Test Vehicle ID": f"E{year}", "Test Fuel Type Description": "Electricity",
                                     "RND_ADJ_FE": 120.0})
        pd.DataFrame(rows).reindex(columns=HEADER).to_csv(folder / f"{str(year)[2:]}tstcar.csv", index=False,
                                                          encoding="utf-8-sig")
    return cars


@pytest.fixture(scope="module")
def planted(tmp_path_factory):
    root = tmp_path_factory.mktemp("epa")
    speeds = _schedules(root / "cycles")
    (root / "epa_test_car_list").mkdir()
    cars = _write_lists(root / "epa_test_car_list", speeds)
    return root, ef.study(root), cars


def test_planted_line_is_recovered_and_hybrids_left_out(planted):
    _, res, cars = planted
    f = res["fit_all"]
    assert f["eta"] == pytest.approx(ETA, rel=1e-6) and f["p_idle_w_per_l"] == pytest.approx(P_L, rel=1e-6)
    assert f["n_configurations"] == len(cars)  # the hybrid, plug-in and electric configurations are out
    assert res["counts"]["hybrid, plug-in or electric configurations left out"] == 6  # 3 per model year
    for s in res["splits"].values():  # other model years predicted exactly by the planted line
        assert abs(s["own_road_load"]["all"]["mean"]) < 1e-6 and s["own_road_load"]["all"]["mean_abs"] < 1e-6
        assert s["fit"]["eta"] == pytest.approx(ETA, rel=1e-6)
    # the cold start: bag 1 was written as 0.8 × bag 3's economy → 1/0.8 − 1 = 25 % more fuel
    for cls in ("car", "light_truck"):
        cs = res["cold_start"][cls]
        assert cs["median_ml"] > 0


def test_cold_start_excess_by_hand(planted):
    root, res, cars = planted
    speeds = ef.schedules(root / "cycles")
    ex = [(_litres(speeds["ftp_bag3"], *c["car"])[0] / 0.8 - _litres(speeds["ftp_bag3"], *c["car"])[0]) * 1000
          for c in cars if c["type"] == "Car"]
    assert res["cold_start"]["car"]["median_ml"] == pytest.approx(np.median(ex), rel=1e-6)


def test_cold_start_in_the_cold_by_hand(planted):
    """Cold CO rows planted for 30 cars (bag 1 at 0.5, bag 2 at 0.9, bag 3 at 0.95 of the
    warm economies): the cold start at −6.7 °C, its difference to the FTP's, the slope per
    kelvin and the bag-2 ratio, by hand; the built-in carries the slope (≥ 20 pairs); no
    Cold CO row for the light trucks: none paired, no slope."""
    root, res, cars = planted
    speeds = ef.schedules(root / "cycles")
    paired = [c for c in cars if c["type"] == "Car"]
    paired = [c for c in paired if int(c["name"][1:]) < 30]
    l3 = np.array([_litres(speeds["ftp_bag3"], *c["car"])[0] for c in paired])
    cold, warm = (l3 / 0.5 - l3 / 0.95) * 1000, (l3 / 0.8 - l3) * 1000
    cc = res["cold_start_cold"]["car"]
    assert cc["configurations"] == len(paired) == 30
    assert cc["cold_ml"] == pytest.approx(np.median(cold), rel=1e-6)
    assert cc["warm_ml"] == pytest.approx(np.median(warm), rel=1e-6)
    assert cc["difference_ml"] == pytest.approx(np.median(cold - warm), rel=1e-6)
    assert cc["ml_per_k"] == pytest.approx(np.median(cold - warm) / (ef.FTP_AIR_C - ef.COLD_CO_AIR_C), rel=1e-6)
    assert cc["bag2_ratio"] == pytest.approx(1 / 0.9, rel=1e-6)
    # bag 3 at 0.95 of the economy: 1/0.95 − 1 more fuel over the 30.6 K, the built-in's factor
    span = ef.FTP_AIR_C - ef.COLD_CO_AIR_C
    assert cc["bag3_ratio"] == pytest.approx(1 / 0.95, rel=1e-6)
    assert cc["running_per_k"] == pytest.approx((1 / 0.95 - 1) / span, rel=1e-6)
    assert res["equations"]["car"]["chain"]["running_fuel_per_k"] == pytest.approx((1 / 0.95 - 1) / span, abs=1e-6)
    held = cc["running_held_out"]  # 15 pairs of the older year: too few to hold one out
    assert held is None and cc["running_records_left_out"] == 0
    rel = (cold - warm) / warm / (ef.FTP_AIR_C - ef.COLD_CO_AIR_C)
    assert cc["relative_per_k"] == pytest.approx(np.median(rel), rel=1e-6)
    ch = res["equations"]["car"]["chain"]
    assert ch["cold_start_fuel_l_per_k"] == pytest.approx(cc["ml_per_k"] / 1000, abs=1e-6)
    assert "light_truck" not in res["cold_start_cold"]
    assert res["equations"]["light_truck"]["chain"]["cold_start_fuel_l_per_k"] == 0.0
    # the light trucks, unpaired, take the cars' relative slope times their own cold start
    both = {"gasoline": copy.deepcopy(res)}
    ef.transfer_cold_slopes(both)
    lt = both["gasoline"]
    want = np.median(rel) * lt["cold_start"]["light_truck"]["median_ml"] / 1000
    assert lt["equations"]["light_truck"]["chain"]["cold_start_fuel_l_per_k"] == pytest.approx(want, abs=1e-6)
    assert lt["cold_start_cold"]["light_truck"]["transferred"]["pairs"] == 30
    assert lt["equations"]["light_truck"]["chain"]["running_fuel_per_k"] == pytest.approx((1 / 0.95 - 1) / span,
                                                                                          abs=1e-6)
    assert lt["equations"]["car"] == res["equations"]["car"]  # enough pairs of its own: unchanged
    # fewer than MIN_COLD_PAIRS pairs in all: nothing to pool, nothing transferred
    few = copy.deepcopy(res)
    few["cold_start_cold"]["car"]["relative_per_k_pairs"] = few["cold_start_cold"]["car"]["relative_per_k_pairs"][:19]
    ef.transfer_cold_slopes({"gasoline": few})
    assert few["equations"]["light_truck"]["chain"]["cold_start_fuel_l_per_k"] == 0.0


def test_class_default_is_the_median_car(planted):
    _, res, cars = planted
    d = res["defaults"]["car"]
    car = [c["car"] for c in cars if c["type"] == "Car"]
    assert d["configurations"] == len(car)
    assert d["a_n_per_kg"] == pytest.approx(np.median([a / m for a, _, _, m, _ in car]))
    assert d["c_n_per_mps2"] == pytest.approx(np.median([c for _, _, c, _, _ in car]))
    eq = res["equations"]["car"]
    assert eq["terms"]["roll"] == pytest.approx(d["a_n_per_kg"] / G, rel=1e-4)
    assert eq["chain"]["idle_fuel_power_w"] == pytest.approx(P_L * d["displacement_l"], rel=1e-4)
    assert eq["chain"]["engine_off_below_w"] == -np.inf


def test_evaluator_matches_the_willans_line_by_hand(tmp_path):
    """One car at constant 20 m/s for 100 s: P = (A + B·v + C·v²)·v, fuel = p_L·D·T + E⁺/η."""
    v = np.full(101, 20.0)
    obs = pd.DataFrame([{"config": "x", "test": "hwfet", "vehicle_type": "Car", "etw_kg": 1500.0,
                         "a_n": 150.0, "b_n_per_mps": 2.0, "c_n_per_mps2": 0.4, "displacement_l": 2.0}])
    got = ef.predict(obs, {"eta": 0.35, "p_idle_w_per_l": 4000.0}, {"hwfet": v})[0]
    p = (150.0 + 2.0 * 20 + 0.4 * 400) * 20  # 7000 W
    assert got == pytest.approx(4000.0 * 2.0 * 100 + p * 100 / 0.35, rel=1e-12)


def test_missing_column_is_one_line(tmp_path):
    (tmp_path / "epa_test_car_list").mkdir()
    pd.DataFrame({"Model Year": [2020]}).to_csv(tmp_path / "epa_test_car_list" / "20tstcar.csv", index=False)
    with pytest.raises(UserError, match=r"20tstcar.csv: column 'Test Vehicle ID' not found"):
        ef.read_lists(tmp_path / "epa_test_car_list")
    r = subprocess.run([sys.executable, "-m", "sumo_drvpw.validation.epa_fleet", str(tmp_path / "r.md"),
                        str(tmp_path)], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert not (tmp_path / "r.md").exists()
    # a file that is no CSV (binary bytes, an unterminated quote): one line naming it
    (tmp_path / "epa_test_car_list" / "20tstcar.csv").write_bytes(b'Model Year,"Test\n2020,\xff\xfe')
    with pytest.raises(UserError, match=r"20tstcar.csv: not a readable CSV file"):
        ef.read_lists(tmp_path / "epa_test_car_list")


@pytest.fixture(scope="module")
def shared_studies():
    if not (SHARED / ef.DATASET).is_dir():
        pytest.skip("shared EPA data not found")
    lists = ef.read_lists(SHARED / ef.DATASET)
    results = {fuel: ef.study(SHARED, fuel, lists) for fuel in ef.TEST_FUELS}
    ef.transfer_cold_slopes(results)
    return results


@pytest.mark.skipif(not (SHARED / "epa_test_car_list").is_dir(), reason="shared data not present")
@pytest.mark.parametrize("fuel", ["gasoline", "diesel"])
def test_builtins_are_what_the_study_writes_on_the_shared_lists(fuel, shared_studies):
    """The built-in equations come from the real lists: regenerating gives the same
    numbers; the line is physical and predicts held-out model years within 10 %."""
    from sumo_drvpw.model.equations import load_equation

    res = shared_studies[fuel]
    f = res["fit_all"]
    assert ef.ETA_PLAUSIBLE[0] <= f["eta"] <= ef.ETA_PLAUSIBLE[1]
    assert 2000 < f["p_idle_w_per_l"] < 8000  # 0.2–0.9 L/h of fuel per litre of displacement
    for s in res["splits"].values():
        assert s["own_road_load"]["all"]["mean_abs"] < 0.10
    assert set(res["equations"]) == {"car", "light_truck"}
    for cls, doc in res["equations"].items():
        eq = load_equation(doc["equation"]["name"])
        assert eq.name == f"epa_{fuel}_{cls}" and eq.chain.fuel == fuel
        assert eq.terms == pytest.approx(doc["terms"])
        assert eq.chain.marginal_efficiency == pytest.approx(doc["chain"]["marginal_efficiency"])
        assert eq.chain.idle_fuel_power_w == pytest.approx(doc["chain"]["idle_fuel_power_w"])
        assert eq.chain.engine_off_below_w == -np.inf and eq.predicts == "fuel"
        assert eq.chain.cold_start_fuel_l == pytest.approx(res["cold_start"][cls]["median_ml"] / 1000, abs=1e-4)
        assert 0.02 < eq.chain.cold_start_fuel_l < 0.2  # tens of mL per start
        cc = res["cold_start_cold"].get(cls, {})
        if cc.get("configurations", 0) >= ef.MIN_COLD_PAIRS:  # petrol: cars and light trucks
            assert eq.chain.cold_start_fuel_l_per_k == pytest.approx(cc["ml_per_k"] / 1000, abs=1e-6)
            assert 0.5e-3 < eq.chain.cold_start_fuel_l_per_k < 20e-3  # a cold start doubles or triples by −7 °C
            assert eq.chain.cold_start_ref_c == ef.FTP_AIR_C
        else:  # the diesels: the relative slope pooled over every pair, times their own cold start
            pool = [x for r in shared_studies.values() for c in r["cold_start_cold"].values()
                    for x in c.get("relative_per_k_pairs", [])]
            assert len(pool) >= ef.MIN_COLD_PAIRS
            want = np.median(pool) * res["cold_start"][cls]["median_ml"] / 1000
            assert eq.chain.cold_start_fuel_l_per_k == pytest.approx(want, abs=1e-6)
            assert 0.01 < np.median(pool) < 0.1  # 1–10 % of the cold start per kelvin
        # a warm engine in the cold: a few % more fuel at −6.7 °C (bag 3 over bag 3), held out by year
        assert 0.001 < eq.chain.running_fuel_per_k < 0.006
        if cc.get("running_held_out"):
            h = cc["running_held_out"]
            assert h["mean_abs_error_with"] < h["mean_abs_error_without"] and h["test_pairs"] >= 20


def test_sumo_run_books_idle_fuel_while_standing(tmp_path):
    """A real SUMO run (city, 300 s) with the built-in petrol car: per vehicle, the fuel
    energy is exactly P_idle × its time in the network + its traction energy / η (engine
    running throughout, η_t = 1, no auxiliaries), times the warm-running factor at the city
    scenario's 20 °C (1 + r · 3.9 K), and the class total is the vehicles' sum."""
    pytest.importorskip("libsumo")
    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.model.equations import load_equation

    out = tmp_path / "run"
    assert cli_main(["run", "city", "--equation", "epa_gasoline_car", "--end", "300", "--no-figures",
                     "--out", str(out)]) == 0
    ch = load_equation("epa_gasoline_car").chain
    veh = pd.read_parquet(out / "vehicles.parquet").set_index("vehicle")
    fuel = pd.read_csv(out / "chain_vehicles.csv", dtype={"key": str}).set_index("key")
    assert len(veh) > 10 and set(fuel.index) == set(veh.index)
    expect = ch.idle_fuel_power_w * veh["time_s"] + veh["traction_total_j"] / ch.marginal_efficiency
    expect = expect * (1.0 + ch.running_fuel_per_k * (ch.cold_start_ref_c - 20.0))
    assert ch.running_fuel_per_k > 0
    assert np.allclose(fuel["fuel_kwh"].reindex(veh.index) * 3.6e6, expect, rtol=1e-9)
    assert (veh["time_s"] > 0).all() and (fuel["fuel_l"] > 0).all()
    cls = pd.read_csv(out / "chain_classes.csv").set_index("key")
    assert cls.loc["passenger", "fuel_l"] == pytest.approx(fuel["fuel_l"].sum(), rel=1e-9)
