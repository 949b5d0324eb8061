"""Riders of parked vehicles (sim/riders.py): a vehicle parked off its lane is not booked, so
its riders are not read while it stands (a parked fleet costs no getter calls, also while
persons walk in the network); they are read when its stop ends, and a car that drives on
from a parking area with a rider is booked with him, as SUMO's emission output books it."""

from __future__ import annotations


import libsumo
import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_probe import build_net, energy_scenario
from test_parking_exit_blocked import sumo_electricity

PARKED = "".join(f'<vehicle id="f{i}" type="ecar" depart="{100 + i}" departPos="5"><route edges="e1"/>'
                 f'<stop parkingArea="pb" duration="5000"/></vehicle>' for i in range(30))
ROUTES = """<routes>
  <vType id="heavy" vClass="pedestrian" mass="400"/>
  <vType id="ecar" vClass="passenger" mass="1600" emissionClass="Energy/unknown" personCapacity="4">
    <param key="rotatingMass" value="80"/></vType>
  <vehicle id="c" type="ecar" depart="triggered" departPos="5" departSpeed="0"><route edges="e1 e2"/>
    <stop parkingArea="pa" duration="20"/></vehicle>
  <person id="r" type="heavy" depart="0" departPos="10"><ride from="e1" to="e2" lines="c"/></person>
  <person id="w" depart="0" departPos="10"><walk edges="e1 e2"/></person>
  {parked}
</routes>"""


def test_parked_fleet_riders(tmp_path, monkeypatch):
    """2 km at 0.5-s steps: a car carrying a 400-kg rider parks 20 s in a parking area and
    drives on with him; then 30 cars park for good while a person walks the whole run.
    Measured 2026-11-27 before the fix (every vehicle at a stop read each step while persons
    exist, parked ones too): getPersonIDList called 2,248 times; now 54 (departures, stop
    starts and ends); the rider's car as SUMO's emission output to 1e-6 after the fix."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="1500" y="0"/><node id="d" x="2000" y="0"/></nodes>',
              '<edges><edge id="e1" from="a" to="b" numLanes="1" speed="14"/><edge id="e2" from="b" to="d" numLanes="1" speed="14"/></edges>')
    (tmp_path / "r.rou.xml").write_text(ROUTES.format(parked=PARKED), encoding="utf-8")
    (tmp_path / "a.add.xml").write_text('<additional><parkingArea id="pa" lane="e1_0" startPos="400" endPos="450" '
                                        'roadsideCapacity="3"/><parkingArea id="pb" lane="e1_0" startPos="600" '
                                        'endPos="1000" roadsideCapacity="40"/></additional>', encoding="utf-8")
    energy_scenario(tmp_path, 250, additional="a.add.xml", fcd=False)
    calls = [0]
    real = libsumo.vehicle.getPersonIDList

    def counted(vid):
        calls[0] += 1
        return real(vid)

    monkeypatch.setattr(libsumo.vehicle, "getPersonIDList", counted)
    res = run_scenario(tmp_path / "s.toml", tmp_path / "o")
    assert res["transportables"]["max_kg"] == 400.0
    # 31 departures, 31 stop starts, 1 stop end: not one read per parked car and step
    assert calls[0] < 200, calls[0]
    sumo_wh, nan = sumo_electricity(tmp_path / "s.toml", tmp_path, vehicles=("c",))  # (the step it parks in too)
    assert not nan
    cv = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv").set_index("key")
    assert cv.loc["c", "net_kwh"] * 1000.0 == pytest.approx(sumo_wh["c"], rel=1e-6)
