"""The heavy-duty diesel fuel chains (sumo_drvpw/validation/hdv_fuel.py, docs/hdv-fuel.md).

By hand: each built-in books P_fuel = P_idle + (max(P, 0)/η_d + P_aux)/η_e at a few (P, v),
and nothing while rolling with P < 0 (overrun fuel cut-off),
with the sourced numbers written out here (idle in US gal/h, 10 kW of accessories, the
engine's 0.45, the driveline's 0.85 or 0.80) on the road load of its MOVES type. A bare SUMO
config books trucks and buses in litres (the warning that no chain applies is gone), an
electric bus is not booked by the diesel chain, and per vehicle the litres are the hand
formula over its booked time and traction. The committed report is what the module
computes (shared cycles; skipped without them).
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
LHV, RHO = 43.1e6, 0.832            # diesel [J/kg], [kg/L] (docs/sources.md, Fuels)
GAL_H = 3.785411784 / 3600 * RHO * LHV   # W of fuel per US gal/h

#: name → (MOVES base, vClasses, idle gal/h, driveline η_d)
HAND = {
    "moves_single_unit_truck_diesel": ("moves_single_unit_truck", ("truck", "army"), (0.59 + 0.84) / 2, 0.85),
    "moves_combination_truck_diesel": ("moves_combination_truck", ("trailer",), 0.49, 0.80),
    "moves_transit_bus_diesel": ("moves_transit_bus", ("bus",), 0.97, 0.85),
    "moves_intercity_bus_diesel": ("moves_intercity_bus", ("coach",), 0.49, 0.80),
}


@pytest.mark.parametrize("name", sorted(HAND))
def test_builtin_books_fuel_by_hand(name):
    base, vclasses, gal_h, eta_d = HAND[name]
    eq, mv = load_equation(name), load_equation(base)
    assert eq.terms == mv.terms and tuple(eq.vclasses) == vclasses
    ch = eq.chain
    assert ch.predicts == "fuel" and ch.fuel == "diesel" and ch.engine_off_below_w == -np.inf
    p = np.array([-40000.0, 0.0, 30000.0, 150000.0, -5000.0])
    v = np.array([8.0, 0.0, 10.0, 22.0, 0.0])
    got = ch.evaluate(p, v, dt_s=2.0)
    idle = gal_h * GAL_H
    # overrun (rolling at P < 0, the first sample): injection cut, no fuel; standing: idles
    fuelled = np.array([0.0, 1.0, 1.0, 1.0, 1.0])
    want_w = fuelled * (idle + (np.maximum(p, 0.0) / eta_d + 10000.0) / 0.45)
    assert ch.fuel_cut_below_w == 0.0 and got["power_w"][0] == 0.0
    assert got["power_w"] == pytest.approx(want_w, rel=1e-4)
    assert got["fuel_l"] == pytest.approx(want_w * 2.0 / LHV / RHO, rel=1e-4)
    assert got["co2_kg"] == pytest.approx(want_w * 2.0 / LHV * 3.158, rel=1e-3)
    # standing: the measured idle plus the accessories, e.g. 0.97 gal/h + 10 kW/0.45 for a bus
    assert got["fuel_l"][1] / 2.0 * 3600 == pytest.approx((gal_h * 3.785411784 + 10000 / 0.45 * 3600 / LHV / RHO),
                                                          rel=1e-4)
    # the road load is the MOVES type's: 1000·C·v³ + (1000·A/M)·m·v at 10 m/s, flat, steady
    from sumo_drvpw.model.terms import Inputs
    one = np.ones(1)
    x = Inputs(v=10 * one, a=0 * one, theta=0 * one, wind=0 * one, mass=mv.provenance["source_mass_t"] * 1000 * one,
               rho=1.2041 * one)
    a_kw, c_kw = mv.provenance["rolling_term_A_kW_s_per_m"], mv.provenance["drag_term_C_kW_s3_per_m3"]
    assert eq.power(x)[0] == pytest.approx(1000 * a_kw * 10 + 1000 * c_kw * 1000, rel=1e-6)


def test_builtins_are_what_the_module_writes():
    """The four TOML files are :func:`builtin_doc` exactly, with a reading and a source for
    every chain parameter."""
    from sumo_drvpw.model.equations import equation_from_dict
    from sumo_drvpw.validation import hdv_fuel as h

    assert set(h.CHAINS) == set(HAND)
    for name in h.CHAINS:
        want = equation_from_dict(h.builtin_doc(name), f"<{name}>").to_dict()
        assert load_equation(name).to_dict() == want, f"{name}: regenerate with python -m sumo_drvpw.validation.hdv_fuel"
        reading = load_equation(name).chain.reading
        for key in ("traction_efficiency", "marginal_efficiency", "idle_fuel_power_w", "aux_power_w"):
            assert "[" in reading[key] or "ESTIMATE" in reading[key], (name, key)


def _config(folder: Path) -> Path:
    """The mixed-class bare config: trucks, buses, a coach, an electric bus and a car that
    write no emissionClass but the electric bus (test_sim_run's city config helper)."""
    from test_sim_run import EAST, WEST, _city_config

    vtypes = """\
    <vType id="lkw" vClass="truck" guiShape="truck"/>
    <vType id="semi" vClass="trailer"/>
    <vType id="bus" vClass="bus"/>
    <vType id="ebus" vClass="bus" emissionClass="Energy/unknown"/>
    <vType id="coach" vClass="coach"/>
    <vType id="car" vClass="passenger" mass="1400"/>
"""
    veh = [("t", "lkw", WEST), ("s", "semi", EAST), ("b", "bus", WEST), ("e", "ebus", EAST),
           ("c", "coach", WEST), ("p", "car", EAST)]
    return _city_config(folder, vtypes, veh, end="150")


def test_bare_config_books_trucks_and_buses_in_litres(tmp_path, capsys):
    """A bare SUMO config (the Hamburg case in small: trucks and buses that write no
    emissionClass, SUMO's default diesel): each is booked by its MOVES type's diesel chain,
    per vehicle exactly P_idle·T_f + E_traction/(η_d·η_e) + P_aux·T_f/η_e, T_f the booked time
    not rolling in overrun (from the run's trace); an electric bus
    (Energy/unknown) is not booked by the diesel chain, and it alone is in the warning."""
    pytest.importorskip("libsumo")
    from sumo_drvpw.cli import main as cli_main

    sc = tmp_path / "sc"
    sc.mkdir()
    out = tmp_path / "o"
    code = cli_main(["run", str(_config(sc)), "--out", str(out), "--no-figures", "--no-progress", "--trace"])
    err = capsys.readouterr().err
    assert code == 0, err
    veh = pd.read_parquet(out / "vehicles.parquet")
    fuel = pd.read_csv(out / "chain_vehicles.csv", dtype={"key": str})
    booked = dict(zip(fuel["key"], fuel["equation"]))
    assert booked["t"] == "moves_single_unit_truck_diesel" and booked["s"] == "moves_combination_truck_diesel"
    assert booked["b"] == "moves_transit_bus_diesel" and booked["c"] == "moves_intercity_bus_diesel"
    assert booked["p"] == "epa_gasoline_car" and "e" not in booked
    trace = pd.read_parquet(out / "trace.parquet")
    cut = 0
    for vid, name in booked.items():
        if name not in HAND:
            continue
        _, _, gal_h, eta_d = HAND[name]
        r = veh[(veh.vehicle == vid) & (veh.equation == name)].iloc[0]
        t = trace[(trace.vehicle == vid) & (trace.equation == name)]
        p, dt = t.p_total_w.to_numpy(), 0.5  # the config's step length
        assert (np.maximum(p, 0) * dt).sum() == pytest.approx(r.traction_total_j, rel=1e-9)
        fuelled = (p >= 0) | (t.speed_mps.to_numpy() <= 0.1)   # not rolling in overrun
        cut += int((~fuelled).sum())
        want = ((gal_h * GAL_H + 10000.0 / 0.45) * dt * fuelled.sum()
                + r.traction_total_j / (eta_d * 0.45))
        got = fuel[(fuel.key == vid) & (fuel.equation == name)].iloc[0]
        assert got.fuel_kwh * 3.6e6 == pytest.approx(want, rel=1e-6) and got.fuel_l > 0
    assert cut > 0  # the heavy vehicles did roll in overrun: the cut was exercised
    cls = pd.read_csv(out / "chain_classes.csv").set_index("key")
    assert {"truck", "trailer", "bus", "coach"} <= set(cls.index)
    assert list(cls.index) == sorted(cls.index)  # by class name (was: order of first departure)
    assert cls.loc["bus", "fuel_l"] == pytest.approx(fuel[fuel.key == "b"].fuel_l.sum(), rel=1e-9)
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["assumptions"]["energy_carrier"]["ebus"]["carrier"] == "electricity"
    assert "moves_transit_bus_diesel" in summary["assumptions"]["energy_carrier"]["ebus"]["not_booked_by"]
    assert "no battery or fuel chain applies to 1 bus vehicle(s)" in err and "truck" not in err.split(
        "no battery or fuel chain applies to")[1].split("vehicle(s)")[0]


HAVE_CYCLES = (DATA / "cycles").is_dir()


@pytest.mark.shared_data
@pytest.mark.skipif(not HAVE_CYCLES, reason=f"shared cycles not found at {DATA}")
def test_committed_report_is_regenerated():
    """docs/hdv-fuel.json's check is what the module computes now (ours exactly, SUMO's
    tool to 1e-6), and docs/hdv-fuel.md is the rendering of docs/hdv-fuel.json."""
    from sumo_drvpw.validation import hdv_fuel as h
    from sumo_drvpw.validation.hdv_fuel_report import render

    committed = json.loads((REPO / "docs" / "hdv-fuel.json").read_text(encoding="utf-8"))
    assert (REPO / "docs" / "hdv-fuel.md").read_text(encoding="utf-8") == render(committed), (
        "docs/hdv-fuel.md is not the rendering of docs/hdv-fuel.json: regenerate with "
        "python -m sumo_drvpw.validation.hdv_fuel docs/hdv-fuel.md")
    fresh = json.loads(json.dumps(h.check(DATA)))
    for name, r in committed["check"].items():
        for cyc, row in r["cycles"].items():
            for who, val in row.items():
                got = fresh[name]["cycles"][cyc][who]
                if val is None or got is None:   # SUMO's tool absent on one side
                    continue
                assert got["l_per_100km"] == pytest.approx(val["l_per_100km"], rel=1e-6), (name, cyc, who)


def test_equation_option_replacing_the_class_equations_says_so(tmp_path, capsys):
    """--equation replaces a bare config's class equations: the trucks and buses it leaves
    unbooked are named with that reason (a newcomer saw them dropped silently)."""
    pytest.importorskip("libsumo")
    from sumo_drvpw.cli import main as cli_main

    sc = tmp_path / "sc"
    sc.mkdir()
    cfg = _config(sc)
    assert cli_main(["run", str(cfg), "--out", str(tmp_path / "a"), "--no-figures", "--no-progress",
                     "--end", "20", "--equation", "vsp_ldv1999"]) == 0
    out = capsys.readouterr().out
    assert "not booked (no equation for the vClass)" in out and "with --equation only the equations given are applied" in out
    # each vClass left out is told the built-ins made for it (a bus was told a truck's)
    assert "bus: moves_transit_bus, moves_transit_bus_diesel" in out
    assert "trailer: moves_combination_truck, moves_combination_truck_diesel" in out
    assert "bus: moves_single_unit_truck" not in out
    assert cli_main(["run", str(cfg), "--out", str(tmp_path / "b"), "--no-figures", "--no-progress",
                     "--end", "20"]) == 0
    assert "with --equation only" not in capsys.readouterr().out


def test_persons_are_counted_apart_not_as_a_vclass_without_an_equation(capsys):
    """A run's persons (walking or riding) are never booked themselves: the console counts
    them on their own line, not as 'pedestrian' among the vClasses no equation is made for
    (a rehearsal on a PRT scenario read its 30 riders as a missing equation)."""
    from sumo_drvpw.cli.run import _print_summary

    _print_summary({"steps": 10, "vehicles": 2, "slope_corrected_samples": 0, "equations": {},
                    "skipped": {"by_vclass": {"pedestrian": 30}}}, "out", replaced=True)
    out = capsys.readouterr().out
    assert "persons (walking or riding; never booked themselves): 30" in out
    assert "not booked" not in out and "pedestrian" not in out


def test_a_failing_sumo_tool_is_one_line(tmp_path):
    """The check runs SUMO's emissionsDrivingCycle; a class that SUMO lacks (or any failure
    of the tool) was a CalledProcessError traceback: now one line with SUMO's own error."""
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.validation.chain_sumo import sumo_tool
    from sumo_drvpw.validation.hdv_fuel import sumo_l_per_100km

    if sumo_tool("emissionsDrivingCycle") is None:
        pytest.skip("SUMO's emissionsDrivingCycle not found")
    with pytest.raises(UserError, match=r"emissionsDrivingCycle with HBEFA4/NoSuchClass: exit \d+: Error"):
        sumo_l_per_100km("HBEFA4/NoSuchClass", np.linspace(0.0, 10.0, 20), tmp_path)


def test_cold_starts_say_which_chains_book_the_trips_warm(tmp_path, capsys):
    """Rehearsal on MoST: with --cold-start every car's trip took its cold-start litres, the
    buses, trucks and coaches printed 'cold starts 0.00 L' and nothing said why (their
    chains carry no cold-start fuel). Now a warning names them; and --cold-start beside a
    --cold-start-share of another value (the share silently won) is refused."""
    pytest.importorskip("libsumo")
    from sumo_drvpw.cli import main as cli_main

    sc = tmp_path / "sc"
    sc.mkdir()
    cfg = _config(sc)
    assert cli_main(["run", str(cfg), "--out", str(tmp_path / "o"), "--no-figures", "--no-progress",
                     "--cold-start"]) == 0
    err = capsys.readouterr().err
    line = next(ln for ln in err.splitlines() if "cold starts asked for" in ln)
    for name in ("moves_single_unit_truck_diesel", "moves_combination_truck_diesel", "moves_transit_bus_diesel",
                 "moves_intercity_bus_diesel"):
        assert name in line
    assert "epa_gasoline_car" not in line  # it books its cold start
    cls = pd.read_csv(tmp_path / "o" / "chain_classes.csv").set_index("key")
    assert cls.loc["passenger", "cold_start_l"] > 0 and cls.loc["truck", "cold_start_l"] == 0
    assert cli_main(["run", str(cfg), "--out", str(tmp_path / "o2"), "--cold-start",
                     "--cold-start-share", "0.5"]) == 2
    assert "say different things" in capsys.readouterr().err
    assert not (tmp_path / "o2").exists()


@pytest.mark.skipif(not HAVE_CYCLES, reason=f"shared cycles not found at {DATA}")
def test_the_measured_trucks_section_survives_regeneration(tmp_path, monkeypatch):
    """docs/hdv-fuel.json's ``measured`` (the chain on two measured trucks, made by hand: the
    logs are not in the shared data) is kept when the report is regenerated, as the Hamburg
    run's litres are, and rendered with its commands."""
    from sumo_drvpw.validation import hdv_fuel as h

    committed = json.loads((REPO / "docs" / "hdv-fuel.json").read_text(encoding="utf-8"))
    out = tmp_path / "hdv.md"
    out.with_suffix(".json").write_text(json.dumps(committed), encoding="utf-8")
    monkeypatch.setattr(h, "write_builtins", lambda *a, **k: [])  # (the package's files stay as they are)
    assert h.main([str(out), str(DATA)]) == 0
    res = json.loads(out.with_suffix(".json").read_text(encoding="utf-8"))
    assert res["measured"] == committed["measured"]
    md = out.read_text(encoding="utf-8")
    assert "## Measured: two class-8 tractors" in md and committed["measured"]["compare"] in md


@pytest.mark.skipif(not HAVE_CYCLES, reason=f"shared cycles not found at {DATA}")
def test_a_study_without_a_measured_section_gains_none(tmp_path):
    """The studies sharing study_main (mc-fuel, hdv-hybrid) keep their JSON as it was: no
    empty 'measured' key is written where none was."""
    from sumo_drvpw.validation.hdv_fuel import study_main

    out = tmp_path / "study.md"
    out.with_suffix(".json").write_text(json.dumps({"run": {"km": 1.0}}), encoding="utf-8")
    args = (str(out), str(DATA))
    assert study_main(args, "m", "x.md", "RUN", "run", lambda d: {}, None, lambda r: "report\n", lambda: None) == 0
    res = json.loads(out.with_suffix(".json").read_text(encoding="utf-8"))
    assert "measured" not in res and res["run"] == {"km": 1.0}


def test_the_measured_trucks_table_is_rendered_from_the_json():
    """The measured trucks' figures (made by hand, kept in docs/hdv-fuel.json ``measured``) are
    the JSON's: a group's litres, errors and the masses changed there change the table, and the
    committed JSON renders the committed report's table."""
    from sumo_drvpw.validation.hdv_fuel_report import render

    res = json.loads((REPO / "docs" / "hdv-fuel.json").read_text(encoding="utf-8"))
    table = [x for x in render(res).splitlines() if x.startswith("| trips | n |")]
    assert table and table[0] in (REPO / "docs" / "hdv-fuel.md").read_text(encoding="utf-8")
    m = res["measured"]
    m["groups"][0].update(n=3, measured_l=12.3, booked_l=45.6, error_pct=271, trip_error_pct=[-1, 2])
    m["all"].update(error_pct=-9.9, trip_mean_abs_pct=7.5)
    m["mass_t"] = 31.5
    md = render(res)
    row = next(x for x in md.splitlines() if x.startswith(f"| {m['groups'][0]['trips']} |"))
    row = row.rstrip(" |")
    assert row.split(" | ")[1:7] == ["3", "12.3", "45.6", "+271 %", "−1 … +2 %", "−34 %"]
    assert "| **−9.9 %** | mean abs. 7.5 %" in md and "booked at 31.5 t [L]" in md
