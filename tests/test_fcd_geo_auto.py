"""A header-less FCD (SUMO's CSV or Parquet) whose coordinates cannot be brought back into
the network's is read as without x, y and said — not taken for the network's own."""

from __future__ import annotations

import importlib.util
import subprocess

import pandas as pd
import pytest
import sumolib

import test_fcd_geo as g
from sumo_drvpw.sim.fcd import process_fcd
from sumo_drvpw.sim.scenario import load_scenario
from sumo_probe import booked_per_vehicle

pytestmark = pytest.mark.sumo

#: the same place as test_fcd_geo's, in a transverse Mercator that is not written as UTM
#: (numerically UTM zone 32): without pyproj nothing here brings its longitudes back
TMERC = g.LOCATION.replace("+proj=utm +zone=32", "+proj=tmerc +lat_0=0 +lon_0=9 +k=0.9996 +x_0=500000 +y_0=0")


def test_a_headerless_geo_fcd_that_cannot_be_converted_is_not_read_as_metres(tmp_path, monkeypatch):
    """Before: the CSV's longitude, latitude (about 10, 53.56) were taken for the network's
    metres (the nearest of the coordinates it could compute, 33 m from the road, was chosen
    whatever the distance), so the queue's standing rows at the red light read as parked
    and were not booked, without a word."""
    if importlib.util.find_spec("pyproj") is not None:
        pytest.skip("pyproj installed: the projection is brought back")
    monkeypatch.setattr(g, "LOCATION", TMERC)
    sc = g._record(tmp_path, "geo")
    live = booked_per_vehicle(tmp_path / "live")
    args = list(load_scenario(sc).sumo_args)
    del args[args.index("--fcd-output"):args.index("--fcd-output") + 2]
    subprocess.run([sumolib.checkBinary("sumo"), *args, "--fcd-output", str(tmp_path / "fcd.csv")],
                   check=True, capture_output=True)
    res = process_fcd(tmp_path / "fcd.csv", scenario=sc, out_dir=tmp_path / "csv", figures=False)
    rep = booked_per_vehicle(tmp_path / "csv")
    queue = [f"q{i}" for i in range(4)]
    pd.testing.assert_series_equal(rep.loc[queue, "time_s"], live.loc[queue, "time_s"], rtol=1e-6)
    assert any("without x, y" in w for w in res.get("warnings", [])), res.get("warnings")
