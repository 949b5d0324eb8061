"""A vType SUMO changes during a trip (a calibrator's type change, as in DLR's Bad Hersfeld
scenario, whose calibrators turn trucks into 'steep_truck' and back): the FCD replay books
on with the new vType's mass as the live run does (found by a rehearsal: the replay kept
the departure's vType and booked 2.5 % less traction for a truck whose steep type was
heavier, without a warning). Checked at the same steps as the live run — every step on a
calibrator's edge — so a replay of the run's own FCD books every vehicle as it did."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from sumo_drvpw.model.equations import Equation
from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd

pytestmark = pytest.mark.sumo

NETS = Path(__file__).resolve().parent.parent / "sumo_drvpw" / "sim" / "builtin" / "networks"
PHYS = Equation("phys", {"acc": 1.0, "grade": 1.0, "aero_rho": 0.25 * 2.23, "roll": 0.01})


def calibrated(d: Path, first: str, second: str, route: str = "c00c10 c10c20", pos: float = 0.0,
               end: float = 200.0) -> Path:
    """A city-net config whose cars (vType 'first', its attributes ``first``) a calibrator on
    their second edge, at ``pos``, makes vType 'second' (attributes ``second``)."""
    (d / "r.rou.xml").write_text(f"""<routes>
    <vType id="first" {first}/>
    <flow id="f" type="first" begin="0" end="60" period="10" departSpeed="max">
        <route edges="{route}"/></flow>
</routes>
""", encoding="utf-8")
    (d / "cal.add.xml").write_text(f"""<additional>
    <vType id="second" {second}/>
    <calibrator id="ca" edge="c10c20" pos="{pos:g}" vTypes="first"><flow begin="0" end="1000" type="second"/></calibrator>
</additional>
""", encoding="utf-8")
    cfg = d / "c.sumocfg"
    cfg.write_text(f"""<configuration>
    <input><net-file value="{NETS / 'city.net.xml'}"/><route-files value="r.rou.xml"/>
        <additional-files value="cal.add.xml"/></input>
    <time><begin value="0"/><end value="{end:g}"/></time>
    <report><no-warnings value="true"/></report>
</configuration>
""", encoding="utf-8")
    return cfg


def _scenario(d: Path) -> Path:
    """Cars of 1600 kg whose calibrator on their second edge makes them vType 'second' (3000 kg)."""
    return calibrated(d, 'vClass="passenger" mass="1600"', 'vClass="passenger" mass="3000"')


@pytest.mark.parametrize("chunk_rows", [None, 97], ids=["whole", "streamed"])
def test_a_vtype_sumo_changes_during_a_trip_replays_as_live(tmp_path, chunk_rows):
    cfg = _scenario(tmp_path)
    live = run_scenario(cfg, None, end=200, equations=[PHYS], figures=False,
                        options=["--fcd-output", str(tmp_path / "fcd.xml"), "--precision", "6"])
    fcd = process_fcd(tmp_path / "fcd.xml", vtype_files=[tmp_path / "r.rou.xml", tmp_path / "cal.add.xml"],
                      net=NETS / "city.net.xml", equations=[PHYS], end=200, figures=False,
                      chunk_rows=chunk_rows)
    assert "type=\"second\"" in (tmp_path / "fcd.xml").read_text(encoding="utf-8")
    a = live.vehicles.set_index("vehicle").sort_index()
    b = fcd.vehicles.set_index("vehicle").sort_index()
    assert len(a) == len(b) == 6 and (a.index == b.index).all()
    # vehicles on a calibrator's edge are read every step, live and replayed: every car
    # changes (read only every TYPE_CHECK_STEPS, the sixth left before a check: 5)
    changed = a.vtype == "second"
    assert live["vtype_changes"] == fcd["vtype_changes"] == changed.sum() == 6
    assert (b.vtype == a.vtype).all() and (b.mass_kg == a.mass_kg).all()
    assert (a.mass_kg[changed] == 3000.0).all() and (a.mass_kg[~changed] == 1600.0).all()
    for c in ("traction_total_j", "traction_acc_j", "traction_grade_j", "net_total_j", "distance_m"):
        np.testing.assert_allclose(b[c], a[c], rtol=1e-4, atol=1.0, err_msg=c)
