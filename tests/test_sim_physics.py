"""Physics at any step length, against real SUMO (libsumo).

The acc term is booked as coefficient × m·v̄·a with v̄ the step's mean speed, i.e. the
kinetic-energy change ½m(v_t² − v_t−1²)/Δt; the other terms at the speed of the distance
SUMO moved the car (Euler: v_t; ballistic: v̄). A car that starts and ends at rest has
zero net acceleration energy whatever the step length and the driver noise.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.model.equations import Equation
from sumo_drvpw.sim import run_scenario

pytestmark = pytest.mark.sumo

REPO = Path(__file__).resolve().parent.parent
NETS = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks"  # the built-in networks
HW_NET = NETS / "highway.net.xml"

# default driver noise (sigma 0.5); every car departs at rest and ends at rest at a stop on
# the flat first kilometre (networks/src/highway.nod.xml: h0, h1 at z = 0)
STOP_ROUTES = """<routes>
  <vType id="car" vClass="passenger" mass="1500" accel="2.6" decel="4.5"/>
  <route id="r" edges="e01 e12"/>
  {vehicles}
</routes>"""
VEH = ('<vehicle id="c{i}" type="car" route="r" depart="{d}" departSpeed="0" departPos="0">'
       '<stop lane="e01_0" endPos="{pos}" duration="100000"/></vehicle>')


def _run(tmp_path, dt, options=(), acceleration="speed_difference"):
    vehicles = "\n  ".join(VEH.format(i=i, d=4 * i, pos=950 - 10 * i) for i in range(4))
    (tmp_path / "r.rou.xml").write_text(STOP_ROUTES.format(vehicles=vehicles), encoding="utf-8")
    opts = ", ".join(f'"{o}"' for o in ("--no-warnings", "true", *options))
    (tmp_path / "s.toml").write_text(
        f'equations = ["x"]\n[sumo]\nnet = "{HW_NET}"\nroutes = ["r.rou.xml"]\nbegin = 0\n'
        f'end = 150\nstep_length = {dt}\noptions = [{opts}]\nacceleration = "{acceleration}"\n'
        '[outputs]\nfigures = false\nedgedata = false\n', encoding="utf-8")
    eq = Equation("kin", {"acc": 1.0, "roll": 0.01})
    s = run_scenario(tmp_path / "s.toml", tmp_path / "o", equations=[eq])
    return s, pd.read_parquet(tmp_path / "o" / "vehicles.parquet")


@pytest.mark.parametrize("dt,options,acceleration", [
    (1.0, (), "speed_difference"),
    (0.1, (), "speed_difference"),
    (1.0, (), "getter"),
    (0.5, ("--step-method.ballistic", "true"), "speed_difference"),
])
def test_acceleration_energy_conserved_from_rest_to_rest(tmp_path, dt, options, acceleration):
    s, veh = _run(tmp_path, dt, options, acceleration)
    assert s["step_length_s"] == dt
    assert s["step_method"] == ("ballistic" if options else "euler")
    assert len(veh) == 4
    for _, r in veh.iterrows():
        gained = r.traction_acc_j
        assert gained > 0.5 * 1500 * 10.0 ** 2  # each car reached > 10 m/s
        assert abs(gained + r.recup_acc_j) <= 1e-9 * gained
    # distance: from departPos 0 to the stop's end position, as SUMO moved the cars. Under
    # the ballistic update a car that comes to rest within a step moves less than v̄·Δt
    # (it stops early in the step), so the last step overshoots by a few centimetres
    stops = 950 - 10 * np.arange(4)
    np.testing.assert_allclose(veh.sort_values("vehicle").distance_m, stops,
                               atol=0.2 if options else 0.05)


@pytest.mark.parametrize("z_c", [None, 2.0], ids=["flat", "one_short_edge_elevated"])
def test_step_length_and_no_elevation_reported(tmp_path, z_c):
    """step_length_s from SUMO's getDeltaT (the config's, when the scenario gives none);
    a network without z is named in a warning and in summary.json; so is one with z on a
    small share of its lanes (DLR's Bad Hersfeld: 0.09 %, said to have elevation, unwarned)."""
    flat = tmp_path / "flat.net.xml"
    import subprocess

    import sumolib

    from sumo_drvpw.sim.accountant import PARTIAL_ELEVATION_SHARE

    nod = tmp_path / "f.nod.xml"
    edg = tmp_path / "f.edg.xml"
    if z_c is None:
        nod.write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="500" y="0"/></nodes>', encoding="utf-8")
        edg.write_text('<edges><edge id="ab" from="a" to="b" numLanes="1" speed="20"/></edges>', encoding="utf-8")
    else:  # a 40-m ramp beyond the 500-m flat edge: z on 40 of 540 m of lanes
        nod.write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="500" y="0"/>'
                       f'<node id="c" x="540" y="0" z="{z_c}"/></nodes>', encoding="utf-8")
        edg.write_text('<edges><edge id="ab" from="a" to="b" numLanes="1" speed="20"/>'
                       '<edge id="bc" from="b" to="c" numLanes="1" speed="20"/></edges>', encoding="utf-8")
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", str(nod), "-e", str(edg),
                    "-o", str(flat), "--no-warnings"], check=True, capture_output=True)
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="car" mass="1500"/><vehicle id="v" type="car" depart="0">'
        '<route edges="ab"/></vehicle></routes>', encoding="utf-8")
    (tmp_path / "c.sumocfg").write_text(
        '<configuration><input><net-file value="flat.net.xml"/><route-files value="r.rou.xml"/>'
        '</input><time><step-length value="0.25"/></time></configuration>', encoding="utf-8")
    (tmp_path / "s.toml").write_text('equations = ["vsp_ldv1999"]\n[sumo]\nconfig = "c.sumocfg"\n'
                                     '[outputs]\nfigures = false\n', encoding="utf-8")
    s = run_scenario(tmp_path / "s.toml", tmp_path / "o")
    assert s["step_length_s"] == 0.25
    doc = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))
    if z_c is None:
        assert s["network"]["has_elevation"] is False and s["network"]["z_share"] == 0.0
        assert any("no elevation" in w for w in s["warnings"])
        assert doc["network"]["has_elevation"] is False
    else:
        share = s["network"]["z_share"]
        assert s["network"]["has_elevation"] is True and 0.0 < share < PARTIAL_ELEVATION_SHARE
        assert doc["network"]["z_share"] == share
        assert [w for w in s["warnings"] if "has elevation on only" in w and
                f"{100 * share:.2g} % of its lane length" in w]


def test_standing_and_moving_constants_in_a_sumo_run(tmp_path):
    """A real SUMO run (the bundled city, 150 s, traffic lights): ``v^0`` books its power for
    every second a vehicle is in the network, ``moving`` only while it moves, their difference
    only while it stands — which vehicles at red lights do."""
    import sumo_drvpw.sim as sim

    city = Path(sim.__file__).parent / "builtin" / "scenarios" / "city.toml"
    eqs = [Equation("always", {"v^0": 1000.0}), Equation("moving", {"moving": 1000.0}),
           Equation("standing", {"v^0": 1000.0, "moving": -1000.0})]
    res = run_scenario(city, tmp_path / "o", end=150, equations=eqs, figures=False)
    tot = {e.name: res.summary["equations"][e.name]["energy_j"]["city"]["total"] for e in eqs}
    led = res.ledger
    assert tot["always"] == pytest.approx(1000.0 * float(np.sum(led.veh_time[:led.n_veh])), rel=1e-9)
    assert tot["standing"] == pytest.approx(tot["always"] - tot["moving"], rel=1e-9)
    assert 0 < tot["standing"] < tot["moving"] < tot["always"]


def _network(tmp_path, nodes: str, edges: str, routes: str, outputs: str = "") -> Path:
    """Nodes, edges (netconvert) and routes written into ``tmp_path``; its SUMO config."""
    import subprocess

    import sumolib

    (tmp_path / "n.nod.xml").write_text(f"<nodes>{nodes}</nodes>", encoding="utf-8")
    (tmp_path / "n.edg.xml").write_text(f"<edges>{edges}</edges>", encoding="utf-8")
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "n.net.xml",
                    "--no-warnings"], check=True, capture_output=True, cwd=tmp_path)
    (tmp_path / "n.rou.xml").write_text(f"<routes>{routes}</routes>", encoding="utf-8")
    (tmp_path / "n.sumocfg").write_text('<configuration><input><net-file value="n.net.xml"/><route-files '
                                        f'value="n.rou.xml"/></input>{outputs}</configuration>', encoding="utf-8")
    return tmp_path / "n.sumocfg"


@pytest.mark.parametrize("step", [1.0, 0.1])
def test_a_closed_loop_books_no_net_climb_on_odd_lanes(tmp_path, step):
    """Found by the review of the step-grade change: a lane whose `length` (250 m) is shorter
    than its shape (503 m, falling 40 m) had every step taken for a jump and booked −20 m per
    lap; an edge falling 3 m over 1 m (an elevation step, steeper than [slope] max_rad on
    average) left a step at its end, booked or not as the step length fell (2.7–5.4 m). Two
    laps of a loop with both now book no net climb, live and replayed from the FCD, and no
    step steeper than max_rad."""
    import pandas as pd

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.model.constants import G
    from sumo_drvpw.sim.run import run_scenario

    _network(tmp_path,
             '<node id="n0" x="0" y="0" z="0"/><node id="n1" x="500" y="0" z="0"/>'
             '<node id="n2" x="500" y="500" z="40"/><node id="n3" x="0" y="500" z="40"/>'
             '<node id="n4" x="0" y="499" z="37"/>',
             '<edge id="a" from="n0" to="n1" numLanes="1" speed="15"/>'
             '<edge id="b" from="n1" to="n2" numLanes="1" speed="15" shape="500,0,0 500,100,0 500,350,40 500,500,40"/>'
             '<edge id="c" from="n2" to="n3" numLanes="1" speed="15"/>'
             '<edge id="s" from="n3" to="n4" numLanes="1" speed="15"/>'
             '<edge id="d" from="n4" to="n0" numLanes="1" speed="15" length="250" shape="0,499,37 0,400,37 0,150,0 0,0,0"/>',
             '<vType id="car" mass="1500" sigma="0" maxSpeed="15"/><vType id="slow" mass="1500" sigma="0" '
             'maxSpeed="5"/><route id="loop" edges="a b c s d a b c s d a"/>'
             '<vehicle id="fast" type="car" route="loop" depart="0" departPos="100" arrivalPos="100"/>'
             '<vehicle id="slow" type="slow" route="loop" depart="0" departPos="50" arrivalPos="50"/>',
             '<output><fcd-output value="fcd.xml"/></output>')
    (tmp_path / "g.toml").write_text('[equation]\nname = "g"\n[terms]\ngrade = 1.0\n', encoding="utf-8")
    (tmp_path / "s.toml").write_text(f'equations = ["g.toml"]\n[sumo]\nconfig = "n.sumocfg"\nstep_length = {step}\n'
                                     '[outputs]\nfigures = false\ntrace = true\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    # no step books a grade beyond [slope] max_rad (0.25): the 3-m step was booked at up to
    # 0.41 rad in one step (MoST's 7.6-m step between lanes at 1.10 rad, 2.7 MW of a trailer's
    # grade power); the rise beyond the limit is carried to the next steps
    theta = pd.read_parquet(tmp_path / "o" / "trace.parquet", columns=["theta_rad"])["theta_rad"]
    assert theta.abs().max() <= 0.25 + 1e-9 and theta.abs().max() > 0.2
    for out in ("o", "r"):
        if out == "r":
            assert cli_main(["fcd", str(tmp_path / "o" / "sumo" / "fcd.xml"), "--scenario", str(tmp_path / "s.toml"),
                             "--out", str(tmp_path / "r")]) == 0
        veh = pd.read_parquet(tmp_path / out / "vehicles.parquet").set_index("vehicle")
        net_grade = (veh.traction_grade_j + veh.recup_grade_j) / (1500 * G)   # booked climb [m]
        assert set(net_grade.index) == {"fast", "slow"}
        np.testing.assert_allclose(net_grade.to_numpy(), 0.0, atol=0.05)
        assert (veh.traction_grade_j / (1500 * G) > 70).all()   # two climbs of 40 m each


def test_an_output_the_scenario_options_name_relatively_goes_into_the_run_folder(tmp_path, monkeypatch):
    """Found by the review of the step-grade change: `options = ["--fcd-output", "fcd.xml"]` in a
    scenario wrote fcd.xml into the working directory, outside the run's output set (the
    config's own outputs go into OUT/sumo/). A relative output path of the options now goes
    there too; an absolute one is kept."""
    from sumo_drvpw.sim.run import run_scenario

    cfg = _network(tmp_path,
                   '<node id="a" x="0" y="0" z="0"/><node id="b" x="1500" y="0" z="0"/>'
                   '<node id="c" x="2500" y="0" z="100"/><node id="d" x="2600" y="0" z="100"/>',
                   '<edge id="ab" from="a" to="b" numLanes="1" speed="30"/><edge id="bc" from="b" to="c" '
                   'numLanes="1" speed="30"/><edge id="cd" from="c" to="d" numLanes="1" speed="30"/>',
                   '<vType id="semi" vClass="trailer" mass="24000" sigma="0" accel="1.0" maxSpeed="30"/>'
                   '<vType id="bus" vClass="bus" mass="15000" sigma="0" maxSpeed="8"/>'
                   '<vType id="car" vClass="passenger" sigma="0" maxSpeed="30"/><route id="r" edges="ab bc cd"/>'
                   '<vehicle id="t" type="semi" route="r" depart="0"/><vehicle id="b" type="bus" route="r" depart="5"/>'
                   '<vehicle id="c" type="car" route="r" depart="10"/>')
    res = run_scenario(cfg, tmp_path / "o", figures=False)
    dyn = res.summary["driving_dynamics"]["vclasses"]
    semi, bus = dyn["trailer"]["beyond_engine_power"], dyn["bus"]["beyond_engine_power"]
    assert semi["share"] > 0.1 and semi["steps"] > 20 and bus["steps"] == 0 and bus["of_steps"] > 100
    assert "beyond_engine_power" not in dyn["passenger"]
    said = [w for w in res.summary["warnings"] if "beyond any engine's power" in w]
    assert len(said) == 1 and "trailer" in said[0] and "bus" not in said[0]


def test_a_first_step_on_a_lane_steeper_than_max_rad_books_at_most_max_rad(tmp_path):
    """Regression rehearsal on MoST after the step-grade limit: steps booked from the slope
    — a trip's first step, a step shorter than 1 cm — still took a lane's mean gradient where
    the whole lane is steeper than max_rad (0.27 rad, a trailer's 340 kW first step; 1.2 rad
    standing). Planted: a car departing on a lane of 0.40 rad books its first step at 0.25."""
    cfg = _network(tmp_path, '<node id="a" x="0" y="0" z="0"/><node id="b" x="50" y="0" z="21"/>'
                             '<node id="c" x="150" y="0" z="21"/>',
                   '<edge id="ab" from="a" to="b" numLanes="1" speed="15"/>'
                   '<edge id="bc" from="b" to="c" numLanes="1" speed="15"/>',
                   '<vType id="car" mass="1500" sigma="0"/><route id="r" edges="ab bc"/>'
                   '<vehicle id="v" type="car" route="r" depart="0" departPos="5" departSpeed="5"/>')
    (tmp_path / "s.toml").write_text('equations = ["vsp_ldv1999"]\n[sumo]\nconfig = "n.sumocfg"\n'
                                     '[outputs]\nfigures = false\ntrace = true\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    tr = pd.read_parquet(tmp_path / "o" / "trace.parquet").sort_values("time_s")
    assert tr["theta_rad"].abs().max() <= 0.25 + 1e-9
    assert tr["theta_rad"].iloc[0] == pytest.approx(0.25)  # (the lane's 0.40, clipped)


def _own_loop(tmp_path, routes: str, end: float, options: tuple, eqs: list):
    """A libsumo run of the highway's flat start stepped here (Δt 1 s), the Accountant
    booking each step after this loop read every vehicle's speed and odometer
    (vehicle.getSpeed, vehicle.getDistance) from SUMO itself: (vehicles table, speeds per
    vehicle and step, last odometer reading per vehicle)."""
    from sumo_drvpw.sim import Accountant, close_sumo, start_sumo
    from sumo_drvpw.sim.scenario import load_scenario

    (tmp_path / "r.rou.xml").write_text(routes, encoding="utf-8")
    opts = ", ".join(f'"{o}"' for o in ("--no-warnings", "true", *options))
    toml = tmp_path / "s.toml"
    toml.write_text(f'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "{HW_NET}"\nroutes = ["r.rou.xml"]\n'
                    f'begin = 0\nend = {end}\nstep_length = 1.0\noptions = [{opts}]\n'
                    '[outputs]\nfigures = false\nedgedata = false\n', encoding="utf-8")
    conn = start_sumo(load_scenario(toml, equations=eqs).sumo_args)
    speeds, odometer = {}, {}
    try:
        acc = Accountant(conn, equations=eqs, scenario=toml, figures=False, keep_vehicles=True)
        while conn.simulation.getTime() < end - 1e-9:
            conn.simulationStep()
            for vid in conn.vehicle.getIDList():
                speeds.setdefault(vid, []).append(conn.vehicle.getSpeed(vid))
                odometer[vid] = conn.vehicle.getDistance(vid)
            acc.step()
        veh = acc.result().vehicles.set_index(["vehicle", "equation"])
    finally:
        close_sumo(conn)
    return veh, {k: np.asarray(s) for k, s in speeds.items()}, odometer


def test_acc_pos_books_the_kinetic_energy_gained_in_steps_that_speed_up(tmp_path):
    """``acc_pos`` (m·v̄·max(a, 0), v̄ the step's mean speed, as ``acc``): in a SUMO run
    (Euler, Δt 1 s, driver noise, a 5-s stop on the way) its energy per vehicle is the
    kinetic energy gained, ½m·Σ(v_t² − v_t−1²) over the steps where v_t > v_t−1, with the
    speeds read from SUMO by hand (m·v_t·a·Δt would add ½m·Σ(v_t − v_t−1)² there). It is the
    difference of an equation with acc + acc_pos and one with acc alone, whose own energy is
    ½m(v_last² − v_first²)."""
    routes = """<routes>
  <vType id="car" vClass="passenger" mass="1500" accel="2.6" decel="4.5"/>
  <route id="r" edges="e01 e12"/>
  <flow id="c" type="car" route="r" begin="0" end="12" period="4" departSpeed="0" departPos="0">
    <stop lane="e01_0" endPos="500" duration="5"/></flow>
</routes>"""
    eqs = [Equation("kin", {"acc": 1.0}), Equation("kin_pos", {"acc": 1.0, "acc_pos": 1.0})]
    veh, speeds, _ = _own_loop(tmp_path, routes, 150, (), eqs)
    assert len(speeds) == 3
    for vid, v in speeds.items():
        gained = np.diff(v ** 2)
        acc_e = {e.name: veh.loc[(vid, e.name), "traction_acc_j"] + veh.loc[(vid, e.name), "recup_acc_j"]
                 for e in eqs}
        assert (gained < 0).sum() > 5 and v.min() < 0.1  # it slowed down and stood at the stop
        assert acc_e["kin"] == pytest.approx(0.5 * 1500 * (v[-1] ** 2 - v[0] ** 2), rel=1e-9)
        want = 0.5 * 1500 * gained[gained > 0].sum()
        assert acc_e["kin_pos"] - acc_e["kin"] == pytest.approx(want, rel=1e-9)


def test_ballistic_books_the_distance_sumo_moved_cars_still_moving_at_the_end(tmp_path):
    """Under SUMO's ballistic update a car moves v̄·Δt in a step (v̄ = (v_t + v_t−1)/2), so the
    distance booked per vehicle is SUMO's own odometer (vehicle.getDistance) and Σ v̄·Δt from
    its speeds, and a v³ term books Σ v̄³·Δt, by hand; v_t·Δt would book ½Δt·(v_end − v_0)
    more (about 15 m for a car at 30 m/s), which a run from rest to rest cannot show. The
    cars depart at rest and are still driving at the end (40 s)."""
    routes = """<routes>
  <vType id="car" vClass="passenger" mass="1500" accel="2.6" decel="4.5"/>
  <route id="r" edges="e01 e12"/>
  <flow id="c" type="car" route="r" begin="0" end="16" period="5" departSpeed="0" departPos="0"/>
</routes>"""
    eqs = [Equation("cube", {"v3": 1.0})]
    veh, speeds, odometer = _own_loop(tmp_path, routes, 40, ("--step-method.ballistic", "true"), eqs)
    assert len(speeds) == 4
    for vid, v in speeds.items():
        r = veh.loc[(vid, "cube")]
        assert r.on_road_at_end and v[-1] > 20.0 and v[0] == 0.0
        v_bar = 0.5 * (v[1:] + v[:-1])
        assert r.distance_m == pytest.approx(odometer[vid], abs=1e-6)
        assert r.distance_m == pytest.approx(v_bar.sum(), abs=1e-6)
        assert r.traction_aero_j + r.recup_aero_j == pytest.approx(np.sum(v_bar ** 3), rel=1e-9)
