"""``vtype_energy`` on the vTypes public SUMO scenarios write (sim/vtype_energy.py): SUMO's
own battery tests (tests/sumo/devices/battery/… of eclipse-sumo/sumo) give Energy-model
parameters without an emissionClass and switch the battery device on, which makes SUMO
1.28 run them on its Energy model ("The emission class Energy/unknown will be used");
others write the bare ``emissionClass="Energy"``. Both are SUMO's Energy model and are
booked; a vType without an emissionClass and without the battery device is not."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.vtype_energy import vtype_equations
from sumo_drvpw.sim.vtypes import read_vtypes

REPO = Path(__file__).resolve().parent.parent
HW_NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "highway.net.xml"

#: the Energy-model parameters of SUMO's test tests/sumo/devices/battery/braunschweig
#: (its vType PKW: no emissionClass)
PARAMS = """<param key="vehicleMass" value="1600"/><param key="internalMomentOfInertia" value="30"/>
    <param key="frontSurfaceArea" value="2.2"/><param key="airDragCoefficient" value="0.33"/>
    <param key="radialDragCoefficient" value="0"/><param key="rollDragCoefficient" value="0.1"/>
    <param key="constantPowerIntake" value="40"/><param key="propulsionEfficiency" value="0.8"/>
    <param key="recuperationEfficiency" value="0.8"/>"""

ROUTES = f"""<routes>
  <vType id="own_device" vClass="passenger" sigma="0.5">
    <param key="has.battery.device" value="true"/>{PARAMS}</vType>
  <vType id="bare_energy" vClass="passenger" emissionClass="Energy" sigma="0.5">{PARAMS}</vType>
  <vType id="no_device" vClass="passenger" sigma="0.5">{PARAMS}</vType>
  <flow id="a" type="own_device" from="e01" to="e56" begin="0" end="30" period="10" departSpeed="0"/>
  <flow id="b" type="bare_energy" from="e01" to="e56" begin="5" end="35" period="10" departSpeed="0"/>
</routes>"""


class _Options:
    """A scenario whose SUMO options give ``device.battery.probability``."""

    def __init__(self, p):
        self.sumo_args = ["--device.battery.probability", str(p)]


def test_vtypes_sumo_runs_on_its_energy_model_are_booked(tmp_path):
    """No emissionClass with param has.battery.device, and emissionClass "Energy": booked;
    no emissionClass without the battery device: not, and the listing says why; with the
    SUMO option device.battery.probability 1 it is (every vehicle has the device), with
    0.5 not (SUMO's model differs per vehicle)."""
    f = tmp_path / "r.rou.xml"
    f.write_text(ROUTES, encoding="utf-8")
    vt = read_vtypes([f])
    assert vt["own_device"].battery_device and not vt["no_device"].battery_device
    eqs, listing = vtype_equations(vt)
    assert [e.name for e in eqs] == ["vtype_energy.own_device", "vtype_energy.bare_energy"]
    assert "no battery device" in listing["not_booked"]["no_device"]
    assert listing["booked"]["own_device"]["emission_class"].startswith("none written")
    assert listing["booked"]["bare_energy"]["emission_class"] == "Energy"
    for e in eqs:  # the parameters read as written: 1600 kg, rotating mass 30 kg
        assert e.terms["acc"] == pytest.approx(1 + 30 / 1600) and e.chain.aux_power_w == 40.0
    eqs, _ = vtype_equations(vt, _Options(1))
    assert [e.name for e in eqs][-1] == "vtype_energy.no_device"
    eqs, _ = vtype_equations(vt, _Options(0.5))
    assert "vtype_energy.no_device" not in [e.name for e in eqs]


def test_battery_device_vtypes_agree_with_sumos_device(tmp_path):
    """Run on the straight highway, 60 steps of 1 s, beside SUMO's emissions device: the
    vType without emissionClass but with the battery device and the one of emissionClass
    "Energy" are each booked by their own parameters, battery kWh within 1 % of SUMO's
    electricity per equation (measured 2026-11-27: 0.9997 and 0.9993; what remains is the
    steps of departure and arrival). Before, neither was booked and vtype_energy, the
    run's only equation, was refused."""
    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["vtype_energy"]\n[sumo]\nnet = "{HW_NET}"\nroutes = ["r.rou.xml"]\nend = 60\n'
        'step_length = 1\noptions = ["--no-warnings", "true"]\n[outputs]\nsumo_device = true\nfigures = false\n',
        encoding="utf-8")
    res = run_scenario(tmp_path / "s.toml", tmp_path / "o")
    cmp = pd.read_csv(tmp_path / "o" / "sumo_device.csv").set_index("equation")
    assert sorted(cmp.index) == ["vtype_energy.bare_energy", "vtype_energy.own_device"]
    for eq in cmp.index:
        assert cmp.loc[eq, "vehicles"] >= 3
        assert cmp.loc[eq, "ratio"] == pytest.approx(1.0, abs=0.01), eq
    v = res.vehicles
    assert set(v[v.equation == "vtype_energy.own_device"].vtype) == {"own_device"}
