"""The stepping loop and the ledger with a fake connection (no SUMO process).

The fake replays scripted vehicle states on the bundled highway network, so every
expected energy is a hand calculation: P = Σ c·term with θ from the network geometry.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sumo_drvpw.model.constants import G
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.errors import UserError
from sumo_drvpw.sim import VTypeResolver
from sumo_drvpw.sim.ledger import LEDGER_CATEGORIES, EquationSet, Ledger
from sumo_drvpw.sim.loop import Physics
from sumo_drvpw.sim.stepping import run_loop
from sumo_drvpw.sim.network import load_network
from sumo_drvpw.sim.scenario import RoadClassRule, load_scenario
from sumo_drvpw.model.terms import Inputs

REPO = Path(__file__).resolve().parent.parent
NETS = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks"  # the built-in networks
NET = load_network(NETS / "highway.net.xml", RoadClassRule())
GRADE = math.atan(0.04)  # e12: +40 m over 1000 m
#: everything read from the (scripted) getters every step, as the hand calculations assume
GETTERS = dict(acceleration="getter", slope_reference="getslope", heading="getangle",
               positions="getter")


class _Sim:
    def __init__(self, fake):
        self.f = fake

    def getDeltaT(self):
        return self.f.dt

    def getTime(self):
        return self.f.t

    def getMinExpectedNumber(self):
        return int(self.f.k < len(self.f.script))

    def getDepartedIDList(self):
        return self.f.departed


class _Veh:
    def __init__(self, fake):
        self.f = fake

    def getIDList(self):
        return tuple(self.f.state)

    def getTypeID(self, vid):
        return self.f.types[vid]

    def __getattr__(self, name):  # getSpeed, getAcceleration, ... from the scripted state
        key = {"getSpeed": 0, "getAcceleration": 1, "getAngle": 2, "getLaneID": 3,
               "getLanePosition": 4, "getSlope": 5}[name]
        return lambda vid: self.f.state[vid][key]


class FakeConnection:
    """Replays ``script``: a list of steps, each {vehicle: (v, a, angle, lane, pos, slope_deg)}."""

    def __init__(self, script, types, dt=1.0):
        self.script, self.types, self.dt = script, types, dt
        self.t, self.k, self.state, self.departed = 0.0, 0, {}, ()
        self.simulation, self.vehicle = _Sim(self), _Veh(self)

    def simulationStep(self):
        before = set(self.state)
        self.state = self.script[self.k]
        self.departed = tuple(v for v in self.state if v not in before)
        self.k += 1
        self.t += self.dt


def _resolver(mass, n_eq=2):
    return lambda vt, vid: (mass.get(vt, np.nan), np.ones(n_eq), vt in mass)


def test_loop_books_hand_calculated_energies():
    eqs = [Equation("phys", {"acc": 1.0, "grade": 1.0, "aero_rho": 0.6, "roll": 0.01}),
           Equation("fixed", {"acc": 1.0, "grade": 1.0}, mass_kg=1000.0)]
    slope_deg = math.degrees(GRADE)
    script = [
        {"a": (20.0, 0.0, 90.0, "e12_0", 100.0, slope_deg)},
        {"a": (20.0, 0.5, 90.0, "e12_0", 120.0, slope_deg),
         "b": (10.0, -1.0, 90.0, "e01_0", 50.0, 30.0)},   # getSlope noise: corrected
        {"a": (21.0, 0.0, 90.0, ":h2_0_0", 0.05, 0.0),    # internal lane → e23
         "b": (9.0, -1.0, 90.0, "e01_0", 60.0, 0.0),
         "p": (5.0, 0.0, 90.0, "e01_1", 10.0, 0.0),       # a type not accounted
         "t": (7.0, 0.0, 90.0, "", 0.0, 0.0)},            # teleporting: no lane
    ]
    types = {"a": "car", "b": "car", "p": "bus", "t": "car"}
    conn = FakeConnection(script, types, dt=0.5)
    led = Ledger(len(NET.edge_ids), 2)
    phys = Physics(wind_speed=2.0, wind_from_deg=270.0, rho=1.2, slope_tol=0.01, **GETTERS)
    info = run_loop(conn, NET, EquationSet(eqs), led, phys, _resolver({"car": 1500.0}))
    assert info == {"interrupted": False, "end_time_s": 1.5, "step_length_s": 0.5,
                    "step_method": "euler"}
    assert led.steps == 3 and led.samples == 5
    assert led.corrected == 1  # b at step 2: getSlope 30° vs a flat lane

    # the acc term takes the step's mean speed v − a·Δt/2 (kinetic-energy change / Δt)
    def p_phys(v, a, th, w, m=1500.0):
        u = v - w  # eastbound (90°) with wind from 270°: tailwind +2 m/s
        return (m * (v - 0.25 * a) * a + m * G * v * math.sin(th) + 0.6 * 0.5 * 1.2 * v * u * abs(u)
                + 0.01 * m * G * v * math.cos(th))

    def p_fixed(v, a, th):
        return 1000.0 * (v - 0.25 * a) * a + 1000.0 * G * v * math.sin(th)

    # a's second step moved 20 m in 0.5 s at 20 m/s (the script is no Euler update): it books
    # the 0.8 m it rose, m·g·Δz, as sin θ = Δz/(v·Δt) = 2·sin(grade) (Network.step_grade)
    a_steps = [(20.0, 0.0, GRADE), (20.0, 0.5, math.asin(2 * math.sin(GRADE))), (21.0, 0.0, 0.0)]
    b_steps = [(10.0, -1.0, 0.0), (9.0, -1.0, 0.0)]
    ia, ib = led.veh_ids.index("a"), led.veh_ids.index("b")
    ea = sum(p_phys(v, a, th, 2.0) * 0.5 for v, a, th in a_steps)
    # (the profile's rise: the 4 % within 1e-8, what spreading its end effects over the lane leaves)
    np.testing.assert_allclose(led.veh_trac[ia, 0].sum(), ea, rtol=1e-8)
    eb = [p_phys(v, a, th, 2.0) * 0.5 for v, a, th in b_steps]
    assert all(e < 0 for e in eb)  # braking: recuperable
    np.testing.assert_allclose(led.veh_recup[ib, 0].sum(), sum(eb), rtol=1e-12)
    assert led.veh_trac[ib].sum() == 0.0
    np.testing.assert_allclose(led.veh_trac[ia, 1].sum(),
                               sum(p_fixed(v, a, th) * 0.5 for v, a, th in a_steps), rtol=1e-8)
    # per category: grade of a on e12
    g = LEDGER_CATEGORIES.index("grade")
    np.testing.assert_allclose(led.veh_trac[ia, 0, g], 3 * 1500 * G * 20 * math.sin(GRADE) * 0.5, rtol=1e-7)
    # edges: a's last step is on e23 (via the internal lane), b on e01; p and t not booked
    e12, e23, e01 = (NET.edge_ids.index(e) for e in ("e12", "e23", "e01"))
    np.testing.assert_allclose(led.edge_trac[e23, 0].sum(), p_phys(21.0, 0.0, 0.0, 2.0) * 0.5)
    np.testing.assert_allclose(led.edge_recup[e01, 0].sum(), sum(eb))
    np.testing.assert_allclose(led.edge_count[[e12, e23, e01], 0], [1, 1, 1])
    np.testing.assert_allclose(led.edge_trac.sum(0), led.veh_trac[:led.n_veh].sum(0))
    np.testing.assert_allclose(led.edge_dist.sum(), led.veh_dist[:led.n_veh].sum())
    assert led.veh_keep[led.veh_ids.index("p")] == False  # noqa: E712
    assert led.veh_dist[led.veh_ids.index("t")] == 0.0


def test_loop_stops_at_end_and_on_ctrl_c():
    script = [{"a": (10.0, 0.0, 90.0, "e01_0", float(k), 0.0)} for k in range(10)]
    conn = FakeConnection(script, {"a": "car"})
    led = Ledger(len(NET.edge_ids), 1)
    es = EquationSet([Equation("r", {"roll": 0.01})])
    run_loop(conn, NET, es, led, Physics(**GETTERS), _resolver({"car": 1000.0}, 1), end=4.0)
    assert led.steps == 4

    class Interrupting(FakeConnection):
        def simulationStep(self):
            if self.k == 6:
                raise KeyboardInterrupt
            super().simulationStep()

    conn = Interrupting(script, {"a": "car"})
    led = Ledger(len(NET.edge_ids), 1)
    info = run_loop(conn, NET, es, led, Physics(**GETTERS), _resolver({"car": 1000.0}, 1))
    assert info["interrupted"] and led.steps == 6
    # every booked step is complete: 6 × roll power × 1 s
    np.testing.assert_allclose(led.veh_trac[0, 0].sum(), 6 * 0.01 * 1000 * G * 10.0)


def test_vtype_without_mass_is_an_error():
    """Without a mass: an error when class defaults are off; else the vClass default
    (MOVES source mass), listed as an assumption."""
    import dataclasses

    sc = load_scenario(REPO / "scenarios" / "city.toml", equations=[Equation("r", {"roll": 0.01})])
    res = VTypeResolver(dataclasses.replace(sc, default_masses=False), {}, ["r"])
    with pytest.raises(UserError, match=r"vType 'prius3' of vehicle 'v0'.*no mass"):
        res("prius3", "v0")
    assert res("other", "v1")[2] is False  # not in vehicles.vtypes: not accounted, no error
    assert res.excluded == 1 and res.skipped["by_vclass"] == {}
    res = VTypeResolver(sc, {}, ["r"])
    mass, app, keep, vclass = res("prius3", "v0")
    assert (mass, keep, vclass) == (1478.8, True, "passenger")
    assert res.assumptions["prius3"]["mass_kg"] == 1478.8


def test_vclass_selects_equations_and_skips_the_rest():
    """Equations apply by vClass; vehicles of a class no equation is made for are counted
    as skipped by vClass and vType; [vclasses.X] picks equations and masses for a class."""
    from sumo_drvpw.sim.vtypes import VTypeInfo

    car = Equation("car", {"roll": 0.01}, vclasses=("passenger",))
    bus = Equation("bus", {"roll": 0.007}, vclasses=("bus", "coach"))
    files = {vt: VTypeInfo(vt, None, None, "f.xml", vc) for vt, vc in
             (("pkw", "passenger"), ("bus1", "bus"), ("bike", "bicycle"), ("coach1", "coach"))}
    sc = load_scenario(doc={"equations": ["vsp_ldv1999"], "sumo": {"net": str(
        NETS / "highway.net.xml")}, "vclasses": {"coach": {"mass_kg": 12000}}})
    res = VTypeResolver(sc, files, [car, bus])
    np.testing.assert_array_equal(res("pkw", "a")[1], [1, 0])
    assert res("bus1", "b")[:3:2] == (16556.0, True)
    np.testing.assert_array_equal(res("bus1", "b2")[1], [0, 1])
    assert res("coach1", "c")[0] == 12000.0  # the scenario's class mass, not the default
    for k in range(3):
        assert res("bike", f"k{k}")[2] is False
    assert res.skipped == {"by_vclass": {"bicycle": 3}, "by_vtype": {"bike": 3}}
    assert set(res.assumptions) == {"pkw", "bus1"}


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 40), st.integers(0, 2 ** 31 - 1))
def test_equation_set_matches_each_equation(n, seed):
    rng = np.random.default_rng(seed)
    x = Inputs(rng.uniform(0, 40, n), rng.uniform(-3, 3, n), rng.uniform(-0.1, 0.1, n),
               rng.uniform(-5, 5, n), rng.uniform(800, 3000, n), np.full(n, 1.2))
    eqs = [Equation("a", {"acc": 1.1, "grade": 1.0, "m_v1": 0.132, "m_v3": 0.000302}),
           Equation("b", {"acc": 0.99, "grade": 1.1, "aero": 0.9, "roll": 0.0129}),
           Equation("c", {"acc": 1.0, "roll_v2": 0.001, "one": 300.0}, mass_kg=1530.9)]
    pc = EquationSet(eqs).category_powers(x)
    for e, eq in enumerate(eqs):
        cp = eq.category_powers(x)
        for k, cat in enumerate(LEDGER_CATEGORIES):
            np.testing.assert_allclose(pc[:, e, k], cp.get(cat, np.zeros(n)), rtol=1e-12,
                                       atol=1e-9)
        np.testing.assert_allclose(pc[:, e].sum(1), eq.power(x), rtol=1e-12, atol=1e-9)


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2 ** 31 - 1))
def test_ledger_balances(seed):
    rng = np.random.default_rng(seed)
    led = Ledger(7, 2, capacity=2)
    for i in range(12):
        led.add_vehicle(f"v{i}", "car", 1000.0, np.array([1.0, 0.0 if i % 3 else 1.0]), True)
    # reference: every step booked directly on the edge of the vehicle at that step
    C = len(LEDGER_CATEGORIES)
    ref_tr, ref_rc, ref_d = np.zeros((7, 2, C)), np.zeros((7, 2, C)), np.zeros(7)
    edge_of = rng.integers(0, 7, 12)
    for _ in range(8):
        vidx = rng.permutation(12)[:rng.integers(1, 12)]
        moved = rng.random(len(vidx)) < 0.4  # some vehicles change edge, most stay
        edge_of[vidx[moved]] = rng.integers(0, 7, int(moved.sum()))
        eidx = edge_of[vidx]
        pc = rng.normal(0, 1e4, (len(vidx), 2, len(LEDGER_CATEGORIES)))
        pc *= led.veh_app[vidx][:, :, None]
        v = rng.uniform(0, 30, len(vidx))
        tr, rc = led.book(vidx, eidx, v, 0.5, pc)
        np.testing.assert_allclose(tr + rc, pc * 0.5)
        assert (tr.sum(2) >= 0).all() and (rc.sum(2) <= 0).all()
        np.add.at(ref_tr, eidx, tr)
        np.add.at(ref_rc, eidx, rc)
        np.add.at(ref_d, eidx, v * 0.5)
        # edge totals read mid-run include the open segments and stay right afterwards
        np.testing.assert_allclose(led.edge_trac, ref_tr, rtol=1e-9, atol=1e-6)
        np.testing.assert_allclose(led.edge_recup, ref_rc, rtol=1e-9, atol=1e-6)
        np.testing.assert_allclose(led.edge_dist, ref_d, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(led.edge_trac.sum(0), led.veh_trac[:12].sum(0), rtol=1e-10)
    np.testing.assert_allclose(led.edge_recup.sum(0), led.veh_recup[:12].sum(0), rtol=1e-10)


# ---- tracked positions ------------------------------------------------------------
# A fake SUMO that moves cars with SUMO's Euler update along the bundled highway
# (e01 → :h1_0 → e12 → …, both lanes), changing lanes now and then (same edge, same
# position) and crossing lane ends as SUMO does (x > length: next lane, x − length).
ROUTE = ["e01", ":h1_0", "e12", ":h2_0", "e23", ":h3_0", "e34", ":h4_0", "e45", ":h5_0", "e56"]


def _lane_len(lid):
    return float(NET.lane_length[NET.lane_index[lid]])


def euler_script(seed, n_veh=6, steps=60, dt=0.5, jump=None):
    """Steps of {vid: (v, a, angle, lane, pos, slope)}; ``jump=(step, vid, metres)``
    moves a car without speed (what a teleport or moveTo does) to test the full reads."""
    rng = np.random.default_rng(seed)
    cars = {}  # vid → [route index, lane suffix, pos, v]
    script = []
    for k in range(steps):
        if len(cars) < n_veh and rng.random() < 0.5:  # departures at random places
            cars[f"c{len(cars)}"] = [2 * int(rng.integers(0, 4)), int(rng.integers(0, 2)),
                                     float(rng.uniform(0, 900)), 0.0]
        state = {}
        for vid, c in list(cars.items()):
            v_old = c[3]
            v = float(np.clip(v_old + rng.normal(0, 1.5), 0, 40)) if rng.random() > 0.1 else 0.0
            c[2] += v * dt
            if jump is not None and (k, vid) == jump[:2]:
                c[2] += jump[2]
            while c[2] > _lane_len(f"{ROUTE[c[0]]}_{c[1]}") and c[0] < len(ROUTE) - 1:
                c[2] -= _lane_len(f"{ROUTE[c[0]]}_{c[1]}")
                c[0] += 1
            if c[0] == len(ROUTE) - 1 and c[2] > 900:  # arrival
                del cars[vid]
                continue
            if not ROUTE[c[0]].startswith(":") and rng.random() < 0.05:
                c[1] = 1 - c[1]  # lane change: same edge, same position
            c[3] = v
            state[vid] = (v, (v - v_old) / dt, 90.0, f"{ROUTE[c[0]]}_{c[1]}", c[2], 0.0)
        script.append(state)
    return script


class EulerFake(FakeConnection):
    """The fake SUMO as it reports itself: Euler update; lane/position reads counted."""

    def __init__(self, script, types, dt=0.5):
        super().__init__(script, types, dt)
        self.simulation.getOption = lambda key: "false" if key == "step-method.ballistic" else ""
        self.simulation.getEndingTeleportIDList = lambda: ()
        self.lane_reads = 0
        veh = self.vehicle

        class Counting(type(veh)):
            def __getattr__(inner, name):
                g = _Veh.__getattr__(inner, name)
                if name != "getLaneID":
                    return g

                def counted(vid):
                    self.lane_reads += 1
                    return g(vid)
                return counted
        self.vehicle = Counting(self)


def _run(conn, positions):
    led = Ledger(len(NET.edge_ids), 2)
    eqs = [Equation("phys", {"acc": 1.0, "grade": 1.0, "aero": 0.8, "roll": 0.01}),
           Equation("g", {"grade": 1.0})]
    phys = Physics(positions=positions, resync_steps=10)
    run_loop(conn, NET, EquationSet(eqs), led, phys, _resolver({"car": 1500.0}))
    return led


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2 ** 31 - 1))
def test_tracked_positions_equal_read_positions(seed):
    """Tracking lane and position under the Euler update books exactly what reading them
    every step books, with far fewer reads, and the full reads find no disagreement."""
    script = euler_script(seed)
    types = {f"c{i}": "car" for i in range(6)}
    read, tracked = EulerFake(script, types), EulerFake(script, types)
    a, b = _run(read, "getter"), _run(tracked, "tracked")
    assert a.samples == b.samples
    n = a.n_veh
    np.testing.assert_allclose(b._veh_energy[:n], a._veh_energy[:n], rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(b.edge_trac, a.edge_trac, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(b.edge_dist, a.edge_dist, rtol=1e-12, atol=1e-9)
    np.testing.assert_array_equal(b.edge_count, a.edge_count)
    assert b.position_mismatches == 0 and b.position_reads == tracked.lane_reads
    assert read.lane_reads == a.samples
    if a.samples > 100:
        assert tracked.lane_reads < 0.5 * read.lane_reads


def test_tracking_counts_and_repairs_a_jump():
    """A car moved without speed (like moveTo) is caught at the next full read: counted
    as a disagreement, and from then on its position is right again."""
    script = euler_script(3, n_veh=2, steps=40, jump=(12, "c0", 30.0))
    types = {"c0": "car", "c1": "car"}
    a, b = _run(EulerFake(script, types), "getter"), _run(EulerFake(script, types), "tracked")
    assert b.position_mismatches == 1  # found at the full read of step 20
    assert a.position_mismatches == 0
    # between the jump and the full read the tracked car's grade lookups lag 30 m; after it
    # they agree again, so only those steps differ: distance stays exact (v·Δt)
    np.testing.assert_allclose(b.veh_dist[:2], a.veh_dist[:2], rtol=1e-12)


def test_tracking_off_without_euler_update():
    """A connection that does not say it integrates with Euler (here: the plain fake) is
    read every step whatever Physics.positions says."""
    script = euler_script(5, n_veh=3, steps=20)
    conn = FakeConnection(script, {f"c{i}": "car" for i in range(3)}, dt=0.5)
    led = _run(conn, "tracked")
    assert led.position_reads == 0 and led.samples > 0


def test_equations_applied_per_vtype():
    """A vType may name its equations: the others book nothing for its vehicles, also when
    such a vehicle departs after vehicles that take every equation."""
    script = [{"a": (10.0, 0.0, 90.0, "e01_0", 10.0, 0.0)},
              {"a": (10.0, 0.0, 90.0, "e01_0", 20.0, 0.0),
               "b": (20.0, 0.0, 90.0, "e01_1", 50.0, 0.0)}]
    apps = {"all": np.array([1.0, 1.0]), "only_g": np.array([0.0, 1.0])}
    types = {"a": "all", "b": "only_g"}
    led = Ledger(len(NET.edge_ids), 2)
    eqs = [Equation("roll", {"roll": 0.01}), Equation("aero", {"aero": 0.6})]
    run_loop(FakeConnection(script, types, dt=0.5), NET, EquationSet(eqs), led,
             Physics(**GETTERS), lambda vt, vid: (1000.0, apps[vt], True))
    ia, ib = led.veh_ids.index("a"), led.veh_ids.index("b")
    np.testing.assert_allclose(led.veh_trac[ia, 0].sum(), 2 * 0.01 * 1000 * G * 10.0 * 0.5)
    assert led.veh_trac[ib, 0].sum() == 0.0  # roll does not apply to b
    # "aero" is v·(v − w)·|v − w| (the ½ρ·Cd·A lives in the coefficient), no wind here
    np.testing.assert_allclose(led.veh_trac[ib, 1].sum(), 0.6 * 20.0 ** 3 * 0.5)
    np.testing.assert_array_equal(led.edge_count[NET.edge_ids.index("e01")], [1, 2])


@settings(max_examples=40, deadline=None)
@given(speeds=st.lists(st.floats(0.0, 40.0), min_size=1, max_size=40),
       dt=st.sampled_from([0.1, 0.25, 0.5, 1.0, 2.0]), coef=st.floats(0.5, 1.5))
def test_acc_energy_is_the_kinetic_energy_change(speeds, dt, coef):
    """Any speed history from rest to rest at any Δt: the acc term's net energy is 0 to
    rounding, and at every step the running net equals coef·½m·v_t² (the loop books
    coef·m·v̄·a·Δt = coef·½m(v_t² − v_t−1²))."""
    m = 1300.0
    vs = [0.0, *speeds, 0.0]
    script = [{"a": (v, 0.0, 90.0, "e01_0", 10.0, 0.0)} for v in vs]
    led = Ledger(len(NET.edge_ids), 1)
    run_loop(FakeConnection(script, {"a": "car"}, dt=dt), NET,
             EquationSet([Equation("k", {"acc": coef})]), led,
             Physics(positions="getter", slope_reference="getslope"),
             _resolver({"car": m}, 1))
    net = led.veh_trac[0, 0].sum() + led.veh_recup[0, 0].sum()
    scale = coef * 0.5 * m * max(vs) ** 2 + 1.0
    assert abs(net) <= 1e-9 * scale
    gained = led.veh_trac[0, 0].sum()
    assert gained == pytest.approx(coef * 0.5 * m * sum(
        max(b * b - a * a, 0.0) for a, b in zip(vs, vs[1:])), rel=1e-9, abs=1e-6)
