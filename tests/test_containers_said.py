"""Containers are not booked (their vehicle's load is not read): a run whose route files
define containers says so, since SUMO's emission models add their mass to the vehicle that
carries them (EnergyParams::getTotalMass) and such a vehicle then reads below SUMO's
emission output."""

from __future__ import annotations

import json

import pandas as pd

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.sim import run_scenario
from sumo_probe import build_net, emitted_wh, energy_scenario

ROUTES = """<routes>
  <vType id="etruck" vClass="truck" mass="9000" emissionClass="Energy/unknown" containerCapacity="2">
    <param key="rotatingMass" value="400"/></vType>
  <vehicle id="t" type="etruck" depart="containerTriggered" departPos="15" departSpeed="0"><route edges="e"/></vehicle>
  <container id="k0" depart="0" departPos="20"><transport from="e" to="e" lines="t"/></container>
</routes>"""


def test_containers_not_booked_are_said(tmp_path):
    """A 9-t Energy-model truck carrying one container 800 m at 0.5-s steps: booked 0.87 of
    SUMO's emission output (measured 2026-11-27), and, since this commit, the run and the FCD
    replay warn that containers are not booked (before: no word of it)."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="800" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="14"/></edges>')
    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    energy_scenario(tmp_path, 100)
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    sumo_wh, nan = emitted_wh(tmp_path / "em.xml", 0.5)
    assert not nan
    cv = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv").set_index("key")
    assert cv.loc["t", "net_kwh"] * 1000.0 < 0.95 * sumo_wh["t"]  # the container's mass is left out
    assert cli_main(["fcd", str(tmp_path / "fcd.xml"), "--scenario", str(tmp_path / "s.toml"),
                     "--out", str(tmp_path / "fcd"), "--no-figures"]) == 0
    for out in ("o", "fcd"):
        warnings = json.loads((tmp_path / out / "summary.json").read_text(encoding="utf-8"))["warnings"]
        assert any("1 container(s)" in w and "not booked" in w for w in warnings), (out, warnings)


def test_a_tabular_fcd_s_containers_are_not_read_as_riding_persons(tmp_path):
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
        assert s["transportables"] == {"samples": 0, "max_kg": 0.0}, (name, s["transportables"])
    assert rows["fcd.csv"]["t"] == rows["fcd.xml"]["t"]
