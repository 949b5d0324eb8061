"""A step's fixed cost: what a SUMO step books does not scale with the network's size nor
with equations no vehicle of the step books (benchmarks/run_ratio.py measures the run)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.model.terms import Inputs
from sumo_drvpw.sim.chain import ChainLedger
from sumo_drvpw.sim.ledger import EquationSet


def _count_add_at(monkeypatch, module) -> list:
    """``module``'s numpy replaced by one whose np.add.at calls are counted: the list they append to."""
    calls = []

    class Spy:  # numpy, with np.add.at's calls counted (np.add is a ufunc)
        def __getattr__(self, name):
            return getattr(np, name)

        class add:
            @staticmethod
            def at(*a):
                calls.append(1)
                return np.add.at(*a)

    monkeypatch.setattr(module, "np", Spy())
    return calls


def test_chain_book_works_on_the_steps_edges_only(monkeypatch):
    """ChainLedger.book adds each booked column over the edges of the step's vehicles, not
    over an array as long as the network (13,000 edges in a port scenario: most of a step
    of five vehicles); the totals are those of a per-edge sum over every edge."""
    fuel = EnergyChain(predicts="fuel", idle_fuel_power_w=4000.0, marginal_efficiency=0.35)
    bat = EnergyChain(predicts="battery", aux_power_w=300.0)
    n_edges, rng = 50_000, np.random.default_rng(3)
    led = ChainLedger(["f", "b"], [fuel, bat], n_edges)
    want_edge = np.zeros((n_edges, 2, 8))
    lengths = []
    real = np.bincount

    def spy(x, weights=None, minlength=0):
        lengths.append(minlength)
        return real(x, weights, minlength)

    monkeypatch.setattr(np, "bincount", spy)
    for k in range(40):
        n = 4
        vidx = np.arange(n)  # some steps one vehicle per edge, some several on one
        eidx = rng.permutation([7, 123, 49_999, 2]) if k % 2 else rng.choice([7, 7, 123, 49_999, 2], n)
        calls = len(lengths)
        full = led.expand(led.book(vidx, eidx, rng.uniform(0, 20, n), 0.5, rng.normal(0, 2e4, (n, 2))))
        assert not (k % 2 and len(lengths) > calls), "a bincount for a step of one vehicle per edge"
        for e in range(2):  # the step's quantities summed per edge over the whole network, as before
            for q in range(8):
                want_edge[:, e, q] += real(eidx, full[:, e, q], minlength=n_edges)
    assert max(lengths) <= 4, f"bincount over {max(lengths)} bins for 4 vehicles"
    np.testing.assert_array_equal(led.edge, want_edge)  # to the last bit


def test_equation_booking_no_vehicle_of_the_step_is_not_evaluated():
    """An equation that applies to no vehicle of the step is not evaluated (its rows are 0):
    one needing a signal the step lacks raises nothing, and the others' powers are those they
    have alone."""
    n, rng = 6, np.random.default_rng(1)
    x = Inputs(rng.uniform(0, 40, n), rng.uniform(-3, 3, n), rng.uniform(-0.1, 0.1, n),
               rng.uniform(-5, 5, n), rng.uniform(800, 3000, n), np.full(n, 1.2))
    eqs = [Equation("a", {"acc": 1.1, "grade": 1.0, "m_v1": 0.132}),
           Equation("needs_load", {"acc": 1.0, "[heater_w]": 1.0}),
           Equation("c", {"acc": 1.0, "roll_v2": 0.001, "one": 300.0}, mass_kg=1530.9)]
    app = np.ones((n, 3))
    app[:, 1] = 0.0
    app[:2, 2] = 0.0
    es = EquationSet(eqs)
    pc = es.category_powers(x, app)
    assert not pc[:, 1].any()
    alone = EquationSet([eqs[0], eqs[2]]).category_powers(x, app[:, [0, 2]])
    np.testing.assert_array_equal(pc[:, [0, 2]], alone)
    # the cached selection follows the step's vehicles: now the second equation books one
    app[3, 1] = 1.0
    x.signals["heater_w"] = np.full(n, 500.0)
    pc = es.category_powers(x, app)
    assert pc[3, 1].sum() != 0 and not pc[[0, 1, 2, 4, 5], 1].any()


_RING_ROUTES = """<routes>
  <vType id="car" vClass="passenger" mass="1500" emissionClass="HBEFA4/PC_petrol_Euro-4"/>
  <vType id="ev" vClass="passenger" mass="1600" emissionClass="Energy/unknown"/>
  <route id="ring" edges="a b c d a b c d a b c d"/>
  <vehicle id="v0" type="car" route="ring" depart="0" departSpeed="0"/>
  <vehicle id="v1" type="ev" route="ring" depart="3" departSpeed="0">
    <stop lane="b_0" endPos="150" duration="25" parking="true"/>
  </vehicle>
  <vehicle id="v2" type="car" route="ring" depart="6" departSpeed="max" departLane="1"/>
  <vehicle id="v3" type="car" route="ring" depart="40" departSpeed="0"/>
</routes>
"""


def _flat_ring(d) -> "Path":
    """A ring of four 200-m edges, two lanes each, without any z: cars, an electric car that
    parks on the way, a SUMO config of 240 s at 0.5-s steps."""
    import subprocess

    import sumolib

    xy = [(0, 0), (200, 0), (200, 200), (0, 200)]
    (d / "n.nod.xml").write_text("<nodes>" + "".join(
        f'<node id="n{i}" x="{x}" y="{y}"/>' for i, (x, y) in enumerate(xy)) + "</nodes>", encoding="utf-8")
    (d / "n.edg.xml").write_text("<edges>" + "".join(
        f'<edge id="{e}" from="n{i}" to="n{(i + 1) % 4}" numLanes="2" speed="13.89"/>'
        for i, e in enumerate("abcd")) + "</edges>", encoding="utf-8")
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "n.net.xml",
                    "--no-turnarounds"], check=True, capture_output=True, cwd=d)
    (d / "r.rou.xml").write_text(_RING_ROUTES, encoding="utf-8")
    (d / "ring.sumocfg").write_text(
        '<configuration><input><net-file value="n.net.xml"/><route-files value="r.rou.xml"/></input>'
        '<time><begin value="0"/><end value="240"/><step-length value="0.5"/></time></configuration>',
        encoding="utf-8")
    return d / "ring.sumocfg"


def test_a_network_without_elevation_books_its_grade_without_step_grade(tmp_path, monkeypatch):
    """On a network with no z anywhere the step's grade is the slope where the vehicle
    stands (0, or a parking space's) and nothing is carried: the loop skips Network.step_grade
    (a tenth of a step of five cars) and writes the same rows. The run's outputs are byte for
    byte those of the run that calls it; a network with elevation is not taken for flat."""
    import json

    from sumo_drvpw.sim import loop, run_scenario
    from sumo_drvpw.sim.network import Network, load_network
    from sumo_drvpw.sim.scenario import RoadClassRule

    (tmp_path / "in").mkdir()
    cfg = _flat_ring(tmp_path / "in")
    calls, real = [], Network.step_grade

    def spy(self, *a, **kw):
        calls.append(1)
        return real(self, *a, **kw)

    monkeypatch.setattr(Network, "step_grade", spy)
    run_scenario(cfg, tmp_path / "flat", figures=False, progress=False)
    assert calls == []
    monkeypatch.setattr(loop, "flat_network", lambda net: False)
    run_scenario(cfg, tmp_path / "graded", figures=False, progress=False)
    assert len(calls) > 400  # (the run the shortcut must equal: step_grade every step)
    for name in ("vehicles.parquet", "edges.parquet", "classes.parquet", "edgedata.xml", "chain_vehicles.csv"):
        assert (tmp_path / "flat" / name).read_bytes() == (tmp_path / "graded" / name).read_bytes(), name
    a, b = (json.loads((tmp_path / f / "summary.json").read_text()) for f in ("flat", "graded"))
    for s in (a, b):
        s.pop("wall_time_s")
        s.get("network", {}).pop("table", None)
    assert a == b
    assert a["vehicles"] == 4
    hilly = load_network(Path(loop.__file__).parent / "builtin" / "networks" / "highway.net.xml", RoadClassRule())
    assert not loop.flat_network(hilly)


def test_a_few_vehicles_term_powers_are_added_in_one_call_per_group(monkeypatch):
    """At up to 32 vehicles a group's term powers go into their (equation, category) rows in one
    np.add.at (one add per term and equation before: most of category_powers at five cars),
    at more one add each; either way bit for bit the sum, term by term in each equation's
    order, of coefficient × term value."""
    from sumo_drvpw.model.terms import parse_term
    from sumo_drvpw.sim import ledger as L

    eqs = [Equation("a", {"acc": 1.1, "grade": 1.0, "m_v1": 0.132, "m_v3": 3e-4}),
           Equation("b", {"v1": 156.4, "v2": 2.0, "v3": 0.49, "acc": 1.0, "grade": 1.0}, mass_kg=1478.8),
           Equation("c", {"roll": 0.0096, "v2": 2.11, "aero_rho": 0.72, "acc": 1.0, "grade": 1.0})]
    calls = _count_add_at(monkeypatch, L)
    rng = np.random.default_rng(4)
    for n, want_calls in ((5, 2), (100, 0)):
        x = Inputs(rng.uniform(0, 40, n), rng.uniform(-3, 3, n), rng.uniform(-0.1, 0.1, n),
                   rng.uniform(-5, 5, n), rng.uniform(800, 3000, n), np.full(n, 1.2))
        calls.clear()
        pc = EquationSet(eqs).category_powers(x, np.ones((n, 3)))
        assert len(calls) == want_calls, n
        want = np.zeros((n, 3, len(L.LEDGER_CATEGORIES)))
        for e, eq in enumerate(eqs):
            xm = x.with_mass(eq.mass_kg)
            for t, c in eq.terms.items():
                want[:, e, L.LEDGER_CATEGORIES.index(parse_term(t).category)] += c * parse_term(t).evaluate(xm)
        np.testing.assert_array_equal(pc, want)


def test_the_edge_table_takes_its_names_by_index_arrays_not_row_by_row():
    """edges.parquet's name columns (edge, equation, class, type) are taken from the network's
    lists by index arrays, not read per row in Python (edges × equations rows: 700,000 on a
    city's network with a bare config's equations); each row names its edge and equation."""
    from types import SimpleNamespace

    from sumo_drvpw.sim.ledger import Ledger
    from sumo_drvpw.sim.outputs import edges_table

    class Counted(list):  # a list whose reads by index are counted
        reads = 0

        def __getitem__(self, i):
            Counted.reads += 1
            return super().__getitem__(i)

    n, names = 40, ["a", "b", "c"]
    net = SimpleNamespace(edge_ids=Counted(f"e{i}" for i in range(n)), edge_class=Counted(["urban", "motorway"] * (n // 2)),
                          edge_type=Counted([None if i % 7 == 0 else f"t{i % 3}" for i in range(n)]),
                          edge_length=np.full(n, 100.0), edge_speed=np.full(n, 13.9))
    t = edges_table(Ledger(n, len(names)), net, names)
    assert Counted.reads == 0
    assert t.column("edge").to_pylist() == [f"e{i}" for i in range(n) for _ in names]
    assert t.column("equation").to_pylist() == names * n
    assert t.column("class").to_pylist() == [c for c in net.edge_class for _ in names]
    assert t.column("type").to_pylist() == [c for c in net.edge_type for _ in names]
    assert str(t.schema.field("type").type) == "string"


def test_class_energy_sums_the_edges_of_each_class_in_their_order_without_np_add_at(monkeypatch):
    """The road classes' energies (classes.parquet, the summary) are per class the sum over its
    edges in their order, bit for bit what np.add.at adds (signed zeros too), by a bincount per
    equation and category (np.add.at over a city's edges × equations × categories was slower)."""
    from types import SimpleNamespace

    from sumo_drvpw.sim import outputs as O
    from sumo_drvpw.sim.ledger import Ledger

    n, E, rng = 300, 3, np.random.default_rng(9)
    led = Ledger(n, E)
    C = led.C
    trac, recup = rng.normal(size=(n, E, C)), rng.normal(size=(n, E, C))
    trac[rng.uniform(size=trac.shape) < 0.5] = -0.0
    monkeypatch.setattr(Ledger, "edge_trac", property(lambda self: trac))
    monkeypatch.setattr(Ledger, "edge_recup", property(lambda self: recup))
    classes = ["urban", "rural", "motorway", "unused"]
    net = SimpleNamespace(classes=classes, edge_class=[classes[i] for i in rng.integers(0, 3, n)])
    calls = _count_add_at(monkeypatch, O)
    got_classes, tr, rc = O.class_energy(led, net)
    assert calls == [] and got_classes == classes
    k = np.array([classes.index(c) for c in net.edge_class])
    for got, x in ((tr, trac), (rc, recup)):
        want = np.zeros((len(classes), E, C))
        np.add.at(want, k, x)
        assert got.tobytes() == want.tobytes()
    monkeypatch.undo()  # (the ledger's own, empty, edge totals)
    empty = O.class_energy(Ledger(0, E), SimpleNamespace(classes=[], edge_class=[]))
    assert empty[1].shape == (0, E, C)
