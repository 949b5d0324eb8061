"""An FCD replay reads a vType's energy carrier as the recorded run did where SUMO's battery
device is on: a vType that writes no emissionClass then runs on SUMO's Energy model
(vehicletype.getEmissionClass reads Energy/default), so the live run books it by the
electric car's chain. The replay answered SUMO's default petrol class and booked the same
cars by the petrol car's fuel chain (found by a rehearsal on SUMO's own test
devices/battery/chargingStations_totalPower2: 0.325 kWh/km live, 28.6 L/100 km replayed)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd

pytestmark = pytest.mark.sumo

NETS = Path(__file__).resolve().parent.parent / "sumo_drvpw" / "sim" / "builtin" / "networks"


def _scenario(d: Path, battery: str) -> Path:
    """Cars of a vType without emissionClass ('plain'), one that asks for the battery device
    ('device'), and a petrol one that writes its class; ``battery``: the config's
    battery-device options."""
    (d / "r.rou.xml").write_text("""<routes>
    <vType id="plain" vClass="passenger" mass="1600"/>
    <vType id="device" vClass="passenger" mass="1600"><param key="has.battery.device" value="true"/></vType>
    <vType id="petrol" vClass="passenger" mass="1600" emissionClass="HBEFA4/PC_petrol_Euro-4"/>
    <flow id="p" type="plain" begin="0" end="30" period="10" departSpeed="max"><route edges="c00c10 c10c20"/></flow>
    <flow id="d" type="device" begin="3" end="33" period="10" departSpeed="max"><route edges="c00c10 c10c20"/></flow>
    <flow id="g" type="petrol" begin="6" end="36" period="10" departSpeed="max"><route edges="c00c10 c10c20"/></flow>
</routes>
""", encoding="utf-8")
    cfg = d / "c.sumocfg"
    cfg.write_text(f"""<configuration>
    <input><net-file value="{NETS / 'city.net.xml'}"/><route-files value="r.rou.xml"/></input>
    {battery}
    <time><begin value="0"/><end value="150"/></time>
    <report><no-warnings value="true"/></report>
</configuration>
""", encoding="utf-8")
    return cfg


@pytest.mark.parametrize("battery,electric", [
    ('<battery><device.battery.probability value="1"/></battery>', {"plain", "device"}),
    ("", {"device"}),
], ids=["every-vehicle", "param-only"])
def test_the_replay_books_battery_device_cars_as_the_live_run(tmp_path, battery, electric):
    cfg = _scenario(tmp_path, battery)
    fcd = tmp_path / "fcd.xml"
    live = run_scenario(cfg, None, end=150, figures=False, options=["--fcd-output", str(fcd), "--precision", "6"])
    rep = process_fcd(fcd, scenario=cfg, end=150, figures=False)
    for res in (live, rep):
        v = res.vehicles
        chains = v[v.equation.isin(["bmw_i3_battery", "epa_gasoline_car"])]
        by_type = chains.groupby("vtype").equation.unique().map(sorted).to_dict()
        assert by_type == {t: ["bmw_i3_battery"] if t in electric else ["epa_gasoline_car"]
                           for t in ("plain", "device", "petrol")}, by_type
    a = live.vehicles.set_index(["vehicle", "equation"]).sort_index()
    b = rep.vehicles.set_index(["vehicle", "equation"]).sort_index()
    assert (a.index == b.index).all()
    for c in ("traction_total_j", "net_total_j", "distance_m"):
        np.testing.assert_allclose(b[c], a[c], rtol=1e-4, atol=1.0, err_msg=c)
