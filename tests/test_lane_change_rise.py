"""A lane change within an edge whose lanes' elevation profiles part (MoST: lanes of one edge
up to 0.6 m apart, a 3D network's lanes each with its own shape) books the rise between
the lanes as any other step's (sim/network.py Network.step_grade: clipped at max_rad, the
rest carried), not as a jump; live with positions tracked (a lane change tracking misses
until its next read), read every step, and the FCD replay alike. Real SUMO runs: cars
overtaking slow trucks on a two-lane road whose left lane rises 1.5 m where the right lane
stays flat, and changing back to the right lane, the one that goes on."""

from __future__ import annotations

import numpy as np
import pytest

from sumo_drvpw.model.constants import G
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.sim.fcd import read_fcd
from sumo_drvpw.sim.network import load_network
from sumo_drvpw.sim.scenario import load_scenario
from sumo_probe import build_net, fcd_rise, tracked_getter_replay

pytestmark = pytest.mark.sumo

PHYS = Equation("phys", {"acc": 1.0, "grade": 1.0, "aero_rho": 0.25 * 2.23, "roll": 0.01})


def test_a_lane_change_between_lanes_at_different_heights_books_thefcd_rise(tmp_path):
    """Before 2026-11-29 a step from one lane of an edge to another whose profile lies higher
    by more than the step could climb at the lanes' steepest slope was taken for a jump and
    booked at the slope, its rise lost (here 1.5 m per lane change where the lanes part), and the
    tracked live run, which sees a lane change only at its next read (up to 25 steps on),
    lost it where the replay, reading every row, did not: MoST 18000–19100 s, coach
    commercial_1-2_4 net −7.57 MJ live against −7.69 MJ replayed (0.6 m of rise, 116 kJ).
    Now every car's net grade is m·g·(z_last − z_first) + its first step's
    (to 1 cm of rise), tracked, read and replayed."""
    (tmp_path / "n.con.xml").write_text('<connections><connection from="AB" to="BC" fromLane="0" toLane="0"/>'
                                        '</connections>', encoding="utf-8")  # (only the right lane goes on)
    build_net(tmp_path, '<nodes><node id="A" x="0" y="0" z="0"/><node id="B" x="800" y="0" z="0"/>'
                        '<node id="C" x="900" y="0" z="0"/></nodes>',
              '<edges><edge id="AB" from="A" to="B" numLanes="2" speed="27.8">'
              '<lane index="1" shape="0,-1.6,0 300,-1.6,1.5 800,-1.6,1.5"/></edge>'
              '<edge id="BC" from="B" to="C" numLanes="1" speed="27.8"/></edges>', "-x", "n.con.xml")
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="slow" vClass="truck" maxSpeed="8" length="12"/>'
        '<vType id="fast" vClass="passenger" maxSpeed="30"/><route id="r" edges="AB BC"/>'
        '<flow id="t" type="slow" route="r" begin="0" end="150" period="20" departLane="0" departSpeed="max"/>'
        '<flow id="c" type="fast" route="r" begin="3" end="150" period="4" departLane="0" departSpeed="max"/>'
        '</routes>', encoding="utf-8")
    sc = tmp_path / "s.toml"
    sc.write_text('equations = ["vsp_ldv1999"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["r.rou.xml"]\n'
                  'begin = 0\nend = 300\nstep_length = 0.25\n', encoding="utf-8")
    fcd = tmp_path / "fcd.xml"
    books = tracked_getter_replay(sc, fcd, [PHYS])
    rows = read_fcd(fcd)
    s = load_scenario(sc)
    net = load_network(s.net_file, s.road_class, s.slope_window, s.slope_max)
    r = fcd_rise(net, rows)
    ab = rows[rows["id"].str.startswith("c") & rows["lane"].str.startswith("AB")].sort_values("time", kind="stable")
    change = ab["lane"].ne(ab.groupby("id")["lane"].shift()) & ab.duplicated("id")
    assert (change & (ab["pos"] > 320)).sum() >= 10  # (lane changes where the lanes lie 1.5 m apart)
    for name, res in books.items():
        b = res.vehicles.set_index("vehicle").sort_index()
        b = b[b["vclass"] == "passenger"]
        assert len(b) >= 30, name
        m, z = b["mass_kg"] * G, r.reindex(b.index)
        expect = m * (z.z1 - z.z0) + m * np.sin(z.theta) * z.v * 0.25
        np.testing.assert_allclose(b["traction_grade_j"] + b["recup_grade_j"], expect,
                                   rtol=0, atol=float(m.max()) * 0.01, err_msg=name)


def test_a_lane_change_standing_carries_the_rise_between_the_lanes(tmp_path):
    """A step shorter than 1 cm books the slope, not a rise: a lane change standing (SUMO's
    sublane model moves a waiting bus across, MoST bus_4:Fontvieille.0 at 19682 s) lost the
    rise between the lanes (before 2026-11-29: the replay, which sees it, 2.9 kJ = 1.8 cm apart
    from the tracked live run, which sees it only when moving on). Now it is carried to the
    next steps: the steps from the upper lane standing across to the lower one and on book
    the profile's Δz in all (Network.step_grade on the two-lane road, lanes 1.5 m apart)."""
    build_net(tmp_path, '<nodes><node id="A" x="0" y="0" z="0"/><node id="B" x="800" y="0" z="0"/></nodes>',
              '<edges><edge id="AB" from="A" to="B" numLanes="2" speed="27.8">'
              '<lane index="1" shape="0,-1.6,0 300,-1.6,1.5 800,-1.6,1.5"/></edge></edges>')
    s = _scenario(tmp_path)
    net = load_network(s.net_file, s.road_class, s.slope_window, s.slope_max)
    up, down = net.lane_index["AB_1"], net.lane_index["AB_0"]
    last = net.place(np.array([up]), np.array([400.0]))
    booked = 0.0
    for lane, pos, ds in ((down, 400.0, 0.0), (down, 400.0, 0.002)) + tuple((down, 400.0 + 3 * k, 3.0)
                                                                           for k in range(1, 6)):
        theta, last = net.step_grade(np.array([lane]), np.array([pos]), np.array([ds]), last,
                                     net.slope(np.array([lane]), np.array([pos]))[0])
        booked += float(np.sin(theta[0]) * ds)
    z0 = net.elevation(np.array([up]), np.array([400.0]))[0]
    z1 = net.elevation(np.array([down]), np.array([415.0]))[0]
    assert z0 - z1 > 1.4
    assert booked == pytest.approx(z1 - z0, abs=1e-6)


def _scenario(d):
    (d / "r.rou.xml").write_text("<routes/>", encoding="utf-8")
    (d / "s.toml").write_text('equations = ["vsp_ldv1999"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["r.rou.xml"]\n',
                              encoding="utf-8")
    return load_scenario(d / "s.toml")


def test_a_lane_change_standing_where_the_lanes_part_most_between_samples_keeps_itsfcd_rise(tmp_path):
    """The lanes' spread (sim/lane_spread.py) is their profiles' largest difference at the
    same position: before 2026-11-29 it was sampled at 33 fractions of the lane's length,
    25 m apart on this 800-m road whose left lane rises 3 m to a crest 100 m in: 2.906 m where
    the lanes part 2.940 m at 106 m, so a lane change standing there was taken for a jump
    and its 2.93-m rise lost (booked 0 of it, then the right lane's flat road)."""
    build_net(tmp_path, '<nodes><node id="A" x="0" y="0" z="0"/><node id="B" x="800" y="0" z="0"/></nodes>',
              '<edges><edge id="AB" from="A" to="B" numLanes="2" speed="27.8">'
              '<lane index="1" shape="0,-1.6,0 100,-1.6,3 300,-1.6,1.5 800,-1.6,1.5"/></edge></edges>')
    s = _scenario(tmp_path)
    net = load_network(s.net_file, s.road_class, s.slope_window, s.slope_max)
    up, down = net.lane_index["AB_1"], net.lane_index["AB_0"]
    p = np.arange(0.0, 800.0, 0.5)
    part = np.abs(net.elevation(np.full(p.size, up), p) - net.elevation(np.full(p.size, down), p))
    assert net.lane_spread[up] == net.lane_spread[down] >= part.max() - 1e-9
    at = float(p[np.argmax(part)])
    last = net.place(np.array([up]), np.array([at]))
    booked = 0.0
    for lane, pos, ds in ((down, at, 0.0),) + tuple((down, at + 3 * k, 3.0) for k in range(1, 6)):
        theta, last = net.step_grade(np.array([lane]), np.array([pos]), np.array([ds]), last,
                                     net.slope(np.array([lane]), np.array([pos]))[0])
        booked += float(np.sin(theta[0]) * ds)
    z0 = net.elevation(np.array([up]), np.array([at]))[0]
    z1 = net.elevation(np.array([down]), np.array([at + 15.0]))[0]
    assert z0 - z1 > 2.9
    assert booked + last[0, 3] == pytest.approx(z1 - z0, abs=1e-6)
