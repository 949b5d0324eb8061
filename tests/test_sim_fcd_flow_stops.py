"""An FCD replay knows when a flow's planned stop ends, whatever form the flow takes
(sim/fcd_stops.py): SUMO shifts the ``until`` of a flow vehicle's own stops by n × the
flow's spacing (``period``, 3600/``vehsPerHour``, (end − begin)/``number``; none for a
flow by ``probability``) and a named route's stops by the vehicle's depart. Real SUMO runs,
live and replayed from their FCD; SUMO's own stop output is the reference."""

from __future__ import annotations

import json
import math
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd
from sumo_drvpw.sim.fcd_stops import read_declared_stops

pytestmark = pytest.mark.sumo

REPO = Path(__file__).resolve().parent.parent
NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"
I3_BATTERY = REPO / "docs" / "energy-chain" / "bmw_i3_battery.toml"


def _row(r: int, back: bool = False) -> tuple[str, str]:
    """Row r of the city grid (three 232-m edges) and its middle lane."""
    e = [f"c{r}0c{r}1", f"c{r}1c{r}2", f"c{r}2c{r}3"]
    if back:
        e = [f"c{r}{b}c{r}{a}" for a, b in (("2", "3"), ("1", "2"), ("0", "1"))]
    return " ".join(e), f"{e[1]}_0"


def _stop(lane: str, until: int) -> str:
    return f'<stop lane="{lane}" startPos="0" endPos="230" until="{until}"/>'


#: electric cars at stops that end at an until (each > 300 s planned: SUMO's default
#: shutOffStopDuration switches them off live): a flow of number 4 from 0 to 100 s without
#: period (25 s apart, until 600 + 25 n), one of number 2 with neither period nor end (the
#: run's end, 1000 s: 500 s apart), a vehsPerHour flow (30 s apart), a flow by probability
#: (until not shifted) and a vehicle departing at 30 s on a named route whose stop says
#: until 600 (SUMO: 630)
ROUTES = f"""<routes>
    <vType id="ev" vClass="passenger" mass="1500" emissionClass="Energy/unknown"/>
    <route id="rr" edges="{_row(0)[0]}">{_stop(_row(0)[1], 600)}</route>
    <flow id="num" type="ev" begin="0" end="100" number="4" departSpeed="0">
        <route edges="{_row(3)[0]}"/>{_stop(_row(3)[1], 600)}</flow>
    <flow id="noend" type="ev" begin="0" number="2" departSpeed="0">
        <route edges="{_row(1, True)[0]}"/>{_stop(_row(1, True)[1], 450)}</flow>
    <flow id="vph" type="ev" begin="0" end="60" vehsPerHour="120" departSpeed="0">
        <route edges="{_row(2)[0]}"/>{_stop(_row(2)[1], 650)}</flow>
    <flow id="prob" type="ev" begin="0" end="100" probability="0.05" departSpeed="0">
        <route edges="{_row(4)[0]}"/>{_stop(_row(4)[1], 640)}</flow>
    <vehicle id="v" type="ev" route="rr" depart="30" departSpeed="0"/>
</routes>
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """The scenario run live (libsumo) with its FCD (--precision 6) and SUMO's stop output."""
    return _run_live(tmp_path_factory.mktemp("flowstops"), ROUTES)


def _run_live(d: Path, routes: str, additional: str | None = None) -> Path:
    """The i3 battery chain on the routes ``routes`` (and the additional file ``additional``)
    of the city net, 0-1000 s at 1-s steps, run live in ``d``/live with its FCD
    (--precision 6) in ``d``/fcd.xml and SUMO's stop output in ``d``/stops.xml."""
    (d / "r.rou.xml").write_text(routes, encoding="utf-8")
    add = ""
    if additional is not None:
        (d / "p.add.xml").write_text(additional, encoding="utf-8")
        add = 'additional = ["p.add.xml"]\n'
    (d / "s.toml").write_text(
        f'equations = ["{I3_BATTERY}"]\n[sumo]\nnet = "{NET}"\nroutes = ["r.rou.xml"]\n{add}'
        'begin = 0\nend = 1000\nstep_length = 1.0\noptions = ["--no-warnings", "true"]\n'
        '[air]\ntemperature_c = 20.0\n[outputs]\nfigures = false\n', encoding="utf-8")
    run_scenario(d / "s.toml", d / "live", options=["--fcd-output", str(d / "fcd.xml"), "--precision", "6",
                                                    "--stop-output", str(d / "stops.xml")])
    return d


def _booked(out: Path):
    c = pd.read_csv(out / "chain_vehicles.csv").set_index("key").sort_index()
    t = pd.read_parquet(out / "vehicles.parquet").groupby("vehicle")["time_s"].first().sort_index()
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))["shut_off_at_long_stops"]
    return c, t, s


def test_declared_until_shifts_are_sumos(recorded):
    """Each stop's end as SUMO's stop output has it (the first 1-s step at or after the
    shifted until) from the declared stops alone: number without period, number without
    end (the run's end), vehsPerHour, probability (not shifted), a named route's stop
    (shifted by the depart)."""
    d = recorded
    ended = {s.get("id"): float(s.get("ended")) for s in ET.parse(d / "stops.xml").getroot()}
    assert {v.rpartition(".")[0] or v for v in ended} == {"num", "noend", "vph", "prob", "v"}
    assert len([v for v in ended if v.startswith("prob.")]) >= 2
    ds = read_declared_stops([d / "r.rou.xml"], begin=0.0, end=1000.0)
    for vid, t in ended.items():
        stops, shifts, why = ds.stops_of(vid)
        assert why is None and len(stops) == 1, vid
        assert math.ceil(stops[0].until + shifts[0] - 1e-9) == t, (vid, stops[0].until, shifts, t)
    assert ended["num.3"] == 675 and ended["noend.1"] == 950 and ended["v"] == 630


@pytest.mark.parametrize("chunk_rows", [None, 7])
def test_fcd_switches_off_at_flow_stops_as_live(recorded, tmp_path, chunk_rows):
    """Live, every one of these stops is switched off (planned > 300 s); the replay books
    each vehicle's time and auxiliary energy as the live run (to 1e-9 / 1e-6) and knows
    every until. Before, the replay knew the until of no flow but a period one (number,
    vehsPerHour, probability: booked standing, +300..550 s each) and took the named
    route's until unshifted (the vehicle booked standing its last 30 s)."""
    d = recorded
    process_fcd(d / "fcd.xml", scenario=d / "s.toml", out_dir=tmp_path / "o", chunk_rows=chunk_rows)
    (lc, lt, ls), (rc, rt, rs) = _booked(d / "live"), _booked(tmp_path / "o")
    n_stops = len(ET.parse(d / "stops.xml").getroot())
    assert ls["stops"] == n_stops >= 10
    assert rs["stops"] == ls["stops"] and rs["vehicle_s"] == pytest.approx(ls["vehicle_s"])
    pd.testing.assert_series_equal(rt, lt, rtol=1e-9)
    np.testing.assert_allclose(rc["auxiliary_kwh"], lc["auxiliary_kwh"], rtol=1e-6)
    assert rs["replay"]["stops_whose_until_is_not_known"] == 0
    assert rs["replay"]["stops_reached"] == n_stops and rs["replay"]["stops_left_before_their_end"] == 0


def test_a_parking_stop_ends_when_the_vehicle_leaves_its_space(tmp_path):
    """SUMO ends a ``parking`` stop when the vehicle can leave its space, past its planned
    end when traffic blocks it (DLR's port_lübeck, SUMO 1.28 stop output: cars parked at
    a bus stop until 830, 870, 880 s left at 836, 881, 887 s, the live run booking nothing
    until then); a stop on the lane ends at its planned end, the vehicle standing on booked
    standing. Before, the replay ended both at the until and booked the parked car's wait
    standing (port_lübeck: +5, +10, +6 s)."""
    from types import SimpleNamespace

    from sumo_drvpw.sim.fcd_stops import StopTracker

    f = tmp_path / "r.rou.xml"
    f.write_text('<routes><vehicle id="p" depart="0"><route edges="a"/>'
                 '<stop lane="a_0" endPos="50" until="100" parking="true"/></vehicle>'
                 '<vehicle id="q" depart="0"><route edges="a"/><stop lane="a_0" endPos="50" until="100"/></vehicle>'
                 '<vehicle id="r" depart="0"><route edges="a"/><stop parkingArea="pa" until="100"/></vehicle>'
                 '<parkingArea id="pa" lane="a_0" startPos="0" endPos="50"/></routes>', encoding="utf-8")
    net = SimpleNamespace(lane_index={"a_0": 0}, lane_length=np.array([100.0]))
    tr = StopTracker(read_declared_stops([f]), net)
    ids, ends = ["p", "q", "r"], {}
    for t in range(90, 111):
        v = 0.0 if t < 106 else 3.0  # all three stand until 106 s (blocked), then drive off
        tr.step(float(t), ids, ["a_0"] * 3, [50.0] * 3, [v] * 3)
        ends.update({vid: t for vid in tr.ending})
        if t == 90:
            assert set(tr.starting) == {"p", "q", "r"}
    assert ends == {"p": 106, "q": 100, "r": 106}
    assert tr.left_early == 0


#: electric cars at long ``parking`` stops (until > 300 s after arrival): parked in a bus
#: bay (a busStop with parkingLength: live, dwelling there, switched off, one stop each),
#: beside a lane and at a containerStop (live, parked off the lane: not booked, no
#: switched-off stop), as DLR's port_lübeck parks its cars and trucks
PARKED = f"""<routes>
    <vType id="ev" vClass="passenger" mass="1500" emissionClass="Energy/unknown"/>
    <flow id="bay" type="ev" begin="0" end="100" number="4" departSpeed="0">
        <route edges="{_row(0)[0]}"/><stop busStop="bs" until="600" parking="true"/></flow>
    <flow id="side" type="ev" begin="0" end="100" number="4" departSpeed="0">
        <route edges="{_row(3)[0]}"/>{_stop(_row(3)[1], 600).replace("/>", ' parking="true"/>')}</flow>
    <flow id="box" type="ev" begin="0" end="100" number="4" departSpeed="0">
        <route edges="{_row(2)[0]}"/><stop containerStop="cs" until="650" parking="true"/></flow>
    <vehicle id="v" type="ev" depart="30" departSpeed="0">
        <route edges="{_row(1, True)[0]}"/>{_stop(_row(1, True)[1], 500).replace("/>", ' parking="true"/>')}</vehicle>
</routes>
"""


@pytest.fixture(scope="module")
def parked(tmp_path_factory):
    """The parking scenario run live (libsumo) with its FCD (--precision 6)."""
    return _run_live(tmp_path_factory.mktemp("parkstops"), PARKED,
                     f'<additional><busStop id="bs" lane="{_row(0)[1]}" startPos="100" endPos="200" '
                     'parkingLength="1000"/>'
                     f'<containerStop id="cs" lane="{_row(2)[1]}" startPos="100" endPos="200" '
                     'parkingLength="1000"/></additional>')


@pytest.mark.parametrize("chunk_rows", [None, 7])
def test_fcd_books_parking_stops_as_live(parked, tmp_path, chunk_rows):
    """SUMO puts a parked vehicle back on its lane, at its space, the step before it
    drives off (its parking ends there; its stop ends in the step it drives off, and one
    switched off for its stop — in a bus bay, beside the lane, at a containerStop, all of
    them here — is written at 0 in the step between: booked from its stop's end, live
    and replayed; before 2026-11-27 both booked that row); a vehicle parked off the lane
    (beside it, at a containerStop) is no switched-off stop live, one in a bus bay is.
    Before, the replay ended a parking stop in the row the vehicle drove off (−1 s for
    each one in a bus bay: port_lübeck's cars), counted as switched off a vehicle it took
    as at its stop a row before SUMO parked it (port_lübeck: trucktoship.5 at a
    containerStop, 10 stops against 9; here box.3, −1 s, 5 against 4), and the live run
    counted the bay's last row both booked and switched off (+1 s each)."""
    d = parked
    process_fcd(d / "fcd.xml", scenario=d / "s.toml", out_dir=tmp_path / "o", chunk_rows=chunk_rows)
    (lc, lt, ls), (rc, rt, rs) = _booked(d / "live"), _booked(tmp_path / "o")
    ended = [s.get("id") for s in ET.parse(d / "stops.xml").getroot()]
    assert len(ended) == 13 and all(s.get("parking") == "1" for s in ET.parse(d / "stops.xml").getroot())
    assert ls["stops"] == 4  # the bay's: dwelling in service, switched off
    assert rs["stops"] == ls["stops"] and rs["vehicle_s"] == pytest.approx(ls["vehicle_s"])
    pd.testing.assert_series_equal(rt, lt, rtol=1e-9)
    np.testing.assert_allclose(rc["auxiliary_kwh"], lc["auxiliary_kwh"], rtol=1e-6)


def test_bus_stops_of_the_vtype_files_are_read_without_a_scenario(parked, tmp_path):
    """fcd without a scenario, the route and additional files given as vType files (as
    `fcd --vtypes`, or those the FCD's header names): the bus bay of the additional file
    is known, so the cars dwelling in it are booked and switched off as live (before, its
    bus stops were read only from a scenario's additional files: the bay's cars were taken
    as parked off the lane and not booked, 0 stops against 4)."""
    d = parked
    process_fcd(d / "fcd.xml", net=NET, equations=[str(I3_BATTERY)], out_dir=tmp_path / "o",
                vtype_files=[d / "r.rou.xml", d / "p.add.xml"], air_temperature_c=20.0, figures=False)
    (lc, lt, ls), (rc, rt, rs) = _booked(d / "live"), _booked(tmp_path / "o")
    assert ls["stops"] == 4 and rs["stops"] == ls["stops"]
    pd.testing.assert_series_equal(rt, lt, rtol=1e-9)
    np.testing.assert_allclose(rc["auxiliary_kwh"], lc["auxiliary_kwh"], rtol=1e-6)
