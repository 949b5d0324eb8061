"""SUMO's recuperation efficiency by deceleration is the vType param
``recuperationEfficiencyByDecel`` (SUMOXMLDefinitions.cpp; SUMO's own test
tests/sumo/devices/battery/recuperateByDecel writes it): SUMO 1.28 reads that key and
ignores a longer ``recuperationEfficiencyByDeceleration``. ``vtype_energy`` reads the key
SUMO reads, so such a vType is booked and what it cannot express is listed."""

from __future__ import annotations

import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import sumolib

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.energy_params import ENERGY_PARAMS, energy_params_equation
from sumo_drvpw.sim import run_scenario

REPO = Path(__file__).resolve().parents[1]
HW_NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "highway.net.xml"

ROUTES = """<routes>
  <vType id="k" vClass="passenger" emissionClass="Energy/unknown" sigma="0.8" speedDev="0.2">
    {param}
  </vType>
  <flow id="c" type="k" from="e01" to="e56" begin="0" end="30" period="3" departSpeed="max"/>
</routes>"""


def _sumo_wh(d: Path, name: str, param: str) -> float:
    """SUMO's own electricity [Wh] of the flow, from its emission output (60 steps of 1 s)."""
    (d / f"{name}.rou.xml").write_text(ROUTES.format(param=param))
    subprocess.run([sumolib.checkBinary("sumo"), "-n", str(HW_NET), "-r", f"{name}.rou.xml", "-e", "60",
                    "--seed", "3", "--emission-output", f"{name}.xml", "--precision", "6",
                    "--no-step-log", "--no-warnings"], check=True, capture_output=True, cwd=d)
    return sum(float(v.get("electricity")) for ts in ET.parse(d / f"{name}.xml").getroot() for v in ts)


def test_the_key_sumo_reads_is_recuperationEfficiencyByDecel(tmp_path):
    """SUMO 1.28 itself: k = 2 under SUMO's key costs more energy than none (less is
    recuperated, η·exp(−k/|a|)); under the longer key it is exactly none (SUMO does not read
    it). The plug-in reads SUMO's key: a vType writing only it is booked and the note names
    it; the longer key is no Energy-model parameter (SUMO reads none): not booked, and a
    run with it as the only such vType is refused, saying so."""
    none = _sumo_wh(tmp_path, "none", '<param key="constantPowerIntake" value="100"/>')
    short = _sumo_wh(tmp_path, "short", '<param key="recuperationEfficiencyByDecel" value="2"/>')
    long_ = _sumo_wh(tmp_path, "long", '<param key="recuperationEfficiencyByDeceleration" value="2"/>')
    assert short > none * 1.01
    assert long_ == pytest.approx(none, rel=1e-9)
    assert "recuperationEfficiencyByDecel" in ENERGY_PARAMS
    assert "recuperationEfficiencyByDeceleration" not in ENERGY_PARAMS
    _, notes = energy_params_equation("x", {"recuperationEfficiencyByDecel": "2"}, 1500.0, "f: vType 'x'")
    assert any(n.startswith("recuperationEfficiencyByDecel 2: ") for n in notes)
    _, notes = energy_params_equation("x", {"recuperationEfficiencyByDeceleration": "2"}, 1500.0, "f")
    assert not any("ByDecel" in n for n in notes)
    # a run: the vType with SUMO's key only is booked, and what it cannot carry is listed
    (tmp_path / "s.toml").write_text(
        f'equations = ["vtype_energy"]\n[sumo]\nnet = "{HW_NET}"\nroutes = ["short.rou.xml"]\nend = 60\n'
        'options = ["--no-warnings", "true", "--seed", "3"]\n[outputs]\nfigures = false\n')
    res = run_scenario(tmp_path / "s.toml")
    booked = res["assumptions"]["vtype_energy"]["booked"]
    assert any(n.startswith("recuperationEfficiencyByDecel 2: ") for n in booked["k"]["not_expressed"])
    (tmp_path / "s.toml").write_text((tmp_path / "s.toml").read_text().replace("short.rou", "long.rou"))
    with pytest.raises(UserError, match="no vType .* writes SUMO's Energy model .*k: writes no Energy-model"):
        run_scenario(tmp_path / "s.toml")
