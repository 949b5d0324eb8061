"""The full-hybrid study on the EPA Test Car List (sumo_drvpw/validation/epa_hybrid.py) and
its built-in ``epa_gasoline_hybrid_car``.

Planted: synthetic Test Car List files whose full hybrids' fuel economies come from a known
line with engine-off (computed here by hand, sample by sample), with a mild hybrid (town
below highway), a plug-in and conventional cars that the selection must leave out; the
study must recover the line and its threshold. Real: the shared lists; the built-in must be
what the study writes, and it must book no fuel while a car stands in SUMO.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.model.constants import FUELS, LB, LBF, MILE, MPH
from sumo_drvpw.validation import epa_fleet as ef
from sumo_drvpw.validation import epa_hybrid as eh
from test_epa_fleet import HEADER, _mpg, _schedules

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"

ETA, P_L, P_OFF = 0.42, 3000.0, 4000.0  # the planted line: η, idle fuel per litre [W/L], engine off below [W]
COLD_RATIO = 1.2  # the Cold CO test's bag 3 burns 20 % more than the FTP's


def _hybrid_litres(v, a_n, b, c, m, disp) -> tuple[float, float]:
    """Fuel [L] and distance [m] of the planted line on schedule v, by hand: 1-s steps at the
    mean speed, m·v̄·Δv; idle fuel only in the steps whose power exceeds P_OFF, every joule of
    positive power at η (charge-sustaining)."""
    vm, dv = 0.5 * (v[1:] + v[:-1]), np.diff(v)
    p = (a_n + b * vm + c * vm ** 2) * vm + m * vm * dv
    on = p > P_OFF
    e_fuel = P_L * disp * on.sum() + p[p > 0].sum() / ETA
    f = FUELS["gasoline"]
    return e_fuel / (f["lhv_j_per_kg"] * f["density_kg_per_l"]), float(vm.sum())


def _hmpg(v, *car) -> float:
    litres, dist = _hybrid_litres(v, *car)
    return dist / MILE / (litres / ef.GALLON_L)


def _write(folder: Path, speeds: dict, n: int = 24, seed: int = 3) -> list[dict]:
    rng = np.random.default_rng(seed)
    cars = []
    u = speeds["udds"]
    for year in (2016, 2021):
        rows = []
        for i in range(n):
            m = rng.uniform(1300, 2200)
            car = (rng.uniform(0.07, 0.1) * m, rng.uniform(0.0, 4.0), rng.uniform(0.3, 0.5), m,
                   rng.choice([1.5, 1.8, 2.5]))
            base = {"Model Year": year, "Vehicle Manufacturer Name": "maker", "Represented Test Veh Make": "Maker",
                    "Represented Test Veh Model": f"H{i} Hybrid", "Test Vehicle ID": f"V{year}{i}",
                    "Test Veh Configuration #": 0, "Test Veh Displacement (L)": car[4], "Vehicle Type": "Car",
                    "Equivalent Test Weight (lbs.)": m / LB, "Test Fuel Type Description": "Tier 2 Cert Gasoline",
                    "Analytically Derived FE?": "No", "FE_UNIT": "MPG", "Target Coef A (lbf)": car[0] / LBF,
                    "Target Coef B (lbf/mph)": car[1] * MPH / LBF, "Target Coef C (lbf/mph**2)": car[2] * MPH ** 2 / LBF}
            b3, b4 = _hmpg(u[:506], *car), _hmpg(u[505:1370], *car)
            rows.append(base | {"Test Procedure Description": "Federal fuel 2-day exhaust (w/can load)",
                                "FE Bag 1": b3 * 0.8, "FE Bag 2": b4, "FE Bag 3": b3, "FE Bag 4": b4,
                                "RND_ADJ_FE": b4})
            rows.append(base | {"Test Procedure Description": "HWFE", "RND_ADJ_FE": _hmpg(speeds["hwfet"], *car)})
            if i % 2:
                rows.append(base | {"Test Procedure Description": "US06", "RND_ADJ_FE": _hmpg(speeds["us06"], *car)})
            if i < 22:  # the FTP at −6.7 °C on winter fuel: bag 3 (hot start) at 1/1.2 of the FTP's economy
                rows.append(base | {"Test Procedure Description": "Cold CO", "Test Fuel Type Description":
                                    "Cold CO Regular (Tier 2)", "FE Bag 1": b3 * 0.5, "FE Bag 2": b4 * 0.9,
                                    "FE Bag 3": b3 / COLD_RATIO, "RND_ADJ_FE": b4 * 0.8})
            cars.append({"year": year, "car": car})
        conv = dict(rows[1]) | {"Represented Test Veh Model": "Sedan", "Test Vehicle ID": f"C{year}"}
        car0 = cars[-1]["car"]
        rows.append(conv | {"Test Procedure Description": "Federal fuel 2-day exhaust (w/can load)",
                            "FE Bag 1": 25.0, "FE Bag 2": 30.0, "FE Bag 3": 28.0, "RND_ADJ_FE": 29.0})
        rows.append(conv | {"RND_ADJ_FE": _mpg(speeds["hwfet"], *car0)})
        mild = dict(rows[0]) | {"Represented Test Veh Model": "X6 ActiveHybrid", "Test Vehicle ID": f"M{year}",
                                "FE Bag 1": 18.0, "FE Bag 2": 22.0, "FE Bag 3": 21.0, "FE Bag 4": 22.0}
        rows += [mild, dict(rows[1]) | {"Represented Test Veh Model": "X6 ActiveHybrid", "Test Vehicle ID": f"M{year}",
                                        "RND_ADJ_FE": 30.0}]
        plug = dict(rows[0]) | {"Represented Test Veh Model": "Q9", "Test Vehicle ID": f"P{year}"}
        rows += [plug, plug | {"Test Procedure Description": "Charge Depleting Highway", "RND_ADJ_FE": 90.0},
                 dict(rows[1]) | {"Represented Test Veh Model": "Q9", "Test Vehicle ID": f"P{year}"}]
        pd.DataFrame(rows).reindex(columns=HEADER).to_csv(folder / f"{str(year)[2:]}tstcar.csv", index=False,
                                                          encoding="utf-8-sig")
    return cars


@pytest.fixture(scope="module")
def planted(tmp_path_factory):
    root = tmp_path_factory.mktemp("hev")
    speeds = _schedules(root / "cycles")
    (root / "epa_test_car_list").mkdir()
    cars = _write(root / "epa_test_car_list", speeds)
    return root, eh.study(root), cars, speeds


def test_planted_line_and_threshold_are_recovered_and_the_rest_left_out(planted):
    _, res, cars, _ = planted
    f = res["fit_all"]
    assert f["engine_off_below_w"] == P_OFF
    assert f["eta"] == pytest.approx(ETA, rel=1e-6) and f["p_idle_w_per_l"] == pytest.approx(P_L, rel=1e-6)
    assert f["n_configurations"] == len(cars)
    c = res["counts"]
    assert c["full hybrids"] == len(cars) and c["mild hybrids (town below highway) left out"] == 2
    assert c["plug-ins left out"] == 2 and c["conventional configurations (epa_fleet)"] == 2
    # the thresholds next to it fit worse: the grid's choice is not a tie
    errs = {g["engine_off_below_w"]: g["mean_abs_error"] for g in f["grid"]}
    assert errs[P_OFF] < 1e-9 < min(errs[P_OFF - 1000], errs[P_OFF + 1000])
    for s in res["splits"].values():  # the other model year predicted exactly through the evaluator
        assert s["own_road_load"]["all"]["mean_abs"] < 1e-6


def test_cold_start_by_hand(planted):
    _, res, cars, speeds = planted
    hot = [_hybrid_litres(speeds["udds"][:506], *c["car"])[0] for c in cars]
    # bag 1 written at 0.8 × bag 3's economy: 1/0.8 − 1 = 25 % more fuel over the first part
    assert res["cold_start"]["median_ml"] == pytest.approx(np.median(hot) * 0.25 * 1000, rel=1e-6)


def test_warm_running_in_the_cold_by_hand(planted):
    """44 configurations tested both ways, bag 3 at −6.7 °C burning 20 % more: 0.2 / 30.6 K
    per kelvin; the newest year predicted exactly with it, 1/1.2 − 1 off without it."""
    _, res, _, _ = planted
    rn = res["running"]
    assert rn["configurations"] == 44 and rn["bag3_ratio"] == pytest.approx(COLD_RATIO, rel=1e-9)
    assert rn["running_per_k"] == pytest.approx((COLD_RATIO - 1) / (ef.FTP_AIR_C - ef.COLD_CO_AIR_C), rel=1e-9)
    h = rn["held_out"]
    assert h["mean_abs_error_with"] < 1e-9 and h["mean_abs_error_without"] == pytest.approx(1 - 1 / COLD_RATIO)
    assert res["equation"]["chain"]["running_fuel_per_k"] == pytest.approx(rn["running_per_k"], abs=1e-6)


def test_evaluator_books_no_idle_fuel_below_the_threshold():
    """Standing: no fuel; creeping below P_off: P/η, no idle fuel; above it: p_L·D + P/η,
    sample by sample (charge-sustaining)."""
    obs = pd.DataFrame([{"config": "x", "test": "hwfet", "vehicle_type": "Car", "etw_kg": 1500.0, "a_n": 150.0,
                         "b_n_per_mps": 2.0, "c_n_per_mps2": 0.4, "displacement_l": 2.0,
                         "p_w": np.r_[np.zeros(10), np.full(10, 3000.0), np.full(10, 9000.0)]}])
    v = np.r_[np.zeros(11), np.full(10, 5.0), np.full(10, 20.0)]
    got = eh.predict(obs, {"eta": 0.4, "p_idle_w_per_l": 3000.0, "engine_off_below_w": 4000.0}, {"hwfet": v})[0]
    assert got == pytest.approx(10 * 3000.0 / 0.4 + 10 * (3000.0 * 2.0 + 9000.0 / 0.4), rel=1e-12)


@pytest.fixture(scope="module")
def shared():
    if not (SHARED / ef.DATASET).is_dir():
        pytest.skip("shared EPA data not found")
    return eh.study(SHARED)


def test_builtin_is_what_the_study_writes_on_the_shared_lists(shared):
    """The built-in comes from the real lists: regenerating gives the same numbers; the line
    is physical, an engine that stops, and predicts the newest model year within 10 %."""
    from sumo_drvpw.model.equations import equation_from_dict, load_equation

    f = shared["fit_all"]
    assert eh.ETA_PLAUSIBLE[0] <= f["eta"] <= eh.ETA_PLAUSIBLE[1] and f["engine_off_below_w"] > 0
    assert shared["splits"]["newest held out"]["own_road_load"]["all"]["mean_abs"] < 0.10
    assert shared["counts"]["full hybrids"] > 50 and shared["counts"]["mild hybrids (town below highway) left out"] > 0
    eq, want = load_equation(eh.NAME), equation_from_dict(shared["equation"])
    assert eq.terms == pytest.approx(want.terms) and eq.predicts == "fuel"
    for k in ("marginal_efficiency", "idle_fuel_power_w", "engine_off_below_w", "cold_start_fuel_l",
              "running_fuel_per_k"):
        assert getattr(eq.chain, k) == pytest.approx(getattr(want.chain, k)), k
    assert 0.02 < eq.chain.cold_start_fuel_l < 0.2
    h = shared["running"]["held_out"]  # the warm-running factor predicts a newer model year's cold test
    assert 0.001 < eq.chain.running_fuel_per_k < 0.01 and h["mean_abs_error_with"] < h["mean_abs_error_without"]


def test_the_hybrid_burns_less_than_the_conventional_car_on_the_prius_trips(shared):
    """On the Prius Gen 2's OBD trips the hybrid line books less fuel than the conventional
    petrol line (it stops the engine), per trip, with every litre finite."""
    if not (SHARED / "prius_gen2_torquepro").is_dir():
        pytest.skip("shared Prius data not found")
    pr = eh.prius2_check(SHARED, shared["equation"])
    assert len(pr["rows"]) == 2
    for r in pr["rows"]:
        assert 0 < r["class_road_load_l"] < r["conventional_epa_gasoline_car_l"]
        assert np.isfinite(r["measured_corrected_l"]) and r["measured_corrected_l"] > 1.0


def test_sumo_run_books_a_hybrid_charge_sustaining_and_nothing_while_it_stands(tmp_path):
    """A real SUMO run (city, 300 s, 0.5-s steps) with the built-in hybrid: per vehicle, the
    fuel is Σ over its steps of (p_L·D·[P > P_off] + max(P, 0)/η)·Δt, times the warm-running
    factor at the scenario's 20 °C — nothing while standing, no idle fuel below the threshold —
    from the run's own per-step powers (trace); below the engine-on-throughout form; class
    total = Σ vehicles."""
    pytest.importorskip("libsumo")
    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.model.equations import load_equation

    out = tmp_path / "run"
    assert cli_main(["run", "city", "--equation", eh.NAME, "--end", "300", "--no-figures", "--trace",
                     "--out", str(out)]) == 0
    ch = load_equation(eh.NAME).chain
    veh = pd.read_parquet(out / "vehicles.parquet").set_index("vehicle")
    fuel = pd.read_csv(out / "chain_vehicles.csv", dtype={"key": str}).set_index("key")
    tr = pd.read_parquet(out / "trace.parquet")
    assert len(veh) > 10 and set(fuel.index) == set(veh.index)
    dt = float(np.median(np.diff(np.unique(tr["time_s"]))))
    p = tr["p_total_w"].to_numpy()
    warm = 1.0 + ch.running_fuel_per_k * (ch.cold_start_ref_c - 20.0)  # the city scenario's air: 20 °C
    assert ch.running_fuel_per_k > 0
    assert ch.charge_sustaining and ch.engine_off_below_w > 0
    tr["fuel_j"] = (np.where(p > ch.engine_off_below_w, ch.idle_fuel_power_w, 0.0)
                    + np.maximum(p, 0.0) / ch.marginal_efficiency) * dt * warm
    want = tr.groupby("vehicle")["fuel_j"].sum().reindex(veh.index)
    got = fuel["fuel_kwh"].reindex(veh.index) * 3.6e6
    assert np.allclose(got, want, rtol=1e-9, atol=1e-6)
    stand = tr["speed_mps"] == 0.0
    assert stand.sum() > 100 and (tr.loc[stand, "fuel_j"] == 0).all()
    always_on = (ch.idle_fuel_power_w * veh["time_s"] + veh["traction_total_j"] / ch.marginal_efficiency) * warm
    assert (got < always_on).all()
    cls = pd.read_csv(out / "chain_classes.csv").set_index("key")
    assert cls.loc["passenger", "fuel_l"] == pytest.approx(fuel["fuel_l"].sum(), rel=1e-9)


def test_lists_without_a_full_hybrid_are_one_line(tmp_path):
    """Only conventional cars (the conventional study's planted lists): exit 2, one line
    naming the folder, no report and no built-in written."""
    import subprocess
    import sys

    from sumo_drvpw.errors import UserError
    from sumo_drvpw.model.equations import BUILTIN_DIR
    from test_epa_fleet import _write_lists

    speeds = _schedules(tmp_path / "cycles")
    (tmp_path / "epa_test_car_list").mkdir()
    _write_lists(tmp_path / "epa_test_car_list", speeds, n=6)
    with pytest.raises(UserError, match=r"epa_test_car_list: no full hybrid tested on Tier 2 Cert Gasoline"):
        eh.study(tmp_path)
    before = (BUILTIN_DIR / f"{eh.NAME}.toml").read_bytes()
    r = subprocess.run([sys.executable, "-m", "sumo_drvpw.validation.epa_hybrid", str(tmp_path / "r.md"),
                        str(tmp_path)], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert "no full hybrid" in r.stderr and not (tmp_path / "r.md").exists()
    assert (BUILTIN_DIR / f"{eh.NAME}.toml").read_bytes() == before


def test_charge_sustaining_key_round_trips_and_bad_values_are_one_line():
    """``charge_sustaining`` in a [chain] table: kept through to_dict/from_dict; it changes
    nothing where the engine runs whenever the power is positive (P_off ≤ 0), and books the
    power below a positive threshold at η; a non-boolean or a battery chain is refused."""
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.model.chain_toml import chain_from_dict

    base = {"predicts": "fuel", "idle_fuel_power_w": 5000.0, "marginal_efficiency": 0.4, "engine_off_below_w": 0.0,
            "fuel": "gasoline"}
    p = np.array([-2000.0, 0.0, 1500.0, 4000.0, 9000.0])
    v = np.full(p.size, 10.0)
    plain, cs = chain_from_dict(base), chain_from_dict(base | {"charge_sustaining": True})
    assert cs.charge_sustaining and chain_from_dict(cs.to_dict()).charge_sustaining
    assert "charge_sustaining" not in plain.to_dict()
    assert np.array_equal(plain.evaluate(p, v)["power_w"], cs.evaluate(p, v)["power_w"])
    hi = chain_from_dict(base | {"engine_off_below_w": 3000.0, "charge_sustaining": True})
    assert np.allclose(hi.evaluate(p, v)["power_w"], [0.0, 0.0, 1500.0 / 0.4, 5000.0 + 4000.0 / 0.4,
                                                      5000.0 + 9000.0 / 0.4])
    for bad in ({**base, "charge_sustaining": "yes"}, {"predicts": "battery", "charge_sustaining": True}):
        with pytest.raises(UserError, match=r"'charge_sustaining' must be true or false"):
            chain_from_dict(bad, "x.toml")


def _phev_config(d: Path, fcd: bool = False) -> Path:
    """A bare SUMO config in ``d``: PHEV_ROUTES on an 800-m road, 150 s (with ``fcd``, its
    FCD at 6 decimals: a run writes it into OUT/sumo/fcd.xml)."""
    from sumo_probe import build_net

    build_net(d, '<nodes><node id="a" x="0" y="0"/><node id="b" x="800" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="14"/></edges>')
    (d / "r.rou.xml").write_text(PHEV_ROUTES, encoding="utf-8")
    out = '<output><fcd-output value="fcd.xml"/><precision value="6"/></output>' if fcd else ""
    (d / "c.sumocfg").write_text('<configuration><input><net-file value="n.net.xml"/><route-files '
                                 f'value="r.rou.xml"/></input>{out}<time><end value="150"/></time></configuration>', encoding="utf-8")
    return d / "c.sumocfg"


PHEV_ROUTES = """<routes>
  <vType id="phev" emissionClass="HBEFA4/PC_PHEV_petrol_Euro-6d_(P)" mass="1700"/>
  <vType id="petrol" emissionClass="HBEFA4/PC_petrol_Euro-6d" mass="1400"/>
  <vType id="plain" mass="1400"/>
  <flow id="h" type="phev" begin="0" end="30" period="10"><route edges="e"/></flow>
  <flow id="p" type="petrol" begin="1" end="30" period="10"><route edges="e"/></flow>
  <flow id="n" type="plain" begin="2" end="30" period="10"><route edges="e"/></flow>
</routes>"""


def test_a_bare_config_books_a_plug_in_hybrids_petrol_share_with_the_plug_in_chain(tmp_path):
    """A bare SUMO config: the vType whose emissionClass names a plug-in hybrid's petrol share
    (HBEFA4/PC_PHEV_petrol_Euro-6d_(P)) is booked by the plug-in hybrid's chain and not by the
    conventional petrol car's or the full hybrid's; a conventional class, written or SUMO's
    default, by the conventional's only; summary.json says which chain each left out. A scenario that names both chains
    books a vType that writes no class with both (alternatives), and the plug-in hybrid's class
    with the full hybrid's only (no plug-in chain named: the nearest). A charge-sustaining chain whose engine stops only at P ≤ 0 (a
    start-stop engine's, as calibration writes it) is no hybrid's."""
    pytest.importorskip("libsumo")
    import json

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.model.chain import EnergyChain
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.sim.carrier import is_hybrid_chain, is_hybrid_class

    _phev_config(tmp_path)
    books = {}
    for name, target in (("bare", "c.sumocfg"), ("both", "s.toml")):
        if name == "both":
            (tmp_path / "s.toml").write_text(f'equations = ["epa_gasoline_car", "{eh.NAME}"]\n[sumo]\n'
                                             'config = "c.sumocfg"\n[outputs]\nfigures = false\n', encoding="utf-8")
        out = tmp_path / name
        assert cli_main(["run", str(tmp_path / target), "--no-figures", "--out", str(out)]) == 0
        ch = pd.read_csv(out / "chain_vehicles.csv", dtype={"key": str})
        books[name] = ch.groupby(ch["key"].str[0])["equation"].agg(lambda s: sorted(set(s))).to_dict()
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
        books[name + "_summary"] = summary["assumptions"]["powertrain"]
        books[name + "_warned"] = [w for w in summary["warnings"] if "emissionClass names their fuel" in w]
    assert books["bare"] == {"h": ["epa_gasoline_phev_car"], "p": ["epa_gasoline_car"], "n": ["epa_gasoline_car"]}
    pt = books["bare_summary"]   # the bare config's plug-in hybrid (tests/test_epa_phev.py)
    assert pt["phev"]["powertrain"] == "plug-in hybrid" and pt["phev"]["not_booked_by"] == ["epa_gasoline_car", eh.NAME]
    assert pt["petrol"]["not_booked_by"] == pt["plain"]["not_booked_by"] == [eh.NAME, "epa_gasoline_phev_car"]
    assert pt["plain"]["from"].startswith("SUMO's default")
    # the bare config's diesel and battery chains book nobody here (every car writes petrol):
    # the plug-in's own chains, one per carrier, are no news
    assert books["bare_warned"] == [] and books["both_warned"] == []
    assert books["both"] == {"h": [eh.NAME], "p": ["epa_gasoline_car"], "n": ["epa_gasoline_car", eh.NAME]}
    assert set(books["both_summary"]) == {"phev", "petrol"}
    # the classes and chains the routing reads
    assert is_hybrid_class("HBEFA4/LCV_PHEV_petrol_N1-II_Euro-6_(P)") and not is_hybrid_class("HBEFA3/PC_G_EU4")
    stop_start = EnergyChain(predicts="fuel", idle_fuel_power_w=3000.0, marginal_efficiency=0.35,
                             engine_off_below_w=0.0, charge_sustaining=True, aux_power_w=300.0)
    hybrid = EnergyChain(predicts="fuel", idle_fuel_power_w=3000.0, marginal_efficiency=0.35,
                         engine_off_below_w=6000.0, charge_sustaining=True)
    assert [is_hybrid_chain(Equation(name="x", terms={"acc": 1.0}, chain=c)) for c in (stop_start, hybrid)] == [
        False, True]
    assert is_hybrid_chain(Equation(name="x", terms={"acc": 1.0})) is None


def test_an_fcd_replay_serial_or_on_dask_books_the_powertrains_as_the_live_run(tmp_path):
    """The bare config's run replayed from its FCD (no equations: the bare config's): the
    same chain per vehicle as live, and summary.json's energy carrier, powertrain and
    booked-as assumptions the same, also on Dask, whose buckets each resolve their own
    vTypes (the driver's summary had lost them: empty before the buckets' were merged)."""
    pytest.importorskip("libsumo")
    pytest.importorskip("distributed")
    import json

    from sumo_drvpw.cli import main as cli_main

    cfg = _phev_config(tmp_path, fcd=True)
    assert cli_main(["run", str(cfg), "--no-figures", "--out", str(tmp_path / "live")]) == 0
    want = json.loads((tmp_path / "live" / "summary.json").read_text(encoding="utf-8"))["assumptions"]
    assert want["powertrain"] and want["energy_carrier"]
    live = pd.read_csv(tmp_path / "live" / "chain_vehicles.csv").set_index(["key", "equation"])["fuel_l"]
    fcd = tmp_path / "live" / "sumo" / "fcd.xml"  # where the run sends the config's outputs
    got = {}
    for engine, opts in (("local", []), ("dask", ["--workers", "1", "--buckets", "2"])):
        out = tmp_path / engine
        assert cli_main(["fcd", str(fcd), "--scenario", str(cfg), "--no-figures", "--engine", engine, *opts,
                         "--out", str(out)]) == 0
        got[engine] = json.loads((out / "summary.json").read_text(encoding="utf-8"))["assumptions"]
        for key in ("energy_carrier", "powertrain", "booked_as"):  # the replay has no SUMO to ask its
            assert _without_from(got[engine][key]) == _without_from(want[key]), (engine, key)  # default
            assert got[engine][key] == got["local"][key], (engine, key)
        fuel = pd.read_csv(out / "chain_vehicles.csv").set_index(["key", "equation"])["fuel_l"]
        pd.testing.assert_series_equal(fuel.sort_index(), live.sort_index(), rtol=1e-6)


def _without_from(d: dict) -> dict:
    """Per-vType assumptions without where the class came from (a live run asks SUMO for its
    default class, a replay reads SUMO's default for the vClass: the same class)."""
    return {vt: {k: x for k, x in a.items() if k != "from"} for vt, a in d.items()}


def test_a_hybrid_without_a_hybrid_chain_for_its_vclass_is_said(tmp_path):
    """A bare SUMO config with a plug-in hybrid van's petrol share (vClass delivery) and a
    hybrid city bus: no hybrid chain is made for the van's vClass, so the conventional van's
    chain books it — and the run says so, naming the vType, its class and the chain
    (summary.json assumptions.powertrain ``no_hybrid_chain``); the petrol van is not named;
    the bus is booked by the built-in hybrid bus's chain (docs/hdv-hybrid.md). Given a hybrid
    chain in a scenario (the built-in car's, for the van) and only the diesel bus's, the van
    is no longer named; the bus now is."""
    pytest.importorskip("libsumo")
    import json

    from sumo_drvpw.cli import main as cli_main
    from sumo_probe import build_net

    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="800" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="14"/></edges>')
    (tmp_path / "r.rou.xml").write_text("""<routes>
  <vType id="hvan" vClass="delivery" emissionClass="HBEFA4/LCV_PHEV_petrol_N1-II_Euro-6_(P)"/>
  <vType id="van" vClass="delivery" emissionClass="HBEFA4/LCV_petrol_N1-II_Euro-6d"/>
  <vType id="hbus" vClass="bus" emissionClass="HBEFA4/UBus_Std_gt15-18t_HEV_Euro-VI_D-E"/>
  <flow id="h" type="hvan" begin="0" end="20" period="10"><route edges="e"/></flow>
  <flow id="v" type="van" begin="1" end="20" period="10"><route edges="e"/></flow>
  <flow id="b" type="hbus" begin="2" end="20" period="10"><route edges="e"/></flow>
</routes>""", encoding="utf-8")
    (tmp_path / "c.sumocfg").write_text('<configuration><input><net-file value="n.net.xml"/><route-files '
                                        'value="r.rou.xml"/></input><time><end value="100"/></time></configuration>', encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["epa_gasoline_light_truck", "moves_transit_bus_diesel", "{eh.NAME}"]\n'
        f'[vtypes.hvan]\nequations = ["{eh.NAME}"]\n[sumo]\nconfig = "c.sumocfg"\n', encoding="utf-8")
    seen = {}
    for name, target in (("bare", "c.sumocfg"), ("given", "s.toml")):
        out = tmp_path / name
        assert cli_main(["run", str(tmp_path / target), "--no-figures", "--out", str(out)]) == 0
        summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
        ch = pd.read_csv(out / "chain_vehicles.csv", dtype={"key": str})
        seen[name] = (summary["assumptions"]["powertrain"],
                      [w for w in summary["warnings"] if "no hybrid chain is made" in w],
                      ch.groupby(ch["key"].str[0])["equation"].agg(lambda s: sorted(set(s))).to_dict())
    pt, warned, books = seen["bare"]
    assert books == {"h": ["epa_gasoline_light_truck"], "v": ["epa_gasoline_light_truck"],
                     "b": ["moves_transit_bus_hybrid_diesel"]}
    assert pt["hvan"]["no_hybrid_chain"] == ["epa_gasoline_light_truck"]
    assert pt["hbus"] == {"emission_class": "HBEFA4/UBus_Std_gt15-18t_HEV_Euro-VI_D-E", "from": "written",
                          "powertrain": "hybrid", "not_booked_by": ["moves_transit_bus_diesel"]}
    assert "van" not in pt and len(warned) == 1
    assert "hvan (HBEFA4/LCV_PHEV_petrol_N1-II_Euro-6_(P): epa_gasoline_light_truck)" in warned[0]
    assert "hbus (" not in warned[0] and "van (" not in warned[0].replace("hvan (", "")
    pt, warned, books = seen["given"]
    assert books["h"] == [eh.NAME] and "hvan" not in pt and "hbus" in pt
    assert len(warned) == 1 and "hvan" not in warned[0] and "hbus (" in warned[0]
