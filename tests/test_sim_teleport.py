"""Teleports booked apart from driving (sim/teleport.py), on a real SUMO run in which jams make
SUMO teleport cars (the hilly city, `--time-to-teleport 5`, 200 one-second steps), live and
replayed from its FCD: per vehicle the energy balance closes with the teleport line."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.model.constants import G
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd, read_fcd
from sumo_probe import fcd_rise
from test_sim_fcd import CITY, PHYS

pytestmark = pytest.mark.sumo

END, DT = 200, 1.0
#: an equation with its own mass and a rotating-mass factor: it books the jumps at its mass
HEAVY = Equation("heavy", {"acc": 1.1, "grade": 1.0, "m_v1": 0.132}, mass_kg=2000.0)


@pytest.fixture(scope="module")
def teleported(tmp_path_factory):
    """The live run, its replay, the FCD rows (with SUMO's odometer and where it jumps: SUMO's
    placements at a teleport's end) and the network."""
    from sumo_drvpw.sim.network import load_network
    from sumo_drvpw.sim.scenario import load_scenario

    d = tmp_path_factory.mktemp("teleport")
    fcd = d / "fcd.xml"
    live = run_scenario(CITY, None, end=END, equations=[PHYS, HEAVY], figures=False, period=50,
                        options=["--fcd-output", str(fcd), "--precision", "6", "--time-to-teleport", "5",
                                 "--step-length", "1", "--fcd-output.attributes",
                                 "id,type,speed,lane,pos,x,y,odometer"])
    rep = process_fcd(fcd, scenario=CITY, out_dir=d / "o", equations=[PHYS, HEAVY], end=END, figures=False,
                      period=50)
    rows = read_fcd(fcd).sort_values(["id", "time"], kind="stable")
    raw = pd.read_xml(fcd, xpath=".//vehicle", parser="etree")[["id", "odometer"]]
    raw["k"] = raw.groupby("id").cumcount()
    rows["k"] = rows.groupby("id").cumcount()
    rows = rows.merge(raw[["id", "k", "odometer"]], on=["id", "k"])
    moved = rows.groupby("id")["odometer"].diff()
    rows["jump"] = (rows["k"] > 0) & ((moved - rows["speed"] * DT).abs() > 1e-3)
    sc = load_scenario(CITY)
    net = load_network(sc.net_file, sc.road_class, sc.slope_window, sc.slope_max)
    return live, rep, rows, net


def test_a_vehicles_energy_balance_closes_with_its_teleports(teleported):
    """Over each vehicle's trip the acc term (coefficient 1) books the kinetic-energy change
    from its first to its last step but the jumps SUMO's placements make (½m(v_after² −
    v_before²) each), the grade term the rise m·g·Δz but the jumps' (plus its first step's
    slope × v·Δt): the teleport line holds exactly those jumps, so driving + teleports =
    ½m(v_last² − v_first²) and m·g·(z_last − z_first), live and replayed. The teleports counted
    per vehicle are SUMO's placements (where its odometer jumps). Before the teleport line
    (e5e6b3e), the jumps were nowhere: the cars stood in a jam, were put back at 13.9 m/s and
    braked from there, booking recuperable energy that had no traction. An equation with its
    own mass books the jumps at that mass, and its term 1.1·acc 1.1 times the balance."""
    live, rep, rows, net = teleported
    g = rows.groupby("id")
    v0, v1 = g["speed"].first(), g["speed"].last()
    placements = g["jump"].sum()
    assert placements.sum() >= 3 and rows.loc[rows["jump"], "speed"].min() > 5.0
    for res, eq, c_acc in ((live, "phys", 1.0), (rep, "phys", 1.0), (live, "heavy", 1.1), (rep, "heavy", 1.1)):
        b = res.vehicles.query("equation == @eq").set_index("vehicle").sort_index()
        assert len(b) > 40 and b["teleports"].sum() == placements.sum()
        np.testing.assert_array_equal(b["teleports"], placements.reindex(b.index))
        m = b["mass_kg"] if eq == "phys" else pd.Series(2000.0, b.index)
        dke = 0.5 * m * (v1.reindex(b.index) ** 2 - v0.reindex(b.index) ** 2)
        acc = (b["traction_acc_j"] + b["recup_acc_j"]) / c_acc
        np.testing.assert_allclose(acc + b["teleport_kinetic_j"], dke, rtol=1e-6, atol=1.0, err_msg=eq)
        r = fcd_rise(net, rows).reindex(b.index)
        rise = m * G * (r.z1 - r.z0) + m * G * np.sin(r.theta) * r.v * DT
        grade = b["traction_grade_j"] + b["recup_grade_j"]
        np.testing.assert_allclose(grade + b["teleport_potential_j"], rise, rtol=1e-4, atol=m.max() * G * 0.01, err_msg=eq)
        moved = b["teleports"] > 0
        assert (b.loc[~moved, ["teleport_kinetic_j", "teleport_potential_j"]] == 0).all().all()
        # the jumps are no rounding: without them the balance misses by up to ½m·(13.9 m/s)²
        assert b.loc[moved, "teleport_kinetic_j"].max() > 0.5 * 1000 * 10.0 ** 2
        assert (b.loc[moved, "teleport_potential_j"].abs() > m[moved] * G * 0.1).any()
    a = live.vehicles.set_index(["vehicle", "equation"]).sort_index()
    b = rep.vehicles.set_index(["vehicle", "equation"]).sort_index()
    for c in ("teleport_kinetic_j", "teleport_potential_j"):
        np.testing.assert_allclose(b[c], a[c], rtol=1e-6, atol=1.0, err_msg=c)


def test_teleports_are_booked_on_the_edge_put_back_on_and_totals_agree(teleported, capsys):
    """Each placement counts on the edge SUMO put the car back on (its FCD row's lane), and
    vehicles, edges, road classes and summary.json hold the same teleports and energies; the
    driving energy (traction, recuperable, net) does not include them. The console says them
    (`run`, `fcd`), and warns when they reach 1 % of the net driving energy (here ~19 %)."""
    from sumo_drvpw.cli.run import _print_summary

    live, rep, rows, net = teleported
    put = rows.loc[rows["jump"], "lane"].map(lambda ln: net.edge_ids[net.lane_edge[net.lane_index[ln]]])
    for res in (live, rep):
        v, e, c = (t[t["equation"] == "phys"] for t in (res.vehicles, res.edges, res.classes))
        got = e.set_index("edge")["teleports"]
        np.testing.assert_array_equal(got[got > 0].sort_index(), put.value_counts().sort_index())
        # classes.parquet: the class × equation figures on each of its term rows (as distance_m)
        assert set(c["class"]) == set(net.classes) and len(c) == len(net.classes) * 5
        assert len(res.classes) == 2 * len(c)
        assert (c.groupby(["class", "equation"])[["teleports", "teleport_kinetic_j"]].nunique() == 1).all().all()
        per_class = c[c["term"] == "roll"].set_index("class")
        s = res.summary
        assert s["teleports"]["count"] == v["teleports"].sum() == e["teleports"].sum() == per_class["teleports"].sum()
        for col, key in (("teleport_kinetic_j", "kinetic_j"), ("teleport_potential_j", "potential_j")):
            total = v[col].sum()
            assert abs(total) > 1e3
            np.testing.assert_allclose([e[col].sum(), per_class[col].sum(), s["teleports"][key]["phys"],
                                        sum(d[key] for d in s["equations"]["phys"]["teleports"].values())],
                                       total, rtol=1e-9)
        # the driving energy is what the terms booked, without the jumps
        cats = ["acc", "grade", "aero", "roll", "other"]
        np.testing.assert_allclose(v["net_total_j"], v[[f"{p}_{k}_j" for p in ("traction", "recup") for k in cats]].sum(axis=1))
        # edgedata.xml: each interval's placements on their edges, (begin, end] as it books steps
        import xml.etree.ElementTree as ET

        jumps = rows[rows["jump"]].assign(edge=put)
        tele = [(float(iv.get("begin")), float(iv.get("end")), ed.get("id"), float(ed.get("phys_teleports", 0)),
                 float(ed.get("phys_teleport_kinetic_j", 0.0)))
                for iv in ET.fromstring(res.edgedata_xml()).iter("interval") for ed in iv.iter("edge")]
        tele = pd.DataFrame(tele, columns=["t0", "t1", "edge", "n", "kin"])
        assert tele["t1"].nunique() == END // 50 and tele["kin"].sum() == pytest.approx(v["teleport_kinetic_j"].sum(), rel=1e-6)
        for (t0, t1), ivl in tele[tele["n"] > 0].groupby(["t0", "t1"]):
            want = jumps[(jumps["time"] > t0) & (jumps["time"] <= t1)]["edge"].value_counts().sort_index()
            np.testing.assert_array_equal(ivl.set_index("edge")["n"].sort_index(), want)
        assert tele["n"].sum() == len(jumps)
        _print_summary(s, "out")
        said = capsys.readouterr()
        kwh = s["teleports"]["kinetic_j"]["phys"] / 3.6e6
        assert f"teleports: {s['teleports']['count']} vehicles put back on a lane" in said.out
        assert f"phys kinetic {kwh:+.3f} kWh" in said.out and kwh > 0.01 * v["net_total_j"].sum() / 3.6e6
        assert f"warning: {s['teleports']['count']} teleports put vehicles back on a lane" in said.err


def test_fcd_on_dask_books_the_teleports_as_the_serial_replay(teleported, tmp_path):
    """`fcd --engine dask`: each bucket books its own vehicles' teleports; the merged edges,
    classes and summary hold all of them, as the serial replay (1e-9: the order of additions)."""
    pytest.importorskip("distributed")
    from sumo_drvpw.sim.fcd_dask import process_fcd_dask

    _, rep, _, _ = teleported
    fcd = rep.summary["source"]["fcd"]
    res = process_fcd_dask(fcd, tmp_path / "od", scenario=CITY, equations=[PHYS, HEAVY], end=END,
                           buckets=2, workers=1, figures=False)
    s = res.summary
    assert s["teleports"]["count"] == rep.summary["teleports"]["count"] > 0
    for key in ("kinetic_j", "potential_j"):
        for eq in ("phys", "heavy"):
            assert s["teleports"][key][eq] == pytest.approx(rep.summary["teleports"][key][eq], rel=1e-9)
    cols = ["teleports", "teleport_kinetic_j", "teleport_potential_j"]
    for name, table, key in (("vehicles", rep.vehicles, "vehicle"), ("edges", rep.edges, "edge")):
        got = pd.read_parquet(tmp_path / "od" / f"{name}.parquet").set_index([key, "equation"]).sort_index()[cols]
        np.testing.assert_allclose(got.to_numpy(float),
                                   table.set_index([key, "equation"]).sort_index()[cols].to_numpy(float),
                                   rtol=1e-9, atol=1e-6, err_msg=name)


def test_an_accountant_in_a_user_loop_books_the_teleports_as_run(teleported):
    """The Accountant in a user's libsumo loop books the teleports as `run` (same SUMO
    options), and energy(vehicle) says them while the car runs."""
    from sumo_drvpw.sim import Accountant, close_sumo, start_sumo
    from sumo_drvpw.sim.scenario import load_scenario

    live = teleported[0]
    sc = load_scenario(CITY, end=END)
    conn = start_sumo(sc.sumo_args + ["--time-to-teleport", "5", "--step-length", "1"])
    try:
        acc = Accountant(conn, equations=[PHYS], scenario=CITY, figures=False)
        conn.addStepListener(acc)
        while conn.simulation.getTime() < END - 1e-9:
            conn.simulationStep()
        running = {v: acc.energy(v)["phys"] for v in conn.vehicle.getIDList()}
        res = acc.result()
    finally:
        close_sumo(conn)
    cols = ["teleports", "teleport_kinetic_j", "teleport_potential_j"]
    a = live.vehicles.query("equation == 'phys'").set_index("vehicle").sort_index()
    b = res.vehicles.set_index("vehicle").sort_index()
    assert (a.index == b.index).all() and a["teleports"].sum() > 0
    np.testing.assert_allclose(b[cols].to_numpy(float), a[cols].to_numpy(float), rtol=1e-12, atol=1e-9)
    said = pd.DataFrame(running).T.reindex(columns=["teleports", "teleport_kinetic", "teleport_potential"])
    assert len(said) > 5 and said["teleports"].sum() > 0
    np.testing.assert_allclose(said.to_numpy(float), a.loc[said.index, cols].to_numpy(float), rtol=1e-12, atol=1e-9)
