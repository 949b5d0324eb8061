"""An FCD replay switches vehicles off as the live run does (sim/shutoff.py): start-stop
systems from the route files' vType params, long planned stops from the stops the route
files declare (sim/fcd_stops.py). Real SUMO runs, live and replayed from their FCD."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd

pytestmark = pytest.mark.sumo

REPO = Path(__file__).resolve().parent.parent
NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"
I3_BATTERY = REPO / "docs" / "energy-chain" / "bmw_i3_battery.toml"

#: petrol cars with a start-stop system (off after 2 s standing) through the city's
#: traffic lights, and electric cars at planned stops: 600 s at a bus stop, until 700 s at
#: it (queued inside the stop behind the first), a 600-s stop of a vType that keeps its
#: engine on up to 1000 s, a 120-s stop on the lane, a flow's stop until 500 s (its second
#: vehicle's shifted by the 30-s period, as SUMO does) and a 600-s stop on a route drawn from
#: a routeDistribution (which member's stops: not in the FCD)
ROUTES = """<routes>  <!-- in order of departure, as SUMO reads them -->
    <vType id="car" vClass="passenger" mass="1500" emissionClass="HBEFA4/PC_petrol_Euro-6ab">
        <param key="shutOffAutoDuration" value="2"/></vType>
    <vType id="ev" vClass="passenger" mass="1500" emissionClass="Energy/unknown"/>
    <vType id="ev_on" vClass="passenger" mass="1500" emissionClass="Energy/unknown">
        <param key="shutOffStopDuration" value="1000"/></vType>
    <route id="r" edges="c00c01 c01c11 c11c21 c21c22 c22c23"/>
    <route id="rb" edges="c00c01 c01c02 c02c03"/>
    <routeDistribution id="rd">
        <route id="rd0" edges="c40c41 c41c42 c42c43" probability="1"><stop lane="c41c42_0" endPos="50" duration="600"/></route>
    </routeDistribution>
    <flow id="f" type="car" route="r" begin="0" end="200" period="10" departSpeed="0"/>
    <vehicle id="bus" type="ev" route="rb" depart="0" departSpeed="0"><stop busStop="bs1" duration="600"/></vehicle>
    <vehicle id="kept_on" type="ev_on" depart="0" departSpeed="0">
        <route edges="c10c11 c11c12 c12c13"/><stop lane="c11c12_0" endPos="80" duration="600"/></vehicle>
    <vehicle id="drawn" type="ev" route="rd" depart="0" departSpeed="0"/>
    <vehicle id="bus_until" type="ev" route="rb" depart="5" departSpeed="0"><stop busStop="bs1" until="700"/></vehicle>
    <vehicle id="short" type="ev" depart="10" departSpeed="0">
        <route edges="c10c11 c11c12 c12c13"/><stop lane="c11c12_0" endPos="20" duration="120"/></vehicle>
    <flow id="fs" type="ev" begin="20" end="80" period="30" departSpeed="0">
        <route edges="c30c31 c31c32 c32c33"/><stop lane="c31c32_0" startPos="5" endPos="90" until="500"/></flow>
</routes>
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The scenario run live (libsumo), with its FCD (--precision 6) and tripinfo."""
    d = tmp_path_factory.mktemp("shutoff")
    (d / "bs.add.xml").write_text('<additional><busStop id="bs1" lane="c01c02_0" startPos="30" '
                                  'endPos="70"/></additional>\n', encoding="utf-8")
    (d / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    (d / "s.toml").write_text(
        f'equations = ["epa_gasoline_car", "{I3_BATTERY}"]\n[sumo]\nnet = "{NET}"\n'
        'routes = ["r.rou.xml"]\nadditional = ["bs.add.xml"]\nbegin = 0\nend = 1000\nstep_length = 1.0\n'
        'options = ["--no-warnings", "true"]\n[air]\ntemperature_c = 20.0\n[outputs]\nfigures = false\n', encoding="utf-8")
    run_scenario(d / "s.toml", d / "live", options=["--fcd-output", str(d / "fcd.xml"), "--precision", "6",
                                                    "--tripinfo-output", str(d / "ti.xml")])
    return d


def _booked(out: Path):
    c = pd.read_csv(out / "chain_vehicles.csv").set_index(["key", "equation"]).sort_index()
    t = pd.read_parquet(out / "vehicles.parquet").groupby("vehicle")["time_s"].first().sort_index()
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))["shut_off_at_long_stops"]
    return c, t, s


@pytest.mark.parametrize("chunk_rows", [None, 7])
def test_fcd_books_a_start_stop_vtype_as_the_live_run(recorded, tmp_path, chunk_rows):
    """shutOffAutoDuration (SUMO's start-stop: the engine off once the vehicle has stood
    longer, EnergyParams::isEngineOff) read from the route files' vType: the replay books
    each petrol car's fuel as the live run did, and the same time engines stood off.
    Tolerance 1e-6: the replay books every FCD row in the step the live run booked that
    state (row t is the state after SUMO's step t), standing by the same 0.1 m/s on the same
    speeds, which the FCD holds to 6 decimals (measured: 4e-9). Before, the replay booked
    the cars' idle fuel throughout (summary: no shut-off at all)."""
    d = recorded
    process_fcd(d / "fcd.xml", scenario=d / "s.toml", out_dir=tmp_path / "o", chunk_rows=chunk_rows)
    (lc, _, ls), (rc, _, rs) = _booked(d / "live"), _booked(tmp_path / "o")
    fuel = lc.xs("epa_gasoline_car", level="equation")["fuel_l"]
    assert len(fuel) == 20 and fuel.min() > 0
    np.testing.assert_allclose(rc.xs("epa_gasoline_car", level="equation")["fuel_l"], fuel, rtol=1e-6)
    assert ls["start_stop_vehicle_s"] > 100
    assert rs["start_stop_vehicle_s"] == ls["start_stop_vehicle_s"]


@pytest.mark.parametrize("chunk_rows", [None, 7])
def test_fcd_switches_off_at_the_long_stops_the_route_files_declare(recorded, tmp_path, chunk_rows):
    """A 600-s bus stop (and one until 700 s, a flow's until 500 s shifted per vehicle): the
    live run switches the vehicle off there (shutOffStopDuration, default 300 s) and books
    neither time nor auxiliary energy; the replay matches each to the stop its vehicle's
    route file declares and books the same time and auxiliary energy per vehicle; the
    vType that keeps its engine on up to 1000 s and the 120-s stop are booked standing in
    both. The vehicle whose route is drawn from a routeDistribution: its stops are not known
    to the replay, which books its 600 s standing and says so. Before, the replay booked
    every stop standing (+600 s and 600 s of auxiliary power at the bus stop)."""
    d = recorded
    process_fcd(d / "fcd.xml", scenario=d / "s.toml", out_dir=tmp_path / "o", chunk_rows=chunk_rows)
    (lc, lt, ls), (rc, rt, rs) = _booked(d / "live"), _booked(tmp_path / "o")
    trips = {t.get("id"): float(t.get("duration")) for t in ET.parse(d / "ti.xml").getroot()}
    # live: off at the bus stop for its 600 s; kept on and short stops booked standing (to
    # 2 s: at 1-s steps the steps it comes to rest in and drives off in are booked)
    assert lt["bus"] == pytest.approx(trips["bus"] - 600, abs=2.0)
    assert lt["kept_on"] == pytest.approx(trips["kept_on"], abs=2.0)
    assert lt["short"] == pytest.approx(trips["short"], abs=2.0)
    assert ls["stops"] == 5  # bus, bus_until, fs.0, fs.1, drawn
    known = lt.index != "drawn"
    pd.testing.assert_series_equal(rt[known], lt[known], rtol=1e-9)
    aux = lc.xs("bmw_i3_battery", level="equation")["auxiliary_kwh"]
    raux = rc.xs("bmw_i3_battery", level="equation")["auxiliary_kwh"]
    pd.testing.assert_series_equal(raux.drop("drawn"), aux.drop("drawn"), rtol=1e-6)
    # what the replay cannot know: booked standing (the time the live run had it off), and said
    assert rt["drawn"] == pytest.approx(lt["drawn"] + 600, abs=2.0)
    assert rs["stops"] == 4 and rs["vehicle_s"] == ls["vehicle_s"] - (rt["drawn"] - lt["drawn"])
    assert rs["replay"]["vehicles_whose_stops_are_not_known"] == {
        "its route is drawn from a routeDistribution with stops": 1}
    assert rs["replay"]["stops_reached"] == 6 and rs["replay"]["stops_left_before_their_end"] == 0
    assert "routeDistribution" in rs["replay"]["rule"]


def test_declared_stops_are_read_in_sumos_order_and_a_bad_one_is_named(tmp_path, capsys):
    """The route files' stops: a route's and the vehicle's own in the order along the route
    (SUMO's), waypoints left out, a flow's vehicles with the flow's stops and their until
    shifted by n periods (the named route's by the depart: the same for a period flow from
    0); a duration that is no number: one line naming the file, the vehicle and the key,
    exit 2."""
    from sumo_drvpw.sim.fcd_stops import read_declared_stops

    f = tmp_path / "r.rou.xml"
    f.write_text("""<routes>
    <route id="r" edges="a b c"><stop lane="c_0" duration="9"/></route>
    <vehicle id="v" route="r" depart="0"><stop lane="a_0" duration="5"/><stop lane="b_0" speed="3"/></vehicle>
    <flow id="f" route="r" begin="0" end="50" period="10"><stop edge="b" until="1:00:00"/></flow>
    <flow id="p" route="r" begin="0" end="50" probability="0.1"/>
</routes>""", encoding="utf-8")
    ds = read_declared_stops([f])
    stops, shift, why = ds.stops_of("v")
    assert [s.lane for s in stops] == ["a_0", "c_0"] and shift == [0, 0] and why is None
    stops, shift, _ = ds.stops_of("f.3")
    assert [(s.lane, s.edge) for s in stops] == [(None, "b"), ("c_0", None)] and stops[0].until == 3600
    assert shift == [30, 30]
    assert np.isnan(ds.stops_of("p.2")[1][0])  # a flow by probability: its departs not known
    assert ds.stops_of("x")[0] is None
    f.write_text('<routes><vehicle id="v" depart="0"><route edges="a"/><stop lane="a_0" duration="long"/>'
                 "</vehicle></routes>", encoding="utf-8")
    (tmp_path / "s.toml").write_text(f'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "{NET}"\nroutes = ["r.rou.xml"]\n', encoding="utf-8")
    (tmp_path / "fcd.xml").write_text('<fcd-export><timestep time="0.00"/><timestep time="1.00"/></fcd-export>', encoding="utf-8")
    code = cli_main(["fcd", str(tmp_path / "fcd.xml"), "--scenario", str(tmp_path / "s.toml"),
                     "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1, err
    assert "r.rou.xml" in err and "vehicle 'v'" in err and "duration" in err and "'long'" in err


def test_a_stop_on_a_route_of_an_additional_file_is_matched(tmp_path):
    """SUMO loads the additional files before the route files: a bus line's route with its
    stop defined in the .add.xml serves the route file's vehicle. The replay read the route
    file first, found no route 'line' and booked the 600-s stop standing (7x the live
    run's auxiliary energy, unsaid)."""
    (tmp_path / "l.add.xml").write_text(
        '<additional><busStop id="bs1" lane="c01c02_0" startPos="30" endPos="70"/>\n'
        '<route id="line" edges="c00c01 c01c02 c02c03"><stop busStop="bs1" duration="600"/></route>'
        "</additional>\n", encoding="utf-8")
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="ev" vClass="passenger" mass="1500" emissionClass="Energy/unknown"/>\n'
        '<vehicle id="bus" type="ev" route="line" depart="0" departSpeed="0"/></routes>\n', encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["{I3_BATTERY}"]\n[sumo]\nnet = "{NET}"\nroutes = ["r.rou.xml"]\n'
        'additional = ["l.add.xml"]\nbegin = 0\nend = 900\nstep_length = 1.0\n'
        'options = ["--no-warnings", "true"]\n[air]\ntemperature_c = 20.0\n[outputs]\nfigures = false\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "live", options=["--fcd-output", str(tmp_path / "fcd.xml"),
                                                                 "--precision", "6"])
    process_fcd(tmp_path / "fcd.xml", scenario=tmp_path / "s.toml", out_dir=tmp_path / "o")
    (lc, lt, ls), (rc, rt, rs) = _booked(tmp_path / "live"), _booked(tmp_path / "o")
    assert ls["stops"] == rs["stops"] == 1 and rs["replay"]["vehicles_with_declared_stops"] == 1
    assert rt["bus"] == pytest.approx(lt["bus"], rel=1e-9) and lt["bus"] < 300
    np.testing.assert_allclose(rc["auxiliary_kwh"], lc["auxiliary_kwh"], rtol=1e-6)


def test_fcd_on_dask_reports_the_buckets_switch_offs(recorded, tmp_path):
    """fcd --engine dask: each bucket switches its own vehicles off; summary.json added them
    up nowhere (the driver's accountant, which read no rows, reported 0 stops and no
    declared stops) while the energies included them. Now the same as the serial replay."""
    pytest.importorskip("distributed")
    from sumo_drvpw.sim.fcd_dask import process_fcd_dask

    d = recorded
    process_fcd(d / "fcd.xml", scenario=d / "s.toml", out_dir=tmp_path / "o")
    process_fcd_dask(d / "fcd.xml", tmp_path / "od", scenario=d / "s.toml", buckets=3, workers=1)
    (rc, rt, rs), (dc, dtm, ds) = _booked(tmp_path / "o"), _booked(tmp_path / "od")
    pd.testing.assert_series_equal(dtm, rt, rtol=1e-9)
    assert rs["stops"] == 4 and ds["stops"] == rs["stops"]
    assert ds["vehicle_s"] == pytest.approx(rs["vehicle_s"]) and rs["vehicle_s"] > 1000
    assert ds["start_stop_vehicle_s"] == pytest.approx(rs["start_stop_vehicle_s"])
    for k in ("vehicles_with_declared_stops", "stops_reached", "declared_stops_on_unknown_stopping_places",
              "vehicles_whose_stops_are_not_known"):
        assert ds["replay"][k] == rs["replay"][k], k


def test_a_car_manoeuvring_into_its_parking_space_is_switched_off_as_it_parks(tmp_path):
    """With parking.maneuver SUMO holds a car on its lane at its parking stop for the entry
    manoeuvre (2 s for a car, 4 s for a coach in Bad Hersfeld's config), idling — its stop
    not yet started (isStopped false; its emission output books idle fuel) — and starts the
    stop as it parks it. The replay started the stop, and switched a long one off, in the
    first row the car stood there: idle fuel of 1 s (a car) to 4 s (a coach) less than the
    live run per vehicle that parked for more than 300 s (rehearsal 2026-11-29, DLR Bad
    Hersfeld with 700 trips, 40 % parking: 185 vehicles, up to 1 % of a trip's fuel; petrol
    cars 236.645 L against 236.693; shut-off 688 against the live run's 387 vehicle-s). Now
    the replay starts a parking stop in the row the car is parked off its lane, unless the
    FCD has no x, y to show that."""
    (tmp_path / "pa.add.xml").write_text('<additional><parkingArea id="pa" lane="c11c12_0" startPos="30" '
                                         'endPos="40" roadsideCapacity="1000"/></additional>\n', encoding="utf-8")
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="car" vClass="passenger" mass="1500" emissionClass="HBEFA4/PC_petrol_Euro-6ab"/>\n'
        + "".join(f'<vehicle id="p{k}" type="car" depart="{5 * k}" departSpeed="0"><route edges="c10c11 c11c12 c12c13"/>'
                  f'<stop parkingArea="pa" duration="{d}"/></vehicle>\n' for k, d in enumerate((400, 100, 500)))
        + "</routes>\n", encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["epa_gasoline_car"]\n[sumo]\nnet = "{NET}"\nroutes = ["r.rou.xml"]\nadditional = ["pa.add.xml"]\n'
        'begin = 0\nend = 800\nstep_length = 1.0\n[air]\ntemperature_c = 20.0\n[outputs]\nfigures = false\n',
        encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "live", options=["--parking.maneuver", "true", "--no-warnings", "true",
                                                                 "--fcd-output", str(tmp_path / "fcd.xml"), "--precision", "6"])
    # the premise: rows at rest (SUMO's 0.1 m/s) on the lane inside the stop's range, turning
    # in, before the row the car is parked beside its lane (x moved 3.2 m off the lane)
    rows = [(float(v.get("speed")), float(v.get("x"))) for ts in ET.parse(tmp_path / "fcd.xml").getroot()
            for v in ts if v.get("id") == "p0"]
    parks = next(i for i, (a, b) in enumerate(zip(rows, rows[1:])) if abs(b[1] - a[1]) > 1.0)
    assert all(v <= 0.1 for v, _ in rows[parks - 2:parks + 1])
    process_fcd(tmp_path / "fcd.xml", scenario=tmp_path / "s.toml", out_dir=tmp_path / "o")
    (lc, lt, ls), (rc, rt, rs) = _booked(tmp_path / "live"), _booked(tmp_path / "o")
    assert (rs["stops"], rs["vehicle_s"]) == (ls["stops"], ls["vehicle_s"])
    pd.testing.assert_series_equal(rt, lt, rtol=1e-9)
    np.testing.assert_allclose(rc["fuel_l"], lc["fuel_l"], rtol=1e-6)
