"""The motorcycle and moped petrol fuel chains (sumo_drvpw/validation/mc_fuel.py, docs/mc-fuel.md).

By hand: each built-in books P_fuel = P_idle + (max(P, 0)/η_d + P_aux)/η_e with the sourced
numbers written out here (carculator_two_wheeler's engine efficiency 0.18, transmission 0.8,
auxiliary 60 W or 30 W; the petrol cars' 4,037 W of zero-output fuel per litre times 0.6 L (to 0.1 W)
or the moped's 50 cm³), on the MOVES motorcycle road load; the motorcycle cuts its fuel in
overrun, the moped idles through. A bare SUMO config books motorcycles and mopeds in litres
(before, no chain applied to them and the run said so), an electric moped is not booked by
the petrol chain, and per vehicle the litres are the hand formula over its trace. On the
ECE-15 urban cycle and the WLTC's low phase the motorcycle's L/100 km lies in the published
range of new motorcycles; the committed report is what the module computes.
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
LHV, RHO = 43.2e6, 0.745            # petrol [J/kg], [kg/L] (docs/sources.md, Fuels)

#: name → (vClass, η_e, η_d, idle [W] = 4037 W/L × displacement, P_aux [W], overrun cut at P < 0)
HAND = {
    "moves_motorcycle_petrol": ("motorcycle", 0.24, 0.8, round(4037.0 * 0.6, 1), 60.0, True),
    "moves_moped_petrol": ("moped", 0.18, 0.8, round(4037.0 * 0.05, 1), 30.0, False),
}


@pytest.mark.parametrize("name", sorted(HAND))
def test_builtin_books_fuel_by_hand(name):
    vclass, eta_e, eta_d, idle, aux, cut = HAND[name]
    eq, mv = load_equation(name), load_equation("moves_motorcycle")
    assert eq.terms == mv.terms and tuple(eq.vclasses) == (vclass,)
    ch = eq.chain
    assert ch.predicts == "fuel" and ch.fuel == "gasoline" and ch.engine_off_below_w == -np.inf
    p = np.array([-3000.0, 0.0, 2000.0, 15000.0, -500.0])
    v = np.array([8.0, 0.0, 10.0, 22.0, 0.0])
    got = ch.evaluate(p, v, dt_s=2.0)
    fuelled = np.array([0.0 if cut else 1.0, 1.0, 1.0, 1.0, 1.0])   # rolling at P < 0: cut or idling
    want_w = fuelled * (idle + (np.maximum(p, 0.0) / eta_d + aux) / eta_e)
    assert got["power_w"] == pytest.approx(want_w, rel=1e-4)
    assert got["fuel_l"] == pytest.approx(want_w * 2.0 / LHV / RHO, rel=1e-4)
    # the road load is MOVES source type 11's: (1000·A/M)·m·v + 1000·C·v³ at 10 m/s, flat, steady
    from sumo_drvpw.model.terms import Inputs
    one = np.ones(1)
    x = Inputs(v=10 * one, a=0 * one, theta=0 * one, wind=0 * one, mass=285.0 * one, rho=1.2041 * one)
    assert eq.power(x)[0] == pytest.approx(1000 * 0.0251 * 10 + 1000 * 0.000315 * 1000, rel=1e-6)


def test_builtins_are_what_the_module_writes_with_their_sources():
    """The two TOML files are :func:`builtin_doc` exactly; every chain parameter has a
    reading that names a source key of the module's SOURCES or says ESTIMATE."""
    from sumo_drvpw.model.equations import equation_from_dict
    from sumo_drvpw.validation import mc_fuel as m

    assert set(m.CHAINS) == set(HAND)
    for name in m.CHAINS:
        want = equation_from_dict(m.builtin_doc(name), f"<{name}>").to_dict()
        assert load_equation(name).to_dict() == want, f"{name}: regenerate with python -m sumo_drvpw.validation.mc_fuel"
        reading = load_equation(name).chain.reading
        for key in ("traction_efficiency", "marginal_efficiency", "idle_fuel_power_w", "aux_power_w",
                    "engine_off_below_w", "fuel_cut_below_w"):
            keys = [k for k in m.SOURCES if f"[{k}]" in reading[key]]
            assert keys or "ESTIMATE" in reading[key] or key == "fuel_cut_below_w", (name, key)
        assert "[C2W]" in reading["marginal_efficiency"] and "[EPA-TCL]" in reading["idle_fuel_power_w"]


def _config(folder: Path) -> Path:
    """A bare config with a motorcycle and a moped that write no emissionClass (SUMO's
    default petrol classes), an electric moped and a car."""
    from test_sim_run import EAST, WEST, _city_config

    vtypes = """\
    <vType id="mc" vClass="motorcycle"/>
    <vType id="mop" vClass="moped"/>
    <vType id="emop" vClass="moped" emissionClass="Energy/unknown"/>
    <vType id="car" vClass="passenger" mass="1400"/>
"""
    veh = [("m", "mc", WEST), ("s", "mop", EAST), ("e", "emop", WEST), ("p", "car", EAST)]
    return _city_config(folder, vtypes, veh, end="150")


def test_bare_config_books_motorcycles_and_mopeds_in_litres(tmp_path, capsys):
    """A bare SUMO config books motorcycles and mopeds by their petrol chains, per vehicle
    exactly P_idle·T_f + (E_traction/η_d + P_aux·T_f)/η_e over its fuelled time T_f (the
    trace); the electric moped is not booked by the petrol chain, and it alone is in the
    warning of vehicles no chain books (before: the motorcycle and moped were too)."""
    pytest.importorskip("libsumo")
    from sumo_drvpw.cli import main as cli_main

    sc = tmp_path / "sc"
    sc.mkdir()
    out = tmp_path / "o"
    code = cli_main(["run", str(_config(sc)), "--out", str(out), "--no-figures", "--no-progress", "--trace"])
    err = capsys.readouterr().err
    assert code == 0, err
    fuel = pd.read_csv(out / "chain_vehicles.csv", dtype={"key": str})
    booked = dict(zip(fuel["key"], fuel["equation"]))
    assert booked["m"] == "moves_motorcycle_petrol" and booked["s"] == "moves_moped_petrol"
    assert booked["p"] == "epa_gasoline_car" and "e" not in booked
    veh = pd.read_parquet(out / "vehicles.parquet")
    trace = pd.read_parquet(out / "trace.parquet")
    for vid in ("m", "s"):
        name = booked[vid]
        _, eta_e, eta_d, idle, aux, cut = HAND[name]
        r = veh[(veh.vehicle == vid) & (veh.equation == name)].iloc[0]
        t = trace[(trace.vehicle == vid) & (trace.equation == name)]
        p, dt = t.p_total_w.to_numpy(), 0.5
        fuelled = (p >= 0) | (t.speed_mps.to_numpy() <= 0.1) if cut else np.ones(p.size, bool)
        want = (idle + aux / eta_e) * dt * fuelled.sum() + r.traction_total_j / (eta_d * eta_e)
        got = fuel[(fuel.key == vid) & (fuel.equation == name)].iloc[0]
        assert got.fuel_kwh * 3.6e6 == pytest.approx(want, rel=1e-6) and got.fuel_l > 0
    cls = pd.read_csv(out / "chain_classes.csv").set_index("key")
    assert {"motorcycle", "moped", "passenger"} <= set(cls.index)
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert "moves_moped_petrol" in summary["assumptions"]["energy_carrier"]["emop"]["not_booked_by"]
    key = "no battery or fuel chain applies to"
    said = err.split(key)[1].split("\n")[0] if key in err else ""
    assert "moped" in said and "motorcycle" not in said
    # each chain that booked says once that it is an estimate checked against no measured ride
    for name in ("moves_motorcycle_petrol", "moves_moped_petrol"):
        assert sum(w.startswith(f"{name}: its chain's calibration warned: an estimate") for w in summary["warnings"]) == 1
    # the chains of the other built-ins, which booked nothing here, say nothing
    assert not [w for w in summary["warnings"] if "its chain's calibration warned" in w
                and not w.startswith(("moves_motorcycle_petrol", "moves_moped_petrol"))]


def test_a_two_wheeler_or_bus_on_sumos_battery_device_gets_no_litres(tmp_path, capsys):
    """A vType that writes no emissionClass but has param has.battery.device runs on SUMO's
    Energy model (an electric scooter, an e-bus): before, where one carrier's chains alone
    apply to its vClass (the moped's petrol, the bus's diesel) the carrier was not asked and
    the scooter was booked 0.0166 L by moves_moped_petrol, the bus 0.21 L by
    moves_transit_bus_diesel (a car so written was already booked by the i3's battery
    chain); now neither gets litres, and the run says no chain books them."""
    pytest.importorskip("libsumo")
    from test_sim_run import EAST, WEST, _city_config

    from sumo_drvpw.cli import main as cli_main

    batt = '<param key="has.battery.device" value="true"/>'
    vtypes = (f'    <vType id="escooter" vClass="moped">{batt}</vType>\n'
              f'    <vType id="ebus" vClass="bus">{batt}</vType>\n    <vType id="mop" vClass="moped"/>\n')
    cfg = _city_config(tmp_path, vtypes, [("b", "escooter", WEST), ("c", "ebus", EAST), ("s", "mop", EAST)],
                       end="100")
    code = cli_main(["run", str(cfg), "--out", str(tmp_path / "o"), "--no-figures", "--no-progress"])
    err = capsys.readouterr().err
    assert code == 0, err
    fuel = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv", dtype={"key": str})
    assert set(fuel["key"]) == {"s"}  # (the petrol moped beside them: booked as before)
    carriers = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))["assumptions"][
        "energy_carrier"]
    assert carriers["escooter"]["carrier"] == carriers["ebus"]["carrier"] == "electricity"
    assert carriers["escooter"]["not_booked_by"] == ["moves_moped_petrol"]


@pytest.mark.parametrize("name", sorted(HAND))
def test_check_is_at_the_plug_in_s_default_mass_of_the_vclass(name):
    """The check computes L/100 km at the mass a vType of the vClass without one is booked
    at (sim/vtypes.py DEFAULT_MASS_KG): the moped's was checked at the MOVES motorcycle's
    285 kg, a moped now books 167 kg (kerb + rider); the committed report says the same."""
    from sumo_drvpw.sim.vtypes import DEFAULT_MASS_KG
    from sumo_drvpw.validation import mc_fuel as m

    vclass = HAND[name][0]
    committed = json.loads((REPO / "docs" / "mc-fuel.json").read_text(encoding="utf-8"))
    assert committed["check"][name]["mass_kg"] == DEFAULT_MASS_KG[vclass]
    assert m.check_mass_kg(name) == DEFAULT_MASS_KG[vclass]


HAVE_CYCLES = (DATA / "cycles").is_dir()


@pytest.mark.shared_data
@pytest.mark.skipif(not HAVE_CYCLES, reason=f"shared cycles not found at {DATA}")
def test_motorcycle_fuel_on_a_commuting_cycle_within_published_range():
    """ADEME (2023) measured new Euro 4 and 5 motorcycles at 2.7–4.8 L/100 km on a commuting
    test cycle (town to motorway); on the WLTC class 3b (town to motorway), computed now at
    the plug-in's default motorcycle mass (285 kg), the chain lies in that range; on the
    cars' Willans slope 0.40 instead of the two-wheeler model's 0.24 it would not. (The
    urban traces alone land at the range's low end, 2.6–2.75: docs/mc-fuel.md.)"""
    from dataclasses import replace

    from sumo_drvpw.validation import mc_fuel as m

    eq = load_equation("moves_motorcycle_petrol")
    v = m.read_trace(DATA / "cycles", "wltc_3b")
    got = m.chain_run(eq, v, 285.0)["l_per_100km"]
    assert 2.7 <= got <= 4.8, got
    eq.chain = replace(eq.chain, marginal_efficiency=0.40)
    assert m.chain_run(eq, v, 285.0)["l_per_100km"] < 2.7


@pytest.mark.shared_data
@pytest.mark.skipif(not HAVE_CYCLES, reason=f"shared cycles not found at {DATA}")
def test_committed_report_is_regenerated():
    """docs/mc-fuel.json's check is what the module computes now (ours exactly, SUMO's tool
    to 1e-6), and docs/mc-fuel.md is the rendering of docs/mc-fuel.json."""
    from sumo_drvpw.validation import mc_fuel as m

    committed = json.loads((REPO / "docs" / "mc-fuel.json").read_text(encoding="utf-8"))
    assert (REPO / "docs" / "mc-fuel.md").read_text(encoding="utf-8") == m.render(committed), (
        "docs/mc-fuel.md is not the rendering of docs/mc-fuel.json: regenerate with "
        "python -m sumo_drvpw.validation.mc_fuel docs/mc-fuel.md")
    fresh = json.loads(json.dumps(m.check(DATA)))
    for name, r in committed["check"].items():
        assert fresh[name]["mass_kg"] == r["mass_kg"], name
        for cyc, row in r["cycles"].items():
            for who, val in row.items():
                got = fresh[name]["cycles"][cyc][who]
                if val is None or got is None:
                    continue
                assert got["l_per_100km"] == pytest.approx(val["l_per_100km"], rel=1e-6), (name, cyc, who)


def test_a_chain_that_books_nobody_says_nothing_of_its_calibration(tmp_path):
    """A chain's calibration warnings are about what it books: the moped chain in a run
    without mopeds (the built-in highway's cars) gives none (it was said in every run that
    listed it, as a bare config lists every built-in)."""
    pytest.importorskip("libsumo")
    from sumo_drvpw.sim import run_scenario

    s = run_scenario("highway", tmp_path / "o", end=30, equations=["moves_moped_petrol", "vsp_ldv1999"],
                     figures=False)
    assert not any(w.startswith("moves_moped_petrol") for w in s.summary["warnings"])
    assert not any(s.summary["equations"]["moves_moped_petrol"]["distance_m"].values())
