"""SUMO's recuperation efficiency by deceleration is the vType param
``recuperationEfficiencyByDecel`` (SUMOXMLDefinitions.cpp; SUMO's own test
tests/sumo/devices/battery/recuperateByDecel writes it): SUMO 1.28 reads that key and
ignores a longer ``recuperationEfficiencyByDeceleration``. ``vtype_energy`` reads the key
SUMO reads, and books it as SUMO does."""

from __future__ import annotations

import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import sumolib

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.energy_params import ENERGY_PARAMS, energy_params_equation
from sumo_drvpw.sim import run_scenario


ROUTES = """<routes>
  <vType id="k" vClass="passenger" emissionClass="Energy/unknown" sigma="0.8" speedDev="0.2">
    {param}
  </vType>
  <flow id="c" type="k" from="e" to="e" begin="0" end="30" period="3" departSpeed="0"/>
</routes>"""


def _flat_road(d: Path) -> Path:
    """A flat straight 2-lane road of 3 km (the built-in highway's grade changes would add
    the slopes' source to the comparison)."""
    (d / "n.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="3000" y="0"/></nodes>', encoding="utf-8")
    (d / "n.edg.xml").write_text('<edges><edge id="e" from="a" to="b" numLanes="2" speed="27.8"/></edges>', encoding="utf-8")
    subprocess.run([sumolib.checkBinary("netconvert"), "-n", "n.nod.xml", "-e", "n.edg.xml", "-o", "n.net.xml"],
                   check=True, capture_output=True, cwd=d)
    return d / "n.net.xml"


def _sumo_wh(d: Path, name: str, param: str) -> float:
    """SUMO's own electricity [Wh] of the flow, from its emission output (60 steps of 1 s)."""
    (d / f"{name}.rou.xml").write_text(ROUTES.format(param=param), encoding="utf-8")
    subprocess.run([sumolib.checkBinary("sumo"), "-n", str(_flat_road(d)), "-r", f"{name}.rou.xml", "-e", "60",
                    "--seed", "3", "--emission-output", f"{name}.xml", "--precision", "6",
                    "--no-step-log", "--no-warnings"], check=True, capture_output=True, cwd=d)
    return sum(float(v.get("electricity")) for ts in ET.parse(d / f"{name}.xml").getroot() for v in ts)


def test_the_key_sumo_reads_is_recuperationEfficiencyByDecel(tmp_path):
    """SUMO 1.28 itself: k = 2 under SUMO's key costs more energy than none (less is
    recuperated, η·exp(−k/|a|)); under the longer key it is exactly none (SUMO does not read
    it). The plug-in reads SUMO's key into the chain (recuperation × exp(−k/|a|)) and books
    each car as SUMO's emission output does (to 1e-4); the longer key is no Energy-model
    parameter (SUMO reads none): not booked, and a run with it as the only such vType is
    refused, saying so."""
    none = _sumo_wh(tmp_path, "none", '<param key="constantPowerIntake" value="100"/>')
    short = _sumo_wh(tmp_path, "short", '<param key="recuperationEfficiencyByDecel" value="2"/>')
    long_ = _sumo_wh(tmp_path, "long", '<param key="recuperationEfficiencyByDeceleration" value="2"/>')
    assert short > none * 1.1  # measured 2026-11-27: +24 % (3937.7 against 3185.2 Wh)
    assert long_ == pytest.approx(none, rel=1e-9)
    assert "recuperationEfficiencyByDecel" in ENERGY_PARAMS
    assert "recuperationEfficiencyByDeceleration" not in ENERGY_PARAMS
    eq, notes = energy_params_equation("x", {"recuperationEfficiencyByDecel": "2"}, 1500.0, "f: vType 'x'")
    assert eq.chain.recuperation_by_decel_mps2 == 2.0 and not any("ByDecel" in n for n in notes)
    eq, notes = energy_params_equation("x", {"recuperationEfficiencyByDeceleration": "2"}, 1500.0, "f")
    assert eq.chain.recuperation_by_decel_mps2 == 0.0 and not any("ByDecel" in n for n in notes)
    # a run: the vType with SUMO's key only is booked as SUMO books it, car by car
    (tmp_path / "s.toml").write_text(
        'equations = ["vtype_energy"]\n[sumo]\nnet = "n.net.xml"\nroutes = ["short.rou.xml"]\nend = 60\n'
        'options = ["--no-warnings", "true", "--seed", "3", "--emission-output", "em.xml", "--precision", "6"]'
        '\n[outputs]\nfigures = false\n', encoding="utf-8")
    res = run_scenario(tmp_path / "s.toml", tmp_path / "o")
    assert res["assumptions"]["vtype_energy"]["booked"]["k"]["not_expressed"] == []
    sumo = {}
    for ts in ET.parse(tmp_path / "o" / "sumo" / "em.xml").getroot():
        for v in ts:
            sumo[v.get("id")] = sumo.get(v.get("id"), 0.0) + float(v.get("electricity"))
    import pandas as pd

    cv = pd.read_csv(tmp_path / "o" / "chain_vehicles.csv")
    assert len(cv) >= 8
    for key, kwh in zip(cv.key, cv.net_kwh):
        assert kwh * 1000.0 == pytest.approx(sumo[key], rel=1e-4, abs=1e-4), key
    (tmp_path / "s.toml").write_text((tmp_path / "s.toml").read_text(encoding="utf-8").replace("short.rou", "long.rou"), encoding="utf-8")
    with pytest.raises(UserError, match="no vType .* writes its Energy model .*k: writes no Energy-model"):
        run_scenario(tmp_path / "s.toml", tmp_path / "o2")  # (no out: SUMO writes em.xml into the cwd)


def test_the_chains_recuperation_by_deceleration_by_hand():
    """recuperation × exp(−k/|a|) where a ≠ 0 (SUMO: 'if (a != 0)'), traction untouched; the
    acceleration comes as the signal accel_mps2 (the SUMO loop passes it; target_power takes
    it as accel=); without it a UserError names the key; the [chain] key round-trips."""
    import numpy as np

    from sumo_drvpw.model.chain import EnergyChain
    from sumo_drvpw.model.chain_toml import chain_from_dict

    ch = EnergyChain(predicts="battery", traction_efficiency=0.9, recuperation_efficiency=0.8,
                     aux_power_w=100.0, recuperation_by_decel_mps2=0.5)
    p = np.array([-10000.0, -10000.0, 5000.0])
    a = np.array([-2.0, 0.0, 1.0])
    out = ch.evaluate(p, np.full(3, 10.0), signals={"accel_mps2": a})
    np.testing.assert_allclose(out["recuperated_w"], [0.8 * -10000 * np.exp(-0.25), -8000.0, 0.0])
    np.testing.assert_allclose(out["traction_w"], [0.0, 0.0, 5000.0 / 0.9])
    np.testing.assert_allclose(ch.target_power(p, np.full(3, 10.0), accel=a), out["power_w"])
    with pytest.raises(UserError, match="recuperation_by_decel_mps2 needs the acceleration"):
        ch.evaluate(p, np.full(3, 10.0))
    back = chain_from_dict(ch.to_dict(), "x.toml")
    assert back.recuperation_by_decel_mps2 == 0.5
    # to SUMO's Energy model and back (export-vtype, then vtype_energy): the same k
    from sumo_drvpw.model.energy_params import energy_params_equation
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.sim.export import energy_model_params

    params, _ = energy_model_params(Equation("e", {"acc": 1.0, "aero": 0.3}, mass_kg=1500.0, chain=ch))
    assert params["recuperationEfficiencyByDecel"] == 0.5
    again, _ = energy_params_equation("e", {k: str(v) for k, v in params.items() if k != "mass"}, 1500.0)
    assert again.chain.recuperation_by_decel_mps2 == 0.5
