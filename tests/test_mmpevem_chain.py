"""An energy chain holding SUMO's MMPEVEM motor ([chain.motor]) and what else its [chain]
table says: the chain's auxiliary draws — aux_power_w (the motor's constantPowerIntake),
logged loads, HVAC, the standstill draw — are drawn at the motor's battery, through its
internal resistance, as MMPEVEM books constantPowerIntake (before they were read and
silently ignored: the battery power did not change by a watt)."""

from __future__ import annotations

import dataclasses
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.equations import equation_from_dict
from sumo_drvpw.model.mmpevem import mmpevem_equation


def _i3_doc() -> dict:
    import sumo

    vt = ET.parse(Path(sumo.SUMO_HOME) / "data" / "emissions" / "MMPEVEM" / "BMW_i3.xml").getroot().find(".//vType")
    eq, _ = mmpevem_equation("i3", {p.get("key"): p.get("value") for p in vt.findall("param")}, float(vt.get("mass")))
    return eq.to_dict()


def _with(doc: dict, **chain) -> dict:
    return {**doc, "chain": {**doc["chain"], **chain}}


P = np.array([0.0, 0.0, 8000.0, -4000.0, 30000.0])
V = np.array([0.0, 0.0, 12.0, 9.0, 25.0])
SIG = {"heater_w": np.array([1500.0, 0.0, 800.0, 2500.0, 0.0]), "ambient_c": np.full(5, 5.0),
       "grade_rad": np.array([0.03, 0.0, 0.0, 0.0, 0.0]), "accel_mps2": np.zeros(5)}


def _motor_at(doc, aux_w):
    """The battery power of the motor alone with P_const = aux_w per sample (SUMO's formula)."""
    m = equation_from_dict(doc, "i3.toml").chain.motor
    aux = np.broadcast_to(np.asarray(aux_w, float), P.shape)
    return np.array([dataclasses.replace(m, aux_power_w=float(aux[i])).battery(
        P[i:i + 1], V[i:i + 1], {k: s[i:i + 1] for k, s in SIG.items()})["power_w"][0] for i in range(len(P))])


def test_the_chains_auxiliary_is_drawn_at_the_motors_battery():
    doc = _i3_doc()
    base = equation_from_dict(doc, "i3.toml").chain.evaluate(P, V, signals=SIG)["power_w"]
    np.testing.assert_allclose(base, _motor_at(doc, 360.0), rtol=1e-12)
    cases = {  # [chain] keys → P_const per sample at the battery
        "aux": ({"aux_power_w": 2000.0, "motor": {**doc["chain"]["motor"], "aux_power_w": 2000.0}}, np.full(5, 2000.0)),
        "loads": ({"loads": {"heater_w": 1.0}}, 360.0 + SIG["heater_w"]),
        "standstill": ({"standstill_aux_w": 500.0}, 360.0 + 500.0 * (V < 0.1)),
        "hvac": ({"hvac": {"column": "ambient_c", "setpoint_c": 20.0, "heating_w_per_k": 100.0,
                           "cooling_w_per_k": 0.0}}, np.full(5, 360.0 + 1500.0)),
    }
    for name, (keys, aux) in cases.items():
        d = _with(doc, **keys)
        got = equation_from_dict(d, "i3.toml").chain.evaluate(P, V, signals=SIG)
        np.testing.assert_allclose(got["power_w"], _motor_at(doc, aux), rtol=1e-12, err_msg=name)
        assert np.all(got["power_w"] - base > np.minimum(aux - 360.0, 1.0) * 0.99 - 1e-9), name
        back = equation_from_dict(equation_from_dict(d, "i3.toml").to_dict(), "i3.toml")  # round trip
        np.testing.assert_allclose(back.chain.evaluate(P, V, signals=SIG)["power_w"], got["power_w"], rtol=1e-12)


def test_aux_given_once_or_agreeing():
    doc = _i3_doc()
    no_aux = {k: v for k, v in doc["chain"].items() if k != "aux_power_w"}
    ch = equation_from_dict({**doc, "chain": no_aux}, "i3.toml").chain
    assert ch.aux_power_w == 360.0  # the motor's constantPowerIntake
    with pytest.raises(UserError, match=r"i3.toml \[chain\] aux_power_w = 2000.0 and \[chain.motor\] aux_power_w = 360.0"):
        equation_from_dict(_with(doc, aux_power_w=2000.0), "i3.toml")
    # a chain changed in memory (diagnose's aux_power_w finding) writes one value
    eq = equation_from_dict(doc, "i3.toml")
    eq.chain = dataclasses.replace(eq.chain, aux_power_w=900.0)
    d = eq.to_dict()
    assert d["chain"]["aux_power_w"] == d["chain"]["motor"]["aux_power_w"] == 900.0


def test_diagnose_offers_a_motor_chain_only_effects_it_can_hold():
    """``diagnose --target battery`` on an equation whose chain is SUMO's MMPEVEM motor: no
    traction or recuperation efficiency, no recuperation limit (the motor has none of them;
    before they were offered, scored and — had one been accepted — written into fields the
    motor ignores and TOML drops); what it finds acts on the held-out prediction and the
    closed equation reads back from its TOML. A synthetic battery log with a 450-W standstill
    load, declared as SUMO's default MMPEVEM car."""
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from test_diagnose_target import _measured

    from sumo_drvpw.fit.chain_linear import trace_chain

    m, _, _ = _measured(450.0)
    eq, _ = mmpevem_equation("mm", {}, 1400.0, "x")
    res = trace_chain(m, eq)
    offered = {c["effect"] for c in res.report["candidates"]}
    assert not offered & {"traction_efficiency", "recuperation_efficiency", "recuperation_limit_w"}, offered
    assert res.report["findings"]
    assert res.report["final"]["metrics"]["rmse_w"] < 0.9 * res.report["baseline"]["metrics"]["rmse_w"]
    back = equation_from_dict(res.equation.to_dict(), "closed.toml")
    x = m.inputs.with_mass(eq.mass_kg)
    np.testing.assert_allclose(back.chain.evaluate(back.power(x), x.v, signals=m.inputs.signals)["power_w"],
                               res.equation.chain.evaluate(res.equation.power(x), x.v, signals=m.inputs.signals)["power_w"])


def test_calibrate_on_a_motor_equation_says_the_motor_is_replaced(tmp_path, capsys):
    """``calibrate --target battery --equation FILE`` fits a chain of efficiencies on top of
    FILE's road load; when FILE's chain is SUMO's MMPEVEM motor the calibrated file no longer
    claims it (before: its description still read '... motor, loss map and battery as the
    chain's motor' over a chain of η_t, η_r) and the console says it was replaced."""
    import sys

    sys.path.insert(0, str(Path(__file__).parent))
    from test_diagnose_target import _measured

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.model.equations import load_equation, save_equation

    _, _, df = _measured(0.0, trips=3, minutes=5.0)
    log = tmp_path / "log.parquet"
    df.to_parquet(log)
    eq, _ = mmpevem_equation("mm", {}, 1400.0, "x")
    save_equation(eq, tmp_path / "mm.toml")
    for engine in ("local", "memory"):
        out = tmp_path / f"cal_{engine}.toml"
        assert cli_main(["calibrate", str(log), "--vehicle", "prius3", "--target", "battery", "--equation",
                         str(tmp_path / "mm.toml"), "--engine", engine, "--out", str(out)]) == 0
        assert "was SUMO's MMPEVEM motor" in capsys.readouterr().out
        cal = load_equation(str(out))
        assert cal.chain.motor is None and cal.terms == eq.terms
        assert "motor replaced by the calibrated chain" in cal.description


def test_export_vtype_writes_an_mmpevem_vtype_sumo_books_as_the_original(tmp_path, capsys):
    """``export-vtype`` of an equation whose chain is SUMO's MMPEVEM motor writes an MMPEVEM
    vType (before: an Energy-model vType with efficiencies 1 and constantPowerIntake 0, the
    motor, its losses and its 360 W left out): SUMO's emissionsDrivingCycle books it as the
    shipped vehicle file it came from, every step to SUMO's 6 decimals (random 500-s drive with
    slopes and stops, nan on the same steps); a term MMPEVEM has not is listed."""
    import subprocess

    import pandas as pd
    import sumo
    import sumolib

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.model.equations import save_equation
    from test_mmpevem import _drive  # noqa: F401 (tests/ on the path: pytest's rootdir)

    src = Path(sumo.SUMO_HOME) / "data" / "emissions" / "MMPEVEM" / "BMW_i3.xml"
    eq = equation_from_dict(_i3_doc(), "i3.toml")
    save_equation(eq, tmp_path / "i3.toml")
    assert cli_main(["export-vtype", str(tmp_path / "i3.toml"), "--id", "i3x", "--out", str(tmp_path / "x.add.xml")]) == 0
    assert "(MMPEVEM)" in capsys.readouterr().out
    vt = ET.parse(tmp_path / "x.add.xml").getroot().find(".//vType")
    assert vt.get("emissionClass") == "MMPEVEM"
    _drive(tmp_path)
    out = {}
    for name, add, vid in (("orig", src, "BMW_i3"), ("export", tmp_path / "x.add.xml", "i3x")):
        subprocess.run([sumolib.checkBinary("emissionsDrivingCycle"), "-t", "tl.csv", "-e", "MMPEVEM", "--have-slope",
                        "-o", f"{name}.csv", "--additional-files", str(add), "--vtype", vid],
                       check=True, capture_output=True, cwd=tmp_path)
        out[name] = pd.read_csv(tmp_path / f"{name}.csv", sep=";", header=None).iloc[:, -1].to_numpy(float)
    assert np.isnan(out["orig"]).sum() >= 1
    np.testing.assert_allclose(out["export"], out["orig"], atol=2e-6, equal_nan=True)
    eq.terms = {**eq.terms, "v2": 0.5}
    save_equation(eq, tmp_path / "i3v2.toml")
    assert cli_main(["export-vtype", str(tmp_path / "i3v2.toml"), "--id", "i3y", "--out", str(tmp_path / "y.add.xml")]) == 0
    assert "v2 (MMPEVEM's road load has acc, grade, roll and aero only)" in capsys.readouterr().out


@pytest.mark.parametrize("engine", ["local", "memory"])
def test_compare_books_the_motor_holding_a_car_on_a_slope(tmp_path, engine):
    """``compare --target battery`` with an equation whose chain is SUMO's MMPEVEM motor
    passes the log's grade to the motor, as the SUMO loop does: a car standing 60 s on a
    5 % slope draws P_const plus the loss of the torque that holds it (SUMO's formula by
    hand: the i3's map at 0 rpm and m·g·sin θ·r/i/η); without the grade it drew P_const only."""
    import json
    import math

    import pandas as pd

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.model.equations import save_equation

    doc = _i3_doc()
    eq = equation_from_dict(doc, "i3.toml")
    save_equation(eq, tmp_path / "i3.toml")
    th = math.atan(0.05)
    n = 600
    pd.DataFrame({"trip_id": "stand", "time_s": np.arange(n) * 0.1, "speed_mps": 0.0, "grade_rad": th,
                  "mass_kg": 1417.0, "battery_voltage_v": 370.0, "battery_current_a": 2.0}).to_parquet(tmp_path / "s.parquet")
    assert cli_main(["compare", str(tmp_path / "s.parquet"), "--equation", str(tmp_path / "i3.toml"),
                     "--target", "battery", "--engine", engine, "--out", str(tmp_path / "o")]) == 0
    rep = json.loads((tmp_path / "o" / "report.json").read_text(encoding="utf-8"))["equations"]["i3"]
    mo = eq.chain.motor
    torque = 1417.0 * 9.80665 * math.sin(th) * mo.wheel_radius_m / mo.gear_ratio / mo.gear_efficiency
    pb = float(mo.loss_map(0.0, torque)[0]) + mo.aux_power_w
    u, r = mo.battery_voltage_v, mo.battery_resistance_ohm
    p_bat = u * u / (2 * r) - u * math.sqrt((u * u - 4 * r * pb) / (4 * r * r))
    trip = rep["trip_net_energy"]["trips"]["stand"]
    assert float(mo.loss_map(0.0, torque)[0]) > 20.0
    assert trip["predicted_j"] == pytest.approx(p_bat * (n - 1) * 0.1, rel=2e-3)
