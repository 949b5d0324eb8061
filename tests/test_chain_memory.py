"""Chain calibration in less memory per row: the same results as the code before.

`calibrate --target battery|fuel` reads the logs once for the target and the driving
power (it read them two or three times), keeps only the arrays the fit needs and lets the
table go, and fits each chain on the triangular factor of its design built block by block
(the design was built whole, with scaled copies). The old fit is reproduced here by
building the design whole and solving it as the code before did (``_whole_design_solve``,
the body of ``fit/chain.py``'s ``_solve`` and ``_covariance`` before this change); every
number of the fits must equal it to 1e-9 relative. Memory itself is measured in
``benchmarks/chain_memory.py``, not here.
"""

import tomllib

import numpy as np
import pytest
from scipy.optimize import lsq_linear

import corpus
import sumo_drvpw.fit.chain as fc
from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data import measured as dm
from sumo_drvpw.fit.chain import calibrate_battery
from sumo_drvpw.fit.chain_fuel import calibrate_fuel
from sumo_drvpw.model.chain import EnergyChain

RTOL = 1e-9


def _whole_design_solve(make, w, ok, lb, ub):
    """The fit before block factoring: the whole design, weighted, scaled, BVLS on it."""
    x, y = make(slice(None))
    x, y = x[ok], np.broadcast_to(y, ok.shape)[ok]
    sw = np.sqrt(w[ok])
    xs = x * sw[:, None]
    ys = y * sw
    scale = np.sqrt((xs ** 2).sum(axis=0))
    scale[scale == 0] = 1.0
    res = lsq_linear(xs / scale, ys, bounds=(np.asarray(lb) * scale, np.asarray(ub) * scale),
                     method="bvls", lsmr_tol="auto")
    beta = np.clip(res.x / scale, lb, ub)
    r = ys - xs @ beta
    return beta, float(r @ r), res.active_mask, xs


def _whole_design_covariance(xs, rss, active):
    k = xs.shape[1]
    se = np.full(k, np.nan)
    free = np.flatnonzero(active == 0)
    dof = xs.shape[0] - free.size
    if free.size and dof > 0:
        a = xs[:, free]
        cov = np.linalg.inv(a.T @ a) * rss / dof
        se[free] = np.sqrt(np.maximum(np.diag(cov), 0.0))
    return se


@pytest.fixture
def old_fit(monkeypatch):
    """A context in which fit/chain.py fits as the code before did."""
    def use():
        monkeypatch.setattr(fc, "_solve", _whole_design_solve)
        monkeypatch.setattr(fc, "_covariance", _whole_design_covariance)
    return use


def _close(a, b):
    corpus.assert_close_documents(a, b, RTOL, abs_at_zero=1e-12)


def _fit_doc(fit) -> dict:
    return {"chain": fit.chain.to_dict(), "parameters": fit.parameters, "n": fit.n, "r2": fit.r2,
            "rmse_w": fit.rmse_w, "energy_ratio": fit.energy_ratio, "profile": fit.profile}


def _drive(n, seed):
    """A physical drive: speed, road-load driving power, a heater load, the air temperature."""
    rng = np.random.default_rng(seed)
    v = np.clip(np.cumsum(rng.normal(0, 0.3, n)) % 30.0, 0.0, None)
    a = rng.normal(0, 0.8, n)
    p = 1500.0 * v * a + 180.0 * v + 0.35 * v ** 3
    p[rng.random(n) < 0.08] = 0.0
    heater = np.where(rng.random(n) < 0.5, rng.uniform(0, 4000, n), 0.0)
    heater[rng.random(n) < 0.01] = np.nan  # unknown now and then: out of the fit
    temp = rng.uniform(-5, 30, n)
    dt = rng.uniform(0.05, 0.15, n)
    return rng, v, p, heater, temp, dt


@pytest.mark.parametrize("efficiency", ["constant", "power", "speed-power"])
@pytest.mark.parametrize("block", [3000, 65_536])
def test_battery_fit_equals_the_whole_design_fit(efficiency, block, old_fit, monkeypatch):
    rng, v, p, heater, temp, dt = _drive(25_000, 4)
    plant = EnergyChain(predicts="battery", traction_efficiency=0.88, recuperation_efficiency=0.7,
                        aux_power_w=400.0, recuperation_limit_w=20_000.0, loads={"heater_w": 0.9},
                        hvac={"column": "t_c", "setpoint_c": 21.0, "heating_w_per_k": 80.0,
                              "cooling_w_per_k": 50.0})
    sig = {"heater_w": heater, "t_c": temp}
    meas = plant.evaluate(p, v, signals=sig)["power_w"] + rng.normal(0, 250.0, p.size)
    mask = rng.random(p.size) > 0.05
    kw = dict(loads=["heater_w"], hvac={"column": "t_c", "setpoint_c": 21.0}, mask=mask,
              efficiency=efficiency)
    monkeypatch.setattr(fc, "BLOCK_ROWS", block)
    new = _fit_doc(calibrate_battery(p, v, meas, dt, sig, **kw))
    fixed = _fit_doc(calibrate_battery(p, v, meas, dt, sig, fixed={"aux_power_w": 420.0}, **kw))
    old_fit()
    _close(_fit_doc(calibrate_battery(p, v, meas, dt, sig, **kw)), new)
    _close(_fit_doc(calibrate_battery(p, v, meas, dt, sig, fixed={"aux_power_w": 420.0}, **kw)), fixed)
    # the profile found the planted limit's neighbourhood, the fit the planted chain
    assert new["chain"]["recuperation_limit_w"] is not None and len(new["profile"]) > 2
    if efficiency == "constant":
        assert new["chain"]["traction_efficiency"] == pytest.approx(0.88, rel=0.02)


@pytest.mark.parametrize("block", [4777, 65_536])
def test_fuel_fit_equals_the_whole_design_fit(block, old_fit, monkeypatch):
    rng, v, p, heater, temp, dt = _drive(30_000, 5)
    heater = np.nan_to_num(heater)
    plant = EnergyChain(predicts="fuel", idle_fuel_power_w=4_000.0, marginal_efficiency=0.36,
                        engine_off_below_w=5_000.0, engine_on_above_mps=14.0, loads={"heater_w": 1.0})
    on = plant.engine_on(p, v)
    assist = np.where(on, rng.uniform(-0.3, 0.3, p.size) * np.maximum(p, 0), 0.0)
    fuel = np.where(on, 4_000.0 + (np.maximum(p, 0) - assist + heater) / 0.36, 0.0)
    fuel = fuel + rng.normal(0, 200.0, p.size) * on
    monkeypatch.setattr(fc, "BLOCK_ROWS", block)
    new = _fit_doc(calibrate_fuel(p, v, fuel, dt, battery_w=assist, signals={"heater_w": heater},
                                  loads=["heater_w"]))
    old_fit()
    old = _fit_doc(calibrate_fuel(p, v, fuel, dt, battery_w=assist, signals={"heater_w": heater},
                                  loads=["heater_w"]))
    _close(old, new)
    assert len(new["profile"]) > 50 and new["chain"]["marginal_efficiency"] == pytest.approx(0.36, rel=0.02)


@pytest.fixture(scope="module")
def battery_log(tmp_path_factory):
    """A synthetic Prius 3 log (power-split signals: a measured driving power) with battery
    V·I from a known chain (synth BatteryLog), three trips, and a heater column."""
    from sumo_drvpw.synth.effects import BatteryLog, synth_trips

    df, _ = synth_trips(n_trips=3, minutes=6.0, seed=2, effects=[BatteryLog()])
    df["heater_w"] = np.where(df["time_s"] > 60.0, 1500.0, np.nan)
    p = tmp_path_factory.mktemp("chain_memory") / "log.parquet"
    df.to_parquet(p, row_group_size=2000)
    return p


def _same_array(a, b):
    if a is None or b is None:
        assert a is None and b is None
        return
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    if a.dtype.kind == "f":
        assert np.array_equal(a, b, equal_nan=True)
    else:
        assert np.array_equal(a, b)


def test_one_read_gives_what_two_reads_gave_and_keeps_only_the_arrays(battery_log):
    m, mw = dm.load_measured_pair([battery_log], "prius3", None, "battery")
    ref_m = dm.load_measured([battery_log], "prius3", None, target="battery")
    ref_w = dm.load_measured([battery_log], "prius3", None)
    for got, ref in ((m, ref_m), (mw, ref_w)):
        assert got.counts == ref.counts and got.source == ref.source
        for f in ("power_w", "usable", "battery_w"):
            _same_array(getattr(got, f), getattr(ref, f))
        for f in ("v", "a", "theta", "wind", "mass", "rho", "trip"):
            _same_array(getattr(got.inputs, f), getattr(ref.inputs, f))
        assert sorted(got.inputs.signals) == sorted(ref.inputs.signals)
        for c in ref.inputs.signals:  # read from the table when asked for, the same values
            _same_array(got.inputs.signals[c], ref.inputs.signals[c])
    sel = dm.with_signals(mw, {"heater_w", "not_a_column"})  # the table stays, two columns less
    assert set(sel.inputs.signals) == {"heater_w"} and sel.log.df is mw.log.df
    assert isinstance(sel.inputs.signals["heater_w"], np.ndarray)
    kept = dm.keep_arrays(m, ["heater_w", "not_a_column"])
    assert list(kept.log.df.columns) == ["dt_s"] and set(kept.inputs.signals) == {"heater_w"}
    assert kept.counts == m.counts and kept.context() == m.context()
    arrays = [kept.power_w, kept.usable, kept.log.df["dt_s"].to_numpy(), kept.inputs.signals["heater_w"]]
    arrays += [getattr(kept.inputs, f) for f in ("v", "a", "theta", "wind", "mass", "rho", "trip")]
    for arr in arrays:  # none holds more than its own values (no view into a block of columns)
        root = arr
        while isinstance(root.base, np.ndarray):
            root = root.base
        assert root.nbytes <= arr.nbytes or arr.strides == (0,)
    for f in ("v", "a", "theta", "wind", "mass", "rho", "trip"):
        _same_array(getattr(kept.inputs, f), getattr(ref_m.inputs, f))
    _same_array(kept.inputs.signals["heater_w"], ref_m.inputs.signals["heater_w"])
    # a table of one block of columns (as pandas makes of a CSV): its columns are copied
    import pandas as pd

    block = pd.DataFrame(np.arange(12.0).reshape(4, 3), columns=["a", "b", "c"])
    col = block["b"].to_numpy()
    assert dm._own(col) is not col and np.shares_memory(col, block.to_numpy())
    own = np.arange(4.0)
    assert dm._own(own) is own and dm._own(np.broadcast_to(1.0, (4,))).strides == (0,)


@pytest.mark.parametrize("equation", [["--equation", "drvpw_prius3"], []])
def test_cli_chain_calibration_reads_once_and_equals_the_old_path(battery_log, equation, tmp_path,
                                                                  monkeypatch, old_fit, capsys):
    """The CLI reads the logs once (it read them twice with --equation, three times without)
    and writes the chain the old path fits: two reads, the whole design."""
    from sumo_drvpw.data.measured import load_measured, resolve_equations
    from sumo_drvpw.fit.chain import calibrate_on

    reads = []
    real = dm.read_log
    monkeypatch.setattr(dm, "read_log", lambda *a, **k: reads.append(a) or real(*a, **k))
    monkeypatch.setattr(fc, "BLOCK_ROWS", 1500, raising=False)
    out = tmp_path / "chain.toml"
    assert cli_main(["calibrate", str(battery_log), "--vehicle", "prius3", "--target", "battery",
                     "--load", "heater_w", "--out", str(out), "--report", str(tmp_path / "rep"),
                     "--engine", "memory", *equation]) == 0  # (the streamed path: test_chain_stream.py)
    assert len(reads) == 1
    said = capsys.readouterr().out
    doc = tomllib.loads(out.read_text(encoding="utf-8"))
    assert (tmp_path / "rep" / "report.json").is_file()
    # the old path: the target and the driving power read apart, the design whole
    old_fit()
    m = load_measured([battery_log], "prius3", None, target="battery")
    mw = load_measured([battery_log], "prius3", None)
    eq = resolve_equations([equation[1]] if equation else [str(out)], m.vehicle)[0]
    ref = calibrate_on(m, eq, loads=["heater_w"], p_drive_w=mw.power_w)
    got = {k: v for k, v in doc["chain"].items() if k not in ("provenance", "reading")}
    want = {k: v for k, v in ref.chain.to_dict().items() if k in got}
    assert {"traction_efficiency", "recuperation_efficiency", "aux_power_w", "loads", "metrics"} <= set(got)
    _close(want, got)
    assert "measured driving power" in doc["chain"]["provenance"]["chain_input"] and "R²" in said


def test_parquet_frame_is_pandas_reading_with_the_metadata(tmp_path):
    """The reader's Parquet path (Arrow freed column by column) gives pandas' own frame."""
    import pandas as pd
    import pyarrow as pa
    import pyarrow.parquet as pq

    from sumo_drvpw.data.paths import SPLIT_COLUMNS_MAX, parquet_frame

    rng = np.random.default_rng(1)
    for ncol in (5, SPLIT_COLUMNS_MAX + 5):
        df = pd.DataFrame({f"c{i}": rng.normal(size=300) for i in range(ncol)})
        df["trip_id"] = np.repeat(["a", "b", "c"], 100)
        df["brake"] = rng.random(300) < 0.1
        table = pa.Table.from_pandas(df).replace_schema_metadata(
            {b"sumo_drvpw.truth": b"{}", b"drive_log.roles": b"x", b"other": b"y"})
        p = tmp_path / f"{ncol}.parquet"
        pq.write_table(table, p)
        got, meta = parquet_frame(p, (b"sumo_drvpw", b"drive_log."))
        pd.testing.assert_frame_equal(got, pd.read_parquet(p))
        assert meta == {"sumo_drvpw.truth": "{}", "drive_log.roles": "x"}
        # a block per column, or one per dtype beyond the limit (pandas: fragmented past 100)
        assert (len(got._mgr.blocks) == ncol + 2) == (ncol + 2 <= SPLIT_COLUMNS_MAX)
