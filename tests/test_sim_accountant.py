"""The plug-in where SUMO users work: Accountant in a user's own loop, edgeData as SUMO
writes it (parsed by sumolib), vClass-aware equations on a mixed scenario. Real SUMO."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sumo_drvpw.model.equations import Equation
from sumo_drvpw.sim import Accountant, close_sumo, run_scenario, start_sumo
from sumo_drvpw.sim.scenario import load_scenario

pytestmark = pytest.mark.sumo

REPO = Path(__file__).resolve().parent.parent
NETS = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks"  # the built-in networks
CITY = REPO / "scenarios" / "city.toml"
PHYS = Equation("phys", {"acc": 1.0, "grade": 1.0, "aero_rho": 0.25 * 2.23, "roll": 0.01})
VSP = Equation("vsp", {"acc": 1.1, "grade": 1.0, "m_v1": 0.132, "m_v3": 0.000302})
COLS = ["traction_acc_j", "traction_grade_j", "traction_aero_j", "traction_roll_j",
        "recup_total_j", "net_total_j", "distance_m", "time_s"]


def test_accountant_in_a_user_loop_equals_run(tmp_path):
    """A step listener in the user's own libsumo loop books what `run` books, writes the
    same files, and answers energy(vehicle) while the simulation runs."""
    ran = run_scenario(CITY, tmp_path / "run", end=200, equations=[PHYS, VSP], figures=False)
    sc = load_scenario(CITY, end=200)
    conn = start_sumo(sc.sumo_args)
    seen = {}
    try:
        acc = Accountant(conn, equations=[PHYS, VSP], scenario=CITY, figures=False)
        conn.addStepListener(acc)
        while conn.simulation.getTime() < 200 - 1e-9:
            conn.simulationStep()
            ids = conn.vehicle.getIDList()
            if ids and "probe" not in seen:
                seen["probe"] = ids[0]
            if "probe" in seen and seen["probe"] in ids:
                seen["energy"] = acc.energy(seen["probe"])  # readable during the run
        res = acc.result()
        res.write(tmp_path / "user")
        driving = set(conn.vehicle.getIDList())
    finally:
        close_sumo(conn)
    a = ran.vehicles.sort_values(["vehicle", "equation"]).reset_index(drop=True)
    b = res.vehicles.sort_values(["vehicle", "equation"]).reset_index(drop=True)
    assert len(a) == len(b) > 40
    assert (a.vehicle == b.vehicle).all()
    # on_road_at_end: the trips the end cut (SUMO's vehicles then), the others arrived
    assert set(b.vehicle[b.on_road_at_end]) == driving and 0 < len(driving) < b.vehicle.nunique()
    assert (a.on_road_at_end == b.on_road_at_end).all()
    assert not b.on_road_at_begin.any() and not a.on_road_at_begin.any()  # booked from the start
    np.testing.assert_allclose(b[COLS], a[COLS], rtol=1e-12, atol=1e-9)
    assert res["equations"] == ran["equations"]
    for name in ("vehicles.parquet", "edges.parquet", "classes.parquet", "edgedata.xml"):
        assert (tmp_path / "user" / name).is_file()
    doc = json.loads((tmp_path / "user" / "summary.json").read_text(encoding="utf-8"))
    assert doc["equations"]["phys"]["energy_j"] == ran["equations"]["phys"]["energy_j"]
    # energy(vehicle) while running: the vehicle's running totals, per equation and term
    row = b[(b.vehicle == seen["probe"]) & (b.equation == "phys")].iloc[0]
    e = acc.energy(seen["probe"])["phys"]
    assert e["traction"] == pytest.approx(row.traction_total_j, rel=1e-12)
    assert e["net"] == pytest.approx(row.net_total_j, rel=1e-12)
    assert seen["energy"]["phys"]["net"] == pytest.approx(e["net"], abs=1e-6) or \
        seen["energy"]["phys"]["traction"] <= e["traction"] + 1e-6
    with pytest.raises(KeyError):
        acc.energy("no such vehicle")


def test_edgedata_intervals_parsed_by_sumolib(tmp_path):
    """edgeData with one <interval> per outputs.period, SUMO's layout: sumolib reads it;
    intervals add up to edges.parquet; sampledSeconds to the vehicles' time."""
    import sumolib

    res = run_scenario(CITY, tmp_path / "o", end=300, equations=[PHYS, VSP], figures=False,
                       period=100.0)
    intervals = list(sumolib.xml.parse(str(tmp_path / "o" / "edgedata.xml"), "interval"))
    assert [(float(i.begin), float(i.end)) for i in intervals] == \
        [(0.0, 100.0), (100.0, 200.0), (200.0, 300.0)]
    # from a later begin: SUMO's own edgeData intervals run from the begin (they ran from
    # multiples of the period: 50–100, 100–200, …; found by a sweep)
    run_scenario(CITY, tmp_path / "late", begin=50, end=300, equations=[PHYS], figures=False, period=100.0)
    late = list(sumolib.xml.parse(str(tmp_path / "late" / "edgedata.xml"), "interval"))
    assert [(float(i.begin), float(i.end)) for i in late] == [(50.0, 150.0), (150.0, 250.0), (250.0, 300.0)]
    edges = res.edges
    veh = res.vehicles
    for name in ("phys", "vsp"):
        tot = sum(float(getattr(e, f"{name}_total_j")) for i in intervals for e in i.edge)
        np.testing.assert_allclose(tot, edges[edges.equation == name].traction_total_j.sum(),
                                   rtol=1e-6)
        rec = sum(float(getattr(e, f"{name}_recup_j")) for i in intervals for e in i.edge)
        np.testing.assert_allclose(rec, edges[edges.equation == name].recup_total_j.sum(),
                                   rtol=1e-6, atol=1.0)
        terms = sum(float(getattr(e, f"{name}_{t}_j")) for i in intervals for e in i.edge
                    for t in ("acc", "grade", "aero", "roll", "other"))
        np.testing.assert_allclose(terms, tot, rtol=1e-6)
    secs = sum(float(e.sampledSeconds) for i in intervals for e in i.edge)
    np.testing.assert_allclose(secs, veh[veh.equation == "phys"].time_s.sum(), rtol=1e-6)
    # per-vehicle and per-metre figures are the totals divided as SUMO's _perVeh/_normed
    e0 = next(e for i in intervals for e in i.edge if float(e.phys_total_j) > 0)
    assert float(e0.phys_total_perVeh_j) > 0 and float(e0.phys_total_normed_jpm) > 0
    # per vehicle driving the whole edge (SUMO's _perVeh): never 0 where energy was booked — it
    # divided by the vehicles that entered in the interval, 0 for one driving on across its start
    length = {eid: float(ln) for eid, ln in zip(edges.edge, edges.length_m)}
    for e in (e for i in intervals for e in i.edge if float(e.phys_total_j) > 0):
        assert float(e.phys_total_perVeh_j) == pytest.approx(
            float(e.phys_total_normed_jpm) * length[e.id], rel=1e-5, abs=2e-3)
    assert not any(f.startswith("drvpw_") for f in e0._fields)  # no doubled prefixes
    # SUMO's router takes it as edge weights (energy-optimal routes)
    import subprocess

    (tmp_path / "t.xml").write_text(
        '<routes><trip id="t" depart="0" from="c00c10" to="c34c44"/></routes>', encoding="utf-8")
    r = subprocess.run([sumolib.checkBinary("duarouter"), "-n",
                        str(NETS / "city.net.xml"),
                        "-r", str(tmp_path / "t.xml"), "--weight-files",
                        str(tmp_path / "o" / "edgedata.xml"), "--weight-attribute",
                        "phys_total_j", "-o", str(tmp_path / "eco.rou.xml"), "--no-step-log"],
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert "<route edges=" in (tmp_path / "eco.rou.xml").read_text(encoding="utf-8")


MIXED = """<routes>
  <vType id="car" vClass="passenger" mass="1500" sigma="0"/>
  <vType id="lorry" vClass="trailer" sigma="0"/>
  <vType id="bike" vClass="bicycle" sigma="0"/>
  <vType id="walker" vClass="pedestrian"/>
  <flow id="c" type="car" from="c00c10" to="c34c44" begin="0" end="60" period="10"/>
  <person id="p0" type="walker" depart="1"><walk from="c00c10" to="c10c20"/></person>
  <flow id="b" type="bike" from="c00c10" to="c34c44" begin="2" end="60" period="30"/>
  <flow id="l" type="lorry" from="c00c10" to="c34c44" begin="5" end="60" period="20"/>
</routes>"""


def _run_routes(folder, routes: str, equations: list[str], end: float):
    """A city-network scenario of these routes and equations, run (no SUMO warnings)."""
    (folder / "r.rou.xml").write_text(routes, encoding="utf-8")
    (folder / "s.toml").write_text(
        f"equations = {json.dumps(equations)}\n"
        f'[sumo]\nnet = "{NETS / "city.net.xml"}"\nroutes = ["r.rou.xml"]\n'
        f'end = {end}\noptions = ["--no-warnings", "true"]\n[outputs]\nfigures = false\n',
        encoding="utf-8")
    return run_scenario(folder / "s.toml", folder / "o")


def test_vclasses_each_get_their_equation_or_are_skipped(tmp_path):
    """Cars get the car equations, trailers the MOVES combination-truck one (with its
    MOVES source mass as the assumed mass), bicycles and pedestrians are skipped and
    counted."""
    res = _run_routes(tmp_path, MIXED, ["vsp_ldv1999", "drvpw_prius3", "moves_combination_truck"], 200)
    v = res.vehicles
    by = v.groupby("vclass").equation.unique().to_dict()
    assert sorted(by["passenger"]) == ["drvpw_prius3", "vsp_ldv1999"]
    assert list(by["trailer"]) == ["moves_combination_truck"]
    assert "bicycle" not in by
    assert res["skipped"] == {"by_vclass": {"bicycle": 2, "pedestrian": 1},
                              "by_vtype": {"bike": 2, "walker": 1}}
    assert res["assumptions"]["default_masses"]["lorry"]["mass_kg"] == 24419.0
    assert (v[v.vclass == "trailer"].mass_kg == 24419.0).all()
    eqs = res["equations"]
    assert eqs["drvpw_prius3"]["predicts"] == "powertrain_output"
    assert eqs["moves_combination_truck"]["predicts"] == "wheel"
    assert (v.predicts[v.equation == "drvpw_prius3"] == "powertrain_output").all()
    # a 24 t trailer needs far more energy per km than a car on the same climbs
    wh = v.groupby("equation").traction_whpkm.median()
    assert wh["moves_combination_truck"] > 5 * wh["vsp_ldv1999"]
    assert np.isfinite(v.traction_whpkm).all()


def test_persons_of_a_redeclared_default_pedestrian_type_are_pedestrians(tmp_path):
    """SUMO's rail game (tools/game/rail/test.sumocfg in the eclipse-sumo wheel) redeclares
    DEFAULT_PEDTYPE without a vClass, which SUMO reads as passenger: its 65 walkers were
    counted as 'passenger 65' vehicles not booked. A person is a pedestrian, never booked,
    and no warning is given for it."""
    res = _run_routes(tmp_path, """<routes>
  <vType id="car" vClass="passenger" mass="1500" sigma="0"/>
  <vType id="DEFAULT_PEDTYPE" width="2" length="2"/>
  <flow id="c" type="car" from="c00c10" to="c34c44" begin="0" end="30" period="10"/>
  <personFlow id="g" begin="0" end="40" period="10"><walk from="c00c10" to="c10c20"/></personFlow>
</routes>""", ["vsp_ldv1999"], 100)
    assert res["skipped"] == {"by_vclass": {"pedestrian": 4}, "by_vtype": {"DEFAULT_PEDTYPE": 4}}
    assert not any("not booked" in w for w in res["warnings"])
    assert set(res.vehicles.vclass) == {"passenger"} and len(res.vehicles) == 3


def _motorway_cars(tmp_path):
    """s.toml: the mixed flow's cars (no persons) on the highway network for 60 s, departing
    at the 120 km/h limit."""
    mixed = "\n".join(ln for ln in MIXED.splitlines() if "<person" not in ln)
    (tmp_path / "r.rou.xml").write_text(mixed.replace(
        'from="c00c10" to="c34c44"', 'route="r"').replace(
        '<flow id="c"', '<route id="r" edges="e01 e12 e23"/>\n  <flow id="c"').replace(
        'period="10"', 'period="10" departSpeed="max"'), encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["x"]\n[sumo]\nnet = "{NETS / "highway.net.xml"}"\n'
        'routes = ["r.rou.xml"]\nend = 60\noptions = ["--no-warnings", "true"]\n'
        '[vehicles]\nvtypes = ["car"]\n[outputs]\nfigures = false\nedgedata = false\n',
        encoding="utf-8")


def test_out_of_range_counts_the_driving_power_a_chain_was_fitted_on(tmp_path):
    """A chain's fitted driving-power range ([chain.provenance] power_range_w, written by
    calibrate --target): vehicle-steps whose driving power leaves it are counted with the
    speed and acceleration ranges, shown in summary.json and warned about when many."""
    from sumo_drvpw.model.chain import EnergyChain

    _motorway_cars(tmp_path)

    def chained(name, p_range):
        return Equation(name, {"roll": 0.01}, chain=EnergyChain(
            predicts="battery", provenance={"power_range_w": p_range, "speed_range_mps": [0.0, 60.0],
                                            "warnings": ["energy chain x = 1: IMPLAUSIBLE"] * (name == "low")}))

    # rolling power 0.01·m·g·v of a car at motorway speed: kilowatts, above 500 W
    low, wide = chained("low", [-500.0, 500.0]), chained("wide", [-1e6, 1e6])
    res = run_scenario(tmp_path / "s.toml", None, equations=[low, wide])
    assert res["equations"]["low"]["out_of_range_samples"] > 0.5 * res["samples"]
    assert res["equations"]["low"]["power_range_w"] == [-500.0, 500.0]
    assert res["equations"]["wide"]["out_of_range_samples"] == 0
    assert any(w.startswith("low: ") and "fitted on" in w for w in res["warnings"])
    assert not any(w.startswith("wide: ") for w in res["warnings"])
    # what the chain's calibration said is repeated where the run is read
    assert "low: its chain's calibration warned: energy chain x = 1: IMPLAUSIBLE" in res["warnings"]


def test_out_of_range_vehicle_steps_counted(tmp_path):
    """An equation's recorded validity range: vehicle-steps outside it are counted."""
    _motorway_cars(tmp_path)
    slow = Equation("slow", {"roll": 0.01}, speed_range_mps=(0.0, 15.0))
    wide = Equation("wide", {"roll": 0.01}, speed_range_mps=(0.0, 60.0),
                    accel_range_mps2=(-9.0, 9.0))
    res = run_scenario(tmp_path / "s.toml", None, equations=[slow, wide])
    # cars depart at max speed on a 120 km/h motorway: well above 15 m/s
    assert res["equations"]["slow"]["out_of_range_samples"] > 0.5 * res["samples"]
    assert res["equations"]["wide"]["out_of_range_samples"] == 0
    with pytest.raises(Exception, match="vehicles.vtypes names vType"):
        (tmp_path / "t.toml").write_text(
            (tmp_path / "s.toml").read_text(encoding="utf-8").replace('["car"]', '["car", "kar"]'), encoding="utf-8")
        run_scenario(tmp_path / "t.toml", None, equations=[slow])


def test_accountant_with_equations_only_finds_net_and_vtypes(tmp_path):
    """Without a scenario: the net file and the vTypes (masses) come from SUMO's own
    options; Ctrl-free user loop with traci-style target-time steps counted as missed."""
    sc = load_scenario(CITY, end=60)
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, equations=["vsp_ldv1999"])
        assert acc.net.path.name == "city.net.xml"
        for _ in range(40):
            conn.simulationStep()
            acc.step()
        conn.simulationStep(conn.simulation.getTime() + 2.0)  # jumps 4 steps at once
        acc.step()
        res = acc.result()
    finally:
        close_sumo(conn)
    assert res["vehicles"] > 0 and res["missed_steps"] == 3
    assert res["assumptions"]["default_masses"] == {}  # prius3.vtype.xml gives 1625 kg
    assert (res.vehicles.mass_kg == 1625.0).all()
    assert any("not booked" in w for w in res["warnings"])


def test_accountant_misuse_in_a_user_script_is_one_clear_error(tmp_path):
    """Found by running the Accountant inside user scripts: a result taken mid-run and read
    after more steps showed the later tables under the earlier summary (edges 257 MJ, its
    summary 118 MJ); a simulation.load() went on booking both runs into one ledger (1.23×
    the energy); equations="vsp_ldv1999" was read letter by letter; write() onto a file was
    a FileExistsError. Each is now one UserError, or (the single name) accepted."""
    from sumo_drvpw.errors import UserError

    sc = load_scenario(CITY, end=60)
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, equations="vsp_ldv1999")  # one name, not a list
        assert [e.name for e in acc.equations] == ["vsp_ldv1999"]
        for _ in range(40):
            conn.simulationStep()
            acc.step()
        early = acc.result()
        n = len(early.vehicles)  # readable while the run has not moved on
        (tmp_path / "file").write_text("x", encoding="utf-8")
        with pytest.raises(UserError, match="is a file"):
            early.write(tmp_path / "file")
        conn.simulationStep()
        acc.step()
        with pytest.raises(UserError, match="taken after 40 steps.*result\\(\\) again"):
            early.edges
        with pytest.raises(UserError, match="result\\(\\) again"):
            early.write(tmp_path / "stale")
        assert not (tmp_path / "stale").exists()
        assert len(acc.result().vehicles) >= n  # a new result reads the ledger as it is
        conn.load(sc.sumo_args)  # a new run from t = begin
        conn.simulationStep()
        with pytest.raises(UserError, match="time went back from 20.5 s to 0.5 s"):
            acc.step()
    finally:
        close_sumo(conn)


def test_accountant_refuses_a_mesoscopic_simulation():
    """run and fcd refuse --mesosim; an Accountant in a user's mesoscopic session booked
    every vehicle at 0 m and 0 J with no warning (found by a sweep). It is one UserError."""
    from sumo_drvpw.errors import UserError

    sc = load_scenario(CITY, end=60)
    conn = start_sumo(list(sc.sumo_args) + ["--mesosim", "true"])
    try:
        with pytest.raises(UserError, match="mesoscopic"):
            Accountant(conn, equations=["vsp_ldv1999"])
    finally:
        close_sumo(conn)


def _city_accounted(steps: int):
    """The city scenario in libsumo with an Accountant (vsp_ldv1999) after ``steps`` steps:
    (connection, accountant); the caller closes the connection."""
    conn = start_sumo(load_scenario(CITY, end=60).sumo_args)
    try:
        acc = Accountant(conn, equations=["vsp_ldv1999"])
        for _ in range(steps):
            conn.simulationStep()
            acc.step()
    except BaseException:
        close_sumo(conn)
        raise
    return conn, acc


def test_an_id_used_again_is_a_new_trip_with_its_own_vtype():
    """A user's script removes a car and adds a heavier vehicle under the same id: two trips,
    each on its own row with its own vType and mass (it booked on in the first row, at the
    first car's mass, unless that row happened to be flushed in between; found by a sweep)."""
    conn, acc = _city_accounted(30)
    try:
        vid = conn.vehicle.getIDList()[0]
        edges, vt = conn.vehicle.getRoute(vid), conn.vehicle.getTypeID(vid)
        conn.vehicle.remove(vid)
        conn.simulationStep()
        acc.step()
        conn.vehicletype.copy(vt, "heavy")
        conn.vehicletype.setMass("heavy", 5000.0)
        conn.route.add("again", edges)
        conn.vehicle.add(vid, "again", typeID="heavy", departSpeed="0")
        for _ in range(30):
            conn.simulationStep()
            acc.step()
        res = acc.result()
    finally:
        close_sumo(conn)
    rows = res.vehicles[res.vehicles.vehicle == vid]
    assert list(rows.vtype) == [vt, "heavy"]
    assert list(rows.mass_kg) == [1625.0, 5000.0]
    # a vType in no file read takes SUMO's mass, and the run says so
    assert res.summary["assumptions"]["sumo_masses"] == {"heavy": {"vclass": "passenger", "mass_kg": 5000.0}}
    assert any("heavy (passenger, 5000 kg)" in w for w in res.summary["warnings"])
    assert (rows.time_s > 0).all() and rows.time_s.iloc[0] <= 15.5
    # the driving dynamics list how the file's vType drives, and cannot say for the copy
    drv = res.summary["driving_dynamics"]["vclasses"]["passenger"]["vtype_driving"]
    assert drv["heavy"] is None and drv[vt]["car_follow_model"] == "Krauss"


def test_a_car_removed_between_steps_is_retired_at_once():
    """A script's vehicle.remove between steps: SUMO lists the car as arrived at once, in the
    list the listener had read already, so it is in no arrived list the Accountant sees. The
    ledger now finds it gone (unknown to SUMO) and retires its row in the next step; it was
    held as running until the end (found by a sweep). A teleport-free run: nothing else goes."""
    conn, acc = _city_accounted(30)
    try:
        ids = conn.vehicle.getIDList()
        done = acc.ledger.veh_done.copy()
        conn.vehicle.remove(ids[0])
        conn.simulationStep()
        acc.step()
        slot = acc.stepper.vmap[ids[0]]
        assert acc.ledger.veh_done[slot]
        still = [acc.stepper.vmap[v] for v in ids[1:] if v in conn.vehicle.getIDList()]
        assert not acc.ledger.veh_done[still].any() and not done[slot]
        res = acc.result()
    finally:
        close_sumo(conn)
    assert ids[0] in set(res.vehicles.vehicle)


def test_a_vtype_changed_during_a_trip_books_on_with_its_new_mass():
    """vehicle.setMass during a trip (SUMO gives the vehicle a type of its own,
    'prius3@<id>'): the vehicle books on at the new mass from the next vType check
    (every TYPE_CHECK_STEPS steps) — it kept the departure's 1625 kg (found by a sweep).
    Its row keeps its vType (the copy keeps the type's settings) with the new mass, and
    more inertial energy than without; a setMaxSpeed (a copy too, same mass) changes
    nothing booked (the review found it re-resolved as an unknown type: dropped from a
    scenario's vType filter, its scenario mass lost)."""
    from sumo_drvpw.sim.loop import TYPE_CHECK_STEPS

    rows = {}
    for change in ("none", "mass", "speed"):
        sc = load_scenario(CITY, end=60)  # (its vehicles.vtypes = ["prius3"]: a filter)
        conn = start_sumo(sc.sumo_args)
        try:
            acc = Accountant(conn, scenario=sc, equations=["vsp_ldv1999"])
            for k in range(100):
                conn.simulationStep()
                acc.step()
                if k == 20:
                    vid = sorted(conn.vehicle.getIDList())[0]
                    if change == "mass":
                        conn.vehicle.setMass(vid, 5000.0)
                    elif change == "speed":
                        conn.vehicle.setMaxSpeed(vid, 30.0)
            res = acc.result()
        finally:
            close_sumo(conn)
        rows[change] = res.vehicles.set_index("vehicle").loc[vid]
        assert res["vtype_changes"] == (1 if change == "mass" else 0)
    assert rows["none"].mass_kg == 1625.0 and rows["mass"].mass_kg == 5000.0
    assert rows["mass"].vtype == "prius3" and TYPE_CHECK_STEPS <= 50
    assert rows["mass"].traction_acc_j > 1.5 * rows["none"].traction_acc_j
    assert rows["speed"].mass_kg == 1625.0 and rows["speed"].vtype == "prius3"


def test_a_listener_leaves_when_a_new_run_begins(tmp_path):
    """libsumo keeps its step listeners across close() and start(): an Accountant added as
    a listener went on booking every later run of the process into its ledger. At the
    first step of a new run (time goes back) it now leaves the listeners; its result keeps
    the run it booked and says where it stopped."""
    sc = load_scenario(CITY, end=60)
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, equations=[PHYS], scenario=CITY)
        conn.addStepListener(acc)
        while conn.simulation.getTime() < 30 - 1e-9:
            conn.simulationStep()
        booked = acc.result()
        steps, energy = booked["steps"], booked["equations"]["phys"]["energy_j"]
    finally:
        close_sumo(conn)
    conn = start_sumo(sc.sumo_args)  # a second run in the same process
    try:
        for _ in range(4):
            conn.simulationStep()
    finally:
        close_sumo(conn)
    res = acc.result()
    assert res["steps"] == steps and res["equations"]["phys"]["energy_j"] == energy
    assert acc.left_new_run == (30.0, 0.5)
    assert any("new run began (simulation time went back from 30 s to 0.5 s)" in w
               for w in res["warnings"])


@pytest.mark.parametrize("again", [False, True])
def test_a_car_removed_at_its_long_stop_leaves_nothing_switched_off(tmp_path, again):
    """A script removes a car one step after it came to rest at a 600-s stop (SUMO lists a
    vehicle removed between steps in no arrived list), and in one case adds it again under
    the same id. The shut-off kept the removed car 'off' for the rest of the run (355 s
    booked off), or switched off the new trip's row (0 m booked); found by the review."""
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vType id="std" vClass="passenger" mass="1500"/>'
        '<route id="r" edges="c00c01 c01c02 c02c03"/>'
        '<vehicle id="a" type="std" route="r" depart="0" departSpeed="0">'
        '<stop lane="c01c02_0" endPos="60" duration="600"/></vehicle></routes>', encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "{NETS / "city.net.xml"}"\nroutes = ["r.rou.xml"]\n'
        'begin = 0\nend = 300\nstep_length = 1.0\n', encoding="utf-8")
    sc = load_scenario(tmp_path / "s.toml")
    conn = start_sumo(sc.sumo_args)
    removed = False
    try:
        acc = Accountant(conn, scenario=sc)
        while conn.simulation.getTime() < 300 - 1e-9:
            if not removed and "a" in conn.vehicle.getIDList() and conn.vehicle.isStopped("a") \
                    and conn.vehicle.getSpeed("a") == 0.0:
                conn.vehicle.remove("a")
                removed = True
                if again:
                    conn.route.add("again", ["c01c02", "c02c03"])
                    conn.vehicle.add("a", "again", typeID="std", departSpeed="0")
            conn.simulationStep()
            acc.step()
        res = acc.result()
    finally:
        close_sumo(conn)
    assert removed
    so = res["shut_off_at_long_stops"]
    assert so["stops"] == 0 and so["vehicle_s"] == 0.0
    rows = res.vehicles[res.vehicles.vehicle == "a"]
    assert len(rows) == (2 if again else 1) and (rows.distance_m > 100).all()


def test_scenario_vtype_settings_no_vehicle_had_are_said(tmp_path):
    """[vtypes.<id>] for an id no vehicle of the run has (a vTypeDistribution's id, whose
    vehicles take its members' ids; a typo in a user's script) is a warning naming it;
    before, its mass was silently not used (found by a sweep). A run refuses an id of no
    vType of its files before SUMO starts (tests/test_scenario_bad_input.py)."""
    from sumo_drvpw.errors import UserError

    rou = tmp_path / "d.rou.xml"
    rou.write_text((CITY.parent.parent / "sumo_drvpw" / "sim" / "builtin" / "scenarios" / "city.rou.xml").read_text(encoding="utf-8")
                   .replace("<routes>", '<routes><vTypeDistribution id="mix"><vType id="m1" probability="1"/>'
                            '</vTypeDistribution>', 1), encoding="utf-8")
    assert "mix" in rou.read_text(encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["vsp_ldv1999"]\n[sumo]\nconfig = "{CITY.parent / "city.sumocfg"}"\nend = 30\n'
        f'options = ["-r", "{rou}"]\n[vtypes.prius3]\nmass_kg = 1600\n[vtypes.mix]\nmass_kg = 1700\n',
        encoding="utf-8")
    sc = load_scenario(tmp_path / "s.toml")  # a user's script: its own loop, the scenario's settings
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, scenario=tmp_path / "s.toml")
        conn.addStepListener(acc)
        while conn.simulation.getTime() < 30 - 1e-9:
            conn.simulationStep()
        res = acc.result()
    finally:
        close_sumo(conn)
    hit = [w for w in res.summary["warnings"] if "matched no vehicle" in w]
    assert len(hit) == 1 and "[vtypes.mix]" in hit[0] and "[vtypes.prius3]" not in hit[0]
    assert len(res.vehicles) > 0 and (res.vehicles.mass_kg == 1600.0).all()
    with pytest.raises(UserError, match=r"\[vtypes\.mix\] names a vTypeDistribution"):
        run_scenario(tmp_path / "s.toml", None, figures=False)  # a run refuses both before SUMO starts
    (tmp_path / "s.toml").write_text((tmp_path / "s.toml").read_text(encoding="utf-8").replace("vtypes.mix", "vtypes.prius_3"), encoding="utf-8")
    with pytest.raises(UserError, match=r"\[vtypes\.prius_3\] names no vType .*did you mean 'prius3'"):
        run_scenario(tmp_path / "s.toml", None, figures=False)


def test_each_row_shows_the_mass_its_equation_booked(tmp_path):
    """vehicles.parquet's mass_kg is the mass the row's equation took: a MOVES equation's
    fixed source mass (1478.8 kg, whatever the vehicle weighs), the vehicle's own for an
    equation without one (a rehearsal read 2124 kg on a MOVES row booked at 1478.8 kg)."""
    routes = """<routes>
      <vType id="heavy_car" vClass="passenger" mass="2124"/>
      <flow id="f" type="heavy_car" begin="0" end="30" period="10" departSpeed="max">
        <route edges="c00c10 c10c20"/></flow>
    </routes>"""
    res = _run_routes(tmp_path, routes, ["vsp_ldv1999", "moves_passenger_car"], 120)
    v = res.vehicles
    assert (v[v.equation == "vsp_ldv1999"].mass_kg == 2124.0).all()
    assert (v[v.equation == "moves_passenger_car"].mass_kg == 1478.8).all() and len(v) == 6


def test_an_accountant_stepped_twice_per_step_books_each_step_once(tmp_path):
    """A script that adds the Accountant as a step listener and also calls its step() (or
    adds the listener twice) booked every step twice — distance, time and energy doubled,
    silently (a rehearsal: +56 % net energy). A call for a time already booked is now
    ignored and counted in a warning; the totals equal a single listener's."""
    ran = run_scenario(CITY, tmp_path / "run", end=120, equations=[PHYS], figures=False)
    sc = load_scenario(CITY, end=120)
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, equations=[PHYS], scenario=CITY, figures=False)
        conn.addStepListener(acc)
        while conn.simulation.getTime() < 120 - 1e-9:
            conn.simulationStep()
            acc.step()  # the script's own call beside the listener
        res = acc.result()
    finally:
        close_sumo(conn)
    a = ran.vehicles.sort_values(["vehicle", "equation"]).reset_index(drop=True)
    b = res.vehicles.sort_values(["vehicle", "equation"]).reset_index(drop=True)
    assert len(a) == len(b) > 10
    np.testing.assert_allclose(b[COLS], a[COLS], rtol=1e-12, atol=1e-9)
    assert res["steps"] == ran["steps"]
    assert any("calls to book a simulation step already booked" in w for w in res["warnings"])


def test_a_scenario_naming_another_network_than_sumo_runs_is_refused(tmp_path):
    """SUMO runs the city network; the Accountant's scenario names the highway network. Every
    vehicle was read on lanes the scenario's network lacks and booked nowhere — all zeros,
    no warning (a rehearsal). Now a UserError names the network and the first lane."""
    from sumo_drvpw.errors import UserError

    (tmp_path / "s.toml").write_text(f'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "{NETS / "highway.net.xml"}"\n', encoding="utf-8")
    sc = load_scenario(CITY, end=300)
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, scenario=tmp_path / "s.toml", figures=False)
        with pytest.raises(UserError, match=r"lanes the network .*highway.net.xml lacks \(the first: '.*'; none on "
                                            r"its lanes\): the scenario's network is not the one SUMO runs"):
            for _ in range(300):
                conn.simulationStep()
                acc.step()
    finally:
        close_sumo(conn)


def test_an_accountant_takes_a_builtin_scenarios_name_and_refuses_a_net_path(tmp_path):
    """`sumo-drvpw run city` takes the built-in scenario's name; Accountant(scenario="city")
    said "scenario file not found: city". And net= given a path (a natural mistake: it takes
    a loaded network) raised an AttributeError; now one UserError line."""
    from sumo_drvpw.errors import UserError

    sc = load_scenario(CITY, end=30)
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, scenario="city", equations=[PHYS], figures=False)
        for _ in range(20):
            conn.simulationStep()
            acc.step()
        assert acc.result()["steps"] == 20
        with pytest.raises(UserError, match=r"Accountant: net must be a loaded network .*got str '/etc/passwd'"):
            Accountant(conn, equations=[PHYS], net="/etc/passwd")
    finally:
        close_sumo(conn)


def test_a_step_after_sumo_closed_is_one_clear_error(tmp_path):
    """step() after the script closed SUMO raised libsumo's or traci's own error ('A network
    was not yet constructed'); now a UserError that says SUMO is closed, and result() stays
    readable."""
    from sumo_drvpw.errors import UserError

    sc = load_scenario(CITY, end=30)
    conn = start_sumo(sc.sumo_args)
    acc = Accountant(conn, equations=[PHYS], scenario=CITY, figures=False)
    for _ in range(5):
        conn.simulationStep()
        acc.step()
    close_sumo(conn)
    with pytest.raises(UserError, match="Accountant: SUMO is closed"):
        acc.step()
    assert acc.result()["steps"] == 5


def test_a_vtype_made_at_run_time_is_booked_by_its_emission_classs_carrier(tmp_path):
    """A script copies a vType and sets the copy's emissionClass to SUMO's Energy model
    (vehicletype.copy, setEmissionClass): its cars were booked by the petrol chain as well
    as the battery chain (a rehearsal: 0.209 L of petrol for an EV), since only the files'
    emissionClass was read. A vType the files do not declare now takes the class SUMO gives
    it; the files' own vType keeps its petrol chain."""
    sc = load_scenario(CITY, end=120)
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, equations=["epa_gasoline_car", "bmw_i3_battery"], figures=False)  # (no vType filter)
        conn.vehicletype.copy("prius3", "ev_rt")
        conn.vehicletype.setEmissionClass("ev_rt", "Energy/unknown")
        conn.route.add("r_rt", ["c00c10", "c10c20"])
        for k in range(3):
            conn.vehicle.add(f"ev{k}", "r_rt", typeID="ev_rt", depart=str(2 * k))
        for _ in range(120):
            conn.simulationStep()
            acc.step()
        v = acc.result().vehicles
    finally:
        close_sumo(conn)
    ev = v[v.vtype == "ev_rt"]
    assert len(ev) == 3 and set(ev.equation) == {"bmw_i3_battery"}, ev[["vehicle", "equation"]]
    other = v[v.vtype == "prius3"]
    assert len(other) > 0 and "epa_gasoline_car" in set(other.equation)


def test_an_accountant_attached_mid_run_books_what_a_whole_run_books_from_then(tmp_path):
    """A rehearsal's Accountant created after SUMO had run 150 steps: the cars already on the
    road had their first booked step without its kinetic-energy change (a = 0 where the speed
    before was unknown), up to 9 kJ off each. Now SUMO's acceleration of that step is read:
    per vehicle and equation, the late Accountant books what one attached at the start books
    after that step (its totals less its energy(vehicle) then), and the vehicles departing
    later alike."""
    sc = load_scenario(CITY, end=300)
    runs = []
    for attach in (0, 150):
        conn = start_sumo(sc.sumo_args)
        try:
            acc, snap = None, {}
            for k in range(300):
                if k == attach:
                    acc = Accountant(conn, equations=[PHYS, VSP], scenario=CITY, keep_vehicles=True)
                    conn.addStepListener(acc)
                conn.simulationStep()
                if attach == 0 and k + 1 == 150:
                    snap = {v: acc.energy(v) for v in conn.vehicle.getIDList()}
            runs.append((acc.result().vehicles.set_index(["vehicle", "equation"]), snap))
        finally:
            close_sumo(conn)
    (whole, snap), (late, _) = runs
    on_road = [v for v in snap if snap[v]["phys"]["traction"] > 0]
    assert len(on_road) >= 5
    # vehicles.parquet says which trips the late Accountant booked from the middle
    began = set(late.index.get_level_values(0)[late.on_road_at_begin.to_numpy()])
    assert began == set(snap) and not whole.on_road_at_begin.any()
    for (v, e), row in late.iterrows():
        was = snap.get(v, {}).get(e, {})
        for col, key in (("traction_total_j", "traction"), ("recup_total_j", "recuperable"),
                         ("net_total_j", "net")):
            assert row[col] == pytest.approx(whole.loc[(v, e), col] - was.get(key, 0.0), rel=1e-9, abs=0.01)


def test_a_vehicle_a_script_turns_electric_is_booked_by_the_battery_chain_from_then(tmp_path):
    """vehicle.setEmissionClass on one car (SUMO gives it its own vType copy, 'prius3@<id>')
    was ignored: the petrol car stayed on the petrol chain for its whole trip. Now the copy's
    emissionClass chooses the chain from the type's equations: the petrol chain books the
    car up to the call, the battery chain from the next step on (the copy adds a vType to
    SUMO's, which has the type check run in that step: sim/riders.OwnCopies; before, the
    petrol chain booked on to the next 25-step check); the car's km split between the two
    add up to its trip; a car left alone stays on petrol."""
    sc = load_scenario(CITY, end=200)
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, equations=["epa_gasoline_car", "bmw_i3_battery"], figures=False,
                         keep_vehicles=True)
        conn.vehicletype.copy("prius3", "petrol")  # a petrol car's vType
        conn.vehicletype.setEmissionClass("petrol", "HBEFA4/PC_petrol_Euro-4")
        conn.route.add("r_ev", ["c00c10", "c10c20"])
        conn.vehicle.add("turned", "r_ev", typeID="petrol", depart="0")
        conn.vehicle.add("left", "r_ev", typeID="petrol", depart="3")
        switched = None
        for _ in range(400):
            conn.simulationStep()
            acc.step()
            if switched is None and "turned" in conn.vehicle.getIDList() \
                    and conn.vehicle.getDistance("turned") > 30.0:  # (not at a multiple of 25 steps)
                assert acc.stepper.ledger.steps % 25 != 0
                conn.vehicle.setEmissionClass("turned", "Energy/unknown")
                switched = conn.vehicle.getDistance("turned")
        v = acc.result().vehicles
    finally:
        close_sumo(conn)
    t = v[v.vehicle == "turned"].set_index("equation")
    assert set(t.index) == {"epa_gasoline_car", "bmw_i3_battery"}, t
    assert t.loc["bmw_i3_battery", "distance_m"] > 2 * t.loc["epa_gasoline_car", "distance_m"] > 0
    assert t.loc["epa_gasoline_car", "distance_m"] == pytest.approx(switched, abs=0.01)  # up to the call
    left = v[v.vehicle == "left"]
    assert list(left.equation) == ["epa_gasoline_car"]
    assert t["distance_m"].sum() == pytest.approx(left["distance_m"].iloc[0], rel=0.05)  # the same route


def test_the_end_of_an_accountant_s_result_is_its_last_booked_step(tmp_path):
    """A listener removed at 100 s, SUMO stepped on to 200 s: the result's end_s and its
    edgeData interval said 200 s (SUMO's time), though the booking ended at 100 s (a
    rehearsal, 2026-11-29). Now the last step it booked."""
    import sumolib

    sc = load_scenario(CITY, end=200)
    conn = start_sumo(sc.sumo_args)
    try:
        acc = Accountant(conn, equations=["vsp_ldv1999"], scenario=CITY, figures=False)
        lid = conn.addStepListener(acc)
        while conn.simulation.getTime() < 100 - 1e-9:
            conn.simulationStep()
        conn.removeStepListener(lid)
        while conn.simulation.getTime() < 200 - 1e-9:
            conn.simulationStep()
        res = acc.result()
        res.write(tmp_path / "o")
    finally:
        close_sumo(conn)
    assert res.summary["end_s"] == pytest.approx(100.0)
    ends = [float(i.end) for i in sumolib.xml.parse(str(tmp_path / "o" / "edgedata.xml"), "interval")]
    assert ends == [pytest.approx(100.0)]


def test_edgedata_counts_every_vehicle_entering_an_edge_in_the_same_step(tmp_path):
    """edgedata.xml's ``entered`` counts each accounted vehicle that entered the edge (its
    first edge too, where it departed), also when several enter in one step: two cars depart
    side by side on the highway's two lanes at t = 0 and two more at t = 10 (seen by this
    test's own libsumo loop entering e01 in the same step, pairwise). The true number is what
    SUMO's own edgeData (--edgedata-output) counts: entered + departed per edge."""
    import sumolib

    cars = "\n".join(f'  <vehicle id="v{w}{lane}" type="car" route="r" depart="{10 * w}" departLane="{lane}" '
                     'departSpeed="20" departPos="0"/>' for w in range(2) for lane in range(2))
    (tmp_path / "r.rou.xml").write_text(f"""<routes>
  <vType id="car" vClass="passenger" mass="1500" sigma="0"/>
  <route id="r" edges="e01 e12 e23"/>
{cars}
</routes>""", encoding="utf-8")
    sumo_ed = tmp_path / "sumo_edgedata.xml"
    toml = tmp_path / "s.toml"
    toml.write_text(f'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "{NETS / "highway.net.xml"}"\n'
                    'routes = ["r.rou.xml"]\nbegin = 0\nend = 80\nstep_length = 1.0\n'
                    f'options = ["--no-warnings", "true", "--edgedata-output", "{sumo_ed}"]\n'
                    '[outputs]\nfigures = false\n', encoding="utf-8")
    conn = start_sumo(load_scenario(toml, equations=[PHYS]).sumo_args)
    first_on = {}  # (vehicle, edge) → the step it was first seen there
    try:
        acc = Accountant(conn, equations=[PHYS], scenario=toml, figures=False)
        while conn.simulation.getTime() < 80 - 1e-9:
            conn.simulationStep()
            for vid in conn.vehicle.getIDList():
                first_on.setdefault((vid, conn.vehicle.getRoadID(vid)), conn.simulation.getTime())
            acc.step()
        acc.result().write(tmp_path / "o")
    finally:
        close_sumo(conn)
    assert first_on[("v00", "e01")] == first_on[("v01", "e01")] != first_on[("v10", "e01")] == first_on[("v11", "e01")]
    (sumo_iv,) = sumolib.xml.parse(str(sumo_ed), "interval")
    truth = {e.id: int(e.entered) + int(e.departed) for e in sumo_iv.edge}
    assert truth["e01"] == 4
    (ours,) = sumolib.xml.parse(str(tmp_path / "o" / "edgedata.xml"), "interval")
    assert {e.id: int(e.entered) for e in ours.edge} == {k: n for k, n in truth.items() if n}
