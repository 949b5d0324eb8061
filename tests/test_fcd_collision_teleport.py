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


def _run_both(tmp_path, routes, end, exit_speed, in_speed):
    """The crossing with exits of ``exit_speed`` and approaches of ``in_speed`` [m/s], run live
    and replayed from its FCD: (live, replay) vehicles.parquet and summary.json teleports."""
    build_net(tmp_path, '<nodes><node id="w" x="-500" y="0"/><node id="c" x="0" y="0" type="priority"/>'
              '<node id="e" x="500" y="0"/><node id="s" x="0" y="-500"/><node id="n" x="0" y="500"/></nodes>',
              f'<edges><edge id="we" from="w" to="c" numLanes="1" speed="{in_speed}" priority="2"/>'
              f'<edge id="ce" from="c" to="e" numLanes="1" speed="{exit_speed}" priority="2"/>'
              f'<edge id="sc" from="s" to="c" numLanes="1" speed="{in_speed}" priority="1"/>'
              f'<edge id="cn" from="c" to="n" numLanes="1" speed="{exit_speed}" priority="1"/></edges>',
              "--no-turnarounds")
    (tmp_path / "r.rou.xml").write_text(routes, encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["vtype_energy"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["r.rou.xml"]\nend = {end}\n'
        'step_length = 1\noptions = ["--no-warnings", "true", "--precision", "6", "--collision.check-junctions", '
        f'"true", "--collision.action", "teleport", "--fcd-output", "{tmp_path / "fcd.xml"}"]\n'
        '[outputs]\nfigures = false\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    assert cli_main(["fcd", str(tmp_path / "fcd.xml"), "--net", str(tmp_path / "n.net.xml"), "--vtypes",
                     str(tmp_path / "r.rou.xml"), "--equation", "vtype_energy", "--end", str(end),
                     "--out", str(tmp_path / "f"), "--no-figures"]) == 0
    cols = ["net_total_j", "distance_m", "time_s", "teleports", "teleport_kinetic_j"]
    a = pd.read_parquet(tmp_path / "o" / "vehicles.parquet").set_index(["vehicle", "equation"])[cols]
    b = pd.read_parquet(tmp_path / "f" / "vehicles.parquet").set_index(["vehicle", "equation"])[cols]
    return a, b.loc[a.index]


def test_a_collisions_teleport_within_8_mps2_and_its_own_way_books_as_live(tmp_path):
    """Exits of 20 m/s, approaches of 15 (SUMO 1.28, 1-s steps, 240 steps): car c.62 collides
    on the junction at 13.7 m/s 1.6 m into it and is put on the next edge 5 m on at 18.1 m/s,
    4.4 m/s faster (its vType's accel is 2.6 m/s²) and nearer than 18.1 m: neither 8 m/s²
    faster nor farther than it could go, so before (2026-11-29) the replay booked the jump as
    driven (its net energy 1.255 of the live run's over 600 s, teleports 30 against 32; a
    side-road car put back from 6.7 at 13.8 m/s, 1.379). The gain beyond its vType's accel
    tells it: every vehicle's energy, distance, time and teleport count equal the live run's."""
    a, b = _run_both(tmp_path, ROUTES.replace('end="150"', 'end="240"'), 240, 20, 15)
    assert a.teleports.sum() >= 1
    pd.testing.assert_frame_equal(b, a, rtol=1e-6, atol=1.0, check_dtype=False)  # (1 J: 6-decimal speeds)


def test_hard_acceleration_across_junctions_is_driving(tmp_path):
    """Cars of an accel of 7 m/s² (below the 8 m/s² every vType is held to) and no collisions
    (nobody ignores a foe) cross the junction while accelerating hard from a standstill: the
    replay, which reads their vType's accel, books no placement, as the live run."""
    routes = """<routes>
  <vType id="quick" vClass="passenger" mass="1600" emissionClass="Energy/unknown" accel="7" decel="7" sigma="0"/>
  <route id="r1" edges="we ce"/><route id="r2" edges="sc cn"/>
  <flow id="c" type="quick" route="r1" begin="0" end="120" period="5" departSpeed="0" departPos="480"/>
  <flow id="x" type="quick" route="r2" begin="2" end="120" period="5" departSpeed="0" departPos="480"/>
</routes>"""
    a, b = _run_both(tmp_path, routes, 120, 30, 10)
    assert a.teleports.sum() == 0
    pd.testing.assert_frame_equal(b, a, rtol=1e-6, atol=1.0, check_dtype=False)  # (1 J: 6-decimal speeds)
