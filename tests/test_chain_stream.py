"""Streamed `calibrate --target battery|fuel` (fit/chain_stream.py): the same equation as
the in-memory path to 1e-9 relative.

The planted logs of tests/test_stream_chain.py (several trips in a Parquet file with small
row groups and a CSV; battery: a charging stop, a heater load unknown on one trip, the
ambient temperature of an HVAC; fuel: a hybrid battery's V·I, engine-off and engine-on
speed planted) are calibrated with ``--engine memory`` and streamed in batches of 2,000
rows (every trip crosses chunk boundaries); every number of the two equation files is
compared, the recuperation limits found from streamed bin counts and the quantile bins'
values included. With the road load calibrated stepwise first, on a synthetic Prius 3 log
with a measured driving power, the road load's terms too.
"""

import json
import tomllib
from functools import partial

import numpy as np
import pytest

import corpus
import test_stream_chain as planted
import sumo_drvpw.fit.engine as engine_mod
from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.fit import chain_stream
from sumo_drvpw.fit.chain_quantiles import _keys, quantile_of_order

RTOL = 1e-9
_RUN = engine_mod.run
chain_logs = planted.chain_logs  # the module's fixture: the planted battery and fuel logs


def _calibrate(monkeypatch, capsys, log, out, engine, *extra, rows=2000):
    monkeypatch.setattr(engine_mod, "run", partial(_RUN, rows=rows))
    rc = cli_main(["calibrate", str(log), "--out", str(out), "--name", "chain", "--engine", engine, *extra])
    cap = capsys.readouterr()
    monkeypatch.undo()
    assert rc == 0, cap.err
    said = [ln for ln in cap.out.splitlines() if not ln.startswith("wrote")]
    return _undated(out), cap, said


def _undated(path) -> dict:
    """An equation file's document without the time it was written."""
    doc = tomllib.loads(path.read_text(encoding="utf-8"))
    doc.get("provenance", {}).pop("date", None)
    return doc


def test_quantiles_of_order_statistics_are_numpys():
    rng = np.random.default_rng(3)
    for n in (21, 22, 100, 1001, 4096, 77777):
        a = rng.lognormal(9.0, 1.0, n)
        a[: n // 10] = a[0]  # ties
        s = np.sort(a)
        for q in (0.5, 0.7, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995):
            assert quantile_of_order(lambda i: float(s[i]), n, q) == float(np.quantile(a, q))
    # the bins are monotone in the value: the order statistics are found bin by bin
    x = np.sort(rng.lognormal(9.0, 2.0, 5000))
    assert np.all(np.diff(_keys(x)) >= 0)


@pytest.mark.parametrize("kind", ["battery", "fuel"])
def test_streamed_chain_calibration_equals_in_memory(chain_logs, kind, tmp_path, monkeypatch, capsys):
    folder, eq, _ = chain_logs[kind]
    extra = ["--target", kind, "--equation", str(eq)]
    if kind == "battery":
        extra += ["--load", "heater_power_w", "--hvac", "ambient_c:20"]
    ref, cm, said_m = _calibrate(monkeypatch, capsys, folder, tmp_path / "memory.toml", "memory", *extra,
                                 "--report", str(tmp_path / "rep_memory"))
    got, cl, said_l = _calibrate(monkeypatch, capsys, folder, tmp_path / "local.toml", "local", *extra,
                                 "--report", str(tmp_path / "rep_local"))
    assert "local engine:" in cl.err and "local engine:" not in cm.err
    corpus.assert_close_documents(ref, got, RTOL)
    # the report: every number of report.json (the chain against the measured power, per trip)
    rep = {e: json.loads((tmp_path / f"rep_{e}" / "report.json").read_text(encoding="utf-8")) for e in ("memory", "local")}
    assert rep["local"]["settings"].pop("percentiles") == "exact"
    corpus.assert_close_documents(rep["memory"], rep["local"], RTOL)
    ch = got["chain"]
    if kind == "battery":  # what was planted (BATTERY_EQ), through the streamed fit
        assert ch["traction_efficiency"] == pytest.approx(0.88, rel=0.03)
        assert ch["loads"]["heater_power_w"] == pytest.approx(1.0, rel=0.1)
        # the scan (the quantile bins and the limits' factors on the arrays it kept), the report
        assert cl.err.count("local engine:") == 2
        assert "left out of the fit" in cl.out  # the heater unknown on B4
    else:
        assert ch["engine_off_below_w"] == 4000.0 and ch["engine_on_above_mps"] == pytest.approx(19.0, abs=3.0)
        assert ch["marginal_efficiency"] == pytest.approx(0.34 * 0.92, rel=0.1)  # η_m·η_t planted
        # the charge-sustaining form, with an auxiliary draw (the planted 300 W, carried by the
        # battery standing; its size also takes the η_t the fit has not: tests/test_chain.py)
        assert ch["charge_sustaining"] and ch["aux_power_w"] > 100.0
    # the console says the same (but the engine's resource line)
    assert said_l == said_m


def test_streamed_chain_with_held_parameters_equals_in_memory(chain_logs, tmp_path, monkeypatch, capsys):
    """``--fix``: a logged load's gain, an HVAC gain and the auxiliary draw held at the planted
    values (BATTERY_EQ), the recuperation limit profiled: streamed (the held part taken off
    the factors, fit/chain_fixed.py) = in memory (off the target, row by row) to 1e-9."""
    folder, eq, _ = chain_logs["battery"]
    extra = ["--target", "battery", "--equation", str(eq), "--load", "heater_power_w", "--hvac", "ambient_c:20",
             "--fix", "loads.heater_power_w=1", "--fix", "hvac.cooling_w_per_k=40", "--fix", "aux_power_w=450"]
    ref, _, said_m = _calibrate(monkeypatch, capsys, folder, tmp_path / "memory.toml", "memory", *extra)
    got, cl, said_l = _calibrate(monkeypatch, capsys, folder, tmp_path / "local.toml", "local", *extra)
    corpus.assert_close_documents(ref, got, RTOL)
    ch = got["chain"]
    assert ch["loads"]["heater_power_w"] == 1.0 and ch["hvac"]["cooling_w_per_k"] == 40.0
    assert ch["aux_power_w"] == 450.0 and ch["traction_efficiency"] == pytest.approx(0.88, rel=0.03)
    assert ch["provenance"]["fixed"] == {"loads.heater_power_w": 1.0, "hvac.cooling_w_per_k": 40.0,
                                         "aux_power_w": 450.0}
    assert cl.err.count("local engine:") == 1 and said_l == said_m


def test_streamed_chain_on_a_stepwise_road_load_equals_in_memory(tmp_path, monkeypatch, capsys):
    """No --equation: the road load calibrated stepwise in the same pass (the chain's input
    is the log's measured driving power), the chain after it: both equal the in-memory ones."""
    from sumo_drvpw.synth.effects import BatteryLog, synth_trips

    df, _ = synth_trips(n_trips=3, minutes=8.0, seed=3, effects=[BatteryLog()])
    log = tmp_path / "prius3.parquet"
    df.drop(columns=["phase"]).to_parquet(log, row_group_size=1500)
    extra = ["--vehicle", "prius3", "--target", "battery"]
    ref, cm, said_m = _calibrate(monkeypatch, capsys, log, tmp_path / "memory.toml", "memory", *extra)
    got, cl, said_l = _calibrate(monkeypatch, capsys, log, tmp_path / "local.toml", "local", *extra, rows=3000)
    corpus.assert_close_documents(ref, got, RTOL)
    assert got["terms"] and got["chain"]["provenance"]["chain_input"].startswith("measured driving power")
    assert cl.err.count("local engine:") == 1  # the scan; the later passes on the arrays it kept
    assert said_l == said_m
    # nothing kept (logs beyond KEEP_BYTES): the quantile bins and the limits' factors read the logs again
    monkeypatch.setattr(chain_stream, "KEEP_BYTES", 0)
    again, cl, said_l = _calibrate(monkeypatch, capsys, log, tmp_path / "again.toml", "local", *extra, rows=3000)
    assert cl.err.count("local engine:") == 3 and said_l == said_m
    corpus.assert_close_documents(ref, again, RTOL)


def test_streamed_chain_refuses_what_the_in_memory_path_refuses(chain_logs, tmp_path, capsys):
    """A load column no file has, and a battery current whose sign is flipped: exit 2 with
    the in-memory path's words, nothing written."""
    folder, eq, _ = chain_logs["battery"]
    for engine in ("memory", "local"):
        out = tmp_path / f"{engine}.toml"
        assert cli_main(["calibrate", str(folder), "--target", "battery", "--equation", str(eq), "--load",
                         "seat_heater_w", "--out", str(out), "--engine", engine]) == 2
        assert "2 files: no load column 'seat_heater_w'" in capsys.readouterr().err and not out.exists()
    flipped = planted.flipped_current(folder, tmp_path / "flipped")
    said = {}
    for engine in ("memory", "local"):
        out = tmp_path / f"flipped_{engine}.toml"
        assert cli_main(["calibrate", str(flipped), "--target", "battery", "--equation", str(eq),
                         "--out", str(out), "--engine", engine]) == 2
        said[engine] = capsys.readouterr().err
        assert "falls where" in said[engine] and not out.exists()
    r = lambda e: e.split("r = ")[1].split(" ")[0]  # noqa: E731
    assert r(said["memory"]) == r(said["local"])


def test_dask_chain_calibration_equals_memory(chain_logs, tmp_path, capsys):
    pytest.importorskip("distributed", reason="Dask not installed: pip install 'sumo-drvpw[dask]'")
    from distributed import LocalCluster

    folder, eq, _ = chain_logs["fuel"]
    docs = {}
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as c:
        for e, more in (("memory", []), ("dask", ["--scheduler", c.scheduler_address])):
            out = tmp_path / f"{e}.toml"
            assert cli_main(["calibrate", str(folder), "--target", "fuel", "--equation", str(eq),
                             "--out", str(out), "--name", "chain", "--engine", e, *more]) == 0
            docs[e] = _undated(out)
    assert "dask engine:" in capsys.readouterr().err
    corpus.assert_close_documents(docs["memory"], docs["dask"], RTOL)


def _mixed_power_folder(chain_logs, tmp_path):
    """The planted battery logs with a driving power (0.9·V·I) logged in a.parquet only (in
    row groups of 700), b.csv as it was: (folder, road-load equation)."""
    import pandas as pd

    folder, eq, _ = chain_logs["battery"]
    mixed = tmp_path / "mixed"
    mixed.mkdir()
    a = pd.read_parquet(folder / "a.parquet")
    a["power_w"] = 0.9 * a["battery_voltage_v"] * a["battery_current_a"]
    a.to_parquet(mixed / "a.parquet", row_group_size=700)
    (mixed / "b.csv").write_bytes((folder / "b.csv").read_bytes())
    return mixed, eq


def _refused_naming_the_files(mixed, eq, tmp_path, capsys, extra):
    """calibrate --target battery on the mixed folder (with the options ``extra``) exits 2
    with one line naming b.csv (no driving power) and a.parquet (direct power_w), writes nothing."""
    out = tmp_path / "eq.toml"
    rc = cli_main(["calibrate", str(mixed), "--target", "battery", "--equation", str(eq), "--out", str(out), *extra])
    err = capsys.readouterr().err
    assert rc == 2, err
    line = [ln for ln in err.splitlines() if ln.startswith("sumo-drvpw calibrate: error: ")]
    assert len(line) == 1 and "Traceback" not in err
    assert f"{mixed / 'b.csv'}: no measured driving power" in line[0]
    assert "direct (power_w)" in line[0] and str(mixed / "a.parquet") in line[0]
    assert not out.exists()


def test_streamed_chain_refuses_files_that_differ_in_their_chain_input(chain_logs, tmp_path, capsys):
    """One file logs a driving power (the chain's input there), the other not (the road
    load's power there): the streamed fit takes one input for all, so it refuses, naming
    the file without it and the file with it (as in memory, below), and writes nothing (in memory the second file's rows would have no
    measured driving power and drop out of the fit)."""
    mixed, eq = _mixed_power_folder(chain_logs, tmp_path)
    _refused_naming_the_files(mixed, eq, tmp_path, capsys, [])


def test_in_memory_chain_refuses_files_that_differ_in_their_chain_input(chain_logs, tmp_path, capsys):
    """The same folder as above with ``--engine memory``: the table read whole has
    ``power_w`` empty on the CSV's rows, which dropped out of the fit silently (the chain
    fitted on the Parquet file alone); refused as streamed, one line naming the file
    without it, nothing written."""
    mixed, eq = _mixed_power_folder(chain_logs, tmp_path)
    for extra in ([], ["--efficiency", "power"]):
        _refused_naming_the_files(mixed, eq, tmp_path, capsys, ["--engine", "memory", *extra])


def test_streamed_battery_only_log_without_equation_is_refused_as_in_memory(chain_logs, tmp_path, capsys):
    """A log with battery V·I but no driving power, a load column it has, no --equation:
    both engines refuse it for the missing road load (not for the load column), nothing written."""
    folder, _, _ = chain_logs["battery"]
    for engine in ("memory", "local"):
        out = tmp_path / f"{engine}.toml"
        assert cli_main(["calibrate", str(folder), "--target", "battery", "--load", "heater_power_w",
                         "--out", str(out), "--engine", engine]) == 2
        err = capsys.readouterr().err
        assert "2 files logs no driving power" in err and "give its road load with --equation" in err, engine
        assert not out.exists()


def test_dask_local_cluster_serves_every_pass(chain_logs, tmp_path, capsys, monkeypatch):
    """--engine dask --workers N: the battery chain's three passes run on one local cluster
    (one started per pass cost its start-up three times), with the memory engine's equation."""
    pytest.importorskip("distributed", reason="Dask not installed: pip install 'sumo-drvpw[dask]'")
    from contextlib import contextmanager

    folder, eq, _ = chain_logs["battery"]
    started = []
    real = engine_mod.dask_client

    @contextmanager
    def counting(scheduler=None, workers=None):
        if scheduler is None:
            started.append(workers)
        with real(scheduler, workers) as c:
            yield c

    monkeypatch.setattr(engine_mod, "dask_client", counting)
    docs = {}
    for e, more in (("memory", []), ("dask", ["--workers", "1"])):
        out = tmp_path / f"{e}.toml"
        assert cli_main(["calibrate", str(folder), "--target", "battery", "--equation", str(eq),
                         "--out", str(out), "--name", "chain", "--engine", e, *more]) == 0
        docs[e] = _undated(out)
    assert capsys.readouterr().err.count("dask engine:") == 3 and started == [1]
    corpus.assert_close_documents(docs["memory"], docs["dask"], RTOL)


def test_streamed_recuperation_limits_are_numpys_quantiles_with_ties():
    """The limits from merged bin counts and the quantile bins' distinct values equal
    np.quantile of all braking powers, bit for bit, also when one value repeats across
    the quantiles (a power logged at a clipped constant) and batches are merged."""
    from sumo_drvpw.fit.chain import LIMIT_QUANTILES
    from sumo_drvpw.fit.chain_stream import ChainSpec, ChainStats, _merge_hist

    rng = np.random.default_rng(9)
    brake = rng.lognormal(9.5, 0.8, 30_000)
    brake[rng.random(brake.size) < 0.3] = 41_250.0  # 30 % at one value
    brake[:50] = np.nextafter(41_250.0, 0.0)        # and its neighbour, in the same bin
    batches = np.array_split(brake, 7)
    spec = ChainSpec("battery")
    st = ChainStats(spec)
    for b in batches:
        st.hist = _merge_hist(st.hist, np.unique(_keys(b), return_counts=True))
    _, bins = st.brake_bins()
    assert 0 < len(bins) <= 16
    col = ChainStats(spec, "collect", bins=bins)
    for b in batches:
        sel = b[np.isin(_keys(b), np.asarray(bins))]
        if sel.size:
            col.values = _merge_hist(col.values, np.unique(sel, return_counts=True))
    assert col.values[0].size < 0.3 * brake.size  # the repeated value kept once
    assert st.limits_from(col) == sorted({float(np.quantile(brake, q)) for q in LIMIT_QUANTILES})
