"""A teleport that lasts several steps leaves a gap in SUMO's FCD rows; the streamed replay
writes finished vehicles out of memory (Ledger.flush) and must not take a car in such a gap
for finished: it holds cars whose rows end while they stand (sim/fcd.py TELEPORT_HOLD_S).
Real SUMO: a straight road blocked by a stopped car, so the queue behind it spills back over
an edge and the cars waiting before that edge are teleported across it."""

from __future__ import annotations

import subprocess

import pandas as pd
import pytest

from sumo_drvpw.sim.fcd import process_fcd, read_fcd

pytestmark = pytest.mark.sumo

#: the first blocker stands at the end of e2, a 38-m vehicle fills the 40-m e3: cars
#: teleported from the queue on e2 find e3 full and pass it in the teleport (a few steps
#: without rows) before SUMO puts them back on e4
ROUTES = """<routes>
    <vType id="car" vClass="passenger" mass="1500"/>
    <vType id="long" vClass="passenger" mass="1500" length="38"/>
    <route id="r" edges="e0 e1 e2 e3 e4"/>
    <vehicle id="block2" type="long" depart="0" departPos="last" departSpeed="0">
        <route edges="e3 e4"/><stop lane="e3_0" endPos="39" duration="1000"/></vehicle>
    <vehicle id="block1" type="car" route="r" depart="0" departPos="0" departSpeed="0">
        <stop lane="e2_0" endPos="190" duration="1000"/></vehicle>
    <flow id="f" type="car" route="r" begin="5" end="150" period="3" departSpeed="max"/>
</routes>
"""
#: node x [m]: e3 is 40 m long
NODES_X = (0, 200, 400, 600, 640, 840)


@pytest.fixture(scope="module")
def jammed(tmp_path_factory):
    import sumolib

    d = tmp_path_factory.mktemp("jam")
    (d / "n.nod.xml").write_text("<nodes>" + "".join(
        f'<node id="n{i}" x="{x}" y="0"/>' for i, x in enumerate(NODES_X)) + "</nodes>", encoding="utf-8")
    (d / "n.edg.xml").write_text("<edges>" + "".join(
        f'<edge id="e{i}" from="n{i}" to="n{i + 1}" numLanes="1" speed="13.89"/>' for i in range(5))
        + "</edges>", encoding="utf-8")
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", "n.nod.xml", "-e", "n.edg.xml",
                    "-o", "n.net.xml", "--no-turnarounds"], check=True, capture_output=True, cwd=d)
    (d / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    subprocess.run([sumolib.checkBinary("sumo"), "-n", "n.net.xml", "-r", "r.rou.xml", "-e", "300",
                    "--time-to-teleport", "20", "--fcd-output", "fcd.xml", "--precision", "6",
                    "--no-step-log", "--no-warnings"], check=True, capture_output=True, cwd=d)
    return d


def test_a_car_in_a_teleport_gap_is_not_flushed_and_split_in_two(jammed, tmp_path):
    """The replay flushing every finished car (flush_vehicles=1) books what the replay that
    keeps every car in memory books: one row per car, the same teleports and energies.
    Before, each car back from a multi-step teleport was flushed in its gap and booked again
    as a new trip: two rows, its placement not counted as a teleport."""
    d = jammed
    rows = read_fcd(d / "fcd.xml").sort_values(["id", "time"], kind="stable")
    gap = rows.groupby("id")["time"].diff() > 1.0 + 1e-9
    last = rows.groupby("id")["speed"].shift()
    assert gap.sum() >= 2 and (last[gap] <= 0.1).all()  # the premise: cars vanish standing
    kw = dict(net=d / "n.net.xml", vtype_files=[d / "r.rou.xml"], equations=["vsp_ldv1999"],
              figures=False)
    ref = process_fcd(d / "fcd.xml", out_dir=tmp_path / "ref", keep_vehicles=True, **kw)
    res = process_fcd(d / "fcd.xml", out_dir=tmp_path / "out", flush_vehicles=1, **kw)
    assert res.ledger.flushed_vehicles >= 5  # it did flush
    a = pd.read_parquet(tmp_path / "ref" / "vehicles.parquet").sort_values("vehicle").reset_index(drop=True)
    b = pd.read_parquet(tmp_path / "out" / "vehicles.parquet").sort_values("vehicle").reset_index(drop=True)
    assert a.vehicle.is_unique and b.vehicle.is_unique and len(a) == rows["id"].nunique()
    assert (a.teleports > 0).sum() == gap.sum() and a.teleports.sum() == b.teleports.sum()
    pd.testing.assert_frame_equal(a, b, rtol=1e-9)
    assert res["vehicles"] == ref["vehicles"] and res["teleports"] == ref["teleports"]
