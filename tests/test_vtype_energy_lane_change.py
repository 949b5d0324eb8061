"""Where SUMO's Energy model reads another heading than the angle SUMO writes: a vehicle that
changes lanes in the step it enters a lane from a junction, its back still on the lanes
behind (docs/scenario.md, ``vtype_energy``, radial drag). SUMO's devices take the turn as
SUMO moves the vehicle, before the step's lane changes (MSDevice_Battery::notifyMove); the
angle written (TraCI, FCD) is computed after the change, back to front
(MSVehicle::computeAngle). A real SUMO run on a generated junction: the angle the devices
read is the back-to-front angle on the lane before the change, rebuilt here from the
network's lane shapes, and with it the booking is SUMO's emission output to 1e-6."""

from __future__ import annotations

import math
import re

import numpy as np
import pandas as pd
import pytest
import sumolib

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.sim import run_scenario
from sumo_probe import build_net, emitted_wh, energy_scenario

pytestmark = pytest.mark.sumo

DT = 0.5
LENGTH = 12.0
ROUTES = """<routes>
<vType id="bus" vClass="bus" mass="12000" length="{length}" emissionClass="Energy/unknown" sigma="0">
 <param key="radialDragCoefficient" value="{c}"/>
</vType>
<route id="r" edges="in mid left"/>
<flow id="b" type="bus" route="r" begin="0" end="30" period="10" departSpeed="max"/>
</routes>"""


def _junction(d):
    """A 1-lane edge from the south turning right into a 3-lane edge whose only lane reached
    from it is lane 0, and whose lane 2 alone leads on to the route's next edge (left): the
    buses change lanes as they enter it."""
    build_net(d, '<nodes><node id="s" x="0" y="-200"/><node id="j" x="0" y="0" type="priority"/>'
              '<node id="w" x="-200" y="0"/><node id="k" x="300" y="0"/><node id="n2" x="300" y="200"/>'
              '<node id="s2" x="300" y="-200"/><node id="e2" x="600" y="0"/></nodes>',
              '<edges><edge id="in" from="s" to="j" numLanes="1" speed="13.9"/>'
              '<edge id="w" from="w" to="j" numLanes="3" speed="13.9"/>'
              '<edge id="mid" from="j" to="k" numLanes="3" speed="13.9"/>'
              '<edge id="left" from="k" to="n2" numLanes="1" speed="13.9"/>'
              '<edge id="right" from="k" to="s2" numLanes="1" speed="13.9"/>'
              '<edge id="str" from="k" to="e2" numLanes="1" speed="13.9"/></edges>', "--no-turnarounds")
    (d / "n.con.xml").write_text(
        '<connections><connection from="mid" to="right" fromLane="0" toLane="0"/>'
        '<connection from="mid" to="str" fromLane="1" toLane="0"/>'
        '<connection from="mid" to="left" fromLane="2" toLane="0"/>'
        '<connection from="in" to="mid" fromLane="0" toLane="0"/></connections>', encoding="utf-8")
    import subprocess

    subprocess.run([sumolib.checkBinary("netconvert"), "-n", "n.nod.xml", "-e", "n.edg.xml", "-x", "n.con.xml",
                    "-o", "n.net.xml", "--no-turnarounds"], check=True, capture_output=True, cwd=d)


def _at(lane, pos):
    """x, y of SUMO position ``pos`` on ``lane`` (its length scaled onto its shape)."""
    shape = lane.getShape()
    return sumolib.geomhelper.positionAtShapeOffset(
        shape, pos * sumolib.geomhelper.polyLength(shape) / lane.getLength())


def _navi(back, front):
    """SUMO's written angle [deg] (clockwise from north) from ``back`` to ``front``."""
    return (90.0 - math.degrees(math.atan2(front[1] - back[1], front[0] - back[0]))) % 360.0


def test_the_devices_read_the_angle_before_the_lane_change(tmp_path):
    """Each bus enters mid on lane 0 and is written on lane 1 in that step, its back 2.2 m
    up the edge before. The angle written then is the back-to-front angle to lane 1, the
    one SUMO's Energy model read the back-to-front angle to lane 0, 9.1° apart (measured
    2026-11-29: 30.02° and 39.16°). Put in the FCD for the written one, the replay books
    each bus as SUMO's emission output to 1e-6 (measured 3e-8); as written, the live run and
    the replay agree (1e-6) and, without radial drag (coefficient 0), both are SUMO's to
    1e-6 — the lane change's angle is the whole of the difference (1.00092 of SUMO's at
    coefficient 0.5, the known gap)."""
    _junction(tmp_path)
    net = sumolib.net.readNet(str(tmp_path / "n.net.xml"), withInternal=True)
    got = {}
    for c in ("0.5", "0"):
        (tmp_path / "r.rou.xml").write_text(ROUTES.format(length=LENGTH, c=c), encoding="utf-8")
        sc = energy_scenario(tmp_path, 200, step_length=DT)
        run_scenario(sc, tmp_path / f"live{c}")
        sumo, _ = emitted_wh(tmp_path / "em.xml", DT)
        fcd = (tmp_path / "fcd.xml").read_text(encoding="utf-8")
        (tmp_path / f"fcd{c}.xml").write_text(fcd, encoding="utf-8")
        (tmp_path / f"r{c}.rou.xml").write_text(ROUTES.format(length=LENGTH, c=c), encoding="utf-8")
        got[c] = (sumo, fcd)
        live = pd.read_csv(tmp_path / f"live{c}" / "chain_vehicles.csv").set_index("key").net_kwh * 1000.0
        assert len(live) == 3
        rep = _replay(tmp_path, f"fcd{c}.xml", f"r{c}.rou.xml", f"rep{c}")
        np.testing.assert_allclose(rep[live.index], live, rtol=1e-6)
        if c == "0":
            np.testing.assert_allclose(live, live.index.map(sumo), rtol=1e-6)
    sumo, fcd = got["0.5"]
    # the step each bus enters mid: written on lane 1, the connection from `in` leads to lane 0
    rows = re.findall(r'<vehicle id="(b\.\d)"[^>]*angle="([\d.]+)"[^>]*pos="([\d.]+)" lane="mid_1"', fcd)
    first = {}
    for vid, angle, pos in rows:
        first.setdefault(vid, (float(angle), float(pos)))
    assert len(first) == 3
    into, behind = net.getLane("mid_0"), [net.getLane(":j_0_0"), net.getLane("in_0")]
    fixed = fcd
    for vid, (written, pos) in first.items():
        assert pos < LENGTH - behind[0].getLength()  # its back is on `in`, beyond the internal lane
        back = _at(behind[1], behind[1].getLength() - (LENGTH - pos - behind[0].getLength()))
        assert _navi(back, _at(net.getLane("mid_1"), pos)) == pytest.approx(written, abs=1e-4)
        before = _navi(back, _at(into, pos))
        assert before - written > 5.0
        fixed = re.sub(rf'(<vehicle id="{re.escape(vid)}"[^>]*angle=")[\d.]+("[^>]*lane="mid_1")',
                       lambda m: f"{m.group(1)}{before:.6f}{m.group(2)}", fixed, count=1)
    (tmp_path / "fixed.xml").write_text(fixed, encoding="utf-8")
    rep = _replay(tmp_path, "fixed.xml", "r0.5.rou.xml", "fixed")
    np.testing.assert_allclose(rep, rep.index.map(sumo), rtol=1e-6)


def _replay(d, fcd, routes, out):
    assert cli_main(["fcd", str(d / fcd), "--net", str(d / "n.net.xml"), "--vtypes", str(d / routes),
                     "--equation", "vtype_energy", "--end", "200", "--out", str(d / out), "--no-figures"]) == 0
    return pd.read_csv(d / out / "chain_vehicles.csv").set_index("key").net_kwh * 1000.0
