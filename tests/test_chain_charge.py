"""A plug-in hybrid's battery charge at departure (sim/chain_charge.py): read from the route
files as SUMO's battery device reads it (checked against libsumo), booked in a real SUMO run
live and replayed from its FCD, and bad values refused in one line."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sumo_drvpw.errors import UserError
from test_chain_plugin import DEP, DOC

U_J = 1.2e6   # the test's plug-in battery: 333.3 Wh usable
PHEV = 'emissionClass="HBEFA4/PC_PHEV_petrol_Euro-6d_(P)"'


def _param(key, value):
    return f'<param key="{key}" value="{value}"/>' if value is not None else ""


#: (vType's params, vehicle's params) → what SUMO's battery device starts with [Wh]
CASES = {
    "vType's chargeLevel": ({"device.battery.chargeLevel": 1000}, {}),
    "vehicle's over vType's": ({"device.battery.chargeLevel": 1000}, {"device.battery.chargeLevel": 2000}),
    "vType's old key over the vehicle's new": ({"actualBatteryCapacity": 1500}, {"device.battery.chargeLevel": 2000}),
    "vehicle's old key over all": ({"device.battery.chargeLevel": 1000, "actualBatteryCapacity": 1200},
                                   {"actualBatteryCapacity": 2500}),
}


@pytest.mark.sumo
@pytest.mark.parametrize("case", list(CASES))
def test_the_charge_is_read_as_sumos_battery_device_reads_it(tmp_path, case):
    """For each case, the charge read from the route file (a vehicle, and a flow's vehicle) is
    what libsumo's battery device departs with (device.battery.chargeLevel, Wh)."""
    libsumo = pytest.importorskip("libsumo")
    from sumo_probe import build_net

    from sumo_drvpw.sim.chain_charge import DepartureCharges
    from sumo_drvpw.sim.vtypes import read_vtypes

    typ, veh = CASES[case]
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="b" x="500" y="0"/></nodes>',
              '<edges><edge id="ab" from="a" to="b" numLanes="1" speed="22"/></edges>', "--no-warnings")
    own = "".join(_param(k, x) for k, x in veh.items())
    (tmp_path / "r.rou.xml").write_text(
        f'<routes><vType id="h" {PHEV}>{_param("has.battery.device", "true")}'
        f'{_param("device.battery.capacity", 8000)}{"".join(_param(k, x) for k, x in typ.items())}</vType>'
        f'<vehicle id="v" type="h" depart="0"><route edges="ab"/>{own}</vehicle>'
        f'<flow id="f" type="h" begin="0" number="1" period="1"><route edges="ab"/>{own}</flow></routes>',
        encoding="utf-8")
    fv = read_vtypes([tmp_path / "r.rou.xml"])
    mine = DepartureCharges.of_files(fv)
    libsumo.start(["sumo", "-n", str(tmp_path / "n.net.xml"), "-r", str(tmp_path / "r.rou.xml"),
                   "--no-step-log", "--no-warnings"])
    try:
        libsumo.simulationStep()
        for vid in ("v", "f.0"):
            sumo = float(libsumo.vehicle.getParameter(vid, "device.battery.chargeLevel"))
            assert float(mine.of(vid, "h")[0]) == pytest.approx(sumo, abs=0.01)
    finally:
        libsumo.close()


def _road(tmp_path, routes: str) -> None:
    """Three parallel roads A, B, C of five 1.1-km edges, and the route file ``routes``."""
    from sumo_probe import build_net

    nodes = "".join(f'<node id="{r}{i}" x="{1100 * i}" y="{500 * k}"/>' for k, r in enumerate("abc") for i in range(6))
    edges = "".join(f'<edge id="{r.upper()}{i}" from="{r}{i}" to="{r}{i + 1}" numLanes="1" speed="22"/>'
                    for r in "abc" for i in range(5))
    build_net(tmp_path, f"<nodes>{nodes}</nodes>", f"<edges>{edges}</edges>", "--no-warnings")
    (tmp_path / "r.rou.xml").write_text(routes, encoding="utf-8")


def _vtype(params: str = "") -> str:
    return f'<vType id="h" vClass="passenger" mass="1500" sigma="0" speedDev="0" {PHEV}>{params}</vType>'


def _trip(vid, road, params="", tag="vehicle"):
    when = 'depart="0"' if tag == "vehicle" else 'begin="0" number="1" period="1"'
    return f'<{tag} id="{vid}" type="h" {when}><route edges="{" ".join(f"{road}{i}" for i in range(5))}"/>{params}</{tag}>'


@pytest.mark.sumo
def test_a_plug_in_departing_half_charged_burns_fuel_earlier_live_and_replayed(tmp_path):
    """Three twins on three parallel 5.5-km roads at 22 m/s, 1.2 MJ usable: one departs charged
    (no param), one with its own chargeLevel at half (166.67 Wh), a flow's with SUMO's old key
    at 0. Each spends exactly what it departs with, no more; the less charge, the more fuel and
    the earlier the first edge with fuel; vehicle, edge and class totals agree; the FCD replay
    books the same. (Before: every one departed charged, 0.333 kWh each.)"""
    pytest.importorskip("libsumo")
    import pandas as pd
    from test_chain_battery_window import run_and_replay, write_equation

    half_wh = U_J / 3600.0 / 2
    _road(tmp_path, f'<routes>{_vtype()}{_trip("full", "A")}'
                    f'{_trip("half", "B", _param("device.battery.chargeLevel", half_wh))}'
                    f'{_trip("e", "C", _param("actualBatteryCapacity", 0), "flow")}</routes>')
    run_and_replay(tmp_path, [write_equation(tmp_path / "phev.toml", "phev", DOC, {"depleting": {**DEP, "usable_j": U_J}})])
    got = {}
    for run in ("o", "r"):
        veh = pd.read_csv(tmp_path / run / "chain_vehicles.csv", dtype={"key": str}).set_index("key")
        assert veh.loc["full", "net_kwh"] == pytest.approx(U_J / 3.6e6, rel=1e-9)
        assert veh.loc["half", "net_kwh"] == pytest.approx(half_wh / 1000, rel=1e-9)
        assert veh.loc["e.0", "net_kwh"] == pytest.approx(0.0, abs=1e-12)
        assert veh.loc["e.0", "fuel_l"] > veh.loc["half", "fuel_l"] > veh.loc["full", "fuel_l"] > 0
        edges = pd.read_csv(tmp_path / run / "chain_edges.csv", dtype={"key": str}).set_index("key")
        first = {r: next(i for i in range(5) if edges.loc[f"{r}{i}", "fuel_l"] > 0) for r in "ABC"}
        assert first["C"] == 0 < first["B"] < first["A"]
        cls = pd.read_csv(tmp_path / run / "chain_classes.csv", dtype={"key": str})
        for col in ("fuel_l", "net_kwh", "traction_kwh"):
            assert edges[col].sum() == pytest.approx(veh[col].sum(), rel=1e-9)
            assert cls[col].sum() == pytest.approx(veh[col].sum(), rel=1e-9)
        summary = json.loads((tmp_path / run / "summary.json").read_text(encoding="utf-8"))
        assert summary["chain"]["departure_charge"]["vehicles"] == 2
        got[run] = veh
    for col in ("fuel_l", "net_kwh", "traction_kwh", "recuperated_kwh"):
        assert np.allclose(got["r"].loc[got["o"].index, col], got["o"][col], rtol=1e-6, atol=1e-12)


def _scenario(tmp_path, vtypes: str = "") -> object:
    from test_chain_battery_window import write_equation

    eq = write_equation(tmp_path / "phev.toml", "phev", DOC, {"depleting": {**DEP, "usable_j": U_J}})
    s = tmp_path / "s.toml"
    s.write_text(f'equations = ["{eq}"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["r.rou.xml"]\nend = 300\n'
                 'options = ["--no-warnings", "true"]\n[outputs]\nfigures = false\n' + vtypes, encoding="utf-8")
    return s


@pytest.mark.sumo
@pytest.mark.parametrize("where, value, said", [
    ("vehicle", "-1", r"r\.rou\.xml: vehicle 'v': device\.battery\.chargeLevel must be a number of Wh ≥ 0.*'-1'"),
    ("vehicle", "half", r"r\.rou\.xml: vehicle 'v': device\.battery\.chargeLevel must be a number.*'half'"),
    ("vType", "400", r"r\.rou\.xml: vType 'h' \(of vehicle 'v'\): device\.battery\.chargeLevel = '400' Wh is above "
                     r"the usable energy of phev's plug-in battery \(333\.3 Wh"),
])
def test_a_bad_charge_is_refused_naming_the_vehicle_or_vtype_and_the_key(tmp_path, where, value, said):
    """Negative, not a number, above the usable energy: one UserError naming the file, the
    vehicle or vType and the key; no output set. A battery electric vehicle's charge far above
    the plug-in's usable energy is not the plug-in's to refuse (it books no such vehicle)."""
    pytest.importorskip("libsumo")
    from sumo_drvpw.sim.run import run_scenario

    p = _param("device.battery.chargeLevel", value)
    ev = ('<vType id="ev" vClass="passenger" emissionClass="Energy/unknown">'
          f'{_param("device.battery.chargeLevel", 30000)}</vType>'
          '<vehicle id="b" type="ev" depart="0"><route edges="C0"/></vehicle>')
    _road(tmp_path, f'<routes>{_vtype(p if where == "vType" else "")}{ev}'
                    f'{_trip("v", "A", p if where == "vehicle" else "")}</routes>')
    with pytest.raises(UserError, match=said):
        run_scenario(_scenario(tmp_path), tmp_path / "o")
    assert not (tmp_path / "o" / "summary.json").exists()
    (tmp_path / "r.rou.xml").write_text(f'<routes>{_vtype()}{ev}{_trip("v", "A")}</routes>', encoding="utf-8")
    run_scenario(_scenario(tmp_path), tmp_path / "ok")   # the electric car's 30 kWh is not refused


@pytest.mark.sumo
def test_the_scenario_declares_a_vtypes_charge_and_a_vehicle_s_own_wins(tmp_path, capsys):
    """``[vtypes.h] battery_charge_wh = 100`` departs the vType's vehicles with 100 Wh (over its
    own param's 300); a vehicle's own param wins over the scenario's; a negative value or one
    under [vclasses] is refused in one line, exit 2."""
    pytest.importorskip("libsumo")
    import pandas as pd

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.sim.run import run_scenario

    _road(tmp_path, f'<routes>{_vtype(_param("device.battery.chargeLevel", 300))}{_trip("t", "A")}'
                    f'{_trip("own", "B", _param("device.battery.chargeLevel", 50))}</routes>')
    run_scenario(_scenario(tmp_path, "[vtypes.h]\nbattery_charge_wh = 100\n"), tmp_path / "o")
    veh = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv", dtype={"key": str}).set_index("key")
    assert veh.loc["t", "net_kwh"] == pytest.approx(0.100, rel=1e-9)
    assert veh.loc["own", "net_kwh"] == pytest.approx(0.050, rel=1e-9)
    for table, value, said in (("vtypes.h", "-5", "'vtypes.h.battery_charge_wh' must be a number of Wh ≥ 0"),
                               ("vclasses.passenger", "100", "'vclasses.passenger.battery_charge_wh' is a vType's")):
        s = _scenario(tmp_path, f"[{table}]\nbattery_charge_wh = {value}\n")
        capsys.readouterr()
        assert cli_main(["run", str(s), "--out", str(tmp_path / "bad")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and said in err[0] and "s.toml" in err[0]
        assert not (tmp_path / "bad").exists()


def _scripted(tmp_path, vtype: str, after=None):
    """A user's own libsumo loop with the Accountant: the route file's car 't' (vType ``vtype``)
    and a car the script adds ('added') told 100 Wh by Accountant.set_battery_charge; ``after``
    (the accountant) once the run has stepped to 300 s. Each vehicle's chain row (net_kwh …)."""
    pytest.importorskip("libsumo")
    import pandas as pd

    from sumo_drvpw.sim import Accountant, close_sumo, start_sumo
    from sumo_drvpw.sim.scenario import load_scenario

    _road(tmp_path, f'<routes>{vtype}{_trip("t", "A")}</routes>')
    s = _scenario(tmp_path)
    conn = start_sumo(load_scenario(s).sumo_args)
    try:
        acc = Accountant(conn, scenario=s)
        conn.addStepListener(acc)
        conn.route.add("rb", [f"B{i}" for i in range(5)])
        conn.vehicle.add("added", "rb", typeID="h", depart="now")
        acc.set_battery_charge("added", 100)
        with pytest.raises(ValueError, match="≥ 0"):
            acc.set_battery_charge("later", -1)
        while conn.simulation.getTime() < 300 - 1e-9:
            conn.simulationStep()
        if after is not None:
            after(acc)
        res = acc.result()
    finally:
        close_sumo(conn)
    res.write(tmp_path / "o")
    return pd.read_csv(tmp_path / "o" / "chain_vehicles.csv", dtype={"key": str}).set_index("key")


@pytest.mark.sumo
def test_a_traci_script_says_an_added_plug_in_s_charge(tmp_path):
    """Accountant.set_battery_charge in a user's own libsumo loop: a vehicle the script adds
    departs with the 100 Wh it is told (net 0.1 kWh), the route file's vehicle charged (0.333
    kWh); a negative charge, or one said after the departure, is a ValueError."""
    def said_late(acc):
        with pytest.raises(ValueError, match="departed already"):
            acc.set_battery_charge("added", 50)

    veh = _scripted(tmp_path, _vtype(), said_late)
    assert veh.loc["added", "net_kwh"] == pytest.approx(0.100, rel=1e-9)
    assert veh.loc["t", "net_kwh"] == pytest.approx(U_J / 3.6e6, rel=1e-9)


def test_dask_buckets_add_up_the_declared_charges():
    """An FCD replay on Dask books vehicles in buckets whose ledgers merge_ledgers adds: the
    vehicles that departed with a declared charge (summary.json chain.departure_charge) are the
    buckets' sums, as each books its own; a bucket's vehicle departs with U − 3600·charge spent."""
    from sumo_drvpw.model.chain_toml import chain_from_dict
    from sumo_drvpw.sim.chain import ChainLedger
    from sumo_drvpw.sim.chain_charge import CHARGE_LEVEL, DepartureCharges
    from sumo_drvpw.sim.fcd_dask import merge_ledgers
    from sumo_drvpw.sim.ledger import Ledger

    ch = chain_from_dict({**DOC, "depleting": {**DEP, "usable_j": U_J}})
    leds = []
    for vids in (["a"], ["b", "c"]):
        led = Ledger(3, 1)
        led.chain = ChainLedger(["phev"], [ch], 3)
        led.chain.charges = DepartureCharges({v: {CHARGE_LEVEL: ("100", "r.rou.xml")} for v in vids})
        led.chain.charges.depart(led.chain, np.arange(len(vids)), vids, ["h"] * len(vids), np.ones((len(vids), 1)))
        assert led.chain._spent[:len(vids), 0] == pytest.approx(U_J - 3.6e5)
        leds.append(led)
    got = merge_ledgers(leds).chain.charges.summary()
    assert got["vehicles"] == 3 and got["mean_charge_wh"] == pytest.approx(100.0)


@pytest.mark.parametrize("own, typ, scenario, want", [
    # the scenario's key replaces the vType's params (its old key too), never the vehicle's own
    ({"device.battery.chargeLevel": "100"}, {"actualBatteryCapacity": "50"}, 200.0, "100"),
    ({}, {"actualBatteryCapacity": "50"}, 200.0, 200.0),
    ({"actualBatteryCapacity": "70"}, {"device.battery.chargeLevel": "50"}, 200.0, "70"),
    # without the scenario's key, SUMO's order: the old key anywhere wins
    ({"device.battery.chargeLevel": "100"}, {"actualBatteryCapacity": "50"}, None, "50"),
])
def test_the_scenario_s_charge_replaces_the_vtype_s_params_not_the_vehicle_s(own, typ, scenario, want):
    """docs/energy-chain.md, docs/scenario.md: ``[vtypes.<id>] battery_charge_wh`` replaces what
    the vType's params say, a vehicle's own param wins over it — also where the vType's param is
    SUMO's old key, which then no longer outranks the vehicle's chargeLevel."""
    from sumo_drvpw.sim.chain_charge import DepartureCharges

    d = DepartureCharges({"v": {k: (x, "r.rou.xml") for k, x in own.items()}}, None,
                         {"t": {k: (x, "r.rou.xml") for k, x in typ.items()}},
                         {} if scenario is None else {"t": (scenario, "s.toml")})
    assert d.of("v", "t")[0] == want


@pytest.mark.sumo
def test_a_traci_script_s_charge_wins_over_the_vtype_s_old_key(tmp_path):
    """Accountant.set_battery_charge overrides what the route files say: also where the vehicle's
    vType declares SUMO's old key actualBatteryCapacity (300 Wh), which outranks a vehicle's
    chargeLevel param — the script's 100 Wh was stored as one and silently lost (the added car
    booked the vType's 0.300 kWh). The route file's own vehicle keeps the vType's 300 Wh."""
    veh = _scripted(tmp_path, _vtype(_param("actualBatteryCapacity", 300)))
    assert veh.loc["added", "net_kwh"] == pytest.approx(0.100, rel=1e-9)
    assert veh.loc["t", "net_kwh"] == pytest.approx(0.300, rel=1e-9)


@pytest.mark.sumo
def test_a_replay_from_begin_says_the_plug_ins_driving_then_start_from_their_departure_charge(tmp_path):
    """A replay from ``--begin 100`` (2.2 km into both trips): the two plug-ins driving then
    (one declared half, one charged) spent some of their charge before it, which neither the
    FCD nor the route files tell; each is booked from its charge at departure (its net kWh as
    the whole run's) and counted and said once: ``driving_at_begin`` 2 and one warning; a car
    departing after the begin is not counted. Without a declared charge at all (charges None)
    the same. (Before: booked from the departure charge without a word.)"""
    pytest.importorskip("libsumo")
    import pandas as pd
    from test_chain_battery_window import run_and_replay, write_equation

    from sumo_drvpw.cli import main as cli_main

    half_wh = U_J / 3600.0 / 2
    late = _trip("late", "C").replace('depart="0"', 'depart="150"')
    for declared in (True, False):
        d = tmp_path / str(declared)
        d.mkdir()
        _road(d, f'<routes>{_vtype()}{_trip("full", "A")}'
                 f'{_trip("half", "B", _param("device.battery.chargeLevel", half_wh) if declared else "")}{late}</routes>')
        run_and_replay(d, [write_equation(d / "phev.toml", "phev", DOC, {"depleting": {**DEP, "usable_j": U_J}})])
        assert cli_main(["fcd", str(d / "o" / "sumo" / "fcd.xml"), "--scenario", str(d / "s.toml"),
                         "--begin", "100", "--out", str(d / "b")]) == 0
        summary = json.loads((d / "b" / "summary.json").read_text(encoding="utf-8"))
        assert summary["chain"]["departure_charge"]["driving_at_begin"] == 2
        said = [w for w in summary["warnings"] if "driving at the run's first step" in w]
        assert len(said) == 1 and said[0].startswith("2 plug-in hybrid vehicle(s)")
        veh = pd.read_csv(d / "b" / "chain_vehicles.csv", dtype={"key": str}).set_index("key")
        assert veh.loc["half", "net_kwh"] == pytest.approx(half_wh / 1000 if declared else U_J / 3.6e6, rel=1e-9)
        whole = json.loads((d / "r" / "summary.json").read_text(encoding="utf-8"))  # from the start: none
        assert "driving_at_begin" not in whole["chain"].get("departure_charge", {})
        assert not [w for w in whole["warnings"] if "driving at the run's first step" in w]


def test_dask_buckets_add_up_the_plug_ins_driving_at_begin():
    """A replay from --begin on Dask: one bucket's plug-ins driving then, counted in a charges
    record the bucket made (none declared), the other bucket's none: the merged ledger keeps
    the count, whichever bucket comes first."""
    from sumo_drvpw.model.chain_toml import chain_from_dict
    from sumo_drvpw.sim.chain import ChainLedger
    from sumo_drvpw.sim.chain_charge import book_departures
    from sumo_drvpw.sim.fcd_dask import merge_ledgers
    from sumo_drvpw.sim.ledger import Ledger

    ch = chain_from_dict({**DOC, "depleting": {**DEP, "usable_j": U_J}})
    leds = []
    for vids, driving in ((["a"], False), (["b", "c"], True)):
        led = Ledger(3, 1)
        led.chain = ChainLedger(["phev"], [ch], 3)
        book_departures(led.chain, np.arange(len(vids)), vids, ["h"] * len(vids), np.ones((len(vids), 1)), driving)
        assert (led.chain.charges is not None) == driving
        leds.append(led)
    assert merge_ledgers(leds).chain.charges.summary()["driving_at_begin"] == 2
