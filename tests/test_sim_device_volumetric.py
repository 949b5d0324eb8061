"""sumo_device.csv when the run sets SUMO's ``emissions.volumetric-fuel``: SUMO's emissions
device then writes ``fuel_abs`` in ml, not mg. Real SUMO runs of the same petrol cars with
and without the option."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario

pytestmark = pytest.mark.sumo

REPO = Path(__file__).resolve().parent.parent
NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"


def _run(d: Path, volumetric: bool):
    d.mkdir()
    (d / "r.rou.xml").write_text(
        '<routes><vType id="pc" vClass="passenger" emissionClass="HBEFA4/PC_petrol_Euro-6ab"/>'
        '<flow id="f" type="pc" begin="0" end="60" period="10" departSpeed="0">'
        '<route edges="c00c10 c10c20 c20c30 c30c31 c31c32"/></flow></routes>\n', encoding="utf-8")
    opts = '"--no-warnings", "true", "--device.emissions.probability", "1"' + (
        ', "--emissions.volumetric-fuel", "true"' if volumetric else "")
    (d / "s.toml").write_text(
        f'equations = ["epa_gasoline_car"]\n[sumo]\nnet = "{NET}"\nroutes = ["r.rou.xml"]\n'
        f'begin = 0\nend = 400\nstep_length = 1.0\noptions = [{opts}]\n[outputs]\nfigures = false\n', encoding="utf-8")
    run_scenario(d / "s.toml", d / "o")
    row = pd.read_csv(d / "o" / "sumo_device.csv").set_index("equation").loc["epa_gasoline_car"]
    return row, pd.read_parquet(d / "o" / "vehicles.parquet")


def test_volumetric_fuel_is_read_in_litres(tmp_path):
    """With emissions.volumetric-fuel SUMO's fuel_abs is in ml; it was read as mg and turned
    into litres at petrol's density: SUMO's litres 1/745 of what it booked and the ratio
    662 (rehearsal 2026-11-29, ten petrol cars on a cross: ours 0.263 L, SUMO 0.296 L). Now
    the same SUMO litres as without the option (to SUMO's own density against ours: 0.4 %
    measured), and vehicles.parquet names the column by its unit."""
    mass, vm = _run(tmp_path / "mass", False)
    vol, vv = _run(tmp_path / "vol", True)
    assert mass["vehicles"] == vol["vehicles"] >= 5
    assert vol["ours"] == pytest.approx(mass["ours"], rel=1e-12)
    assert vol["sumo"] == pytest.approx(mass["sumo"], rel=0.02)
    assert 0.5 < vol["ratio"] < 2.0 and "volumetric" in vol["quantity"]
    assert "sumo_fuel_ml" in vv.columns and "sumo_fuel_mg" not in vv.columns
    assert "sumo_fuel_mg" in vm.columns and "sumo_fuel_ml" not in vm.columns
