"""A run that resumes a saved state (SUMO's ``--load-state``, ``--begin`` at the save time):
its first step's vehicles are that state — the step the saving run booked last (SUMO saves
the state of the step at the save time and cannot save at its end, so the saving run ends a
step later) — so they are seeded there, not booked again. Before (a rehearsal, 2026-11-29),
the live run booked that row as a step with SUMO's stored acceleration, and a vehicle the
saving run had just inserted as a departure again, the FCD replay every vehicle as a
departure: the two halves together booked 243 m and 32 s more than the whole run, and live
and replay differed by up to 23 % per vehicle."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd

pytestmark = pytest.mark.sumo

BUILTIN = Path(__file__).resolve().parent.parent / "sumo_drvpw" / "sim" / "builtin"  # (its city network)
ROUTES = """<routes>
    <vType id="car" vClass="passenger" sigma="0" emissionClass="HBEFA4/PC_petrol_Euro-6d"/>
    <route id="r0" edges="c00c01 c01c02 c02c03 c03c04 c04c14 c14c24"/>
    <route id="r1" edges="c10c11 c11c12 c12c13 c13c14 c14c24"/>
    <flow id="fa" type="car" route="r0" begin="0" end="200" period="10"/>
    <flow id="fb" type="car" route="r1" begin="0" end="200" period="10"/>
</routes>
"""


def _config(d: Path, name: str, begin: float, end: float, extra: str) -> Path:
    (d / name).write_text(f"""<configuration>
    <input><net-file value="{BUILTIN / 'networks' / 'city.net.xml'}"/><route-files value="r.rou.xml"/>{extra}</input>
    <time><begin value="{begin:g}"/><end value="{end:g}"/><step-length value="1"/></time>
    <processing><default.speeddev value="0"/></processing>
</configuration>
""", encoding="utf-8")
    return d / name


def _totals(res) -> pd.DataFrame:
    return res.vehicles.set_index(["vehicle", "equation"])[["distance_m", "time_s", "net_total_j", "traction_total_j"]]


def test_a_run_resumed_from_a_saved_state_adds_up_to_the_whole_run(tmp_path):
    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    eqs = ["vsp_ldv1999", "epa_gasoline_car"]
    state = tmp_path / "state150.xml"
    whole = run_scenario(_config(tmp_path, "whole.sumocfg", 0, 500, ""), None, figures=False, equations=eqs)
    first = run_scenario(_config(tmp_path, "a.sumocfg", 0, 151, ""), None, figures=False, equations=eqs,
                         options=["--save-state.times", "150", "--save-state.files", str(state),
                                  "--save-state.rng", "true", "--save-state.precision", "8"])
    cfg_b = _config(tmp_path, "b.sumocfg", 150, 500, f'<load-state value="{state}"/>')
    fcd = tmp_path / "fcd.xml"
    second = run_scenario(cfg_b, None, figures=False, equations=eqs,
                          options=["--fcd-output", str(fcd), "--precision", "6"])
    both = _totals(first).add(_totals(second), fill_value=0.0)
    ref = _totals(whole)
    assert set(both.index) == set(ref.index) and len(ref) > 40
    both = both.loc[ref.index]
    np.testing.assert_allclose(both[["distance_m", "time_s"]], ref[["distance_m", "time_s"]], atol=0.02)
    np.testing.assert_allclose(both[["net_total_j", "traction_total_j"]], ref[["net_total_j", "traction_total_j"]],
                               rtol=1e-3, atol=50.0)
    assert both["net_total_j"].sum() == pytest.approx(ref["net_total_j"].sum(), rel=1e-4)
    # the resumed run's FCD replayed with its config: the same first-step rule
    replay = process_fcd(fcd, scenario=cfg_b, figures=False, equations=eqs)
    got, live = _totals(replay), _totals(second)
    assert got.index.sort_values().equals(live.index.sort_values())
    np.testing.assert_allclose(got.loc[live.index], live, rtol=1e-4, atol=1.0)


def test_a_user_script_that_starts_sumo_from_a_saved_state_is_seen_to_resume(tmp_path):
    """The saved state given to libsumo.start by the user's own script (no scenario file
    saying so): the Accountant reads SUMO's load-state option, and books as the run does
    (before, the first row was booked again: +54 m in a review, 2026-11-29)."""
    from sumo_drvpw.sim import Accountant, close_sumo, start_sumo

    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    state = tmp_path / "state150.xml"
    run_scenario(_config(tmp_path, "a.sumocfg", 0, 151, ""), None, figures=False, equations=["vsp_ldv1999"],
                 options=["--save-state.times", "150", "--save-state.files", str(state), "--save-state.rng", "true",
                          "--save-state.precision", "8"])
    cfg_b = _config(tmp_path, "b.sumocfg", 150, 300, f'<load-state value="{state}"/>')
    ref = _totals(run_scenario(cfg_b, None, figures=False, equations=["vsp_ldv1999"]))
    conn = start_sumo(["-c", str(_config(tmp_path, "plain.sumocfg", 150, 300, "")), "--load-state", str(state)])
    try:
        acc = Accountant(conn, equations=["vsp_ldv1999"])
        conn.addStepListener(acc)
        while conn.simulation.getTime() < 300 - 1e-9:
            conn.simulationStep()
        got = _totals(acc.result())
    finally:
        close_sumo(conn)
    assert got.index.sort_values().equals(ref.index.sort_values())
    np.testing.assert_allclose(got.loc[ref.index], ref, rtol=1e-9, atol=1e-6)
