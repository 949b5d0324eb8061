"""Containers riding a vehicle: SUMO's emission models add their mass to the vehicle that
carries them (EnergyParams::getTotalMass: mass + loading + the mass of its persons and
containers). A live run books it, read from the vehicle's container device
(``device.container.IDList``, each container's vType from the route files) at the same
events as riding persons (sim/riders.py); an FCD replay from the containers' rows, which
SUMO writes at their vehicle's x, y and speed (sim/fcd_conn.py)."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.sim import run_scenario
from sumo_probe import build_net, emitted_wh, energy_scenario

ROUTES = """<routes>
  <vType id="etruck" vClass="truck" mass="9000" emissionClass="Energy/unknown" containerCapacity="2">
    <param key="rotatingMass" value="400"/></vType>
  <vehicle id="t" type="etruck" depart="containerTriggered" departPos="15" departSpeed="0"><route edges="e"/></vehicle>
  <container id="k0" depart="0" departPos="20"><transport from="e" to="e" lines="t"/></container>
</routes>"""


def test_containers_are_booked_live_and_replayed(tmp_path):
    """A 9-t Energy-model truck carrying one container (SUMO's DEFAULT_CONTAINERTYPE, 1,500 kg
    in SUMO 1.28) 800 m at 0.5-s steps: booked 0.87 of SUMO's emission output, with a warning
    (measured 2026-11-27), live and replayed; now both book SUMO's electricity."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="800" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="14"/></edges>')
    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    energy_scenario(tmp_path, 100)
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    sumo_wh, nan = emitted_wh(tmp_path / "em.xml", 0.5)
    assert not nan
    cv = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv").set_index("key")
    assert cv.loc["t", "net_kwh"] * 1000.0 == pytest.approx(sumo_wh["t"], rel=2e-3)
    assert cli_main(["fcd", str(tmp_path / "fcd.xml"), "--scenario", str(tmp_path / "s.toml"),
                     "--out", str(tmp_path / "fcd"), "--no-figures"]) == 0
    rv = pd.read_csv(tmp_path / "fcd" / "chain_vehicles.csv").set_index("key")
    assert rv.loc["t", "net_kwh"] == pytest.approx(cv.loc["t", "net_kwh"], rel=1e-4)
    for out in ("o", "fcd"):
        s = json.loads((tmp_path / out / "summary.json").read_text(encoding="utf-8"))
        assert not any("container" in w for w in s["warnings"]), (out, s["warnings"])
        assert s["transportables"]["max_kg"] == 1500.0, out


def _replayed_as_live(d, sc, live_chain, live_summary, vehicles=("t", "u")) -> None:
    """The run's FCD (``d/fcd.xml``) replayed into ``d/fcd``: each vehicle's electricity that
    of the live run to 1e-4 (``live_chain``: its chain_vehicles table), and its riders' mass
    summary the live run's."""
    assert cli_main(["fcd", str(d / "fcd.xml"), "--scenario", str(sc), "--out", str(d / "fcd"), "--no-figures"]) == 0
    rv = pd.read_csv(d / "fcd" / "chain_vehicles.csv").set_index("key")
    for vid in vehicles:
        assert rv.loc[vid, "net_kwh"] == pytest.approx(live_chain.loc[vid, "net_kwh"], rel=1e-4), vid
    r = json.loads((d / "fcd" / "summary.json").read_text(encoding="utf-8"))
    assert r["transportables"] == live_summary["transportables"]


@pytest.mark.parametrize("connection", ["libsumo", "traci"])
def test_containers_of_their_own_types_loaded_and_unloaded_at_stops(tmp_path, connection):
    """A container of SUMO's default vType (1,500 kg) boarding at the truck's departure and one
    of a containerFlow (``kf.0``, of the files' vType 'box', 2,000 kg: its vType found by its
    flow's id) boarding on the way (SUMO 1.28 carries k0 from 0.5 s, k0 and kf.0 from 37 s,
    kf.0 alone from 126.5 s to 216 s): the truck's electricity equals SUMO's emission output,
    over libsumo and traci and replayed (0.965 of it before, with a warning)."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="800" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="14"/></edges>')
    (tmp_path / "r.rou.xml").write_text("""<routes>
  <vType id="etruck" vClass="truck" mass="9000" emissionClass="Energy/unknown" containerCapacity="3">
    <param key="rotatingMass" value="400"/></vType>
  <vType id="box" vClass="ignoring" mass="2000"/>
  <vehicle id="t" type="etruck" depart="containerTriggered" departPos="15" departSpeed="0"><route edges="e"/>
    <stop lane="e_0" endPos="400" duration="100"/></vehicle>
  <vehicle id="u" type="etruck" depart="0" departPos="5" departSpeed="0"><route edges="e"/></vehicle>
  <container id="k0" depart="0" departPos="20"><transport from="e" to="e" lines="t"/></container>
  <container id="k1" depart="0" departPos="20" type="box"><transport from="e" to="e" lines="t" arrivalPos="400"/></container>
  <containerFlow id="kf" begin="0" number="1" departPos="390" type="box"><transport from="e" to="e" lines="t"/></containerFlow>
</routes>""", encoding="utf-8")
    energy_scenario(tmp_path, 600)
    run_scenario(tmp_path / "s.toml", tmp_path / "o", connection=connection)
    sumo_wh, nan = emitted_wh(tmp_path / "em.xml", 0.5)
    assert not nan and set(sumo_wh) == {"t", "u"}
    cv = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv").set_index("key")
    for vid in ("t", "u"):
        assert cv.loc[vid, "net_kwh"] * 1000.0 == pytest.approx(sumo_wh[vid], rel=2e-3), vid
    s = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))
    assert s["transportables"]["max_kg"] == 3500.0  # k0 and kf.0 (the flow's box: 2,000 kg, not the default's)
    assert not any("container" in w for w in s["warnings"])
    # the replay reads the containers' rows (at their truck's x, y and speed) and books the same
    _replayed_as_live(tmp_path, tmp_path / "s.toml", cv, s)


def test_a_tabular_fcd_s_containers_are_read_as_the_xml_s(tmp_path):
    """SUMO's tabular FCD (CSV) writes a container in the vehicles' columns as it writes a
    person (an edge, no lane): the replay read it as a person riding in its truck, booked its
    mass (the 9-t truck +10 % in a rehearsal, 2026-11-29) and counted it among the persons,
    while saying containers are not booked. Now it equals the XML replay, which has no
    container rows."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="800" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="14"/></edges>')
    (tmp_path / "r.rou.xml").write_text(ROUTES.replace('<container id="k0"', '<vType id="box" vClass="ignoring" '
                                                       'mass="2000"/>\n  <container id="k0" type="box"'), encoding="utf-8")
    sc = energy_scenario(tmp_path, 100)
    run_scenario(sc, tmp_path / "o")  # its FCD in XML
    import subprocess

    import sumo  # SUMO's own binary writes the tabular FCD of the same run
    subprocess.run([f"{sumo.SUMO_HOME}/bin/sumo", "-n", str(tmp_path / "n.net.xml"), "-r", str(tmp_path / "r.rou.xml"),
                    "--end", "100", "--step-length", "0.5", "--precision", "6", "--no-warnings", "true",
                    "--fcd-output", str(tmp_path / "fcd.csv")], check=True, capture_output=True)
    assert "box" in (tmp_path / "fcd.csv").read_text(encoding="utf-8")
    rows = {}
    for name in ("fcd.xml", "fcd.csv"):
        assert cli_main(["fcd", str(tmp_path / name), "--scenario", str(sc), "--out", str(tmp_path / name[4:]),
                         "--no-figures"]) == 0
        s = json.loads((tmp_path / name[4:] / "summary.json").read_text(encoding="utf-8"))
        rows[name] = pd.read_parquet(tmp_path / name[4:] / "vehicles.parquet").set_index("vehicle").net_total_j
        assert s["transportables"]["max_kg"] == 2000.0, (name, s["transportables"])  # the box, no person
        assert s["source"]["riding_person_rows"] == 0 and s["skipped"]["by_vclass"].get("pedestrian") is None
    assert rows["fcd.csv"]["t"] == rows["fcd.xml"]["t"]


def test_riders_of_vtypes_without_a_mass_weigh_their_vclass_s_default_live_and_replayed(tmp_path):
    """SUMO gives a vType without a mass its vClass's default (SUMOVTypeParameter::
    VClassDefaultValues: a truck 4,500 kg, a trailer 13,000 kg; a vType without a vClass is a
    passenger's 1,500 kg, a person's too) and adds each rider's vType mass to its carrier
    (EnergyParams::getTotalMass). A live run reads SUMO's masses; the replay booked every
    container of the files at 1,500 kg and every person at 70 kg whatever its vType's
    vClass (a container of vClass truck on a 9-t truck, a person of a vType without a vClass
    on another: 0.789 and 0.872 of the live run's electricity, measured 2026-11-29). Now SUMO's
    masses, live and replayed, and the live run equals SUMO's emission output."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="800" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="14"/></edges>')
    (tmp_path / "r.rou.xml").write_text("""<routes>
  <vType id="etruck" vClass="truck" mass="9000" emissionClass="Energy/unknown" containerCapacity="2" personCapacity="2">
    <param key="rotatingMass" value="400"/></vType>
  <vType id="crate" vClass="truck"/>
  <vType id="rider"/>
  <vehicle id="t" type="etruck" depart="containerTriggered" departPos="15" departSpeed="0"><route edges="e"/></vehicle>
  <container id="k0" depart="0" departPos="20" type="crate"><transport from="e" to="e" lines="t"/></container>
  <vehicle id="u" type="etruck" depart="triggered" departPos="60" departSpeed="0"><route edges="e"/></vehicle>
  <person id="p0" depart="0" departPos="60" type="rider"><ride from="e" to="e" lines="u"/></person>
</routes>""", encoding="utf-8")
    sc = energy_scenario(tmp_path, 100)
    run_scenario(sc, tmp_path / "o")
    sumo_wh, nan = emitted_wh(tmp_path / "em.xml", 0.5)
    assert not nan
    cv = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv").set_index("key")
    for vid in ("t", "u"):
        assert cv.loc[vid, "net_kwh"] * 1000.0 == pytest.approx(sumo_wh[vid], rel=2e-3), vid
    s = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))
    assert s["transportables"]["max_kg"] == 4500.0  # SUMO's mass of the crate's vType
    _replayed_as_live(tmp_path, sc, cv, s)


def test_the_replay_s_vclass_masses_are_sumo_s(tmp_path):
    """The replay's table of SUMO's default masses per vClass is what SUMO gives a vType of
    that vClass without a mass (libsumo vehicletype.getMass), for every vClass SUMO knows, and
    for SUMO's own vTypes: a container's 1,500 kg, and DEFAULT_PEDTYPE redeclared without a
    vClass a passenger's 1,500 kg, not a pedestrian's 70."""
    import libsumo

    from sumo_drvpw.sim.vtypes import sumo_type_mass

    classes = ("passenger private taxi bus coach delivery truck trailer emergency motorcycle moped bicycle "
               "pedestrian wheelchair scooter tram rail_urban subway rail rail_electric rail_fast ship evehicle "
               "army authority vip hov custom1 custom2 container cable_car aircraft drone ignoring").split()
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="100" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="14"/></edges>')
    (tmp_path / "r.rou.xml").write_text("<routes>" + "".join(f'<vType id="{c}" vClass="{c}"/>' for c in classes)
                                        + '<vType id="DEFAULT_PEDTYPE" width="0.5"/></routes>', encoding="utf-8")
    libsumo.start(["sumo", "-n", str(tmp_path / "n.net.xml"), "-r", str(tmp_path / "r.rou.xml"),
                   "--no-step-log", "--no-warnings", "--end", "1"])
    try:
        sumo = {c: libsumo.vehicletype.getMass(c) for c in classes}
        sumo.update({t: libsumo.vehicletype.getMass(t) for t in ("DEFAULT_PEDTYPE", "DEFAULT_CONTAINERTYPE",
                                                                   "DEFAULT_BIKETYPE", "DEFAULT_RAILTYPE")})
    finally:
        libsumo.close()
    from sumo_drvpw.sim.vtypes import read_vtypes

    files = read_vtypes([tmp_path / "r.rou.xml"])
    ours = {vt: sumo_type_mass(files, vt) for vt in sumo}
    assert ours == sumo
    assert sumo["DEFAULT_PEDTYPE"] == 1500.0 and sumo["pedestrian"] == 70.0
    assert len(set(sumo.values())) > 10
