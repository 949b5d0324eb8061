"""edgedata.xml as a router's weights: an equation that booked nothing on an edge has no
attributes there (it wrote 0, which duarouter takes as a free edge: a rehearsal's trucks'
equation was 0 on 240-336 of about 560 Hamburg edges per interval), and the attributes
written still add up to the run's totals; one whose vehicles only stood there has its sums
and no per-vehicle figure. Real SUMO; duarouter reads the file (an edge without the
attribute costs its travel time there: docs/scenario.md on routing by energy)."""

from __future__ import annotations

import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario

pytestmark = pytest.mark.sumo

REPO = Path(__file__).resolve().parent.parent
NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"
CARS = "c00c10 c10c20 c20c30"   # the cars' route
TRUCKS = "c04c14 c14c24 c24c34"  # the trucks': no edge in common


def test_an_equation_with_no_vehicle_on_an_edge_writes_no_attributes_there(tmp_path):
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="car" vClass="passenger" mass="1400"/><vType id="lorry" vClass="truck" mass="9000"/>'
        f'<flow id="c" type="car" begin="0" end="60" period="10" departSpeed="0"><route edges="{CARS}"/></flow>'
        f'<flow id="t" type="lorry" begin="0" end="60" period="20" departSpeed="0"><route edges="{TRUCKS}"/></flow>'
        '</routes>\n', encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        'equations = ["vsp_ldv1999", "moves_single_unit_truck", "epa_gasoline_car", "moves_single_unit_truck_diesel"]\n'
        f'[sumo]\nnet = "{NET}"\nroutes = ["r.rou.xml"]\nbegin = 0\nend = 200\nstep_length = 1.0\n'
        'options = ["--no-warnings", "true"]\n[outputs]\nfigures = false\nedgedata = true\nperiod = 100\n',
        encoding="utf-8")
    res = run_scenario(tmp_path / "s.toml", tmp_path / "o")
    root = ET.parse(tmp_path / "o" / "edgedata.xml").getroot()
    edges = [(iv.get("begin"), e) for iv in root.iter("interval") for e in iv.iter("edge")]
    cars = {e.get("id") for _, e in edges if e.get("vsp_ldv1999_total_j") is not None}
    trucks = {e.get("id") for _, e in edges if e.get("moves_single_unit_truck_total_j") is not None}
    assert set(CARS.split()) <= cars and set(TRUCKS.split()) <= trucks and not cars & trucks
    for _, e in edges:  # each edge holds the attributes of the equations that booked it, chains included
        car, lorry = e.get("id") in cars, e.get("id") in trucks
        assert (e.get("vsp_ldv1999_total_perVeh_j") is not None) == car
        assert (e.get("epa_gasoline_car_fuel_l") is not None) == car
        assert (e.get("moves_single_unit_truck_total_perVeh_j") is not None) == lorry
        assert (e.get("moves_single_unit_truck_diesel_fuel_l") is not None) == lorry
    # what is written still adds up to the run's per-vehicle totals
    v = pd.read_parquet(tmp_path / "o" / "vehicles.parquet")
    for eq in ("vsp_ldv1999", "moves_single_unit_truck"):
        xml = sum(float(e.get(f"{eq}_total_j")) for _, e in edges if e.get(f"{eq}_total_j") is not None)
        assert xml == pytest.approx(v[v.equation == eq].traction_total_j.sum(), rel=1e-6)
    fuel = sum(float(e.get("moves_single_unit_truck_diesel_fuel_l") or 0) for _, e in edges)
    ch = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv")
    assert fuel == pytest.approx(ch[ch.equation == "moves_single_unit_truck_diesel"].fuel_l.sum(), rel=1e-5)
    # duarouter reads it as weights (an edge without the attribute: its travel time)
    import sumolib

    (tmp_path / "trip.xml").write_text(
        '<routes><vType id="lorry" vClass="truck"/><trip id="x" type="lorry" depart="0" from="c04c14" to="c24c34"/>'
        '</routes>\n', encoding="utf-8")
    r = subprocess.run([sumolib.checkBinary("duarouter"), "-n", str(NET), "-r", str(tmp_path / "trip.xml"),
                        "--weight-files", str(tmp_path / "o" / "edgedata.xml"),
                        "--weight-attribute", "moves_single_unit_truck_total_perVeh_j",
                        "-o", str(tmp_path / "routed.xml"), "--no-warnings"], capture_output=True, text=True)
    assert r.returncode == 0 and "<route edges=" in (tmp_path / "routed.xml").read_text(encoding="utf-8"), r.stderr
    assert res["vehicles"] > 0


def test_an_equation_whose_vehicles_only_stood_on_an_edge_writes_its_sums_and_no_per_vehicle_figure(tmp_path):
    """A car stands 200 s at a stop on its route's second edge, across 50-s intervals. Its
    equations' vehicles were there: each writes its sums (0 at the wheels for vsp_ldv1999;
    a standing constant, ``v^0`` = 500 W, books 500 W × the seconds stood), as the chain
    attributes (auxiliary energy) already were, and no ``_total_perVeh_j`` or
    ``_total_normed_jpm``, which scale by a distance driven there — none —, as SUMO's own
    traffic edgeData leaves out ``traveltime`` there (its emission edgeData on the same run:
    traveltime 100000, its maxTravelTime). Measured 2026-11-29 before the fix: no driving
    attribute of vsp_ldv1999 in those intervals beside the chain's, and for the equation with
    ``v^0`` a ``_total_perVeh_j`` of 0.000 (a free edge to duarouter). A trucks' equation, whose
    vehicles were elsewhere, writes nothing there; duarouter routes over the file."""
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="car" vClass="passenger" mass="1400" emissionClass="Energy/unknown"/>'
        '<vType id="lorry" vClass="truck" mass="9000"/>'
        f'<vehicle id="s" type="car" depart="0" departSpeed="0"><route edges="{CARS}"/>'
        '<stop lane="c10c20_0" endPos="150" duration="200"/></vehicle>'
        f'<flow id="t" type="lorry" begin="0" end="60" period="20" departSpeed="0"><route edges="{TRUCKS}"/></flow>'
        '</routes>\n', encoding="utf-8")
    (tmp_path / "standing.toml").write_text(
        '[equation]\nname = "standing"\ndescription = "a road load with a standing constant"\n'
        '[terms]\nacc = 1.0\nm_v1 = 0.1\n"v^0" = 500.0\n', encoding="utf-8")
    (tmp_path / "ed.add.xml").write_text(
        '<additional><edgeData id="tr" file="sumo_tr.xml" period="50"/></additional>\n', encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["vsp_ldv1999", "{tmp_path / "standing.toml"}", "vtype_energy", "moves_single_unit_truck"]\n'
        f'[sumo]\nnet = "{NET}"\nroutes = ["r.rou.xml"]\nadditional = ["ed.add.xml"]\nbegin = 0\nend = 300\n'
        'step_length = 1.0\noptions = ["--no-warnings", "true"]\n[outputs]\nfigures = false\nedgedata = true\n'
        'period = 50\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    root = ET.parse(tmp_path / "o" / "edgedata.xml").getroot()
    stood = [(iv.get("begin"), e) for iv in root.iter("interval") for e in iv.iter("edge")
             if e.get("id") == "c10c20" and float(iv.get("begin")) >= 50 and float(iv.get("end")) <= 200]
    assert len(stood) == 3
    # the premise: the car stood there all three intervals (SUMO's edgeData: no traveltime there)
    sumo = {iv.get("begin"): e for iv in ET.parse(tmp_path / "o" / "sumo" / "sumo_tr.xml").getroot().iter("interval")
            for e in iv.iter("edge") if e.get("id") == "c10c20"}
    for begin, e in stood:
        s = float(e.get("sampledSeconds"))
        assert s == pytest.approx(50.0) and float(sumo[begin].get("sampledSeconds")) == pytest.approx(50.0, abs=0.1)
        assert sumo[begin].get("traveltime") is None and float(sumo[begin].get("speed")) == 0.0
        for eq, total in (("vsp_ldv1999", 0.0), ("standing", 500.0 * s), ("vtype_energy.car", 0.0)):
            assert float(e.get(f"{eq}_total_j")) == pytest.approx(total, abs=1e-3), eq
            assert float(e.get(f"{eq}_other_j")) == pytest.approx(total, abs=1e-3) and e.get(f"{eq}_acc_j") == "0.000"
            assert e.get(f"{eq}_total_perVeh_j") is None and e.get(f"{eq}_total_normed_jpm") is None, eq
        assert float(e.get("vtype_energy.car_battery_auxiliary_kwh")) > 0
        assert not [k for k in e.attrib if k.startswith("moves_single_unit_truck")]
    # an edge driven on keeps its per-vehicle figure; the sums still add up to the run's totals
    driven = [e for _, e in ((iv.get("begin"), e) for iv in root.iter("interval") for e in iv.iter("edge"))
              if e.get("id") == "c00c10"]
    assert driven and all(float(e.get("vsp_ldv1999_total_perVeh_j")) > 0 for e in driven)
    v = pd.read_parquet(tmp_path / "o" / "vehicles.parquet")
    edges = [e for iv in root.iter("interval") for e in iv.iter("edge")]
    for eq in ("vsp_ldv1999", "standing"):
        xml = sum(float(e.get(f"{eq}_total_j")) for e in edges if e.get(f"{eq}_total_j") is not None)
        assert xml == pytest.approx(v[v.equation == eq].traction_total_j.sum(), rel=1e-6)
    import sumolib

    (tmp_path / "trip.xml").write_text(
        '<routes><vType id="car" vClass="passenger"/><trip id="x" type="car" depart="60" from="c00c10" to="c20c30"/>'
        '</routes>\n', encoding="utf-8")
    r = subprocess.run([sumolib.checkBinary("duarouter"), "-n", str(NET), "-r", str(tmp_path / "trip.xml"),
                        "--weight-files", str(tmp_path / "o" / "edgedata.xml"), "--weight-attribute",
                        "standing_total_perVeh_j", "-o", str(tmp_path / "routed.xml"), "--no-warnings"],
                       capture_output=True, text=True)
    assert r.returncode == 0 and "<route edges=" in (tmp_path / "routed.xml").read_text(encoding="utf-8"), r.stderr
