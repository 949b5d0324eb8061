"""SUMO sweeps (#14): `run A B … --engine dask` runs each scenario as one task (one SUMO)
on a Dask cluster; its energy tables equal those of `--jobs 1`. Real SUMO, real Dask."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main

pytestmark = pytest.mark.sumo

NETS = Path(__file__).resolve().parent.parent / "sumo_drvpw" / "sim" / "builtin" / "networks"


def _scenarios(tmp_path: Path) -> list[str]:
    """Three short city runs that differ by their SUMO seed (a seed sweep)."""
    (tmp_path / "r.rou.xml").write_text(
        '<routes>\n  <vType id="car" vClass="passenger" mass="1500" sigma="0.5"/>\n'
        '  <flow id="f" type="car" from="c00c10" to="c34c44" begin="0" end="60" '
        'period="exp(0.2)"/>\n  <flow id="g" type="car" from="c44c43" to="c00c01" begin="0" '
        'end="60" period="exp(0.2)"/>\n</routes>\n', encoding="utf-8")
    out = []
    for seed in (1, 2, 3):
        p = tmp_path / f"seed{seed}.toml"
        p.write_text(
            f'equations = ["vsp_ldv1999", "drvpw_prius3"]\n[sumo]\nnet = "{NETS / "city.net.xml"}"\n'
            f'routes = ["r.rou.xml"]\nend = 90\n'
            f'options = ["--no-warnings", "true", "--seed", "{seed}"]\n[outputs]\nfigures = false\n',
            encoding="utf-8")
        out.append(str(p))
    return out


def test_run_on_a_local_dask_cluster_equals_jobs_1(tmp_path):
    """--engine dask --workers 2: the same vehicles, edges, classes and runs.csv as --jobs 1
    (exactly: each run is the same deterministic SUMO run, only elsewhere)."""
    pytest.importorskip("distributed")
    scen = _scenarios(tmp_path)
    assert cli_main(["run", *scen, "--jobs", "1", "--out", str(tmp_path / "one")]) == 0
    assert cli_main(["run", *scen, "--engine", "dask", "--workers", "2",
                     "--out", str(tmp_path / "dask")]) == 0
    a = pd.read_csv(tmp_path / "one" / "runs.csv")
    b = pd.read_csv(tmp_path / "dask" / "runs.csv")
    pd.testing.assert_frame_equal(a, b, check_exact=True)
    assert a.scenario.unique().tolist() == ["seed1", "seed2", "seed3"]
    for n in ("seed1", "seed2", "seed3"):
        for t in ("vehicles", "edges", "classes"):
            x = pd.read_parquet(tmp_path / "one" / n / f"{t}.parquet")
            y = pd.read_parquet(tmp_path / "dask" / n / f"{t}.parquet")
            pd.testing.assert_frame_equal(x, y, check_exact=True)
        s = json.loads((tmp_path / "dask" / n / "summary.json").read_text(encoding="utf-8"))
        assert s["vehicles"] > 5
    # the seeds make different runs (a sweep, not three copies)
    v = [pd.read_parquet(tmp_path / "one" / n / "vehicles.parquet").traction_total_j.sum()
         for n in ("seed1", "seed2", "seed3")]
    assert len(set(v)) == 3


def test_engine_dask_without_dask_is_one_line(tmp_path, capsys, monkeypatch):
    """Without Dask installed, --engine dask says how to get it (exit 2, nothing written)."""
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed → ImportError
    code = cli_main(["run", "city", "--engine", "dask", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "pip install 'sumo-drvpw[dask]'" in err
    assert not (tmp_path / "o").exists()
    code = cli_main(["run", "city", "--workers", "2", "--out", str(tmp_path / "o")])
    assert code == 2 and "--workers goes with --engine dask" in capsys.readouterr().err


def test_a_bad_scenario_in_a_sweep_is_refused_before_any_runs(tmp_path, capsys, monkeypatch):
    """A sweep of a good and a bad scenario (--end before the second's begin) ran the good
    one to the end, then refused the bad one and discarded everything: every scenario is
    now checked first, so the refusal costs no simulation."""
    import sumo_drvpw.sim.run as run_mod

    good = _scenarios(tmp_path)[0]
    bad = tmp_path / "late.toml"
    bad.write_text(Path(good).read_text(encoding="utf-8").replace("end = 90", "begin = 3600"), encoding="utf-8")
    ran = []
    monkeypatch.setattr(run_mod, "_sweep_task", lambda *a, **k: ran.append(a) or {})
    code = cli_main(["run", good, str(bad), "--end", "60", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert code == 2 and "late.toml" in err and "the run's end (60 s) is not after sumo.begin (3600 s)" in err, err
    assert ran == [] and not (tmp_path / "o").exists()
