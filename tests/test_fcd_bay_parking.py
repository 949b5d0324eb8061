"""A vehicle parked in a parkingArea whose span touches a bus stop's is parked, not dwelling
in the bus bay: the replay's bus-bay rule (a vehicle standing beside its lane within a bus
stop's span dwells there in service, booked standing: sim/fcd_conn.py ParkedTest) gives way
where the route files say the vehicle's stop there is no bus stop (sim/fcd_stops.py
StopTracker.at_bay). Real SUMO runs: a van parking at a parkingArea whose span overlaps a
bus stop's end (as MoST's parkingArea 1154, 143.38–153.38 m, and busStop 131136, 128.39–143.39 m,
on lane -152814#4_1), and a bus parked in the bay of that bus stop."""

from __future__ import annotations

import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd
from sumo_probe import booked_per_vehicle, build_net, energy_scenario

pytestmark = pytest.mark.sumo


def _record(d, shut_off: bool):
    build_net(d, '<nodes><node id="a" x="0" y="0"/><node id="b" x="600" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="14"/></edges>')
    off = '<param key="shutOffStopDuration" value="30"/>' if shut_off else ""
    (d / "r.rou.xml").write_text(
        f'<routes><vType id="van" vClass="delivery" mass="2500" emissionClass="Energy/unknown">{off}</vType>'
        '<vType id="bus" vClass="bus" mass="12000" emissionClass="Energy/unknown"/>'
        '<vehicle id="van" type="van" depart="0"><route edges="e"/><stop parkingArea="pa" duration="60"/></vehicle>'
        '<vehicle id="bus" type="bus" depart="40"><route edges="e"/><stop busStop="bs" duration="20" parking="true"/>'
        '</vehicle></routes>', encoding="utf-8")
    (d / "a.add.xml").write_text(
        '<additional><busStop id="bs" lane="e_0" startPos="200" endPos="232"/>'
        '<parkingArea id="pa" lane="e_0" startPos="222" endPos="232" roadsideCapacity="1"/></additional>',
        encoding="utf-8")
    sc = energy_scenario(d, 150, step_length=0.25, additional="a.add.xml", fcd=True)
    run_scenario(sc, d / "live")
    return sc


@pytest.mark.parametrize("shut_off", [False, True])
def test_parking_area_beside_a_bus_stop_books_parked_as_live(tmp_path, shut_off):
    """Before 2026-11-29 the van parked in the parkingArea at the bus stop's end was taken
    for one dwelling in the bay: booked standing all its parked time (without a shut-off
    param: 107 s against the live run's 47.5) or, switched off at its long stop, one 0.25-s
    row more than live (47.5 s against 47.25; MoST 18000–19800 s: commercial_3-1_135
    708.75 s against 708.5). Now the van and the bus book
    as the live run (time, distance, auxiliary and net energy per vehicle to 1e-6)."""
    sc = _record(tmp_path, shut_off)
    live = booked_per_vehicle(tmp_path / "live")
    assert live.loc["bus", "time_s"] > live.loc["van", "time_s"]  # (the bus dwells booked, the van parks)
    for chunk in (None, 37):
        out = tmp_path / f"rep{chunk}"
        res = process_fcd(tmp_path / "fcd.xml", scenario=sc, out_dir=out, chunk_rows=chunk, figures=False)
        pd.testing.assert_frame_equal(booked_per_vehicle(out), live, rtol=1e-6, atol=1e-9, obj=str(chunk))
        assert res["source"]["parked_rows"] > 100
