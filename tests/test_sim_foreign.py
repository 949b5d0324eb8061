"""Scenarios written as real public SUMO scenarios write them, unlike the bundled ones: the
ballistic position update, vTypes in ``<include href>``d files, SUMO's own default vTypes,
the vehicle files SUMO ships for its MMPEVEM model, a run without vehicles. Each was found
by a sweep of hand-built scenarios (live run against its FCD replay) and each test failed
before its fix."""

from __future__ import annotations

import json
import re
import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import sumolib

from sumo_drvpw.model.equations import Equation
from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd
from test_sim_run import WEST, _city_config, _run_summary

pytestmark = pytest.mark.sumo

REPO = Path(__file__).resolve().parent.parent
CITY = REPO / "scenarios" / "city.toml"
PHYS = Equation("phys", {"acc": 1.0, "grade": 1.0, "aero_rho": 0.25 * 2.23, "roll": 0.01})
COLS = ["traction_total_j", "recup_total_j", "traction_aero_j", "traction_roll_j", "distance_m"]


def _totals(res) -> pd.Series:
    return res.vehicles[COLS].sum()


def test_fcd_replays_the_ballistic_update_as_the_live_run(tmp_path):
    """Under --step-method.ballistic SUMO moves a car by the mean of the step's two speeds;
    the live run books the drag and rolling terms at that speed. The replay used to take
    every FCD as Euler (its connection had no getOption): at 1-s steps its traction came out
    about 1 % high. Now it reads the recording's header, else the scenario's options."""
    fcd = tmp_path / "fcd.xml"
    live = run_scenario(CITY, None, end=200, step_length=1.0, equations=[PHYS], figures=False,
                        options=["--step-method.ballistic", "true", "--fcd-output", str(fcd),
                                 "--precision", "6"])
    assert live.summary["step_method"] == "ballistic"
    euler = run_scenario(CITY, None, end=200, step_length=1.0, equations=[PHYS], figures=False)
    assert euler.summary["step_method"] == "euler"
    a = _totals(live)
    # the header SUMO wrote says ballistic; the scenario itself does not
    rep = process_fcd(fcd, scenario=CITY, equations=[PHYS], end=200, step_length=1.0,
                      figures=False)
    assert rep.summary["step_method"] == "ballistic"
    np.testing.assert_allclose(_totals(rep), a, rtol=1e-4)
    # without the header, the scenario's SUMO options say it (a flag without a value)
    bare = tmp_path / "bare.xml"
    bare.write_text(re.sub(r"<!--.*?-->", "", fcd.read_text(encoding="utf-8"), count=1, flags=re.S), encoding="utf-8")
    rep = process_fcd(bare, scenario=CITY, equations=[PHYS], end=200, step_length=1.0,
                      figures=False, options=["--step-method.ballistic"])
    assert rep.summary["step_method"] == "ballistic"
    np.testing.assert_allclose(_totals(rep), a, rtol=1e-4)
    # and neither saying it: the rows tell (sim/fcd_method.py), and the replay says so;
    # before, SUMO's default, Euler, was taken — off by more than the tolerance above
    rep = process_fcd(bare, scenario=CITY, equations=[PHYS], end=200, step_length=1.0,
                      figures=False)
    assert rep.summary["step_method"] == "ballistic"
    assert any("replayed as ballistic" in w for w in rep.summary["warnings"])
    np.testing.assert_allclose(_totals(rep), a, rtol=1e-4)


def test_vtypes_in_included_files_and_sumo_default_types(tmp_path, capsys):
    """A vType declared in a file the additional file <include href>s was not read (its
    mass became the class default, its emissionClass SUMO's petrol one); SUMO's own
    DEFAULT_BIKETYPE and DEFAULT_RAILTYPE were booked as cars by the FCD replay (it has no
    SUMO to ask their vClass). Live and replay now book the same vehicles and energy."""
    sc = tmp_path / "sc"
    (sc / "types").mkdir(parents=True)
    (sc / "types" / "diesel.add.xml").write_text(
        '<additional><vType id="heavy" vClass="passenger" mass="2500" '
        'emissionClass="HBEFA4/PC_diesel_Euro-6ab"/></additional>\n', encoding="utf-8")
    (sc / "top.add.xml").write_text('<additional><include href="types/diesel.add.xml"/></additional>\n', encoding="utf-8")
    cfg = _city_config(sc, "", [("h", "heavy", WEST), ("b", "DEFAULT_BIKETYPE", WEST),
                                ("c", "DEFAULT_VEHTYPE", WEST)])
    cfg.write_text(cfg.read_text(encoding="utf-8").replace(
        '<route-files value="r.rou.xml"/>',
        '<route-files value="r.rou.xml"/><additional-files value="top.add.xml"/>'), encoding="utf-8")
    s, _ = _run_summary(cfg, tmp_path / "live", capsys)
    veh = pd.read_parquet(tmp_path / "live" / "vehicles.parquet")
    h = veh[veh.vehicle == "h"]  # (a MOVES equation books its own source mass: its row says so)
    assert set(h[~h.equation.str.startswith("moves_")].mass_kg) == {2500.0}
    assert set(h[h.equation.str.startswith("moves_")].mass_kg) == {1478.8}
    assert s["assumptions"]["energy_carrier"]["heavy"]["carrier"] == "diesel"
    assert set(veh.vehicle) == {"h", "c"}  # the bicycle is not a car
    fcd = tmp_path / "fcd.xml"
    subprocess.run([sumolib.checkBinary("sumo"), "-c", str(cfg), "--fcd-output", str(fcd),
                    "--precision", "6", "--no-step-log"], check=True, capture_output=True)
    rep = process_fcd(fcd, scenario=cfg, figures=False, out_dir=tmp_path / "rep")
    assert rep.summary["skipped"]["by_vclass"] == s["skipped"]["by_vclass"] == {"bicycle": 1}
    a = veh.groupby(["vehicle", "equation"])[COLS].sum()
    b = rep.vehicles.groupby(["vehicle", "equation"])[COLS].sum()
    pd.testing.assert_frame_equal(b, a, rtol=1e-4)
    ch = [pd.read_csv(tmp_path / d / "chain_vehicles.csv").set_index(["key", "equation"])
          for d in ("live", "rep")]
    assert ("h", "epa_diesel_car") in ch[0].index and ("h", "epa_gasoline_car") not in ch[0].index
    pd.testing.assert_frame_equal(ch[1], ch[0], rtol=1e-4)


def test_sumo_shipped_mmpevem_vehicle_is_electric(tmp_path, capsys):
    """Every vehicle file SUMO ships for its MMPEVEM model writes the bare
    emissionClass="MMPEVEM": such cars were booked as petrol cars (litres and CO₂ for a BMW
    i3). SUMO's own BMW_i3.xml now makes them electric: the battery chain books them, and
    ``vtype_energy`` (among the plug-in's own equations) by their MMPEVEM parameters."""
    import sumo

    i3 = Path(sumo.SUMO_HOME) / "data" / "emissions" / "MMPEVEM" / "BMW_i3.xml"
    assert 'emissionClass="MMPEVEM"' in i3.read_text(encoding="utf-8")
    sc = tmp_path / "sc"
    sc.mkdir()
    cfg = _city_config(sc, "", [("e", "BMW_i3", WEST)])
    cfg.write_text(cfg.read_text(encoding="utf-8").replace(
        '<route-files value="r.rou.xml"/>', f'<route-files value="{i3},r.rou.xml"/>'), encoding="utf-8")
    s, _ = _run_summary(cfg, tmp_path / "o", capsys)
    assert s["assumptions"]["energy_carrier"]["BMW_i3"]["carrier"] == "electricity"
    ch = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv")
    assert list(ch.equation) == ["bmw_i3_battery", "vtype_energy.BMW_i3"] and (ch.net_kwh > 0).all()
    assert "fuel_l" not in ch.columns


def test_a_run_without_vehicles_writes_whole_tables(tmp_path, capsys):
    """A config whose route file holds no vehicle: every table has its header (the chain
    CSVs were a bare newline, which pandas cannot read)."""
    sc = tmp_path / "sc"
    sc.mkdir()
    cfg = _city_config(sc, "", [])
    s, _ = _run_summary(cfg, tmp_path / "o", capsys)
    assert s["vehicles"] == 0
    for name in ("chain_vehicles", "chain_edges", "chain_classes"):
        df = pd.read_csv(tmp_path / "o" / f"{name}.csv")
        assert len(df) == 0 and {"key", "equation", "fuel_l", "net_kwh"} <= set(df.columns)
    assert json.loads((tmp_path / "o" / "manifest.json").read_text(encoding="utf-8"))


def test_streamed_replay_keeps_a_vehicle_missing_for_a_teleport(tmp_path):
    """SUMO writes no FCD row for a teleporting vehicle; the live run keeps it in its
    vehicle list and books on from where SUMO puts it back. The streamed replay took such a
    vehicle as arrived and, when it came back, as a new trip of the same id (its own row).
    It now goes on as the same trip, as in the whole-file replay, which arrives a vehicle
    only after its last row."""
    fcd = tmp_path / "fcd.xml"
    run_scenario(CITY, None, end=120, equations=[PHYS], figures=False,
                 options=["--fcd-output", str(fcd), "--precision", "6"])
    from sumo_drvpw.sim.fcd import read_fcd

    df = read_fcd(fcd)
    veh = df[~df["person"]].set_index(["id", "time"])["speed"]
    gain = (veh.groupby(level=0).shift(-5) - veh).dropna()  # over the gap's 2.5 s
    vid, t0 = gain[gain.index.get_level_values(1) > 20].idxmax()  # speeding up across it
    assert gain[(vid, t0)] > 2.0
    gap = (df.id == vid) & (df.time > t0) & (df.time <= t0 + 2.0)  # 4 steps of 0.5 s
    cut = df[~gap]
    cols = {"time": "timestep_time", "id": "vehicle_id", "type": "vehicle_type",
            "speed": "vehicle_speed", "lane": "vehicle_lane", "pos": "vehicle_pos",
            "angle": "vehicle_angle", "slope": "vehicle_slope", "x": "vehicle_x", "y": "vehicle_y"}
    csv = tmp_path / "teleport.csv"
    cut[list(cols)].rename(columns=cols).to_csv(csv, index=False)
    whole = process_fcd(csv, scenario=CITY, equations=[PHYS], end=120, figures=False,
                        chunk_rows=None).vehicles.set_index("vehicle").sort_index()
    streamed = process_fcd(csv, scenario=CITY, equations=[PHYS], end=120, figures=False,
                           chunk_rows=500).vehicles.set_index("vehicle").sort_index()
    assert streamed.index.is_unique and list(streamed.index) == list(whole.index)
    pd.testing.assert_frame_equal(streamed[COLS + ["traction_acc_j"]],
                                  whole[COLS + ["traction_acc_j"]], rtol=1e-9)


def test_a_default_action_step_length_makes_sumo_ballistic(tmp_path):
    """SUMO switches to the ballistic update when a config sets
    default.action-step-length and leaves step-method.ballistic alone ("Integration method
    was set to 'ballistic' …"), while getOption("step-method.ballistic") still reads false:
    the run booked such scenarios (DLR's Doerpfeldstraße with a 1-s action step) as Euler,
    per vehicle up to 17 % off. Live run and replay now follow SUMO's rule; a given false
    keeps Euler."""
    from sumo_drvpw.sim.sumo_start import ballistic_update

    assert ballistic_update(None, "1") and ballistic_update("true", None)
    assert not ballistic_update("false", "1") and not ballistic_update(None, "0")
    kw = dict(end=200, step_length=0.5, equations=[PHYS], figures=False)
    fcd = tmp_path / "fcd.xml"
    action = run_scenario(CITY, None, options=["--default.action-step-length", "1",
                                               "--fcd-output", str(fcd), "--precision", "6"], **kw)
    explicit = run_scenario(CITY, None, options=["--default.action-step-length", "1",
                                                 "--step-method.ballistic", "true"], **kw)
    euler = run_scenario(CITY, None, options=["--default.action-step-length", "1",
                                              "--step-method.ballistic", "false"], **kw)
    assert action.summary["step_method"] == explicit.summary["step_method"] == "ballistic"
    assert euler.summary["step_method"] == "euler"
    np.testing.assert_allclose(_totals(action), _totals(explicit), rtol=1e-12)
    assert action.ledger.position_mismatches == 0
    rep = process_fcd(fcd, scenario=CITY, **kw)  # its header names the action step alone
    assert rep.summary["step_method"] == "ballistic"
    np.testing.assert_allclose(_totals(rep), _totals(action), rtol=1e-4)
