"""`fcd` at fleet scale (#14): the FCD streamed in blocks equals the whole file read at once,
and `--engine dask` (vehicles split into buckets, one task each) equals the local engine."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd, timesteps
from sumo_drvpw.sim.fcd_read import Block, iter_fcd_blocks

REPO = Path(__file__).resolve().parent.parent
CITY = REPO / "scenarios" / "city.toml"
PHYS = Equation("phys", {"acc": 1.0, "grade": 1.0, "aero_rho": 0.25 * 2.23, "roll": 0.01})
VSP = Equation("vsp", {"acc": 1.1, "grade": 1.0, "m_v1": 0.132, "m_v3": 0.000302})
KEY = ["vehicle", "equation"]


@pytest.fixture(scope="module")
def fcd(tmp_path_factory):
    """A real SUMO run of the city scenario (200 s) recording FCD as XML and as Parquet."""
    d = tmp_path_factory.mktemp("fcd")
    run_scenario(CITY, None, end=200, equations=[PHYS], figures=False,
                 options=["--fcd-output", str(d / "fcd.xml.gz"), "--precision", "6",
                          "--fcd-output.acceleration", "true"])
    run_scenario(CITY, None, end=200, equations=[PHYS], figures=False,
                 options=["--fcd-output", str(d / "fcd.parquet")])
    return d


def _tables(res):
    v = res.vehicles.sort_values(KEY).reset_index(drop=True)
    e = res.edges.sort_values(["edge", "equation"]).reset_index(drop=True)
    c = res.classes.sort_values(list(res.classes.columns[:3])).reset_index(drop=True)
    return v, e, c


@pytest.mark.sumo
@pytest.mark.parametrize("name", ["fcd.xml.gz", "fcd.parquet"])
def test_streamed_fcd_equals_the_whole_file(fcd, tmp_path, name):
    """Blocks of 7 rows (Parquet: block boundaries inside timesteps and inside every
    vehicle's trip) book exactly what the whole file read at once books: per-vehicle,
    per-edge and per-class tables and the summary's energies, bit for bit; with flushes of
    2 finished vehicles, so the arrivals must come at the same steps too."""
    path = fcd / name
    if name.endswith(".parquet"):  # the test's premise: a timestep is cut by a block boundary
        blocks = list(iter_fcd_blocks(path, 7))
        cut = sum(a.cols["time"][-1] == b.cols["time"][0] for a, b in zip(blocks, blocks[1:]))
        assert cut > 10
    kw = dict(scenario=CITY, equations=[PHYS, VSP], end=200, figures=False, flush_vehicles=2)
    ref = process_fcd(path, chunk_rows=None, out_dir=tmp_path / "ref", **kw)
    res = process_fcd(path, chunk_rows=7, out_dir=tmp_path / "out", **kw)
    for a, b in zip(_tables(ref), _tables(res)):
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert len(_tables(res)[0]) > 80 and res.ledger.flushed_vehicles >= 8
    for k in ("steps", "samples", "vehicles", "equations", "classes"):
        assert res[k] == ref[k]
    assert res["source"]["timesteps"] == ref["source"]["timesteps"] == res["steps"] > 100
    assert res["source"]["rows"] == ref["source"]["rows"] == res["samples"]
    a = (tmp_path / "ref" / "edgedata.xml").read_text()
    assert a == (tmp_path / "out" / "edgedata.xml").read_text()
    assert json.loads((tmp_path / "out" / "summary.json").read_text())["vehicles"] > 40


def _block(times, rows, first=0):
    t = np.array([r[0] for r in rows], float)
    ids = np.array([r[1] for r in rows], object)
    n = len(rows)
    cols = {"time": t, "id": ids, "type": np.full(n, "car", object),
            "speed": np.arange(n, dtype=float) + first, "lane": np.full(n, "e_0", object),
            "pos": np.zeros(n)}
    return Block(np.asarray(times, float), cols, first)


def test_timesteps_are_never_split_and_keep_empty_ones():
    """Rows of timestep 1 in two blocks come out as one timestep; the empty timestep 2
    (an XML <timestep/> without vehicles) is kept; a bucket filter keeps every timestep."""
    b1 = _block([0.0, 1.0], [(0.0, "a"), (1.0, "a"), (1.0, "b")])
    b2 = _block([1.0, 2.0, 3.0], [(1.0, "c"), (3.0, "a")], first=3)
    steps = list(timesteps([b1, b2]))
    assert [s.t for s in steps] == [0.0, 1.0, 2.0, 3.0]
    assert [list(s.cols["id"]) for s in steps] == [["a"], ["a", "b", "c"], [], ["a"]]
    assert list(steps[1].cols["speed"]) == [1.0, 2.0, 3.0]  # row order of the file
    only_a = list(timesteps([b1, b2], keep=lambda ids: ids == "a"))
    assert [list(s.cols["id"]) for s in only_a] == [["a"], ["a"], [], ["a"]]
    assert [s.t for s in timesteps([b1, b2], begin_s=1.0)] == [1.0, 2.0, 3.0]


def test_rows_out_of_time_order_name_the_row():
    b1 = _block([0.0, 2.0], [(0.0, "a"), (2.0, "a")])
    b2 = _block([1.0], [(1.0, "b")], first=2)
    with pytest.raises(UserError, match=r"time 1 after 2 at vehicle row 3"):
        list(timesteps([b1, b2], label="x.parquet"))
