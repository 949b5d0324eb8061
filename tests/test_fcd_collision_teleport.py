"""A collision's teleport in an FCD replay: SUMO (``--collision.action teleport``, the default
action) takes a moving car off the junction it collided on and puts it back on the next edge
in the same step, which its FCD shows without a gap. The replay tells that placement from the
car's rows, as the live run hears of it from SUMO, and books it apart as the live run does."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.sim import run_scenario
from sumo_probe import build_net

ROUTES = """<routes>
  <vType id="ecar" vClass="passenger" mass="1600" emissionClass="Energy/unknown" sigma="0.5">
    <param key="airDragCoefficient" value="0.28"/>
  </vType>
  <vType id="rude" vClass="passenger" emissionClass="Energy/unknown" sigma="0.5" jmIgnoreFoeProb="1"
         jmIgnoreFoeSpeed="100" jmIgnoreJunctionFoeProb="1" impatience="1">
    <param key="frontSurfaceArea" value="2.2"/>
  </vType>
  <route id="r1" edges="we ce"/><route id="r2" edges="sc cn"/>
  <flow id="c" type="ecar" route="r1" begin="0" end="150" period="3" departSpeed="0"/>
  <flow id="x" type="rude" route="r2" begin="1" end="150" period="4" departSpeed="0"/>
</routes>"""


def _crossing(d):
    """A priority crossing of two 1-lane roads, 500 m each side."""
    build_net(d, '<nodes><node id="w" x="-500" y="0"/><node id="c" x="0" y="0" type="priority"/>'
              '<node id="e" x="500" y="0"/><node id="s" x="0" y="-500"/><node id="n" x="0" y="500"/></nodes>',
              '<edges><edge id="we" from="w" to="c" numLanes="1" speed="15" priority="2"/>'
              '<edge id="ce" from="c" to="e" numLanes="1" speed="15" priority="2"/>'
              '<edge id="sc" from="s" to="c" numLanes="1" speed="15" priority="1"/>'
              '<edge id="cn" from="c" to="n" numLanes="1" speed="15" priority="1"/></edges>', "--no-turnarounds")


def test_a_collisions_teleport_books_in_the_replay_as_live(tmp_path):
    """Side-road cars that ignore their foes collide on the junction (SUMO 1.28, 1-s steps,
    75 steps: at 54 s and 70 s, SUMO's log) and are put back on the next edge at its speed in
    the same step: from 8.1 m/s 20 m on (farther than the 13.8 m its new speed covers) and from
    5.3 to 14.3 m/s. The replay of the run's FCD counts both placements and their kinetic
    energy as the live run does, and every vehicle's net energy and distance equal the live
    run's to 1e-6. Before (2026-11-27) a moving car's placement was booked as driven, its jump
    in the acceleration term: those two cars' net energy 1.455 and 1.927 of the live run's, the
    teleports not counted (replay 0, live 2)."""
    _crossing(tmp_path)
    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        'equations = ["vtype_energy"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["r.rou.xml"]\nend = 75\n'
        'step_length = 1\noptions = ["--no-warnings", "true", "--precision", "6", "--collision.check-junctions", '
        f'"true", "--collision.action", "teleport", "--fcd-output", "{tmp_path / "fcd.xml"}"]\n'
        '[outputs]\nfigures = false\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    assert cli_main(["fcd", str(tmp_path / "fcd.xml"), "--net", str(tmp_path / "n.net.xml"), "--vtypes",
                     str(tmp_path / "r.rou.xml"), "--equation", "vtype_energy", "--end", "75",
                     "--out", str(tmp_path / "f"), "--no-figures"]) == 0
    live = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))["teleports"]
    rep = json.loads((tmp_path / "f" / "summary.json").read_text(encoding="utf-8"))["teleports"]
    assert live["count"] >= 2 and rep["count"] == live["count"]
    assert rep["kinetic_j"]["vtype_energy.rude"] == pytest.approx(live["kinetic_j"]["vtype_energy.rude"], rel=1e-6)
    cols = ["net_total_j", "distance_m", "time_s", "teleports", "teleport_kinetic_j"]
    a = pd.read_parquet(tmp_path / "o" / "vehicles.parquet").set_index(["vehicle", "equation"])[cols]
    b = pd.read_parquet(tmp_path / "f" / "vehicles.parquet").set_index(["vehicle", "equation"])[cols]
    assert (a.teleports > 0).sum() >= 2
    pd.testing.assert_frame_equal(b.loc[a.index], a, rtol=1e-6, check_dtype=False)
