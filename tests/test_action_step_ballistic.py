"""A vType with its own action step length makes SUMO move every vehicle by the ballistic
update when step-method.ballistic is not given (MSVehicleType::check, SUMO 1.28: "Action
step length '1.00' is used for vehicle type … but step-method.ballistic was not set.
Setting it now"). The plug-in followed only the option and default.action-step-length, so
such a run was booked as Euler (a rehearsal: summary step_method euler, 2,078 of 2,670
position reads wrong, traction +0.3 %, recuperation per vehicle up to 3 % off at 0.5-s steps
with actionStepLength 1). It now asks each vehicle's vType, live and replayed, and books
the run as SUMO moved it: the same as the run with the ballistic update given."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd
from sumo_drvpw.sim.sumo_start import action_step_switches

pytestmark = pytest.mark.sumo

NETS = Path(__file__).resolve().parent.parent / "sumo_drvpw" / "sim" / "builtin" / "networks"


def test_which_action_step_lengths_switch():
    assert action_step_switches(1.0, 0.5) and action_step_switches(2.0, 1.0)
    assert not action_step_switches(1.0, 1.0) and not action_step_switches(0.3, 1.0)  # (≤ a step: one step)


def _scenario(d: Path, ballistic: str, asl: str = 'actionStepLength="1.0"') -> Path:
    """The type with the action step departs first: SUMO switches as it builds it, at the
    start, so its whole run moves as one given the ballistic update."""
    (d / "r.rou.xml").write_text(f"""<routes>
    <vType id="plain" vClass="passenger" sigma="0.5"/>
    <vType id="slow" vClass="passenger" sigma="0.5" {asl}/>
    <flow id="s" type="slow" begin="0" end="40" period="4" departSpeed="max"><route edges="c00c10 c10c20"/></flow>
    <flow id="p" type="plain" begin="2" end="60" period="4" departSpeed="max"><route edges="c00c10 c10c20"/></flow>
</routes>
""", encoding="utf-8")
    cfg = d / f"c{len(ballistic)}{len(asl)}.sumocfg"
    cfg.write_text(f"""<configuration>
    <input><net-file value="{NETS / 'city.net.xml'}"/><route-files value="r.rou.xml"/></input>
    <time><begin value="0"/><end value="150"/><step-length value="0.5"/></time>
    <processing>{ballistic}<default.speeddev value="0"/></processing>
    <random_number><seed value="7"/></random_number>
    <report><no-warnings value="true"/></report>
</configuration>
""", encoding="utf-8")
    return cfg


def _per_vehicle(res):
    v = res.vehicles.set_index(["vehicle", "equation"]).sort_index()
    return v[["traction_total_j", "recup_total_j", "distance_m"]]


def test_a_vtype_action_step_books_the_run_ballistic_live_and_replayed(tmp_path):
    given = run_scenario(_scenario(tmp_path, '<step-method.ballistic value="true"/>'), None, end=150,
                         figures=False)
    fcd = tmp_path / "fcd.xml"
    cfg = _scenario(tmp_path, "")
    live = run_scenario(cfg, None, end=150, figures=False,
                        options=["--fcd-output", str(fcd), "--precision", "6"])
    rep = process_fcd(fcd, scenario=cfg, end=150, figures=False)
    assert given.summary["step_method"] == live.summary["step_method"] == rep.summary["step_method"] == "ballistic"
    ref = _per_vehicle(given)
    assert len(ref) > 10
    for res in (live, rep):
        got = _per_vehicle(res)
        assert got.index.equals(ref.index)
        np.testing.assert_allclose(got.to_numpy(), ref.to_numpy(), rtol=1e-5, atol=1e-3)
    # without the action step length the run stays Euler (and books otherwise)
    euler = run_scenario(_scenario(tmp_path, "", asl=""), None, end=150, figures=False)
    assert euler.summary["step_method"] == "euler"
    json.dumps(live.summary)


@pytest.mark.parametrize("ballistic", [True, False])
def test_a_tabular_fcd_without_a_header_is_replayed_by_the_method_its_rows_show(tmp_path, ballistic):
    """SUMO's CSV FCD has no header: replayed without the run's config, a ballistic run was
    booked as Euler, without a word (a rehearsal, 2026-11-29: distance +0.4 %, energy up to
    +0.7 %, per vehicle up to 1 %). Now the rows tell — the step's distance is the mean of its
    two speeds × Δt, or the new speed × Δt — and the replay equals the live run, and says so."""
    from sumo_drvpw.sim.fcd_method import method_of_rows
    from sumo_drvpw.sim.fcd_read import read_fcd

    opt = '<step-method.ballistic value="true"/>' if ballistic else ""
    cfg = _scenario(tmp_path, opt, asl="")
    csv = tmp_path / "fcd.csv"
    live = run_scenario(cfg, None, end=150, figures=False, options=["--fcd-output", str(csv), "--precision", "6"],
                        equations=["vsp_ldv1999", "epa_gasoline_car"])
    assert live.summary["step_method"] == ("ballistic" if ballistic else "euler")
    rep = process_fcd(csv, net=NETS / "city.net.xml", vtype_files=[tmp_path / "r.rou.xml"], figures=False,
                      equations=["vsp_ldv1999", "epa_gasoline_car"])
    assert rep.summary["step_method"] == live.summary["step_method"]
    said = [w for w in rep.summary.get("warnings", []) if "replayed as ballistic" in w]
    assert bool(said) == ballistic, rep.summary.get("warnings")
    got, ref = _per_vehicle(rep), _per_vehicle(live)
    assert got.index.equals(ref.index) and len(ref) > 10
    np.testing.assert_allclose(got.to_numpy(), ref.to_numpy(), rtol=1e-5, atol=1e-3)
    df = read_fcd(csv)  # every other row: rows sparser than the step tell nothing
    assert method_of_rows({k: df[k].to_numpy() for k in df.columns}, None) == live.summary["step_method"]
    sparse = df[np.isin(df["time"], np.unique(df["time"])[::2])]
    assert method_of_rows({k: sparse[k].to_numpy() for k in sparse.columns}, None) is None
