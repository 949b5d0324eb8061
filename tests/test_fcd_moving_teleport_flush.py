"""A moving car's teleport that lasts steps: SUMO takes a car that collides on a junction off
the road (``--collision.action teleport``) and puts it back on the next edge once that edge has
room, writing no FCD rows meanwhile. The streamed replay writes finished vehicles out of memory
(Ledger.flush); it held only cars whose rows end standing (a jam's teleport), so a car whose
rows ended moving was flushed in its gap and booked again as a second trip. It now also holds
a car whose rows end off its route's last edge (sim/fcd_stops.may_return)."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd, read_fcd
from sumo_probe import build_net

pytestmark = pytest.mark.sumo

#: side-road cars that ignore their foes merge into the main road's exit: a car colliding on
#: the junction finds the exit's start taken by the car it hit and waits off the road
ROUTES = """<routes>
  <vType id="car" vClass="passenger" mass="1600" sigma="0.5"/>
  <vType id="rude" vClass="passenger" mass="1500" sigma="0.5" jmIgnoreFoeProb="1" jmIgnoreFoeSpeed="100"
         jmIgnoreJunctionFoeProb="1" impatience="1"/>
  <route id="r1" edges="we ce"/><route id="r2" edges="sc ce"/>
  <flow id="c" type="car" route="r1" begin="0" end="200" period="3" departSpeed="0"/>
  <flow id="x" type="rude" route="r2" begin="1" end="200" period="4" departSpeed="0"/>
</routes>"""


def test_a_car_teleported_moving_is_not_flushed_in_its_gap(tmp_path):
    """A merge of two 500-m roads, 200 one-second steps (SUMO 1.28: x.34 collides on the
    junction at 5.6 m/s and is put back on the exit 2 s later at 13.5 m/s). The replay flushing
    every finished car (flush_vehicles=1) books each vehicle once, with the live run's net
    energy, distance, time, teleports and their kinetic energy. Before, the car was flushed in
    its gap and booked as two trips, its placement not counted (on Hamburg, 900 s,
    `--time-to-teleport 60 --collision.check-junctions`: truck LKW40 at 1.061 of its live net
    energy)."""
    build_net(tmp_path, '<nodes><node id="w" x="-500" y="0"/><node id="c" x="0" y="0" type="priority"/>'
              '<node id="e" x="500" y="0"/><node id="s" x="0" y="-500"/></nodes>',
              '<edges><edge id="we" from="w" to="c" numLanes="1" speed="15" priority="2"/>'
              '<edge id="ce" from="c" to="e" numLanes="1" speed="15" priority="2"/>'
              '<edge id="sc" from="s" to="c" numLanes="1" speed="15" priority="1"/></edges>', "--no-turnarounds")
    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    fcd = tmp_path / "fcd.xml"
    (tmp_path / "s.toml").write_text(
        'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["r.rou.xml"]\nend = 200\n'
        'step_length = 1\noptions = ["--no-warnings", "true", "--precision", "6", "--collision.check-junctions", '
        f'"true", "--collision.action", "teleport", "--fcd-output", "{fcd}"]\n'
        '[outputs]\nfigures = false\n', encoding="utf-8")
    live = run_scenario(tmp_path / "s.toml", tmp_path / "o")
    rows = read_fcd(fcd)
    rows = rows[~rows["person"].to_numpy(bool)].sort_values(["id", "time"], kind="stable")
    g = rows.groupby("id")
    gap = np.nan_to_num(g["time"].diff().to_numpy(float)) > 1.0 + 1e-9
    moving = gap & (np.nan_to_num(g["speed"].shift().to_numpy(float)) > 0.1)
    assert moving.sum() >= 1  # the premise: a car vanishes moving and comes back
    rep = process_fcd(fcd, scenario=tmp_path / "s.toml", out_dir=tmp_path / "f", flush_vehicles=1, figures=False)
    assert rep.ledger.flushed_vehicles >= 20  # it did flush
    cols = ["net_total_j", "distance_m", "time_s", "teleports", "teleport_kinetic_j"]
    a = pd.read_parquet(tmp_path / "o" / "vehicles.parquet").set_index(["vehicle", "equation"])[cols].sort_index()
    b = pd.read_parquet(tmp_path / "f" / "vehicles.parquet").set_index(["vehicle", "equation"])[cols].sort_index()
    assert b.index.is_unique and len(b) == len(a) == live["vehicles"]
    back = set(rows["id"].to_numpy()[moving])
    assert (a.loc[list(back), "teleports"] > 0).all()
    pd.testing.assert_frame_equal(b, a, rtol=1e-6, atol=1.0, check_dtype=False)  # (1 J: 6-decimal speeds)
