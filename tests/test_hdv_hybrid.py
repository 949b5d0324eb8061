"""The diesel-electric hybrid transit bus (sumo_drvpw/validation/hdv_hybrid.py, docs/hdv-hybrid.md);
the chain's braking energy given back: tests/test_chain_round_trip.py.

By hand: the built-in books P_fuel = on·P_idle + (max(P, 0)/η_d + P_aux + η_rt·max(P, −P_lim)/η_d)/η_e
at a few (P, v) with the sourced numbers written out here (0.97 gal/h, 10 kW, 0.45, 0.85, the
round trip 0.98·(0.92·0.96)²·0.97, 186 kW): no idle fuel at rest, a credit while braking. A bare
SUMO config books a bus whose emissionClass names a hybrid (HBEFA 4's UBus_…_HEV_…) by it and
a diesel bus (written or SUMO's default class) by the diesel chain, each exactly once; on the
same drive the hybrid books less. The committed report is what the module computes.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.model.equations import load_equation

REPO = Path(__file__).resolve().parents[1]
DATA = Path(os.environ.get("SUMO_DRVPW_DATA") or REPO.parent / "shared" / "data")
LHV, RHO = 43.1e6, 0.832
IDLE_W = 0.97 * 3.785411784 / 3600 * RHO * LHV
RT = 0.98 * (0.92 * 0.96) ** 2 * 0.97
NAME, DIESEL = "moves_transit_bus_hybrid_diesel", "moves_transit_bus_diesel"


def test_builtin_books_fuel_by_hand():
    eq, dsl = load_equation(NAME), load_equation(DIESEL)
    assert eq.terms == dsl.terms and tuple(eq.vclasses) == ("bus",)
    ch = eq.chain
    assert ch.charge_sustaining and ch.fuel == "diesel" and ch.recuperation_round_trip == pytest.approx(RT, abs=1e-4)
    # moving and pulling; standing (engine off); braking moving; braking beyond the motor; coasting at P = 0
    p = np.array([30000.0, 0.0, -40000.0, -300000.0, 0.0])
    v = np.array([10.0, 0.0, 8.0, 15.0, 5.0])
    got = ch.evaluate(p, v, dt_s=2.0)["power_w"]
    rt = ch.recuperation_round_trip
    want = np.array([IDLE_W + (30000 / 0.85 + 10000) / 0.45,
                     10000 / 0.45,                                    # no idle: the engine is off
                     (10000 - rt * 40000 / 0.85) / 0.45,              # a credit: negative
                     (10000 - rt * 186000 / 0.85) / 0.45,             # capped at the 186-kW motor
                     IDLE_W + 10000 / 0.45])                          # moving: the engine runs
    assert got == pytest.approx(want, rel=1e-6)
    assert got[2] < 0 and got[3] < got[2]
    # the diesel twin idles at rest and books nothing while braking
    d = dsl.chain.evaluate(p, v)["power_w"]
    assert d[1] == pytest.approx(IDLE_W + 10000 / 0.45, rel=1e-6) and d[2] == d[3] == 0.0


def test_builtin_is_what_the_module_writes():
    from sumo_drvpw.model.equations import equation_from_dict
    from sumo_drvpw.sim.carrier import is_hybrid_chain
    from sumo_drvpw.validation import hdv_hybrid as h

    want = equation_from_dict(h.builtin_doc(), f"<{NAME}>").to_dict()
    assert load_equation(NAME).to_dict() == want, "regenerate with python -m sumo_drvpw.validation.hdv_hybrid"
    reading = load_equation(NAME).chain.reading
    for key in ("recuperation_round_trip", "recuperation_limit_w", "engine_on_above_mps"):
        assert "[" in reading[key], key
    assert is_hybrid_chain(load_equation(NAME)) and not is_hybrid_chain(load_equation(DIESEL))


def test_bare_config_books_a_hybrid_bus_on_the_hybrid_chain(tmp_path, capsys):
    """Three buses on the same route, one vType each: HBEFA 4's hybrid standard bus, its
    diesel twin, and one that writes no class (SUMO's default, diesel). Before, the hybrid
    was booked by the diesel chain, with the warning that no hybrid chain is made for vClass
    bus; now by the hybrid's, the others by the diesel's, each once — and on the same drive
    the hybrid books less (no idling at the start, braking energy back)."""
    pytest.importorskip("libsumo")
    from test_sim_run import WEST, _city_config

    from sumo_drvpw.cli import main as cli_main

    vtypes = """\
    <vType id="hbus" vClass="bus" emissionClass="HBEFA4/UBus_Std_gt15-18t_HEV_Euro-VI_A-C"/>
    <vType id="dbus" vClass="bus" emissionClass="HBEFA4/UBus_Std_gt15-18t_Euro-VI_A-C"/>
    <vType id="bus" vClass="bus"/>
"""
    sc = tmp_path / "sc"
    sc.mkdir()
    cfg = _city_config(sc, vtypes, [("h", "hbus", WEST), ("d", "dbus", WEST), ("b", "bus", WEST)], end="200")
    out = tmp_path / "o"
    code = cli_main(["run", str(cfg), "--out", str(out), "--no-figures", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 0, err
    fuel = pd.read_csv(out / "chain_vehicles.csv", dtype={"key": str})
    books = fuel.groupby("key")["equation"].agg(sorted).to_dict()
    assert books == {"h": [NAME], "d": [DIESEL], "b": [DIESEL]}
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    pt = summary["assumptions"]["powertrain"]
    assert pt["hbus"]["powertrain"] == "hybrid" and pt["hbus"]["not_booked_by"] == [DIESEL]
    assert pt["dbus"]["powertrain"] == pt["bus"]["powertrain"] == "conventional"
    assert pt["bus"]["not_booked_by"] == [NAME]
    assert not any("no hybrid chain is made" in w for w in summary["warnings"])
    per = fuel.set_index("key")
    # the three drive alike (same route, same departure order aside): per km the hybrid books less
    veh = pd.read_parquet(out / "vehicles.parquet").groupby("vehicle")["distance_m"].first()
    lpk = per["fuel_l"] / veh.reindex(per.index)
    assert 0 < lpk["h"] < lpk["d"]


@pytest.mark.skipif(not (DATA / "cycles" / "udds.csv").is_file(), reason="shared cycles not present")
def test_report_is_what_the_module_computes():
    from sumo_drvpw.validation import hdv_hybrid as h

    res = json.loads((REPO / "docs" / "hdv-hybrid.json").read_text(encoding="utf-8"))
    now = h.check(DATA)
    for cyc, r in now["cycles"].items():
        assert res["check"]["cycles"][cyc]["hybrid"]["l_per_100km"] == pytest.approx(r["hybrid"]["l_per_100km"],
                                                                                      rel=1e-9)
        assert res["check"]["cycles"][cyc]["saving"] == pytest.approx(r["saving"], rel=1e-9)
    # the physics' pattern: the slowest cycle saves the most, the highway the least
    cy = now["cycles"]
    assert cy["wltc_low_3"]["saving"] > cy["udds"]["saving"] > cy["hwfet"]["saving"] > 0


def test_the_sumo_device_row_of_a_hybrid_bus_says_what_its_ratio_holds(tmp_path):
    """Beside SUMO's emissions device, which books HBEFA 4's hybrid bus class: the hybrid bus
    chain's row says what its ratio holds (its note was the car's: 'SUMO has no full-hybrid
    car class', wrong for a bus); the diesel bus's row has no hybrid note; on the same trips
    the hybrid's ratio is the lower (a scenario naming both chains: the class chooses)."""
    pytest.importorskip("libsumo")
    from test_sim_device_no_chain import NET

    from sumo_drvpw.sim import run_scenario

    route = '<route edges="c00c10 c10c20 c20c30 c30c31 c31c32"/>'
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="hbus" vClass="bus" emissionClass="HBEFA4/UBus_Std_gt15-18t_HEV_Euro-VI_A-C"/>'
        '<vType id="dbus" vClass="bus" emissionClass="HBEFA4/UBus_Std_gt15-18t_Euro-VI_A-C"/>'
        f'<flow id="h" type="hbus" begin="0" end="60" period="15" departSpeed="0">{route}</flow>'
        f'<flow id="d" type="dbus" begin="0" end="60" period="15" departSpeed="0">{route}</flow></routes>\n',
        encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["{DIESEL}", "{NAME}"]\n[sumo]\nnet = "{NET}"\n'
        'routes = ["r.rou.xml"]\nbegin = 0\nend = 400\nstep_length = 1.0\noptions = ["--no-warnings", "true"]\n'
        '[outputs]\nfigures = false\nsumo_device = true\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    rows = pd.read_csv(tmp_path / "o" / "sumo_device.csv").set_index("equation")
    hyb, dsl = rows.loc[NAME], rows.loc[DIESEL]
    assert hyb["vehicles"] == dsl["vehicles"] == 4
    assert "UBus_…_HEV_…" in hyb["note"] and "no full-hybrid car class" not in hyb["note"]
    assert not isinstance(dsl["note"], str) or "hybrid" not in dsl["note"]
    assert hyb["ratio"] < dsl["ratio"]


def test_the_device_note_of_a_hybrid_chain_follows_the_vehicles_class():
    """sumo_device.csv's note on a full hybrid's fuel chain: the bus note (SUMO books HBEFA's
    hybrid bus) for buses, the car note (SUMO has no full-hybrid car class) for cars. It was
    chosen by the chain's recuperation_round_trip, so a user's hybrid car chain declaring its
    braking energy given back (docs/energy-chain.md) was told SUMO books a UBus_…_HEV_… class."""
    from sumo_drvpw.sim.sumo_outputs import HYBRID_BUS_NOTE, HYBRID_NOTE, device_comparison

    ch = load_equation(NAME).chain
    dev = pd.DataFrame({"vehicle": ["b", "c"], "sumo_fuel_mg": [9e5, 3e5], "sumo_electricity_wh": [0.0, 0.0]})
    cv = pd.DataFrame({"vehicle": ["b", "c"], "equation": ["hyb_bus", "hyb_car"], "fuel_l": [1.0, 0.3]})
    v = pd.DataFrame({"vehicle": ["b", "c"], "equation": ["hyb_bus", "hyb_car"], "net_total_j": [1e7, 3e6],
                      "vtype": ["hbus", "hcar"], "vclass": ["bus", "passenger"]})
    rows = device_comparison(v, dev, cv, {"hyb_bus": ch, "hyb_car": ch}).set_index("equation")
    assert rows.note["hyb_bus"] == HYBRID_BUS_NOTE
    assert rows.note["hyb_car"] == HYBRID_NOTE
