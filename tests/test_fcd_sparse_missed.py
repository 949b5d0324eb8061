"""FCD written every N s (``device.fcd.period``) has no row of a vehicle whose whole trip fell
between two rows: the replay cannot book it, and says how many of the route files' vehicles
declared to depart in the replayed window are in no row (or, where their ids cannot be
matched, that such vehicles may exist)."""

from __future__ import annotations

import json
import re

import pandas as pd

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.sim import run_scenario
from sumo_probe import build_net

ROUTES = """<routes>
  <vType id="car" vClass="passenger" mass="1500" emissionClass="Energy/unknown"/>
  <vType id="bus" vClass="bus" mass="12000" emissionClass="Energy/unknown"/>
  <route id="rl" edges="ab"/><route id="rs" edges="cd"/>
  <flow id="long" type="car" route="rl" begin="0" end="90" period="3" departSpeed="max"/>
  <flow id="short" type="car" route="rs" begin="0" end="90" period="2" departSpeed="max"/>
  <vehicle id="b1" type="bus" route="rs" depart="12" departSpeed="max"/>
  <vehicle id="b2" type="bus" route="rl" depart="13" departSpeed="max"/>
</routes>"""


def _run(tmp_path, *extra, sumo=""):
    """Long trips on a 200-m road, 3-s trips on a 40-m one, written every 5 s: the live run's
    and the replay's vehicles and the replay's warning of the sparse rows."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="200" y="0"/>'
              '<node id="c" x="0" y="50"/><node id="d" x="40" y="50"/></nodes>',
              '<edges><edge id="ab" from="a" to="b" numLanes="1" speed="15"/>'
              '<edge id="cd" from="c" to="d" numLanes="1" speed="15"/></edges>')
    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        'equations = ["vtype_energy"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["r.rou.xml"]\nend = 90\n'
        f'step_length = 1\noptions = ["--no-warnings", "true", {sumo}"--device.fcd.period", "5", '
        f'"--fcd-output", "{tmp_path / "fcd.xml"}"]\n[outputs]\nfigures = false\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    assert cli_main(["fcd", str(tmp_path / "fcd.xml"), "--net", str(tmp_path / "n.net.xml"), *extra,
                     "--equation", "vtype_energy", "--out", str(tmp_path / "f"), "--no-figures"]) == 0
    live = set(pd.read_parquet(tmp_path / "o" / "vehicles.parquet").vehicle)
    rep = set(pd.read_parquet(tmp_path / "f" / "vehicles.parquet").vehicle)
    warn = [w for w in json.loads((tmp_path / "f" / "summary.json").read_text(encoding="utf-8"))["warnings"]
            if "written every 5 s" in w]
    assert len(warn) == 1
    return live, rep, warn[0]


def test_the_vehicles_no_row_shows_are_counted(tmp_path):
    """Every vehicle the run inserted, the route files declared: the replay says as many are
    in no row as the live run booked and it did not (short trips that began and ended between
    two rows; before 2026-11-29 the warning said nothing of them)."""
    live, rep, warn = _run(tmp_path, "--vtypes", str(tmp_path / "r.rou.xml"))
    missed = len(live - rep)
    assert missed > 0 and rep <= live
    said = re.search(r"; (\d+) vehicles? the route files declare to depart from \S+ to \S+ s (are|is) in no row", warn)
    assert said, warn
    assert int(said.group(1)) == missed


def test_a_scaled_run_says_its_missed_vehicles_cannot_be_counted(tmp_path):
    """A run with SUMO's --scale names its added vehicles otherwise than the route files (and
    drops some at a scale below 1): the replay says such vehicles may be missing, and why it
    cannot count them, without a number."""
    live, rep, warn = _run(tmp_path, "--vtypes", str(tmp_path / "r.rou.xml"), sumo='"--scale", "2", ')
    assert len(live - rep) > 0
    assert "a vehicle whose whole trip fell between two rows is in none" in warn and "(scale 2)" in warn
    assert "the route files declare" not in warn
