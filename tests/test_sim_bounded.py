"""The bounded ledger (#14): vehicles that left SUMO are written out and dropped from memory;
vehicle, edge and class totals equal those of the run that keeps every vehicle. Real SUMO."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.model.equations import Equation, load_equation
from sumo_drvpw.sim import Accountant, close_sumo, run_scenario, start_sumo
from sumo_drvpw.sim.scenario import load_scenario
from sumo_drvpw.sim.spill import SPILL_DIR

pytestmark = pytest.mark.sumo

NETS = Path(__file__).resolve().parent.parent / "sumo_drvpw" / "sim" / "builtin" / "networks"
#: many short trips (one block each) on the city grid: trips ≫ vehicles running at once
EDGES = ["c00c10", "c20c30", "c01c11", "c44c34", "c04c14", "c40c30", "c12c22", "c03c13"]


def _scenario(tmp_path: Path, end: float = 240.0) -> Path:
    flows = "\n".join(
        f'  <flow id="f{k}" type="car" from="{a}" to="{a}" begin="0" end="{end - 30}" '
        f'period="4" departSpeed="max"/>' for k, a in enumerate(EDGES))
    (tmp_path / "short.rou.xml").write_text(
        '<routes>\n  <vType id="car" vClass="passenger" mass="1500"/>\n'
        '  <vType id="van" vClass="delivery" mass="2600"/>\n'
        f'{flows}\n  <flow id="v" type="van" from="c00c01" to="c00c01" begin="0" '
        f'end="{end - 30}" period="7"/>\n</routes>\n', encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "{NETS / "city.net.xml"}"\n'
        f'routes = ["short.rou.xml"]\nend = {end}\nstep_length = 0.5\n'
        'options = ["--no-warnings", "true"]\n[outputs]\nfigures = false\nedgedata = true\n'
        'period = 60\n', encoding="utf-8")
    return tmp_path / "s.toml"


def _equations():
    fuel = load_equation("drvpw_prius3")
    fuel.chain = EnergyChain(predicts="fuel", idle_fuel_power_w=5000.0, marginal_efficiency=0.36,
                             engine_off_below_w=4000.0)
    bev = Equation("bev", {"acc": 1.05, "grade": 1.0, "roll": 0.009, "aero_rho": 0.6})
    bev.chain = EnergyChain(predicts="battery", traction_efficiency=0.9,
                            recuperation_efficiency=0.7, recuperation_limit_w=20000.0,
                            aux_power_w=500.0)
    return ["vsp_ldv1999", fuel, bev]


def _sorted(df: pd.DataFrame, keys) -> pd.DataFrame:
    return df.sort_values(keys, kind="stable").reset_index(drop=True)


def test_finished_vehicles_leave_memory_and_totals_are_unchanged(tmp_path):
    """In a user's loop with flush_vehicles=1, the Accountant holds no more vehicles than
    are running; its vehicle rows equal the keep-everything run's exactly, edges and classes
    to rounding, and the written files agree (vehicles.parquet, chain tables, summary)."""
    path = _scenario(tmp_path, end=180.0)
    ref = run_scenario(path, tmp_path / "ref", keep_vehicles=True, equations=_equations())
    sc = load_scenario(path)
    conn = start_sumo(sc.sumo_args)
    held, running = [], []
    try:
        acc = Accountant(conn, scenario=path, equations=_equations(), flush_vehicles=1,
                         spill_dir=tmp_path / "spill")
        while conn.simulation.getTime() < sc.end - 1e-9:
            conn.simulationStep()
            acc.step()
            running.append(conn.vehicle.getIDCount())
            held.append(acc.ledger.n_veh)
        res = acc.result()
        res.write(tmp_path / "bounded")
    finally:
        close_sumo(conn)
    led = acc.ledger
    total = ref["vehicles"]
    assert total > 4 * max(running) and led.flushed_vehicles > 0.8 * total
    assert max(held) <= max(running) and led.peak_held <= max(running)
    assert all(h <= r for h, r in zip(held, running))  # only running vehicles are held
    assert res["vehicles"] == total and res["samples"] == ref["samples"]
    # per-vehicle rows: identical (the same additions, only moved in memory)
    a = _sorted(ref.vehicles, ["vehicle", "equation"])
    b = _sorted(pd.read_parquet(tmp_path / "bounded" / "vehicles.parquet"), ["vehicle", "equation"])
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    pd.testing.assert_frame_equal(a, _sorted(res.vehicles, ["vehicle", "equation"]), check_exact=True)
    # edges and classes: the same sums, closed at other times (rounding only)
    num = ["traction_total_j", "recup_total_j", "net_total_j", "distance_m", "vehicles"]
    np.testing.assert_allclose(res.edges[num], ref.edges[num], rtol=1e-11, atol=1e-6)
    np.testing.assert_allclose(res.classes[["traction_energy_j", "recup_energy_j", "distance_m"]],
                               ref.classes[["traction_energy_j", "recup_energy_j", "distance_m"]],
                               rtol=1e-11, atol=1e-6)
    # vehicle totals = edge totals = class totals, per equation
    for eq in ("vsp_ldv1999", "bev"):
        v = b[b.equation == eq].traction_total_j.sum()
        e = res.edges[res.edges.equation == eq].traction_total_j.sum()
        c = res.classes[res.classes.equation == eq].traction_energy_j.sum()
        np.testing.assert_allclose([e, c], v, rtol=1e-10)
    # energy chain: the vehicle rows streamed as CSV equal the reference's; classes balance
    ca = _sorted(pd.read_csv(tmp_path / "ref" / "chain_vehicles.csv"), ["key", "equation"])
    cb = _sorted(pd.read_csv(tmp_path / "bounded" / "chain_vehicles.csv"), ["key", "equation"])
    pd.testing.assert_frame_equal(ca, cb, check_exact=True)
    kc = pd.read_csv(tmp_path / "ref" / "chain_classes.csv")
    kb = pd.read_csv(tmp_path / "bounded" / "chain_classes.csv")
    # the chains are made for cars: the vans' class has no rows (nothing booked there)
    assert list(kc.key) == list(kb.key) == ["passenger", "passenger"]
    np.testing.assert_allclose(kb.select_dtypes("number"), kc.select_dtypes("number"), rtol=1e-11)
    for col in ("net_kwh", "fuel_l"):
        np.testing.assert_allclose(cb[col].sum(), kb[col].sum(), rtol=1e-10)
    doc = json.loads((tmp_path / "bounded" / "summary.json").read_text(encoding="utf-8"))
    assert doc["vehicles"] == total and doc["vehicles_in_memory_peak"] <= max(running)
    # a vehicle that left: the Accountant says so instead of a number
    gone = a.vehicle.iloc[0]
    with pytest.raises(KeyError, match="left the simulation"):
        acc.energy(gone)


def test_run_scenario_streams_and_leaves_no_parts(tmp_path):
    """run_scenario with a small flush size: the outputs equal the keep-everything run's
    and no spill folder is left in the output folder; the result reads the written rows."""
    path = _scenario(tmp_path, end=180.0)
    ref = run_scenario(path, tmp_path / "ref", keep_vehicles=True, trace=True)
    res = run_scenario(path, tmp_path / "out", flush_vehicles=5, trace=True)
    assert not (tmp_path / "out" / SPILL_DIR).exists()
    assert res.ledger.flushed_vehicles > 0
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == \
        sorted(p.name for p in (tmp_path / "ref").iterdir())
    a = _sorted(pd.read_parquet(tmp_path / "ref" / "vehicles.parquet"), ["vehicle", "equation"])
    b = _sorted(pd.read_parquet(tmp_path / "out" / "vehicles.parquet"), ["vehicle", "equation"])
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    pd.testing.assert_frame_equal(a, _sorted(res.vehicles, ["vehicle", "equation"]), check_exact=True)
    assert res["vehicles"] == ref["vehicles"] == len(a)
    # the trace names each vehicle-step's vehicle right across the renumbering of a flush
    key = ["time_s", "vehicle", "equation"]
    ta, tb = (_sorted(pd.read_parquet(tmp_path / d / "trace.parquet").astype(
        {"vehicle": str, "edge": str, "equation": str}), key) for d in ("ref", "out"))
    pd.testing.assert_frame_equal(ta, tb, check_exact=True)
    for name in ("edges.parquet", "classes.parquet"):
        x, y = pd.read_parquet(tmp_path / "ref" / name), pd.read_parquet(tmp_path / "out" / name)
        np.testing.assert_allclose(y.select_dtypes("number"), x.select_dtypes("number"),
                                   rtol=1e-11, atol=1e-6)


def test_fcd_replay_flushes_vehicles_after_their_last_row(tmp_path):
    """`fcd` through the bounded ledger: a vehicle leaves memory the step after its last
    FCD row; rows and totals equal the keep-everything replay's, and no more vehicles are
    held than the file has at one timestep."""
    from sumo_drvpw.sim.fcd import process_fcd, read_fcd

    path = _scenario(tmp_path, end=120.0)
    run_scenario(path, None, options=["--fcd-output", str(tmp_path / "fcd.xml"),
                                      "--precision", "6", "--no-warnings", "true"])
    ref = process_fcd(tmp_path / "fcd.xml", scenario=path, out_dir=tmp_path / "ref",
                      keep_vehicles=True)
    res = process_fcd(tmp_path / "fcd.xml", scenario=path, out_dir=tmp_path / "out",
                      flush_vehicles=3)
    most = int(read_fcd(tmp_path / "fcd.xml").groupby("time").size().max())
    # held: the vehicles of one timestep plus at most flush_vehicles − 1 finished ones
    assert res.ledger.flushed_vehicles > 2 * most and res.ledger.peak_held <= most + 2
    assert not (tmp_path / "out" / SPILL_DIR).exists()
    a = _sorted(pd.read_parquet(tmp_path / "ref" / "vehicles.parquet"), ["vehicle", "equation"])
    b = _sorted(pd.read_parquet(tmp_path / "out" / "vehicles.parquet"), ["vehicle", "equation"])
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert res["vehicles"] == ref["vehicles"] == len(a)
    np.testing.assert_allclose(res.edges.select_dtypes("number"),
                               ref.edges.select_dtypes("number"), rtol=1e-11, atol=1e-6)
