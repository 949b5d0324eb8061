"""Edges only rail vehicles (or ships, aircraft) may use are a class of their own, not a road
class by their speed: a tram line at 90 km/h was booked as "highway", one at 50 km/h as
"city" (sim/scenario.py NON_ROAD_CLASSES, sim/network.load_network)."""

from __future__ import annotations

import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.network import load_network
from sumo_drvpw.sim.scenario import RoadClassRule, non_road_class
from sumo_probe import build_net

NODES = """<nodes>
<node id="a" x="0" y="0"/><node id="b" x="400" y="0"/><node id="c" x="800" y="0"/>
<node id="ta" x="0" y="100"/><node id="tb" x="400" y="100"/><node id="tc" x="800" y="100"/>
<node id="sa" x="0" y="200"/><node id="sb" x="400" y="200"/><node id="sc" x="800" y="200"/>
<node id="wa" x="0" y="300"/><node id="wb" x="400" y="300"/>
</nodes>"""
# a road (r1, r2: city by speed); a tram line, one edge at 90 km/h (highway by speed and by
# a highway type) and one at 50 km/h; a street with a tram and buses (a road), a tram line
# pedestrians may walk on (rail), a canal (waterway)
EDGES = """<edges>
<edge id="r1" from="a" to="b" numLanes="1" speed="13.89"/>
<edge id="r2" from="b" to="c" numLanes="1" speed="13.89"/>
<edge id="t1" from="ta" to="tb" numLanes="1" speed="25" allow="tram" type="highway.trunk"/>
<edge id="t2" from="tb" to="tc" numLanes="1" speed="13.89" allow="tram"/>
<edge id="s1" from="sa" to="sb" numLanes="1" speed="13.89" allow="tram bus"/>
<edge id="s2" from="sb" to="sc" numLanes="1" speed="25" allow="tram pedestrian"/>
<edge id="w1" from="wa" to="wb" numLanes="1" speed="5" allow="ship"/>
</edges>"""
ROUTES = """<routes>
<vType id="car" vClass="passenger" mass="1500"/>
<vType id="tr" vClass="tram" mass="40000" length="30" accel="1.0"/>
<vehicle id="c0" type="car" depart="0"><route edges="r1 r2"/></vehicle>
<vehicle id="t0" type="tr" depart="0"><route edges="t1 t2"/></vehicle>
</routes>"""
SCENARIO = """equations = ["moves_passenger_car", "moves_transit_bus"]
[sumo]
net = "n.net.xml"
routes = ["r.rou.xml"]
end = 200
step_length = 1
options = ["--no-warnings", "true"]
[vclasses.tram]
equations = ["moves_transit_bus"]
[vclasses.passenger]
equations = ["moves_passenger_car"]
[outputs]
figures = false
"""


@pytest.fixture(scope="module")
def tram_net(tmp_path_factory):
    d = tmp_path_factory.mktemp("tram")
    build_net(d, NODES, EDGES)
    (d / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    (d / "s.toml").write_text(SCENARIO, encoding="utf-8")
    return d


def test_rail_and_water_edges_are_classed_apart_from_roads(tram_net):
    net = load_network(tram_net / "n.net.xml", RoadClassRule())
    cls = dict(zip(net.edge_ids, net.edge_class))
    assert {e: cls[e] for e in ("r1", "r2", "t1", "t2", "s1", "s2", "w1")} == {
        "r1": "city", "r2": "city", "t1": "rail", "t2": "rail", "s1": "city", "s2": "rail",
        "w1": "waterway"}
    assert net.classes[:2] == ["city", "highway"] and {"rail", "waterway"} <= set(net.classes)
    # the user's maps still win: an edge id, or an edge type, named in [road_class]
    rule = RoadClassRule(types={"highway.trunk": "trunk"}, edges={"t2": "tramway"})
    cls = dict(zip(net.edge_ids, load_network(tram_net / "n.net.xml", rule).edge_class))
    assert (cls["t1"], cls["t2"], cls["s2"]) == ("trunk", "tramway", "rail")


def test_a_tram_books_on_rail_and_the_totals_agree(tram_net):
    res = run_scenario(tram_net / "s.toml", tram_net / "out", figures=False)
    veh = pd.read_parquet(tram_net / "out" / "vehicles.parquet")
    edges = pd.read_parquet(tram_net / "out" / "edges.parquet")
    classes = pd.read_parquet(tram_net / "out" / "classes.parquet")
    tram = veh[veh["vehicle"] == "t0"].iloc[0]
    assert tram["equation"] == "moves_transit_bus" and tram["distance_m"] > 700
    bus = classes[classes["equation"] == "moves_transit_bus"].groupby("class")["traction_energy_j"].sum()
    car = classes[classes["equation"] == "moves_passenger_car"].groupby("class")["traction_energy_j"].sum()
    # the tram's energy all on rail, none on the road classes its speed would give; the car's in the city
    assert bus["rail"] == pytest.approx(tram["traction_total_j"], rel=1e-9) and bus["rail"] > 0
    assert bus.drop("rail").abs().sum() == 0
    assert car["city"] > 0 and car.drop("city").abs().sum() == 0
    summ = res.summary["equations"]["moves_transit_bus"]
    assert summ["distance_m"]["rail"] == pytest.approx(tram["distance_m"], rel=1e-9)
    assert summ["distance_m"]["highway"] == summ["distance_m"]["city"] == 0
    # vehicle, edge and class totals agree per equation (traction, recuperable, distance)
    for name in ("moves_passenger_car", "moves_transit_bus"):
        v, e = veh[veh["equation"] == name], edges[edges["equation"] == name]
        c = classes[classes["equation"] == name]
        for col, ccol in (("traction_total_j", "traction_energy_j"), ("recup_total_j", "recup_energy_j")):
            assert e[col].sum() == pytest.approx(v[col].sum(), rel=1e-9, abs=1e-6)
            assert c[ccol].sum() == pytest.approx(v[col].sum(), rel=1e-9, abs=1e-6)
        assert sum(res.summary["equations"][name]["distance_m"].values()) == pytest.approx(
            v["distance_m"].sum(), rel=1e-9)
        assert e["distance_m"].sum() == pytest.approx(v["distance_m"].sum(), rel=1e-9)


@pytest.mark.parametrize("allowed, want", [
    ({"tram"}, "rail"), ({"rail", "rail_electric", "subway"}, "rail"), ({"cable_car"}, "rail"),
    ({"tram", "pedestrian", "wheelchair"}, "rail"), ({"ship"}, "waterway"), ({"aircraft"}, "air"),
    ({"tram", "bus"}, None), ({"ship", "rail"}, None), ({"pedestrian"}, None), (set(), None),
    (None, None), ({"passenger", "tram"}, None), ({"bicycle", "tram"}, None)])
def test_non_road_class_of_an_edges_permissions(allowed, want):
    assert non_road_class(allowed) == want
    rule = RoadClassRule()
    assert rule.classify("e", "", 30.0, allowed) == (want or "highway")
    assert rule.classify("e", "", 10.0, allowed) == (want or "city")


@pytest.mark.parametrize("table, value", [
    ("edges", "city "), ("edges", "Rail"), ("types", " highway"), ("types", "WATERWAY"), ("edges", "Air"),
])
def test_a_class_that_is_a_built_in_one_but_for_case_or_spaces_is_refused(tram_net, table, value):
    """`edges = { t2 = "Rail" }` put t2 in a class 'Rail' beside the 'rail' of the other tram
    edges (and 'city ' beside 'city'): one class split in two in every output by class, exit 0."""
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.sim.scenario import load_scenario

    key = "t2" if table == "edges" else "highway.trunk"
    text = SCENARIO.replace("[outputs]", f'[road_class]\n{table} = {{ "{key}" = "{value}" }}\n[outputs]')
    (tram_net / "odd.toml").write_text(text, encoding="utf-8")
    with pytest.raises(UserError, match=rf"odd.toml: 'road_class.{table}.{key}' .*'{value.strip().lower()}'"):
        load_scenario(tram_net / "odd.toml")
    (tram_net / "odd.toml").write_text(text.replace(value, "tramway "), encoding="utf-8")  # a class of its own, spaced
    with pytest.raises(UserError, match=rf"odd.toml: 'road_class.{table}.{key}' 'tramway ' has spaces"):
        load_scenario(tram_net / "odd.toml")
    ok = SCENARIO.replace("[outputs]", f'[road_class]\n{table} = {{ "{key}" = "tramway" }}\n[outputs]')
    (tram_net / "ok.toml").write_text(ok, encoding="utf-8")
    assert "tramway" in load_scenario(tram_net / "ok.toml").road_class.classes
