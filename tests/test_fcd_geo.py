"""An FCD written in longitude, latitude (``--fcd-output.geo``) or UTM (``--fcd-output.utm``)
is replayed as one in the network's x, y (sim/fcd_geo.py): its x, y are brought back into
the network's, so parked vehicles are told beside their lane and standing ones are not.
Real SUMO runs on a hand-made network placed in Hamburg (UTM zone 32): a queue at a red
light on a road 20 m north of the network's origin, and a car parked beside the road."""

from __future__ import annotations

import re
import subprocess

import numpy as np
import pandas as pd
import pytest
import sumolib

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd
from sumo_drvpw.sim.fcd_geo import NetCoordinates
from sumo_drvpw.sim.scenario import load_scenario
from sumo_probe import booked_per_vehicle, build_net, energy_scenario

pytestmark = pytest.mark.sumo

#: the network's place: UTM zone 32 easting, northing of its origin [m] (Hamburg, 10.0°E 53.55°N)
ORIGIN = (566_300.0, 5_934_900.0)
LOCATION = (f'<location netOffset="{-ORIGIN[0]:.2f},{-ORIGIN[1]:.2f}" convBoundary="0.00,20.00,600.00,20.00" '
            'origBoundary="9.99,53.54,10.01,53.56" projParameter="+proj=utm +zone=32 +ellps=WGS84 +datum=WGS84 '
            '+units=m +no_defs"/>')


def _record(d, mode: str):
    net = build_net(d, '<nodes><node id="a" x="0" y="20"/><node id="b" x="300" y="20" type="traffic_light"/>'
                       '<node id="c" x="600" y="20"/></nodes>',
                    '<edges><edge id="e1" from="a" to="b" numLanes="1" speed="14"/>'
                    '<edge id="e2" from="b" to="c" numLanes="1" speed="14"/></edges>',
                    "--offset.disable-normalization")
    net.write_text(re.sub(r"<location [^>]*/>", LOCATION, net.read_text(encoding="utf-8")), encoding="utf-8")
    (d / "tl.add.xml").write_text(
        '<additional><tlLogic id="b" type="static" programID="long" offset="0"><phase duration="60" state="r"/>'
        '<phase duration="60" state="G"/></tlLogic></additional>', encoding="utf-8")
    cars = "".join(f'<vehicle id="q{i}" type="ecar" depart="{3 + 2 * i}"><route edges="e1 e2"/></vehicle>'
                   for i in range(6))
    (d / "r.rou.xml").write_text(
        '<routes><vType id="ecar" vClass="passenger" mass="1500" emissionClass="Energy/unknown"/>'
        '<vehicle id="park" type="ecar" depart="0"><route edges="e1 e2"/>'
        f'<stop lane="e1_0" endPos="100" duration="30" parking="true"/></vehicle>{cars}</routes>', encoding="utf-8")
    sc = energy_scenario(d, 130, step_length=1.0, additional="tl.add.xml", fcd=True)
    sc.write_text(sc.read_text(encoding="utf-8").replace('"--fcd-output",', f'"--fcd-output.{mode}", "true", '
                                                         '"--fcd-output",'), encoding="utf-8")
    run_scenario(sc, d / "live")
    return sc


@pytest.mark.parametrize("mode", ["geo", "utm"])
def test_geo_and_utm_fcd_book_as_the_live_run(tmp_path, mode):
    """Before 2026-11-29 the replay compared longitude, latitude (about 10, 53.56) with the
    network's metres: the queue standing at the red light on a road at y = 20 m lay 33 m
    "beside" it, so its standing rows were taken for parked ones and not booked (measured:
    q0–q3 61 s against the live run's 83–84 s), and in UTM the parked car's x, y lay
    5.9 million m off its lane, so it was booked standing (101 s against 73). Now time,
    distance, auxiliary and net energy equal the live run's per car, from the XML (its
    header says the coordinates) and, for geo, from SUMO's header-less CSV FCD (told by the
    rows' distance from their lanes)."""
    sc = _record(tmp_path, mode)
    live = booked_per_vehicle(tmp_path / "live")
    assert live.loc["q0", "time_s"] > 80  # (the queue waits at the light)
    res = process_fcd(tmp_path / "fcd.xml", scenario=sc, out_dir=tmp_path / "rep", chunk_rows=40, figures=False)
    pd.testing.assert_frame_equal(booked_per_vehicle(tmp_path / "rep"), live, rtol=1e-6, atol=1e-9)
    assert res["source"]["parked_rows"] > 20  # (the parked car: told beside its lane)
    assert res["source"]["unplaced_vehicle_rows"] == 0
    if mode == "geo":  # SUMO's CSV FCD has no header: its coordinates told from its rows
        args = list(load_scenario(sc).sumo_args)
        del args[args.index("--fcd-output"):args.index("--fcd-output") + 2]
        subprocess.run([sumolib.checkBinary("sumo"), *args, "--fcd-output", str(tmp_path / "fcd.csv")],
                       check=True, capture_output=True)
        head = (tmp_path / "fcd.csv").read_text(encoding="utf-8").splitlines()[:3]
        assert any("53.5" in line for line in head)  # (latitudes: SUMO wrote geo)
        process_fcd(tmp_path / "fcd.csv", scenario=sc, out_dir=tmp_path / "csv", figures=False)
        pd.testing.assert_frame_equal(booked_per_vehicle(tmp_path / "csv"), live, rtol=1e-6, atol=1e-9)


def test_utm_series_inverts_the_networks_geo_output(tmp_path):
    """The network's x, y of SUMO's own longitude, latitude (Krüger's series): SUMO's FCD
    rows of cars on the straight road y = 20 m, brought back, lie on it to the 1e-6°
    rounding of the FCD (< 0.1 m)."""
    _record(tmp_path, "geo")
    rows = [dict(re.findall(r'(\w+)="([^"]*)"', m)) for m in
            re.findall(r"<vehicle ([^>]*)/>", (tmp_path / "fcd.xml").read_text(encoding="utf-8"))]
    rows = [r for r in rows if float(r["speed"]) > 1.0 and r["lane"] in ("e1_0", "e2_0")]
    x, y = NetCoordinates("geo", tmp_path / "n.net.xml")(np.array([float(r["x"]) for r in rows]),
                                                       np.array([float(r["y"]) for r in rows]))
    lane_y = 20.0 - 1.6  # (the right-hand lane's centre)
    along = np.array([float(r["pos"]) for r in rows]) + np.where([r["lane"] == "e2_0" for r in rows], 300.0, 0.0)
    assert np.abs(y - lane_y).max() < 0.1
    assert np.abs(x - along).max() < 15.0  # (the junction's shape shortens the lanes a little)


@pytest.mark.parametrize("edit", ["zone", "latitude", "swapped"])
def test_a_geo_fcd_whose_rows_lie_off_the_network_is_read_without_x_y_and_said(tmp_path, edit):
    """An FCD whose header says geo, but whose coordinates the network's projection does not
    put on their lanes — the network of another UTM zone (zone 33 for 32), latitudes out of
    range (+1000°), longitude and latitude swapped — was replayed at those coordinates: the
    parked car lay hundreds of km off its lane and was booked standing (measured: 101 s
    against the live run's 73 s), without a word. Now, as for a header-less FCD (AUTO_MAX_M),
    rows lying so far from their lanes are read as without x, y, and said; the declared
    parking stop tells the parked car."""
    sc = _record(tmp_path, "geo")
    live = booked_per_vehicle(tmp_path / "live")
    fcd = (tmp_path / "fcd.xml").read_text(encoding="utf-8")
    if edit == "zone":
        net = tmp_path / "n.net.xml"
        net.write_text(net.read_text(encoding="utf-8").replace("+zone=32", "+zone=33"), encoding="utf-8")
    elif edit == "latitude":
        fcd = re.sub(r'y="(53\.\d+)"', lambda m: f'y="{float(m.group(1)) + 1000:.6f}"', fcd)
    else:
        fcd = re.sub(r'x="([\d.]+)" y="([\d.]+)"', r'x="\2" y="\1"', fcd)
    (tmp_path / "edited.xml").write_text(fcd, encoding="utf-8")
    res = process_fcd(tmp_path / "edited.xml", scenario=sc, out_dir=tmp_path / "rep", figures=False)
    rep = booked_per_vehicle(tmp_path / "rep")  # (the parked car's distance without x, y: to 1e-5)
    pd.testing.assert_series_equal(rep["time_s"], live["time_s"], rtol=1e-9)
    pd.testing.assert_frame_equal(rep, live, rtol=1e-4, atol=1e-9)
    said = " ".join(res["warnings"]) if "warnings" in res else str(res)
    assert "fcd-output.geo" in said and "another network" in said


def test_a_row_out_of_range_is_without_x_y_not_the_file():
    """Longitude beyond ±180° or latitude beyond ±90° is no position (NaN), and a pole
    raises no numpy warning; the rest of the rows convert."""
    import warnings

    from sumo_drvpw.sim.fcd_geo import utm_forward

    coords = NetCoordinates.__new__(NetCoordinates)
    coords.mode, coords.lost, coords.offset = "geo", None, (-ORIGIN[0], -ORIGIN[1])
    coords._proj = lambda lon, lat: utm_forward(lon, lat, 32)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        x, y = coords(np.array([10.0, 200.0, 10.0, 10.0]), np.array([53.55, 53.55, 95.0, 90.0]))
    assert abs(x[0]) < 1000 and abs(y[0]) < 1000  # (Hamburg: near the network's origin)
    assert np.isnan(x[1:3]).all() and np.isnan(y[1:3]).all()
