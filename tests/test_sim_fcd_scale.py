"""`fcd` at fleet scale (#14): the FCD streamed in blocks equals the whole file read at once,
and `--engine dask` (vehicles split into buckets, one task each) equals the local engine."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd
from sumo_drvpw.sim.fcd_replay import timesteps
from sumo_drvpw.sim.fcd_read import Block, iter_fcd_blocks

REPO = Path(__file__).resolve().parent.parent
CITY = REPO / "scenarios" / "city.toml"
PHYS = Equation("phys", {"acc": 1.0, "grade": 1.0, "aero_rho": 0.25 * 2.23, "roll": 0.01})
VSP = Equation("vsp", {"acc": 1.1, "grade": 1.0, "m_v1": 0.132, "m_v3": 0.000302})
KEY = ["vehicle", "equation"]
BEV = """[equation]
name = "bev"
[terms]
acc = 1.05
grade = 1.0
roll = 0.009
aero_rho = 0.6
[chain]
predicts = "battery"
traction_efficiency = 0.9
recuperation_efficiency = 0.7
recuperation_limit_w = 20000.0
aux_power_w = 500.0
"""


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


#: rows per block of the streamed reads: a prime, so boundaries fall inside timesteps and
#: inside the vehicles' trips (about 200 blocks of the 200-s city FCD)
ROWS = 97


def _tables(res):
    v = res.vehicles.sort_values(KEY).reset_index(drop=True)
    e = res.edges.sort_values(["edge", "equation"]).reset_index(drop=True)
    c = res.classes.sort_values(list(res.classes.columns[:3])).reset_index(drop=True)
    return v, e, c


@pytest.mark.sumo
@pytest.mark.parametrize("name", ["fcd.xml.gz", "fcd.parquet", "fcd.csv"])
def test_streamed_fcd_equals_the_whole_file(fcd, tmp_path, name):
    """Blocks of :data:`ROWS` rows (block boundaries inside timesteps and inside every
    vehicle's trip) book exactly what the whole file read at once books: per-vehicle,
    per-edge and per-class tables and the summary's energies, bit for bit; with flushes of
    2 finished vehicles, so the arrivals must come at the same steps too."""
    path = fcd / name
    if name == "fcd.csv":  # SUMO's tabular CSV, from the Parquet output's rows
        pd.read_parquet(fcd / "fcd.parquet").to_csv(path, sep=";", index=False)
    if name.endswith(".parquet"):  # the test's premise: a timestep is cut by a block boundary
        blocks = list(iter_fcd_blocks(path, ROWS))
        cut = sum(a.cols["time"][-1] == b.cols["time"][0] for a, b in zip(blocks, blocks[1:]))
        assert cut > 10
    kw = dict(scenario=CITY, equations=[PHYS, VSP], end=200, figures=False, flush_vehicles=2)
    ref = process_fcd(path, chunk_rows=None, out_dir=tmp_path / "ref", **kw)
    res = process_fcd(path, chunk_rows=ROWS, out_dir=tmp_path / "out", **kw)
    for a, b in zip(_tables(ref), _tables(res)):
        pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert len(_tables(res)[0]) > 80 and res.ledger.flushed_vehicles >= 8
    for k in ("steps", "samples", "vehicles", "equations", "classes"):
        assert res[k] == ref[k]
    assert res["source"]["timesteps"] == ref["source"]["timesteps"] == res["steps"] > 100
    assert res["source"]["rows"] == ref["source"]["rows"] == res["samples"]
    a = (tmp_path / "ref" / "edgedata.xml").read_text(encoding="utf-8")
    assert a == (tmp_path / "out" / "edgedata.xml").read_text(encoding="utf-8")
    assert json.loads((tmp_path / "out" / "summary.json").read_text(encoding="utf-8"))["vehicles"] > 40


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


def test_the_stream_reads_no_further_ahead_than_two_timesteps():
    """Memory does not grow with the file: with one block per timestep, when the replay
    has booked timestep k it has pulled at most the blocks up to k + 2 (the next timestep,
    and the block that shows it complete)."""
    from sumo_drvpw.sim.fcd_replay import FcdStream

    pulled = []

    def blocks():
        for k in range(50):
            pulled.append(k)
            yield _block([float(k)], [(float(k), f"v{k // 10}"), (float(k), "w")], first=2 * k)

    replay = FcdStream(timesteps(blocks()), dt=1.0)
    for k in range(50):
        replay.simulationStep()
        assert len(pulled) <= k + 3
        assert replay.ids == (f"v{k // 10}", "w") and replay.t == k + 1.0
        if k and k % 10 == 0:  # v(k/10 − 1) left: arrived the step after its last row
            assert replay.arrived == (f"v{k // 10 - 1}",) and replay.departed == (f"v{k // 10}",)
        elif k:
            assert replay.arrived == () == replay.departed
    assert replay.remaining() == 0 and replay.rows == 100


def test_person_rows_are_not_vehicles_and_may_lack_speed_and_position(tmp_path):
    """SUMO's XML FCD writes persons as <person> (speed and position optional); its tabular
    FCD writes them in the vehicles' columns without a lane. Both are read as persons: not
    vehicles of the replay, no error for a missing speed; a vehicle lacking one still is."""
    from sumo_drvpw.sim.fcd_replay import FcdStream

    (tmp_path / "f.xml").write_text(
        '<fcd-export><timestep time="0.00"><vehicle id="v" x="8.3" y="-1.6" speed="0" '
        'pos="5.1" lane="l_0" type="car"/><person id="q" x="1" y="2" type="ped" edge="l"/>'
        '</timestep><timestep time="1.00"><vehicle id="v" x="9.3" y="-1.6" speed="1" '
        'pos="6.1" lane="l_0" type="car"/></timestep></fcd-export>\n', encoding="utf-8")
    pd.DataFrame({"timestep_time": [0.0, 0.0, 1.0], "vehicle_id": ["v", "q", "v"],
                  "vehicle_type": ["car", "ped", "car"], "vehicle_speed": [0.0, 1.2, 1.0],
                  "vehicle_pos": [5.1, 3.0, 6.1], "vehicle_lane": ["l_0", None, "l_0"]}
                 ).to_parquet(tmp_path / "f.parquet")
    for name in ("f.xml", "f.parquet"):
        steps = list(timesteps(iter_fcd_blocks(tmp_path / name)))
        assert list(steps[0].cols["person"]) == [False, True]
        replay = FcdStream(iter(steps), dt=1.0)
        replay.simulationStep()
        assert replay.ids == ("v",) and replay.person_count == 1
        assert replay.simulation.getDepartedPersonIDList() == ("q",)
    (tmp_path / "bad.xml").write_text((tmp_path / "f.xml").read_text(encoding="utf-8").replace(' speed="1"', ""), encoding="utf-8")
    with pytest.raises(UserError, match="column speed missing at vehicle row 3"):
        list(iter_fcd_blocks(tmp_path / "bad.xml"))


def test_a_person_of_an_undeclared_type_is_counted_as_a_pedestrian():
    """An FCD replay knows no vClass (the route files say it); a person whose type no file
    declares (SUMO's DEFAULT_PEDTYPE) is a pedestrian, SUMO's default for persons — before,
    Bologna's 1799 walkers were reported as unbooked 'passenger' vehicles. A vehicle of an
    undeclared type stays a passenger car, SUMO's default for vehicles."""
    from types import SimpleNamespace

    from sumo_drvpw.sim.run import VTypeResolver
    from sumo_drvpw.sim.vtypes import VTypeInfo

    conn = SimpleNamespace(vehicletype=SimpleNamespace(getVehicleClass=lambda vt: ""))
    r = VTypeResolver(None, {"walker": VTypeInfo("walker", None, None, "f", "pedestrian")}, [], conn)
    for vt in ("DEFAULT_PEDTYPE", "DEFAULT_PEDTYPE", "walker"):
        r.skip_person(vt)
    assert r.skipped["by_vclass"] == {"pedestrian": 3}
    assert r._vclass("DEFAULT_VEHTYPE", None) == "passenger"


def test_rows_out_of_time_order_name_the_row():
    b1 = _block([0.0, 2.0], [(0.0, "a"), (2.0, "a")])
    b2 = _block([1.0], [(1.0, "b")], first=2)
    with pytest.raises(UserError, match=r"time 1 after 2 at vehicle row 3"):
        list(timesteps([b1, b2], label="x.parquet"))


def _leaves(doc, path=()) -> dict:
    """A JSON document's leaves: path → value."""
    if isinstance(doc, dict):
        return {k: v for key, x in doc.items() for k, v in _leaves(x, path + (key,)).items()}
    if isinstance(doc, list):
        return {k: v for i, x in enumerate(doc) for k, v in _leaves(x, path + (i,)).items()}
    return {path: doc}


def _numbers_equal(a: pd.DataFrame, b: pd.DataFrame, rtol: float = 1e-9) -> None:
    assert list(a.columns) == list(b.columns) and len(a) == len(b) > 0
    num = a.select_dtypes("number").columns
    pd.testing.assert_frame_equal(a.drop(columns=num), b.drop(columns=num))
    np.testing.assert_allclose(b[num].to_numpy(float), a[num].to_numpy(float), rtol=rtol,
                               atol=1e-9)


@pytest.mark.sumo
def test_fcd_on_dask_equals_local(fcd, tmp_path, capsys):
    """`fcd --engine dask --workers 2 --buckets 3`: three vehicle buckets on a local
    2-worker cluster book per-vehicle, per-edge and per-class tables and the summary's
    energies equal to the local engine's (1e-9 relative: only the order of additions
    differs); with a battery chain and a fuel chain booking cold starts (their vehicle, edge
    and class tables and summary too) and edgeData intervals of 50 s."""
    pytest.importorskip("distributed")
    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.sim.fcd_dask import BUCKET_DIR, bucket_of

    (tmp_path / "bev.toml").write_text(BEV, encoding="utf-8")
    # the city scenario with a [vtypes.prius3] table: no bucket may call it unmatched
    sc = tmp_path / "city.toml"
    sc.write_text(CITY.read_text(encoding="utf-8").replace(
        'config = "city.sumocfg"', f'config = "{(CITY.parent / "city.sumocfg").as_posix()}"')
        + "\n[vtypes.prius3]\nmass_kg = 1625.0\n", encoding="utf-8")
    base = ["fcd", str(fcd / "fcd.xml.gz"), "--scenario", str(sc), "--end", "200",
            "--equation", str(tmp_path / "bev.toml"), "--equation", "vsp_ldv1999",
            "--equation", "epa_gasoline_car", "--cold-start", "--period", "50", "--no-figures"]
    assert cli_main(base + ["--out", str(tmp_path / "local")]) == 0
    out = capsys.readouterr().out
    assert "epa_gasoline_car fuel, passenger: " in out and "(cold starts " in out
    assert cli_main(base + ["--engine", "dask", "--workers", "2", "--buckets", "3",
                            "--out", str(tmp_path / "dask")]) == 0
    a, b = tmp_path / "local", tmp_path / "dask"
    va = pd.read_parquet(a / "vehicles.parquet").sort_values(KEY).reset_index(drop=True)
    vb = pd.read_parquet(b / "vehicles.parquet").sort_values(KEY).reset_index(drop=True)
    _numbers_equal(va, vb)
    assert set(bucket_of(va.vehicle.unique(), 3)) == {0, 1, 2}  # every bucket booked some
    for name in ("edges.parquet", "classes.parquet"):
        _numbers_equal(pd.read_parquet(a / name), pd.read_parquet(b / name))
    sa, sb = (json.loads((d / "summary.json").read_text(encoding="utf-8")) for d in (a, b))
    for k in ("steps", "samples", "vehicles", "classes", "slope_corrected_samples", "end_s"):
        assert sb[k] == sa[k]
    for eq, d in sa["equations"].items():
        for cls, e in d["energy_j"].items():
            for t, x in e.items():
                assert sb["equations"][eq]["energy_j"][cls][t] == pytest.approx(x, rel=1e-9)
    for name in ("chain_vehicles.csv", "chain_edges.csv", "chain_classes.csv"):
        x, y = pd.read_csv(a / name), pd.read_csv(b / name)
        key = list(x.columns[:2])
        _numbers_equal(x.sort_values(key).reset_index(drop=True),
                       y.sort_values(key).reset_index(drop=True))
    assert sb["chain"].keys() == sa["chain"].keys() and sa["chain"]
    assert sb["chain"]["cold_start"]["vehicles"] == sa["chain"]["cold_start"]["vehicles"] == sa["vehicles"]
    la, lb = _leaves(sa["chain"]), _leaves(sb["chain"])
    assert la.keys() == lb.keys() and len(la) > 4
    for k, x in la.items():
        assert lb[k] == (pytest.approx(x, rel=1e-9, abs=1e-9) if isinstance(x, float) else x), k
    da, db = _leaves(sa["driving_dynamics"]), _leaves(sb["driving_dynamics"])  # the buckets' 1-Hz samples add up
    assert da.keys() == db.keys() and len(da) > 10
    for k, x in da.items():
        assert db[k] == (pytest.approx(x, rel=1e-9) if isinstance(x, float) else x), k
    assert sb["source"]["buckets"] == 3 and sb["source"]["rows"] == sa["source"]["rows"]
    assert sb["warnings"] == sa["warnings"] and not any("matched no vehicle" in w for w in sb["warnings"])
    assert not (b / BUCKET_DIR).exists()
    ea, eb = ((d / "edgedata.xml").read_text(encoding="utf-8") for d in (a, b))
    assert ea.count("<interval ") == eb.count("<interval ") == 4
    na, nb = (np.array(re.findall(r'="(-?[0-9.]+(?:e[-+]?[0-9]+)?)"', e), float) for e in (ea, eb))
    np.testing.assert_allclose(nb, na, rtol=1e-5, atol=2e-6)  # printed to 6 decimals
    code = cli_main(base + ["--buckets", "2", "--out", str(tmp_path / "x")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and "--buckets goes with --engine dask" in err
    assert not (tmp_path / "x").exists()


def test_vehicle_buckets_are_the_same_in_every_process():
    """Dask tasks on other processes must agree on each vehicle's bucket: the hash is not
    Python's per-process salted hash(); ids repeated over rows get their id's bucket."""
    import os
    import subprocess
    import sys

    from sumo_drvpw.sim.fcd_dask import bucket_of

    ids = [f"flow{k}.{j}" for k in range(20) for j in range(10)]
    here = bucket_of(ids, 7).tolist()
    code = ("import sys, json; from sumo_drvpw.sim.fcd_dask import bucket_of; "
            "print(json.dumps(bucket_of(json.loads(sys.argv[1]), 7).tolist()))")
    out = subprocess.run([sys.executable, "-c", code, json.dumps(ids)], capture_output=True,
                         text=True, check=True, env=dict(os.environ, PYTHONHASHSEED="123"))
    assert json.loads(out.stdout) == here and set(here) == set(range(7))
    rows = np.array(ids * 3, object)
    assert bucket_of(rows, 7).tolist() == here * 3


def test_fcd_on_dask_books_riders_as_local(tmp_path):
    """Riding persons on Dask: every bucket keeps every person's rows (a person is matched
    to the vehicle at its x, y and speed, whichever bucket that vehicle is in), one bucket
    counts them as skipped: energies, the riders' statistics and the skipped persons equal
    the local engine's."""
    pytest.importorskip("distributed")
    from test_sim_run import bus_riders_scenario

    from sumo_drvpw.cli import main as cli_main

    sc = bus_riders_scenario(tmp_path)
    run_scenario(sc, None, equations=["vsp_ldv1999"], figures=False,
                 options=["--fcd-output", str(tmp_path / "fcd.parquet")])
    (tmp_path / "bus.toml").write_text('[equation]\nname = "phys"\nvclasses = ["bus"]\n[terms]\n'
                                       'acc = 1.0\ngrade = 1.0\naero_rho = 0.5575\nroll = 0.01\n', encoding="utf-8")
    base = ["fcd", str(tmp_path / "fcd.parquet"), "--scenario", str(sc), "--equation",
            str(tmp_path / "bus.toml"), "--no-figures"]
    assert cli_main(base + ["--out", str(tmp_path / "local")]) == 0
    assert cli_main(base + ["--engine", "dask", "--workers", "2", "--buckets", "3",
                            "--out", str(tmp_path / "dask")]) == 0
    sa, sb = (json.loads((tmp_path / d / "summary.json").read_text(encoding="utf-8")) for d in ("local", "dask"))
    assert sa["transportables"]["max_kg"] == 1600.0
    assert sb["transportables"] == sa["transportables"] and sb["skipped"] == sa["skipped"]
    assert sa["skipped"]["by_vclass"] == {"pedestrian": 20}
    assert sb["source"]["riding_person_rows"] == sa["source"]["riding_person_rows"] > 0
    for t, x in sa["equations"]["phys"]["energy_j"]["city"].items():
        assert sb["equations"]["phys"]["energy_j"]["city"][t] == pytest.approx(x, rel=1e-9)


def test_dask_buckets_add_up_the_vehicles_no_chain_books():
    """merge_ledgers adds the buckets' counts of vehicles no chain books, per vClass and per
    vType (it kept the first bucket's only: the warning and summary.json chain.chainless
    counted a third of them on three buckets)."""
    from sumo_drvpw.sim.fcd_dask import merge_ledgers
    from sumo_drvpw.sim.ledger import Ledger

    a, b = Ledger(3, 1), Ledger(3, 1)
    a.chainless, a.chainless_vtypes = {"passenger": 2}, {"cng": 2}
    b.chainless, b.chainless_vtypes = {"passenger": 1, "bus": 4}, {"cng": 1, "ebus": 4}
    out = merge_ledgers([a, b])
    assert out.chainless == {"passenger": 3, "bus": 4} and out.chainless_vtypes == {"cng": 3, "ebus": 4}
