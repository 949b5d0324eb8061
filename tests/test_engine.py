"""The Dask engine (issue #14): the same statistics as the local engine, to 1e-9.

Runs a real ``distributed.LocalCluster`` of 2 worker processes (the statistics are
pickled across processes, as on a cluster); skipped when Dask is not installed
(``pip install 'sumo-drvpw[dask]'``).
"""

import os
import signal
import time
from functools import partial

import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.log import bundled_log
from sumo_drvpw.data.measured import resolve_equations
from sumo_drvpw.data.stream import plan
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.calibrate import CANDIDATES
from sumo_drvpw.fit.engine import run
from sumo_drvpw.fit.stream import CalibrationStats, calibrate_from_stats
from sumo_drvpw.fit.stream_compare import CompareStats
from sumo_drvpw.model.vehicles import load_vehicle

pytest.importorskip("distributed", reason="Dask not installed: pip install 'sumo-drvpw[dask]'")

RTOL = 1e-9


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    """Two files of three trips each (the bundled log per trip, with its own load)."""
    d = tmp_path_factory.mktemp("fleet")
    base = pd.read_parquet(bundled_log())
    for f in range(2):
        frames = []
        for i in range(3):
            df = base.iloc[i:len(base) - i].copy()
            df["trip_id"] = f"f{f}t{i}"
            df["mass_kg"] = df["mass_kg"] + 30.0 * (3 * f + i)
            frames.append(df)
        pd.concat(frames, ignore_index=True).to_parquet(d / f"log{f}.parquet", row_group_size=5000)
    return d


@pytest.fixture(scope="module")
def cluster():
    from distributed import LocalCluster

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                      dashboard_address=":0") as c:
        yield c.scheduler_address


def test_dask_calibration_equals_local(fleet, cluster):
    cands = CANDIDATES["indt-var-2"]
    veh = load_vehicle("prius3")
    parts = plan([fleet], part_rows=15_000)  # several Parts per file, cut at trip starts
    assert len(parts) >= 4
    loc, _ = run([fleet], partial(CalibrationStats, cands), veh, parts=parts)
    dsk, info = run([fleet], partial(CalibrationStats, cands), veh, engine="dask",
                    scheduler=cluster, parts=parts)
    assert info.engine == "dask" and info.rows == loc.rows
    a, b = calibrate_from_stats(loc), calibrate_from_stats(dsk)
    assert a.terms == b.terms and a.n == b.n
    for t in a.terms:
        assert b.params[t] == pytest.approx(a.params[t], rel=RTOL)
        assert b.std_err[t] == pytest.approx(a.std_err[t], rel=RTOL)
    assert b.results.bic == pytest.approx(a.results.bic, rel=RTOL)
    assert sorted(dsk.trips) == sorted(loc.trips)


def test_dask_comparison_equals_local(fleet, cluster):
    veh = load_vehicle("prius3")
    eqs = resolve_equations(["drvpw_prius3", "vsp_spec"], veh)
    parts = plan([fleet], part_rows=15_000)
    make = partial(CompareStats, eqs, "drvpw_prius3", 5000)  # reservoir < samples: sampled
    a = run([fleet], make, veh, parts=parts)[0].comparison().to_json()
    b = run([fleet], make, veh, engine="dask", scheduler=cluster, parts=parts)[0].comparison().to_json()
    assert a["settings"]["percentiles"].startswith("estimated")

    def close(x, y):
        if isinstance(x, dict):
            assert set(x) == set(y)
            for k in x:
                close(x[k], y[k])
        elif isinstance(x, list):
            assert len(x) == len(y)
            for u, v in zip(x, y):
                close(u, v)
        elif isinstance(x, float):
            assert y == pytest.approx(x, rel=RTOL, abs=1e-12)
        else:
            assert x == y
    close(a, b)


def test_cli_dask_engine_local_cluster(fleet, tmp_path, capsys):
    outs = {}
    for engine, extra in (("local", []), ("dask", ["--workers", "2"])):
        out = tmp_path / f"{engine}.toml"
        assert cli_main(["calibrate", str(fleet), "--vehicle", "prius3", "--out", str(out),
                         "--engine", engine, *extra]) == 0
        outs[engine] = out
    assert "dask engine:" in capsys.readouterr().err
    from sumo_drvpw.model.equations import load_equation

    a, b = load_equation(str(outs["local"])), load_equation(str(outs["dask"]))
    for t in a.terms:
        assert b.terms[t] == pytest.approx(a.terms[t], rel=RTOL)


def test_unreachable_scheduler_is_a_user_error(fleet, monkeypatch):
    from sumo_drvpw.fit import engine

    monkeypatch.setattr(engine, "CONNECT_TIMEOUT_S", 1.0)
    with pytest.raises(UserError, match="cannot reach the Dask scheduler"):
        run([fleet], partial(CalibrationStats, ("acc",)), load_vehicle("prius3"), engine="dask",
            scheduler="tcp://127.0.0.1:9")


def test_bad_input_in_a_dask_task_is_one_line(fleet, tmp_path, capfd):
    """A bad log read by a Dask worker comes back as the task's result, not a task failure:
    the user sees the one line naming it, and no worker's "Compute Failed" block."""
    df = pd.read_parquet(bundled_log())
    df.loc[40, "time_s"] = df["time_s"].iloc[10]  # time goes back at row 40
    bad = tmp_path / "bad.parquet"
    df.to_parquet(bad)
    code = cli_main(["calibrate", str(fleet), str(bad), "--vehicle", "prius3", "--engine", "dask",
                     "--workers", "1", "--out", str(tmp_path / "eq.toml")])
    err = capfd.readouterr().err
    lines = [x for x in err.splitlines() if x.strip()]
    assert code == 2 and "Compute Failed" not in err and "Traceback" not in err
    assert [x for x in lines if "error:" in x] == lines[-1:] and "bad.parquet" in lines[-1] and "time_s" in lines[-1]
    assert not (tmp_path / "eq.toml").exists()


@pytest.mark.skipif(not hasattr(signal, "pthread_sigmask"), reason="no signal masks here")
def test_local_cluster_workers_leave_ctrl_c_to_the_driver(capfd):
    """Ctrl-C in a terminal reaches the whole process group. The local cluster's workers
    start with SIGINT blocked, so they neither die with a KeyboardInterrupt traceback above
    the driver's one line nor get restarted; the driver's own mask is as it was."""
    from sumo_drvpw.fit.engine import dask_client

    with dask_client(workers=2) as client:
        before = client.run(os.getpid)
        for pid in before.values():
            os.kill(pid, signal.SIGINT)
        time.sleep(2.0)  # a worker that took it has died (and its nanny started another)
        after = client.run(os.getpid)
    assert after == before
    assert "KeyboardInterrupt" not in capfd.readouterr().err
    assert signal.SIGINT not in signal.pthread_sigmask(signal.SIG_BLOCK, [])
