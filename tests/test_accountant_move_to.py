"""A TraCI script that moves a car itself (``vehicle.moveTo``) booked live by the Accountant
(``positions="getter"``) and replayed from the run's FCD (docs/scenario.md, "Inside your own
TraCI script"): a move along the same edge books alike; a move onto another edge, farther
than the car's speed took it, reads in the FCD as SUMO's placement at a teleport's end (which
the replay cannot tell from it), so the replay books that jump apart and not the step after
it, which SUMO drove from where the script put the car and the live run books driven."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.model.constants import G
from sumo_drvpw.sim import Accountant, close_sumo, start_sumo
from sumo_drvpw.sim.fcd import process_fcd, read_fcd
from sumo_drvpw.sim.network import lane_numbers, load_network
from sumo_drvpw.sim.scenario import load_scenario
from sumo_probe import build_net

pytestmark = pytest.mark.sumo

#: the script moves car v at this time [s], between steps
MOVE_S = 20.0
COLS = ["net_total_j", "distance_m", "time_s", "teleports", "teleport_kinetic_j", "teleport_potential_j"]


def _run(d, move):
    """Live (Accountant, getter positions, libsumo) and replayed vehicles.parquet, the FCD rows
    and the network of a road a → b (20 m up) → c → e, 400 m each, two cars; ``move(conn)``
    moves car v at MOVE_S."""
    build_net(d, '<nodes><node id="a" x="0" y="0" z="0"/><node id="b" x="400" y="0" z="20"/>'
              '<node id="c" x="800" y="0" z="0"/><node id="e" x="1200" y="0" z="0"/></nodes>',
              '<edges><edge id="e0" from="a" to="b" numLanes="1" speed="15"/>'
              '<edge id="e1" from="b" to="c" numLanes="1" speed="15"/>'
              '<edge id="e2" from="c" to="e" numLanes="1" speed="15"/></edges>', "--no-turnarounds")
    (d / "r.rou.xml").write_text(
        '<routes><vType id="car" vClass="passenger" mass="1500" sigma="0"/><route id="r" edges="e0 e1 e2"/>'
        '<vehicle id="v" type="car" route="r" depart="0" departSpeed="0"/>'
        '<vehicle id="w" type="car" route="r" depart="2" departSpeed="0"/></routes>', encoding="utf-8")
    (d / "s.toml").write_text('equations = ["vsp_ldv1999"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["r.rou.xml"]\n'
                              'end = 120\nstep_length = 1\noptions = ["--no-warnings", "true", "--precision", "6"]\n'
                              '[outputs]\nfigures = false\n', encoding="utf-8")
    sc = load_scenario(d / "s.toml")
    conn = start_sumo(list(sc.sumo_args) + ["--fcd-output", str(d / "fcd.xml")], "libsumo")
    try:
        acc = Accountant(conn, equations=["vsp_ldv1999"], positions="getter", scenario=d / "s.toml")
        while conn.simulation.getTime() < sc.end - 1e-9:
            if abs(conn.simulation.getTime() - MOVE_S) < 1e-9:
                move(conn)
            conn.simulationStep()
            acc.step()
        acc.result().write(d / "live")
    finally:
        close_sumo(conn)
    process_fcd(d / "fcd.xml", scenario=d / "s.toml", out_dir=d / "rep", figures=False)
    live, rep = (pd.read_parquet(d / k / "vehicles.parquet").set_index("vehicle")[COLS + ["mass_kg"]]
                 for k in ("live", "rep"))
    return live, rep, read_fcd(d / "fcd.xml"), load_network(sc.net_file, sc.road_class, sc.slope_window, sc.slope_max)


def test_a_move_along_the_edge_books_alike(tmp_path):
    """moveTo 80 m on along its lane: live and replay book every car alike."""
    live, rep, _, _ = _run(tmp_path, lambda c: c.vehicle.moveTo("v", "e0_0", c.vehicle.getLanePosition("v") + 80))
    assert live.loc["v", "distance_m"] > 0
    pd.testing.assert_frame_equal(rep.loc[live.index], live, rtol=1e-6, atol=1.0, check_dtype=False)


def test_a_move_onto_another_edge_books_as_a_placement_in_the_replay(tmp_path):
    """moveTo from 266 m up the climb of e0 (13 m above a) to 50 m into the flat e2, at 15.9
    m/s: the live run books the step after it driven (v·Δt from where the car was put, its road
    load) and the jump nowhere; the replay books a teleport whose potential energy is the jump's
    m·g·Δz (−196 kJ) and not that step: one step's distance and time less, and its road load
    (net energy 0.99156 of the live run's on SUMO 1.28, 2026-11-29). Car w, not moved, books
    alike."""
    live, rep, rows, net = _run(tmp_path, lambda c: c.vehicle.moveTo("v", "e2_0", 50.0))
    pd.testing.assert_frame_equal(rep.loc[["w"]], live.loc[["w"]], rtol=1e-6, atol=1.0, check_dtype=False)
    v = rows[rows["id"] == "v"].set_index("time")
    before, after = v.loc[MOVE_S - 1.0], v.loc[MOVE_S]  # FCD time t: the state after step t
    assert before["lane"] == "e0_0" and after["lane"] == "e2_0"
    a, b = live.loc["v"], rep.loc["v"]
    assert a["teleports"] == 0 and a["teleport_potential_j"] == 0 and b["teleports"] == 1
    assert a["distance_m"] - b["distance_m"] == pytest.approx(after["speed"] * 1.0, abs=1e-4)
    assert a["time_s"] - b["time_s"] == 1.0
    z = net.elevation(lane_numbers(net.lane_index, [before["lane"], after["lane"]]),
                      np.array([before["pos"], after["pos"]]))
    assert b["teleport_potential_j"] == pytest.approx(b["mass_kg"] * G * (z[1] - z[0]), rel=1e-6)
    assert z[0] > 10.0 and b["teleport_kinetic_j"] == pytest.approx(0.0, abs=1.0)
    assert 0.98 < b["net_total_j"] / a["net_total_j"] < 1.0
