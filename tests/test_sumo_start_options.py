"""SUMO's own regression tests write ``--no-step-log`` on their command line
(tests/sumo/devices/emissions/energy_radial_drag/options.sumo: ``--no-step-log -b 0
--no-duration-log …``); given as a scenario's ``sumo.options`` it must not be set twice
(SUMO refuses a second value: "A value for the option 'no-step-log' was already set")."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario

REPO = Path(__file__).resolve().parents[1]
HW_NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "highway.net.xml"


@pytest.mark.parametrize("opts", [["--no-step-log"], ["--no-step-log", "true", "--no-duration-log"],
                                  ["--no-step-log=true"], ["--remote-port=0"]])
def test_a_scenario_may_give_no_step_log_itself(tmp_path, opts):
    """The options as SUMO's tests write them run, and book the car as without them; so does
    --remote-port=0 (the plug-in adds --remote-port 0 in-process unless it is given)."""
    (tmp_path / "r.rou.xml").write_text(
        '<routes><vehicle id="v" depart="0" departSpeed="max"><route edges="e01 e12"/></vehicle></routes>', encoding="utf-8")
    q = ", ".join(f'"{o}"' for o in opts)
    (tmp_path / "s.toml").write_text(
        f'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "{HW_NET}"\nroutes = ["r.rou.xml"]\nend = 20\n'
        f'options = ["--no-warnings", "true", {q}]\n[outputs]\nfigures = false\n', encoding="utf-8")
    run_scenario(tmp_path / "s.toml", tmp_path / "o")
    got = pd.read_parquet(tmp_path / "o" / "vehicles.parquet")
    assert list(got.vehicle) == ["v"] and (got.distance_m > 100).all()
