"""SUMO's MMPEVEM (model/mmpevem.py): its loss map by hand, every step of SUMO 1.28's own
emissionsDrivingCycle along a random drive for the vehicle files SUMO ships and for vTypes
that leave parameters out, the chain's TOML round trip, and ``vtype_energy`` booking
MMPEVEM vTypes beside SUMO's emission output on a slope with stops (live and replayed)."""

from __future__ import annotations

import math
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import sumolib

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.errors import UserError
from sumo_drvpw.model.equations import equation_from_dict
from sumo_drvpw.model.mmpevem import SUMO_DEFAULTS, LossMap, mmpevem_equation
from sumo_drvpw.model.terms import Inputs
from sumo_drvpw.sim import run_scenario
from sumo_probe import build_net, emitted_wh, energy_scenario


def _sumo_home() -> Path:
    import sumo

    return Path(sumo.SUMO_HOME)


def test_loss_map_as_sumo_evaluates_it():
    """SUMO's CharacteristicMap: the nearest grid point plus, per axis, the slope to the
    neighbour on the point's side — no cross term, so not bilinear; nan outside the axes
    (beyond a tolerance of 1e-6). Values by hand on a 3 × 2 grid."""
    # speed axis 0, 1000, 2000 rpm; torque axis -10, 10 N·m; rows = torque
    lm = LossMap.parse("2,1|0,1000,2000;-10,10|100,200,400,300,500,900")
    y = lm(np.array([1000.0, 400.0, 1000.0, 1600.0, 400.0, 2000.0, 2100.0, -1.0, 0.0]),
           np.array([10.0, -10.0, 0.0, -10.0, 5.0, 10.0, 0.0, 0.0, 10.0 + 1e-7]))
    # (1000, 10): node 500; (400, -10): nearest 0 rpm (100) + 400·(200−100)/1000 = 140;
    # (1000, 0): nearest torque: a tie at 0 goes to the lower (−10): 200 + 10·(500−200)/20 = 350;
    # (1600, −10): nearest 2000 (400), s = −400 toward 1000: 400 − 400·(400−200)/1000 = 320;
    # (400, 5): nearest (0 rpm, 10 N·m) = 300, + 400·(500−300)/1000 − 5·(300−100)/20 = 330
    # (bilinear would give 326); (2000, 10) node 900; outside: nan; within 1e-6 of the end: the node
    np.testing.assert_allclose(y, [500.0, 140.0, 350.0, 320.0, 330.0, 900.0, np.nan, np.nan, 300.0])
    for bad in ("2,1|0,1;0,1|1,2,3", "1,1|0,1|1,2", "2,1|0,0;0,1|1,2,3,4", "nonsense"):
        with pytest.raises(UserError, match="powerLossMap"):
            LossMap.parse(bad, "f: vType 'x': param powerLossMap")


def _vtype_params(path: Path):
    vt = ET.parse(path).getroot().find(".//vType")
    return vt.get("id"), {p.get("key"): p.get("value") for p in vt.findall("param")}, vt.get("mass")


def _drive(tmp_path: Path, n=500, seed=4):
    rng = np.random.default_rng(seed)
    v = np.clip(np.cumsum(rng.normal(0, 1.2, n)) + 12, 0, 44)
    v[:5] = 0.0
    v[150:170] = 0.0
    a = np.diff(v, prepend=0.0)
    slope = np.round(rng.normal(0, 2.5, n), 3)  # [deg], standing on slopes included
    pd.DataFrame({"t": np.arange(n, dtype=float), "v": v, "a": a, "s": slope}).to_csv(
        tmp_path / "tl.csv", sep=";", header=False, index=False)
    return v, a, np.radians(slope)


CASES = {  # label: (vehicle file SUMO ships or None, vType XML for None)
    "BMW_i3": ("BMW_i3.xml", None),
    "Hyundai_Ioniq_5": ("Hyundai_Ioniq_5.rou.xml", None),  # its loss map holds nan points
    "bare": (None, '<vType id="x" emissionClass="MMPEVEM"/>'),
    "partial": (None, '<vType id="x" emissionClass="MMPEVEM" mass="1500"><param key="loading" value="120"/>'
                      '<param key="constantPowerIntake" value="800"/><param key="maximumPower" value="60000"/>'
                      '<param key="gearRatio" value="8.5"/><param key="vehicleMass" value="900"/></vType>'),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_every_step_as_sumos_emissions_driving_cycle(tmp_path, case):
    """SUMO 1.28's emissionsDrivingCycle (1-s steps: v, a, slope) against the equation and
    chain ``vtype_energy`` makes of the same vType, fed as the loop feeds them (terms at the
    step's mean speed): every step within 0.5 W (SUMO writes Wh/s to 6 decimals; measured
    2026-11-27 ≤ 0.15 W), the battery energy within 1e-5, and SUMO's nan (torque or power
    beyond the motor's, a point outside the loss map) on exactly the steps the chain marks
    invalid. The vTypes that leave parameters out get SUMO's defaults (a VW ID.3, loss map
    0 W); vehicleMass is not read, loading is."""
    v, a, th = _drive(tmp_path)
    fname, xml = CASES[case]
    if fname:
        path = _sumo_home() / "data" / "emissions" / "MMPEVEM" / fname
    else:
        path = tmp_path / "x.xml"
        path.write_text(f"<routes>{xml}</routes>", encoding="utf-8")
    vid, params, mass = _vtype_params(path)
    subprocess.run([sumolib.checkBinary("emissionsDrivingCycle"), "-t", "tl.csv", "-e", "MMPEVEM", "--have-slope",
                    "-o", "o.csv", "--additional-files", str(path), "--vtype", vid],
                   check=True, capture_output=True, cwd=tmp_path)
    sumo_w = pd.read_csv(tmp_path / "o.csv", sep=";", header=None).iloc[:, -1].to_numpy(float) * 3600.0
    eq, notes = mmpevem_equation("x", params, float(mass) if mass else None, case)
    if case == "partial":
        assert eq.mass_kg == 1620.0 and eq.chain.motor.max_power_w == 60000.0
        assert any("vehicleMass" in n for n in notes)
    if case == "bare":
        assert eq.mass_kg == SUMO_DEFAULTS["mass"]
    vm = v - 0.5 * a
    n = len(v)
    x = Inputs(vm, a, th, np.zeros(n), np.full(n, eq.mass_kg), np.full(n, 1.2041), {}, v_acc=vm)
    out = eq.chain.evaluate(eq.power(x), vm, signals={"accel_mps2": a, "grade_rad": th})
    ok = np.isfinite(sumo_w)
    np.testing.assert_array_equal(~ok, out["invalid"])
    assert (~ok).sum() >= 1  # the random drive asks more than the motor gives somewhere
    np.testing.assert_allclose(out["power_w"][ok], sumo_w[ok], atol=0.5)
    assert out["power_w"][ok].sum() == pytest.approx(sumo_w[ok].sum(), rel=1e-5)
    np.testing.assert_allclose(out["traction_w"] + out["recuperated_w"] + out["auxiliary_w"], out["power_w"])


def test_the_chain_round_trips_through_its_table():
    """An equation with SUMO's motor written as TOML tables and read back books the same
    battery power; a table that lacks a key or holds a bad value, or a chain that gives an
    efficiency the motor replaces, is refused, naming it."""
    i3 = _sumo_home() / "data" / "emissions" / "MMPEVEM" / "BMW_i3.xml"
    _, params, mass = _vtype_params(i3)
    eq, _ = mmpevem_equation("i3_mmpevem", params, float(mass), "BMW_i3.xml")
    doc = eq.to_dict()
    back = equation_from_dict(doc, "i3.toml")
    v = np.linspace(0.0, 35.0, 50)
    a = np.sin(v)
    x = Inputs(v, a, np.zeros(50), np.zeros(50), np.full(50, 1417.0), np.full(50, 1.2041), {}, v_acc=v)
    np.testing.assert_allclose(back.chain.evaluate(back.power(x), v)["power_w"],
                               eq.chain.evaluate(eq.power(x), v)["power_w"])
    motor = dict(doc["chain"]["motor"])
    motor.pop("gear_ratio")
    with pytest.raises(UserError, match=r"i3.toml \[chain.motor\]: missing \['gear_ratio'\]"):
        equation_from_dict({**doc, "chain": {**doc["chain"], "motor": motor}}, "i3.toml")
    with pytest.raises(UserError, match=r"'traction_efficiency' with \[chain.motor\]"):
        equation_from_dict({**doc, "chain": {**doc["chain"], "traction_efficiency": 0.9}}, "i3.toml")
    motor = {**doc["chain"]["motor"], "gear_efficiency": 1.2}
    with pytest.raises(UserError, match="gear_efficiency: must be a finite number > 0 and ≤ 1"):
        equation_from_dict({**doc, "chain": {**doc["chain"], "motor": motor}}, "i3.toml")


ROUTES = """<routes>
  {i3}
  <vType id="id3" emissionClass="MMPEVEM" vClass="passenger" sigma="0.5"/>
  {fast}
  <vType id="ecar" emissionClass="Energy/unknown" vClass="passenger" mass="1600" sigma="0.5">
    <param key="airDragCoefficient" value="0.28"/>
  </vType>
  <flow id="i" type="BMW_i3" from="e" to="e" begin="0" end="60" period="12" departSpeed="0">
    <stop lane="e_0" endPos="900" duration="15"/>
  </flow>
  <flow id="f" type="fast" from="e" to="e" begin="2" end="30" period="14" departSpeed="0" departLane="1"/>
  <flow id="d" type="id3" from="e" to="e" begin="4" end="60" period="12" departSpeed="0">
    <stop lane="e_0" endPos="1300" duration="10"/>
  </flow>
  <flow id="c" type="ecar" from="e" to="e" begin="8" end="60" period="12" departSpeed="0"/>
</routes>"""


def _routes(tmp_path: Path) -> Path:
    """SUMO's own BMW i3 vType, a bare MMPEVEM vType, the i3 with a 4.5-m/s² start (beyond
    its 107-kW motor from about 20 m/s: SUMO writes nan there) and an Energy-model car."""
    text = (_sumo_home() / "data" / "emissions" / "MMPEVEM" / "BMW_i3.xml").read_text(encoding="utf-8")
    i3 = text[text.index("<vType"):text.index("</vType>") + len("</vType>")]
    fast = i3.replace('id="BMW_i3"', 'id="fast" accel="4.5" maxSpeed="30"')
    p = tmp_path / "r.rou.xml"
    p.write_text(ROUTES.format(i3=i3, fast=fast), encoding="utf-8")
    return p


def test_vtype_energy_books_mmpevem_as_sumo(tmp_path):
    """A straight road of 3 km at a constant 2 % grade and 16 m/s (no grade change: the slopes' source
    stays out), 0.5-s steps; MMPEVEM cars stop on the slope (the motor holds them: SUMO
    books its loss map at the holding torque). ``vtype_energy`` books each MMPEVEM car as
    SUMO's emission output does, per car within 1e-6 (measured 2026-11-27: within 2e-8; without the holding torque 1e-4 off), the
    Energy-model car beside them too; the i3 driven beyond its motor, where SUMO writes nan
    on some steps, is booked at the motor's limits: more than SUMO's finite steps, finite;
    summary.json counts exactly the steps SUMO writes nan and a warning says so. An FCD
    replay of the run books the same."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0" z="0"/><node id="b" x="3000" y="0" z="60"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="2" speed="16"/></edges>')
    routes = _routes(tmp_path)
    res = run_scenario(energy_scenario(tmp_path, 250, routes=routes.name), tmp_path / "o")
    booked = res["assumptions"]["vtype_energy"]["booked"]
    assert {b["model"] for b in booked.values()} == {"MMPEVEM", "Energy"} and len(booked) == 4
    assert booked["id3"]["mass_kg"] == SUMO_DEFAULTS["mass"] and "powerLossMap" in booked["id3"]["defaults"]
    sumo, nan = emitted_wh(tmp_path / "em.xml", 0.5)
    cv = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv").set_index("key")
    assert {k[0] for k in cv.index} == {"i", "d", "c", "f"}
    for key, row in cv.iterrows():
        assert np.isfinite(row.net_kwh) and (nan[key] == 0 or key.startswith("f"))
        if nan[key]:  # booked at the motor's limits where SUMO writes nan
            assert row.net_kwh * 1000.0 > sumo[key]
        else:
            assert row.net_kwh * 1000.0 == pytest.approx(sumo[key], rel=1e-6), key
    assert sum(nan[k] for k in cv.index if k.startswith("f")) > 0
    # the steps SUMO writes nan are the steps the chain could not serve, counted and said
    counted = res["chain"]["mmpevem_nan_steps"]
    assert counted == {"vtype_energy.BMW_i3": 0, "vtype_energy.id3": 0,
                       "vtype_energy.fast": sum(nan[k] for k in cv.index if k.startswith("f"))}
    assert any("MMPEVEM would write nan on" in w and "vtype_energy.fast" in w for w in res["warnings"])
    held = [float(v.get("pos")) for ts in ET.parse(tmp_path / "em.xml").getroot() for v in ts
            if v.get("id") == "i.0" and float(v.get("speed")) == 0.0 and float(v.get("pos")) > 800]
    assert len(held) >= 25  # it stood at its stop on the slope (15 s)
    assert cli_main(["fcd", str(tmp_path / "fcd.xml"), "--net", str(tmp_path / "n.net.xml"), "--vtypes",
                     str(routes), "--equation", "vtype_energy", "--end", "250",
                     "--out", str(tmp_path / "fcd"), "--no-figures"]) == 0
    rep = pd.read_csv(tmp_path / "fcd" / "chain_vehicles.csv").groupby("equation").net_kwh.sum()
    live = cv.groupby("equation").net_kwh.sum()
    np.testing.assert_allclose(rep.loc[live.index].values, live.values, rtol=1e-3)


def test_evaluate_where_is_the_chain_on_those_vehicles_only():
    """The SUMO loop evaluates a motor chain only on the vehicles its equation books
    (``evaluate_where``): those rows equal the whole evaluation's, the others are 0."""
    from sumo_drvpw.model.mmpevem import evaluate_where

    _, params, mass = _vtype_params(_sumo_home() / "data" / "emissions" / "MMPEVEM" / "BMW_i3.xml")
    ch = mmpevem_equation("x", params, float(mass), "i3")[0].chain
    rng = np.random.default_rng(1)
    p, v, a = rng.normal(0, 2e4, 40), rng.uniform(0, 30, 40), rng.normal(0, 1, 40)
    sel = rng.random(40) < 0.3
    full = ch.evaluate(p, v, 0.5, {"accel_mps2": a, "grade_rad": np.full(40, 0.01)})
    part = evaluate_where(ch, sel, p, v, 0.5, {"accel_mps2": a, "grade_rad": np.full(40, 0.01)})
    for k in ("traction_j", "recuperated_j", "auxiliary_j", "power_j", "invalid"):
        np.testing.assert_array_equal(part[k][sel], full[k][sel])
        assert not part[k][~sel].any()


def test_off_the_map_the_loss_at_its_edge():
    """Beyond the loss map (SUMO's i3 at 45 m/s turns its motor at 12,000 rpm, the map ends
    at 11,000: SUMO writes nan) the step is marked invalid and booked with the loss at the
    map's nearest edge, by hand: P_b = P_m + loss(11000 rpm, M) + P_const through the battery's
    resistance."""
    _, params, mass = _vtype_params(_sumo_home() / "data" / "emissions" / "MMPEVEM" / "BMW_i3.xml")
    mo = mmpevem_equation("x", params, float(mass), "i3")[0].chain.motor
    v, p = 45.0, 30000.0
    n = v / (2 * math.pi * mo.wheel_radius_m) * 60 * mo.gear_ratio
    assert n > mo.loss_map.speed_rpm[-1]
    m = p / v * mo.wheel_radius_m / mo.gear_ratio / mo.gear_efficiency
    pb = m * 2 * math.pi * n / 60 + float(mo.loss_map(mo.loss_map.speed_rpm[-1], m)[0]) + mo.aux_power_w
    u, r = mo.battery_voltage_v, mo.battery_resistance_ohm
    out = mo.battery(np.array([p]), np.array([v]))
    assert out["invalid"][0]
    assert out["power_w"][0] == pytest.approx(u * u / (2 * r) - u * math.sqrt((u * u - 4 * r * pb) / (4 * r * r)))


def test_a_motor_without_recuperation_round_trips():
    """A vType that writes maximumRecuperationPower 0 (no recuperation) makes an equation
    that is written and read back (limits and the intake may be 0; the gear ratio may not)."""
    eq, _ = mmpevem_equation("norec", {"maximumRecuperationPower": "0", "constantPowerIntake": "0"}, 1500.0, "x")
    back = equation_from_dict(eq.to_dict(), "norec.toml")
    assert back.chain.motor.max_recuperation_power_w == 0.0
    out = back.chain.evaluate(np.array([-20000.0]), np.array([15.0]))
    assert out["recuperated_w"][0] == 0.0 and out["power_w"][0] == pytest.approx(0.0, abs=1e-9)
    bad = eq.to_dict()
    bad["chain"]["motor"]["gear_ratio"] = 0.0
    with pytest.raises(UserError, match="gear_ratio: must be a finite number > 0"):
        equation_from_dict(bad, "norec.toml")
