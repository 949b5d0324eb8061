"""The chain tracer streamed (fit/chain_trace_stream.py) against the in-memory one.

Synthetic logs with a planted chain effect, read in chunks of a few thousand rows (several
batches of whole trips, prepared in memory or on disk): the streamed trace finds what the
in-memory trace finds, with the same coefficients, parameters, closed chain, metrics and
per-trip net energies before and after, to 1e-9 relative (a per-trip *error* near 0, to
1e-9 absolute); `diagnose --target battery --stream yes` runs it (it was refused).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from sumo_drvpw.data.log import from_frame
from sumo_drvpw.data.measured import load_measured, measure
from sumo_drvpw.fit.chain_linear import ChainTraceOptions, trace_chain
from sumo_drvpw.fit.chain_trace_stream import trace_chain_stream
from sumo_drvpw.fit.trip_energy import with_trace_left_out
from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.model.constants import FUELS
from sumo_drvpw.model.equations import Equation, load_equation, save_equation
from sumo_drvpw.model.vehicles import load_vehicle
from sumo_drvpw.synth.effects import BatteryLog, synth_trips
from sumo_drvpw.synth.track import Noise

QUIET = Noise(process_w=50.0, process_rel=0.002)
ROWS = 3000   # rows per chunk read: a 6-trip log in a dozen batches


@pytest.fixture(scope="module")
def base():
    b = BatteryLog(standstill_aux_w=0.0, noise_w=100.0)
    df, _ = synth_trips(n_trips=6, minutes=8.0, seed=3, effects=(b,), noise=QUIET)
    veh = load_vehicle("prius3")
    truth = load_equation("drvpw_prius3")
    p = truth.power(measure(from_frame(df, veh, name="synth"), veh, "battery").inputs)
    return b, df, truth, p


def _battery(df, extra_w):
    d = df.copy()
    d["battery_current_a"] = d["battery_current_a"] + extra_w / d["battery_voltage_v"]
    return d


def _fuel(df, p, chain, seed):
    v = df["speed_mps"].to_numpy(float)
    rng = np.random.default_rng(seed)
    pf = chain.evaluate(p, v)["power_w"] * (1.0 + rng.normal(0, 0.03, p.size)).clip(0.0)
    return df.drop(columns=["battery_voltage_v", "battery_current_a"]).assign(
        fuel_rate_gps=pf / FUELS["gasoline"]["lhv_j_per_kg"] * 1000.0)


def _compare(a, b, path=""):
    """Reports equal: texts exactly, numbers to 1e-9 relative (per-trip errors: absolute)."""
    if isinstance(a, dict):
        assert set(a) == set(b), (path, set(a) ^ set(b))
        for k in a:
            _compare(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _compare(x, y, f"{path}[{i}]")
    elif isinstance(a, float) and not isinstance(b, str):
        if math.isnan(a):
            assert math.isnan(b), path
        elif path.endswith(("error", "energy_gain", "rmse_gain")) or "p_value" in path:
            assert b == pytest.approx(a, rel=1e-9, abs=1e-9), path   # a relative error or gain near 0
        else:
            assert b == pytest.approx(a, rel=1e-9, abs=1e-6), path
    else:
        assert a == b, (path, a, b)


def _both(tmp_path, df, eq, target, opt=None, **kw):
    log = tmp_path / "log.parquet"
    df.to_parquet(log)
    m = load_measured([str(log)], "prius3", target=target)
    mem = trace_chain(m, eq, opt)
    with_trace_left_out(mem, m)
    st = trace_chain_stream([str(log)], "prius3", eq, target, opt, rows=ROWS, **kw)
    assert st.report.pop("resources")["passes"] > 3
    _compare(mem.report, st.report)
    _compare(mem.equation.chain.to_dict(), st.equation.chain.to_dict())
    assert mem.equation.terms == pytest.approx(st.equation.terms, rel=1e-12)
    return mem, st


def test_planted_standstill_load_streamed_equals_in_memory(tmp_path, base):
    b, df, truth, p = base
    stand = 450.0 * (df["speed_mps"].to_numpy(float) < 0.1)
    mem, st = _both(tmp_path, _battery(df, stand), Equation("declared", dict(truth.terms), truth.mass_kg,
                                                               chain=b.chain()), "battery")
    assert [f["term"] for f in st.report["findings"]][0] == "standstill_aux_w"
    assert st.report["findings"][0]["coefficient"] == pytest.approx(450.0, rel=0.2)
    before, after = (st.report[k]["trip_net_energy"] for k in ("baseline", "final"))
    assert after["mean_abs_error"] < before["mean_abs_error"]
    assert len(before["trips"]) == 6 and all("left_out_samples" in t for t in before["trips"].values())


def test_planted_recuperation_limit_refined_streamed_equals_in_memory(tmp_path, base):
    """A profiled parameter refined between its grid values by passes over the batches; the
    batches on disk (cache 0 MB) read the same."""
    b, df, truth, p = base
    mem, st = _both(tmp_path, _battery(df, b.recuperation_efficiency * (np.maximum(p, -8000.0) - p)),
                    Equation("declared", dict(truth.terms), truth.mass_kg, chain=b.chain()), "battery", cache_mb=0)
    f = st.report["findings"][0]
    assert f["term"] == "recuperation_limit_w" and f["parameter"] == pytest.approx(8000.0, rel=0.02)


def test_heating_and_missing_grade_streamed_equal_in_memory(tmp_path, base):
    b, df, truth, p = base
    temps = dict(zip(df["trip_id"].unique(), [-5.0, 0.0, 5.0, 10.0, 15.0, 25.0]))
    d = df.assign(ambient_c=df["trip_id"].map(temps))
    d = _battery(d, 40.0 * np.maximum(20.0 - d["ambient_c"].to_numpy(), 0.0))
    no_grade = Equation("declared", {k: v for k, v in truth.terms.items() if k != "grade"}, truth.mass_kg,
                        chain=b.chain())
    mem, st = _both(tmp_path, d, no_grade, "battery")
    assert st.report["findings"][0]["term"] == "grade"
    assert "hvac" in [c["effect"] for c in st.report["candidates"]]


def test_fuel_cut_off_streamed_equals_in_memory_with_blocks_in_two_trips(tmp_path, base):
    """A fuel chain's overrun cut-off (a fixed column on a grid); two trips: the folds are
    blocks interleaved within trips, numbered across batches."""
    b, df, truth, p = base
    kw = dict(idle_fuel_power_w=6000.0, marginal_efficiency=0.33, engine_off_below_w=-np.inf)
    d = _fuel(df, p, EnergyChain("fuel", 1.0, fuel_cut_below_w=-1000.0, **kw), 8)
    two = d[d["trip_id"].isin(["synth-1", "synth-2"])].reset_index(drop=True)
    eq = Equation("declared", dict(truth.terms), truth.mass_kg, chain=EnergyChain("fuel", 1.0, **kw))
    mem, st = _both(tmp_path, two, eq, "fuel")
    assert "interleaved" in st.report["validation"]
    assert {f["term"]: f["parameter"] for f in st.report["findings"]} == {"fuel_cut_below_w": -1000.0}


def test_cli_streams_the_chain_trace(tmp_path, base, capsys):
    """`--stream yes` with a chain target was refused ("reads the logs in memory"); it now
    streams and writes what `--stream no` writes (trace.md the same, the closed chain's
    values to 1e-9)."""
    from sumo_drvpw.cli import main as cli_main

    b, df, truth, p = base
    log = tmp_path / "log.parquet"
    _battery(df, 450.0 * (df["speed_mps"].to_numpy(float) < 0.1)).to_parquet(log)
    decl = tmp_path / "declared.toml"
    save_equation(Equation("declared", dict(truth.terms), truth.mass_kg, chain=b.chain()), decl)
    outs = {}
    for mode in ("no", "yes"):
        outs[mode] = tmp_path / mode
        assert cli_main(["diagnose", str(log), "--vehicle", "prius3", "--equation", str(decl), "--target", "battery",
                         "--stream", mode, "--out", str(outs[mode]), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "rows streamed" in err and "passes over the prepared batches" in err
    assert (outs["no"] / "trace.md").read_text(encoding="utf-8") == (outs["yes"] / "trace.md").read_text(encoding="utf-8")
    a, s = (json.loads((outs[k] / "trace.json").read_text(encoding="utf-8")) for k in ("no", "yes"))
    assert "resources" in s and "resources" not in a
    s.pop("resources")
    _compare(a, s)
    ca, cs = (load_equation(str(outs[k] / "final_equation.toml")).chain.to_dict() for k in ("no", "yes"))
    _compare(ca, cs)


def test_options_reach_the_streamed_trace(tmp_path, base):
    """skip_effects and the column options: the same candidates and left-out columns."""
    b, df, truth, p = base
    d = df.assign(pump_w=np.random.default_rng(2).uniform(0, 500, len(df)))
    opt = ChainTraceOptions(skip_effects=("standstill_aux_w",), include=("pump_*",), max_findings=2)
    mem, st = _both(tmp_path, d, Equation("declared", dict(truth.terms), truth.mass_kg, chain=b.chain()),
                    "battery", opt)
    assert st.report["columns_left_out"]["standstill_aux_w"] == "not offered (skip_effects option)"
    assert "loads.pump_w" in [c["effect"] for c in st.report["candidates"]]


def test_a_counter_target_streamed_is_refused_in_one_line(tmp_path, capsys):
    """A battery target from the BMS's energy counters (their view spans the log) is traced
    in memory only: `--stream yes` says so in one line naming the option, nothing written."""
    from sumo_drvpw.cli import main as cli_main

    t = np.arange(0.0, 600.0, 1.0)
    v = 10.0 + 5.0 * np.sin(t / 10.0)
    dis = np.cumsum(np.full(t.size, 2000.0))
    log = tmp_path / "soc.csv"
    log.write_text("trip_id,time_s,speed_mps,battery_discharge_energy_j,battery_charge_energy_j\n"
                   + "".join(f"trip,{a:g},{b:.3f},{c:.1f},0\n" for a, b, c in zip(t, v, dis)), encoding="utf-8")
    decl = tmp_path / "declared.toml"
    save_equation(Equation("ev", {"acc": 1.0, "v1": 150.0, "v3": 0.4},
                           chain=EnergyChain("battery", 0.9, 0.85, aux_power_w=400.0)), decl)
    out = tmp_path / "o"
    assert cli_main(["diagnose", str(log), "--vehicle", "prius3", "--equation", str(decl), "--target", "battery",
                     "--stream", "yes", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--stream yes" in err[0] and "energy counters" in err[0] and "--stream no" in err[0]
    assert not out.exists()


def test_a_trip_id_in_two_files_is_refused_streamed_as_in_memory(tmp_path, base):
    """Two files holding the same trip ids: the in-memory reader refuses them in one line; the
    streamed trace took them (two copies of a trip's sums, the second overwriting the first in
    the per-trip energies) and now refuses them with the same line."""
    from sumo_drvpw.errors import UserError

    b, df, truth, p = base
    folder = tmp_path / "logs"
    folder.mkdir()
    for name in ("a", "b"):
        df.to_parquet(folder / f"{name}.parquet")
    eq = Equation("declared", dict(truth.terms), truth.mass_kg, chain=b.chain())
    with pytest.raises(UserError) as mem:
        load_measured([str(folder)], "prius3", target="battery")
    with pytest.raises(UserError) as st:
        trace_chain_stream([str(folder)], "prius3", eq, "battery", rows=ROWS)
    assert str(st.value) == str(mem.value) and "is also in" in str(st.value)


def test_the_limits_quantiles_are_exact_over_all_batches(tmp_path, base):
    """The recuperation limits are offered at np.quantile of the braking power of every
    analysis sample (found from binned counts and the values of the bins that hold the order
    statistics), not of a first-look sample: the same floats as in memory."""
    from sumo_drvpw.fit.chain_effects import LIMIT_QUANTILES
    from sumo_drvpw.fit.chain_linear import chain_samples
    from sumo_drvpw.fit.chain_stream import _keys, _merge_hist
    from sumo_drvpw.fit.chain_trace_stream import _brake_quantiles
    from sumo_drvpw.fit.diagnose.source import Batches, INPUT_FIELDS, read_batches

    b, df, truth, p = base
    log = tmp_path / "log.parquet"
    df.to_parquet(log)
    eq = Equation("declared", dict(truth.terms), truth.mass_kg, chain=b.chain())
    batches, hist, brakes = Batches(), None, []
    for m in read_batches([str(log)], load_vehicle("prius3"), None, "battery", ROWS):
        ok, pw, *_ = chain_samples(m, eq)
        idx = np.flatnonzero(ok)
        brake = -pw[idx][pw[idx] < 0]
        brakes.append(brake)
        hist = _merge_hist(hist, np.unique(_keys(brake), return_counts=True))
        batches.append({f: np.asarray(getattr(m.inputs, f), float)[idx] for f in INPUT_FIELDS})
    assert len(batches) > 5
    every = np.concatenate(brakes)
    assert _brake_quantiles(batches, eq, hist) == [float(np.quantile(every, q)) for q in LIMIT_QUANTILES]


def test_the_battery_sign_is_tested_on_all_batches_as_in_memory(tmp_path, base):
    """One trip of six with its current's sign flipped: the in-memory reader tests the sign on
    all samples (positive correlation: traced); the streamed trace tested it per batch and
    refused that trip's batch. Now tested on the merged sums: traced, equal to in memory; a
    log flipped whole is refused by both in one line."""
    from sumo_drvpw.errors import UserError

    b, df, truth, p = base
    eq = Equation("declared", dict(truth.terms), truth.mass_kg, chain=b.chain())
    d = df.copy()
    one = d["trip_id"] == "synth-3"
    d.loc[one, "battery_current_a"] = -d.loc[one, "battery_current_a"]
    _both(tmp_path, d, eq, "battery", ChainTraceOptions(max_findings=1))
    flipped = df.assign(battery_current_a=-df["battery_current_a"])
    log = tmp_path / "flipped.parquet"
    flipped.to_parquet(log)
    with pytest.raises(UserError) as mem:
        load_measured([str(log)], "prius3", target="battery")
    with pytest.raises(UserError) as st:
        trace_chain_stream([str(log)], "prius3", eq, "battery", rows=ROWS)
    assert "sign" in str(st.value) or "falls" in str(st.value)
    assert str(st.value).split(":")[0] == str(mem.value).split(":")[0]


def test_cli_streams_the_chain_trace_above_the_row_limit(tmp_path, base, monkeypatch, capsys):
    """`--stream auto` (the default) above the row limit: the chain trace streams (it printed
    a note and read the logs in memory)."""
    import sumo_drvpw.cli.diagnose as diag
    from sumo_drvpw.cli import main as cli_main

    b, df, truth, p = base
    log = tmp_path / "log.parquet"
    df.to_parquet(log)
    decl = tmp_path / "declared.toml"
    save_equation(Equation("declared", dict(truth.terms), truth.mass_kg, chain=b.chain()), decl)
    monkeypatch.setattr(diag, "STREAM_ROWS", len(df) - 1)
    out = tmp_path / "o"
    assert cli_main(["diagnose", str(log), "--vehicle", "prius3", "--equation", str(decl), "--out", str(out),
                     "--max-findings", "1", "--quiet"]) == 0
    res = json.loads((out / "trace.json").read_text(encoding="utf-8"))["resources"]
    assert res["rows"] == len(df) and res["passes"] > 3
    assert "rows streamed" in capsys.readouterr().err


def test_a_road_load_that_reads_a_signal_streamed_equals_in_memory(tmp_path, base):
    """A declared road load with terms that read log columns (``radial``: the yaw rate, 0
    without it; ``[pump_w]*v^0``: a logged power, required) or the trip ids (``trip=ID``): the
    streamed trace kept only the
    chain's and its candidates' signals, so its driving power dropped the radial drag (the
    candidates' gains, the limits and every held-out prediction off the in-memory ones) and
    the column term was refused ('needs the signal pump_w'). Now the equation's columns are
    kept: equal to in memory."""
    b, df, truth, p = base
    rng = np.random.default_rng(7)
    yaw = 0.08 * np.sin(np.arange(len(df)) / 7.0) + rng.normal(0, 0.01, len(df))
    pump = rng.uniform(100.0, 400.0, len(df))
    d = _battery(df.assign(yaw_rate_rps=yaw, pump_w=pump), 450.0 * (df["speed_mps"].to_numpy(float) < 0.1))
    eq = Equation("declared", dict(truth.terms, radial=0.3), truth.mass_kg, chain=b.chain())
    _both(tmp_path, d, eq, "battery", ChainTraceOptions(max_findings=2))
    eq = Equation("declared", dict(truth.terms, **{"[pump_w]*v^0": 1.0}), truth.mass_kg, chain=b.chain())
    _both(tmp_path, d, eq, "battery", ChainTraceOptions(max_findings=1))
    # a trip's own offset (a trip=ID factor reads the trip ids: refused streamed, 'needs trip ids')
    eq = Equation("declared", dict(truth.terms, **{"trip=synth-2*v^0": 300.0}), truth.mass_kg, chain=b.chain())
    _both(tmp_path, d, eq, "battery", ChainTraceOptions(max_findings=1))
