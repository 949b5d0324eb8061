"""SUMO's Energy model with riding persons: (m + riders + m_rot)·v̄·a, the rotating mass
rotatingMass not growing with the riders (HelpersEnergy: getTotalMass plus rotatingMass).
``vtype_energy`` books an e-bus whose riders board and leave at its stops as SUMO's emission
output does, live and replayed."""

from __future__ import annotations


import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.sim import run_scenario
from sumo_probe import build_net, emitted_wh, energy_scenario

PERSONS = "".join(f'<person id="p{i}" depart="0" departPos="{151 + i % 28}"><ride from="e" busStop="{"bs2" if i % 2 else "bs3"}" lines="b"/></person>'
                  for i in range(30))
ROUTES = """<routes>
  <vType id="ebus" vClass="bus" mass="13000" emissionClass="Energy/unknown" personCapacity="80" accel="1.2">
    <param key="rotatingMass" value="1500"/><param key="constantPowerIntake" value="4000"/>
    <param key="radialDragCoefficient" value="0"/>
  </vType>
  {persons}
  <vehicle id="b" type="ebus" depart="0" departSpeed="0"><route edges="e"/>
    <stop busStop="bs" duration="20"/><stop busStop="bs2" duration="15"/><stop busStop="bs3" duration="10"/></vehicle>
</routes>"""


def test_energy_bus_riders_as_sumo(tmp_path):
    """A flat road of 2 km at 0.5-s steps: 30 persons board the e-bus at its first stop and
    leave at the second and third. Its rotating mass (1500 kg) does not grow with the 2.1 t
    of riders in SUMO; the bus as SUMO's emission output to 1e-6, live and replayed (measured
    2026-11-27 before the fix, when the acc coefficient 1 + m_rot/m scaled the riders too:
    1583.48 against SUMO's 1582.50 Wh, +6.2e-4)."""
    build_net(tmp_path, '<nodes><node id="a" x="0" y="0"/><node id="c" x="2000" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="c" numLanes="1" speed="14"/></edges>')
    (tmp_path / "r.rou.xml").write_text(ROUTES.format(persons=PERSONS), encoding="utf-8")
    (tmp_path / "a.add.xml").write_text('<additional><busStop id="bs" lane="e_0" startPos="150" endPos="180"/>'
                                        '<busStop id="bs2" lane="e_0" startPos="900" endPos="930"/>'
                                        '<busStop id="bs3" lane="e_0" startPos="1600" endPos="1630"/></additional>', encoding="utf-8")
    energy_scenario(tmp_path, 300, additional="a.add.xml")
    res = run_scenario(tmp_path / "s.toml", tmp_path / "o")
    assert res["assumptions"]["vtype_energy"]["booked"]["ebus"]["mass"] == "the vehicle's (riders included)"
    assert res["transportables"]["max_kg"] == 2100.0  # the 30 riders boarded (SUMO's 70 kg each)
    sumo_wh, nan = emitted_wh(tmp_path / "em.xml", 0.5)
    assert not nan
    assert cli_main(["fcd", str(tmp_path / "fcd.xml"), "--scenario", str(tmp_path / "s.toml"),
                     "--out", str(tmp_path / "fcd"), "--no-figures"]) == 0
    for out in ("o", "fcd"):
        cv = pd.read_csv(tmp_path / out / "chain_vehicles.csv").set_index("key")
        assert list(cv.index) == ["b"]
        assert cv.loc["b", "net_kwh"] * 1000.0 == pytest.approx(sumo_wh["b"], rel=1e-6), out
    # the same FCD without x, y (fcd-output.attributes without them): riders cannot be matched
    # to the bus, said in a warning (before: booked without them, silently — a rehearsal)
    import json
    import re

    bare = re.sub(r' (x|y)="[^"]*"', "", (tmp_path / "fcd.xml").read_text(encoding="utf-8"))
    (tmp_path / "bare.xml").write_text(bare, encoding="utf-8")
    assert cli_main(["fcd", str(tmp_path / "bare.xml"), "--scenario", str(tmp_path / "s.toml"),
                     "--out", str(tmp_path / "bare"), "--no-figures"]) == 0
    warn = json.loads((tmp_path / "bare" / "summary.json").read_text(encoding="utf-8")).get("warnings", [])
    assert any("person rows without x, y" in w and "riders' mass is not booked" in w for w in warn), warn
    assert not any("without x, y" in w for w in json.loads((tmp_path / "fcd" / "summary.json").read_text(encoding="utf-8")).get("warnings", []))
    cv = pd.read_csv(tmp_path / "bare" / "chain_vehicles.csv").set_index("key")
    assert cv.loc["b", "net_kwh"] * 1000.0 < sumo_wh["b"] * (1 - 1e-3)  # (the riders' 2.1 t missing)
