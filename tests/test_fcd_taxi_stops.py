"""An idle taxi waits at its declared stop until it is dispatched (SUMO's taxi device turns
its next stop into a triggered one: MSIdling_Stop), parked past the stop's planned end.
An FCD replay without signals took it for a car whose parking was over and whose way out
was blocked, and booked it idling until it drove off (sim/fcd_taxi.py, sim/fcd_stops.py).
Real SUMO runs on a straight road: taxis equipped by every way SUMO equips them."""

from __future__ import annotations

import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd
from sumo_drvpw.sim.fcd_taxi import TaxiDevices
from sumo_probe import build_net, device_step, energy_scenario

pytestmark = pytest.mark.sumo

TAXI = '<param key="has.taxi.device" value="true"/>'


def _booked(out):
    v = pd.read_parquet(out / "vehicles.parquet").groupby("vehicle")[["time_s"]].first()
    c = pd.read_csv(out / "chain_vehicles.csv").set_index("key")
    return v.join(c[["fuel_l"]]).sort_index()


def test_idle_taxis_parked_past_their_stops_planned_end_book_as_live(tmp_path):
    """DLR's port_lübeck (SUMO 1.28, 3600 s): five container taxis (vType param
    has.taxi.device) with a 10-s stop at a containerStop stayed parked there up to 470 s;
    the replay booked them idling from the stop's planned end: its trucks' diesel 65.43 L
    against the live run's 63.57 (+2.9 %). Here, before the fix (2026-11-29): the container
    taxi 0.264 L against 0.0195 L live (192 s booked against 14), the car taxi 0.080 against
    0.030 L. A car that is no taxi, parked for 10 s, is booked as before (its way out free)."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="900" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="15"/></edges>')
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="tt" vClass="truck" mass="9000" containerCapacity="1"/>'
        f'<vType id="tc" vClass="passenger" mass="1500"/><vType id="tf" vClass="passenger" mass="1500">{TAXI}</vType>'
        f'<vehicle id="ttaxi" type="tt" depart="0"><route edges="e"/>{TAXI}<stop containerStop="cs" duration="10"/>'
        f'</vehicle><vehicle id="ctaxi" type="tc" depart="1"><route edges="e"/>{TAXI}'
        '<stop lane="e_0" endPos="300" duration="10" parking="true"/></vehicle>'
        '<vehicle id="xtaxi" type="tc" depart="2"><route edges="e"/>'
        '<stop lane="e_0" endPos="400" duration="10" parking="true"/></vehicle>'
        '<flow id="f" type="tf" begin="3" number="2" period="2"><route edges="e"/>'
        '<stop lane="e_0" endPos="500" duration="10" parking="true"/></flow>'
        '<vehicle id="car" type="tc" depart="8"><route edges="e"/>'
        '<stop lane="e_0" endPos="700" duration="10" parking="true"/></vehicle></routes>', encoding="utf-8")
    (tmp_path / "a.add.xml").write_text(
        '<additional><containerStop id="cs" lane="e_0" startPos="100" endPos="130"/></additional>', encoding="utf-8")
    sc = energy_scenario(tmp_path, 200, step_length=1.0, additional="a.add.xml", fcd=True)
    sc.write_text(sc.read_text(encoding="utf-8").replace('equations = ["vtype_energy"]\n', "").replace(
        '"--fcd-output",', '"--device.taxi.explicit", "xtaxi", "--fcd-output",'), encoding="utf-8")
    run_scenario(sc, tmp_path / "live")
    live = _booked(tmp_path / "live")
    res = process_fcd(tmp_path / "fcd.xml", scenario=sc, out_dir=tmp_path / "rep", figures=False)
    taxis = ["ctaxi", "f.0", "f.1", "ttaxi", "xtaxi"]
    assert (live.loc[taxis, "time_s"] < 100).all()  # parked from their stop to the end at 200 s
    pd.testing.assert_frame_equal(_booked(tmp_path / "rep"), live, rtol=1e-6)
    assert res["source"]["untold_parked_vehicles"] == len(taxis)


def test_taxi_device_as_sumo_equips_it():
    """SUMO's order: the option device.taxi.explicit, then the vehicle's (or flow's) param,
    its vType's, then device.taxi.probability (an explicit vehicle whose param says false has
    the device: test_an_explicit_taxi_has_the_device_whatever_its_params_say)."""
    opts = {"device.taxi.explicit": "a,b", "device.taxi.probability": None}
    t = TaxiDevices(opts.get)
    for el, tag in ((_el("vType", "yes", "1"), "vType"), (_el("vType", "no", "0"), "vType"),
                    (_el("vehicle", "v1", None, "yes"), "vehicle"), (_el("vehicle", "a", "false", "yes"), "vehicle"),
                    (_el("flow", "f", None, "no"), "flow"), (_el("vehicle", "b", None, "no"), "vehicle")):
        t.read(el, tag)
    assert t.has("v1", "v1") and t.has("a", "a") and not t.has("f.0", "f") and t.has("b", "b")
    assert not t.has("c", "c") and t.has("b", "unknown")  # declared nowhere: the option's list
    assert TaxiDevices({"device.taxi.probability": "0.5"}.get).has("c", "c")
    assert not TaxiDevices({"device.taxi.probability": "0"}.get).has("c", "c")
    circling = TaxiDevices({"device.taxi.idle-algorithm": "randomCircling", "device.taxi.probability": "1"}.get)
    circling.read(_el("vehicle", "v", "true"), "vehicle")
    assert not circling.has("v", "v")


def _el(tag, key, taxi, vtype=None):
    import xml.etree.ElementTree as ET

    el = ET.Element(tag, {"id": key, **({"type": vtype} if vtype else {})})
    if taxi is not None:
        ET.SubElement(el, "param", {"key": "has.taxi.device", "value": taxi})
    return el


def test_an_explicit_taxi_has_the_device_whatever_its_params_say(tmp_path):
    """SUMO 1.28 equips a vehicle --device.taxi.explicit names even where its own param or
    its vType's says has.taxi.device false; TaxiDevices took the param first, so such a
    taxi's stops were replayed as planned (its idle wait booked idling, not parked)."""
    import xml.etree.ElementTree as ET

    import traci  # (its own SUMO process: libsumo keeps a device's explicit ids of an earlier run)

    net = build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="900" y="0"/></nodes>',
                    '<edges><edge id="e" from="a" to="b" numLanes="1" speed="15"/></edges>')
    no = '<param key="has.taxi.device" value="false"/>'
    routes = (f'<routes><vType id="off" vClass="passenger">{no}</vType><vType id="p" vClass="passenger"/>'
              f'<vehicle id="a" type="p" depart="0"><route edges="e"/>{no}</vehicle>'
              '<vehicle id="b" type="off" depart="0"><route edges="e"/></vehicle>'
              f'<vehicle id="c" type="p" depart="0"><route edges="e"/>{no}</vehicle>'
              '<vehicle id="d" type="off" depart="0"><route edges="e"/></vehicle></routes>')
    (tmp_path / "r.rou.xml").write_text(routes, encoding="utf-8")
    opts = {"device.taxi.explicit": "a,b"}
    import sumolib

    traci.start([sumolib.checkBinary("sumo"), "-n", str(net), "-r", str(tmp_path / "r.rou.xml"), "--no-warnings", "true",
                 "--device.taxi.explicit", opts["device.taxi.explicit"]], label="taxi_explicit")
    conn = traci.getConnection("taxi_explicit")
    try:
        conn.simulationStep()
        sumo = {v: conn.vehicle.getParameter(v, "has.taxi.device") == "true" for v in "abcd"}
    finally:
        conn.close()
    t = TaxiDevices(opts.get)
    for el in ET.fromstring(routes):
        t.read(el, el.tag)
    assert sumo == {"a": True, "b": True, "c": False, "d": False}
    assert {v: t.has(v, v) for v in "abcd"} == sumo


def _reparks(em, fcd, step):
    """(time, taxi) of the steps SUMO's emission output writes a taxi standing on its lane
    between two steps it leaves it out (parked), while the FCD writes it in all three."""
    import xml.etree.ElementTree as ET

    def rows(path):
        return {(round(float(ts.get("time")), 6), v.get("id")) for ts in ET.parse(path).getroot()
                for v in ts if v.get("id", "").startswith("t")}

    written, seen = rows(em), rows(fcd)
    return sorted((t, v) for t, v in written if (round(t - step, 6), v) in seen - written
                  and (round(t + step, 6), v) in seen - written)


PERSONS = ('<person id="p0" depart="40" departPos="400"><ride from="e" to="e" arrivalPos="900" lines="taxi"/></person>'
           '<person id="p1" depart="150" departPos="1000"><ride from="e" to="e" arrivalPos="1800" lines="taxi"/></person>'
           '<person id="p2" depart="160" departPos="300"><ride from="e" to="e" arrivalPos="1200" lines="taxi"/></person>')
#: a container taxi's stop lasts the vType's loadingDuration (SUMO's default 90 s) after its container left
CONTAINERS = '<container id="k0" depart="40" departPos="400"><transport from="e" to="e" arrivalPos="900" lines="taxi"/></container>'


@pytest.mark.parametrize("step, load", [(1.0, PERSONS), (0.5, PERSONS), (1.0, CONTAINERS)],
                         ids=["persons-1s", "persons-0.5s", "container-1s"])
def test_an_idle_taxi_parking_again_where_its_last_customer_left_books_as_live(tmp_path, step, load):
    """Two taxis dispatched to three customers, or one container taxi to a container (SUMO's
    default dispatch and idle-algorithm stop): when a taxi's last customer leaves at its
    drop-off and no dispatch follows, SUMO keeps that stop as the idle one once unloading is
    over (the vType's boardingDuration, 0.5 s; for a container its loadingDuration, 90 s);
    libsumo reads the taxi on its lane, standing, for one step, parked again (a parking
    entry) from the next, while the FCD writes it at its space all along. The replay booked
    neither step: with persons, fuel 0.9956 and 0.9975 of the live run's at 1-s steps
    (measured 2026-11-29). Now the replay books them as live."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="2000" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="15"/>'
              '<edge id="r" from="b" to="a" numLanes="1" speed="15"/></edges>')
    cap = ' containerCapacity="2" personCapacity="0"' if load == CONTAINERS else ""
    (tmp_path / "r.rou.xml").write_text(
        f'<routes><vType id="tx" vClass="taxi" mass="1500"{cap}>{TAXI}</vType>'
        '<vehicle id="t0" type="tx" depart="0"><route edges="e"/><stop lane="e_0" endPos="200" duration="5"/></vehicle>'
        '<vehicle id="t1" type="tx" depart="2"><route edges="e"/></vehicle>' + load + '</routes>', encoding="utf-8")
    sc = energy_scenario(tmp_path, 400, step_length=step, fcd=True)
    sc.write_text(sc.read_text(encoding="utf-8").replace('equations = ["vtype_energy"]\n', "").replace(
        "[outputs]\n", "[outputs]\ntrace = true\n"), encoding="utf-8")
    run_scenario(sc, tmp_path / "live")
    process_fcd(tmp_path / "fcd.xml", scenario=sc, out_dir=tmp_path / "rep", figures=False)
    booked = {}
    for out in ("live", "rep"):
        trace = pd.read_parquet(tmp_path / out / "trace.parquet")
        booked[out] = (set(zip(trace.time_s, trace.vehicle)),
                       pd.read_csv(tmp_path / out / "chain_vehicles.csv").set_index("key")[["fuel_l"]].sort_index())
    assert list(booked["live"][1].index) == ["t0", "t1"]
    # SUMO books a re-park once: its emission output writes the taxi in the step it stands
    # on its lane (between two it is parked in), its emissions device books the next (the
    # step it parks in again) and not that one (its parking's end): one idle step either way.
    # The plug-in books as the device (the live run booked both before 2026-11-29, then the
    # step on the lane, as the emission output, until the device's count was taken for every
    # parking's end: sim/parking.py).
    reparks = _reparks(tmp_path / "em.xml", tmp_path / "fcd.xml", step)
    assert reparks
    for t, vid in reparks:
        assert device_step(sc, tmp_path, t, vid, "fuel") == 0.0 < device_step(sc, tmp_path, t + step, vid, "fuel")
        assert (t, vid) not in booked["live"][0] and (t + step, vid) in booked["live"][0]
    assert booked["rep"][0] == booked["live"][0]  # the same vehicle-steps
    pd.testing.assert_frame_equal(booked["rep"][1], booked["live"][1], rtol=1e-6)
