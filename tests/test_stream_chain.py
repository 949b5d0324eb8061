"""Streamed `compare` of energy chains (battery, fuel): equal to the in-memory path to 1e-9.

Each log is several trips in two files (Parquet with small row groups, and CSV), read in
batches smaller than a trip, so every trip crosses chunk boundaries and every batch holds
whole trips of one file. The battery log has a charging stop (left out per trip), a
heater load unknown on one trip and the ambient temperature of an HVAC and a cold drag;
the fuel log a hybrid battery's V·I (the state-of-charge correction) and a temperature
unknown on one trip. Every number of report.json is compared.
"""

import json
import math
import tomllib
from functools import partial

import numpy as np
import pandas as pd
import pytest

import corpus
from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.log import from_frame
from sumo_drvpw.data.measured import load_measured, resolve_equations
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.compare import compare
from sumo_drvpw.fit.trip_energy import left_out_by_trip
from sumo_drvpw.fit.engine import run
from sumo_drvpw.fit.stream_compare import CompareStats
from sumo_drvpw.model.constants import FUELS
from sumo_drvpw.model.equations import equation_from_dict

RTOL = 1e-9

BATTERY_EQ = """[equation]
name = "ev"
[terms]
acc = 1.05
grade = 1.0
v1 = 140.0
v3 = 0.33
[chain]
predicts = "battery"
traction_efficiency = 0.88
recuperation_efficiency = 0.66
recuperation_limit_w = 30000.0
aux_power_w = 450.0
standstill_aux_w = 120.0
[chain.loads]
heater_power_w = 1.0
[chain.hvac]
column = "ambient_c"
setpoint_c = 20.0
heating_w_per_k = 60.0
cooling_w_per_k = 40.0
"""

FUEL_EQ = """[equation]
name = "hev"
[terms]
acc = 1.0
grade = 1.0
v1 = 160.0
v3 = 0.36
[chain]
predicts = "fuel"
traction_efficiency = 0.92
aux_power_w = 300.0
idle_fuel_power_w = 3500.0
marginal_efficiency = 0.34
engine_off_below_w = 4000.0
engine_on_above_mps = 19.0
charge_sustaining = true
running_fuel_per_k = 0.004
cold_start_ref_c = 23.9
fuel = "gasoline"
"""


def _trip(rng, trip: str, n: int, t0_c: float) -> pd.DataFrame:
    t = np.arange(n) * 0.1
    v = np.clip(13 + 11 * np.sin(t / (20.0 + rng.uniform(0, 10))) + rng.normal(0, 0.05, n), 0, None)
    v[:450] = 0.0
    v[-200:] = 0.0
    z = 30.0 * np.sin(t / 90.0)
    # a longitudinal accelerometer (dv/dt + g·sin θ, noisy): what bmw_i3_battery's
    # [measurement] reads (fused grade, logger dropouts)
    s = np.cumsum(v) * 0.1
    theta = np.arctan(np.gradient(z, s + 1e-3 * t))
    imu = np.gradient(v, t) + 9.81 * np.sin(theta) + rng.normal(0, 0.05, n)
    return pd.DataFrame({"trip_id": trip, "time_s": t, "speed_mps": v, "elevation_m": z,
                         "mass_kg": 1450.0 + 30.0 * rng.integers(0, 5),
                         "ambient_c": t0_c + 0.002 * t, "imu_accel_mps2": imu})


def _battery_frame() -> pd.DataFrame:
    rng = np.random.default_rng(11)
    frames = [_trip(rng, f"B{i}", 3000 + 350 * i, -5.0 + 6.0 * i) for i in range(6)]
    df = pd.concat(frames, ignore_index=True)
    df["heater_power_w"] = np.where(df["ambient_c"] < 10.0, 1800.0, 0.0)
    x = from_frame(df.copy()).inputs()
    eq = _eq(BATTERY_EQ)
    sig = {c: df[c].to_numpy(float) for c in ("heater_power_w", "ambient_c")}
    p_bat = eq.chain.evaluate(eq.power(x), x.v, signals=sig)["power_w"] + rng.normal(0, 150.0, len(df))
    b2 = (df["trip_id"] == "B2").to_numpy()
    stop = b2 & (df["time_s"] >= 5.0) & (df["time_s"] < 40.0)   # charging at the first standstill
    p_bat[stop.to_numpy()] = -3500.0 + rng.normal(0, 50.0, int(stop.sum()))
    df.loc[df["trip_id"] == "B4", "heater_power_w"] = np.nan    # heater not logged on B4
    df["battery_voltage_v"] = 355.0
    df["battery_current_a"] = p_bat / 355.0
    return _gaps(df, {"B1": (100.0, 112.0), "B4": (50.0, 53.4)})


def _gaps(df: pd.DataFrame, gaps: dict) -> pd.DataFrame:
    """Logging gaps (rows left out) in trips of both files: their seconds are counted."""
    drop = np.zeros(len(df), bool)
    for trip, (a, b) in gaps.items():
        drop |= ((df["trip_id"] == trip) & (df["time_s"] > a) & (df["time_s"] < b)).to_numpy()
    return df[~drop].reset_index(drop=True)


def _fuel_frame() -> pd.DataFrame:
    rng = np.random.default_rng(12)
    frames = [_trip(rng, f"F{i}", 2800 + 400 * i, 0.0 + 5.0 * i) for i in range(5)]
    df = pd.concat(frames, ignore_index=True)
    x = from_frame(df.copy()).inputs()
    eq = _eq(FUEL_EQ)
    p = eq.power(x)
    ch, sig = eq.chain, {"ambient_c": df["ambient_c"].to_numpy()}
    on = ch.engine_on(p, x.v)
    # engine off, the battery drives (the engine output it stands in for, at the engine's
    # warm-running factor: the fuel that puts it back), so the SOC-corrected fuel is the
    # charge-sustaining line's; engine on, it assists or is charged
    stand_in = (np.maximum(p, 0.0) / ch.traction_efficiency + ch.aux_power_w) * ch.running_factor(len(df), sig)
    assist = np.where(on, rng.uniform(-0.25, 0.25, len(df)) * np.maximum(p, 0.0), stand_in)
    fuel_w = np.where(on, ch.evaluate(p - assist, x.v, signals=sig)["power_w"], 0.0)
    fuel_w = np.maximum(fuel_w + rng.normal(0, 300.0, len(df)) * on, 0.0)
    df["fuel_rate_gps"] = fuel_w / FUELS["gasoline"]["lhv_j_per_kg"] * 1000.0
    df["battery_voltage_v"] = 201.0
    df["battery_current_a"] = assist / 201.0
    df.loc[df["trip_id"] == "F3", "ambient_c"] = np.nan        # no temperature on F3
    return _gaps(df, {"F1": (70.0, 80.0), "F4": (30.0, 36.5)})


def _eq(text: str):
    return equation_from_dict(tomllib.loads(text))


@pytest.fixture(scope="module")
def chain_logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("stream_chain")
    out = {}
    for kind, df in (("battery", _battery_frame()), ("fuel", _fuel_frame())):
        folder = d / kind
        folder.mkdir()
        trips = df["trip_id"].unique()
        first = df["trip_id"].isin(trips[:3])
        df[first].to_parquet(folder / "a.parquet", row_group_size=700)
        df[~first].to_csv(folder / "b.csv", index=False)
        eq = d / f"{kind}.toml"
        eq.write_text(BATTERY_EQ if kind == "battery" else FUEL_EQ, encoding="utf-8")
        out[kind] = (folder, eq, len(df))
    return out


def _close(a, b):
    corpus.assert_close_documents(a, b, RTOL)


def _specs(kind, eq):
    return [str(eq), "bmw_i3_battery"] if kind == "battery" else [str(eq), "epa_gasoline_car"]


@pytest.mark.parametrize("kind", ["battery", "fuel"])
@pytest.mark.parametrize("rows", [1700, 9000])
def test_streamed_chain_comparison_equals_in_memory(chain_logs, kind, rows):
    folder, eq, n = chain_logs[kind]
    eqs = resolve_equations(_specs(kind, eq))
    m = load_measured([folder], target=kind)
    u = m.usable
    comp = compare(m.power_w[u], m.inputs.take(u), eqs, dt_s=m.log.df["dt_s"].to_numpy()[u],
                   target=kind, battery_w=None if m.battery_w is None else m.battery_w[u])
    comp.left_out = left_out_by_trip(m.power_w, u, m.log.df["dt_s"].to_numpy(), m.inputs.trip)  # as the CLI
    ref = comp.to_json()
    cs, info = run([folder], partial(CompareStats, eqs, None, target=kind), rows=rows)
    got = cs.comparison().to_json()
    assert info.rows == n
    # the streamed document says how its percentiles came about; everything else is equal
    assert got["settings"].pop("percentiles") == "exact"
    _close(ref, got)
    r = got["equations"][eqs[0].name]
    # the comparison is of the chain, not of the wheel, and it found what was planted
    assert r["predicts"] == kind and len(r["trip_net_energy"]["trips"]) == (6 if kind == "battery" else 5)
    if kind == "battery":
        assert m.counts["excluded_charging"] > 100 and cs.counts["excluded_charging"] == m.counts["excluded_charging"]
        assert r["chain_unknown_inputs"]["heater_power_w"]["trips"] == ["B4"]
        assert abs(r["trip_net_energy"]["trips"]["B0"]["error"]) < 0.02
    else:
        assert m.battery_w is not None and r["chain_unknown_inputs"]["ambient_c"]["trips"] == ["F3"]
        assert abs(r["trip_energy"]["trips"]["F0"]["error"]) < 0.02


@pytest.mark.parametrize("kind", ["battery", "fuel"])
def test_cli_chain_compare_streams_and_equals_the_memory_engine(chain_logs, kind, tmp_path, capsys,
                                                                monkeypatch):
    """The whole report.json of `compare --engine local` (batches of 2,000 rows) equals
    `--engine memory`'s, its context's counts included; the console says the same."""
    import sumo_drvpw.fit.engine as engine

    folder, eq, n = chain_logs[kind]
    monkeypatch.setattr(engine, "run", partial(engine.run, rows=2000))
    docs, said = {}, {}
    for e in ("memory", "local"):
        out = tmp_path / e
        args = ["compare", str(folder), "--equation", str(eq), "--out", str(out), "--engine", e]
        if kind == "battery":
            args += ["--equation", "bmw_i3_battery"]
        assert cli_main(args) == 0
        cap = capsys.readouterr()
        said[e] = [ln for ln in cap.out.splitlines() if not ln.startswith("wrote")]
        docs[e] = json.loads((out / "report.json").read_text(encoding="utf-8"))
        assert (out / "fig8_error_speed.png").stat().st_size > 0
    assert "local engine:" in cap.err
    assert docs["local"]["settings"].pop("percentiles") == "exact"
    got, ref = docs["local"], docs["memory"]
    assert got["context"]["counts"]["files"] == 2 and got["context"]["counts"]["time_gaps"] == 2
    assert got["context"]["counts"]["time_gaps_s"] > 15.0
    _close(ref, got)
    assert said["local"] == said["memory"] and any("unknown (NaN)" in s for s in said["local"])


def flipped_current(folder, dest):
    """A copy of the logs of ``folder`` in ``dest`` (Parquet, row groups of 700 rows) with
    the battery current's sign flipped."""
    dest.mkdir()
    for f in folder.iterdir():
        df = pd.read_parquet(f) if f.suffix == ".parquet" else pd.read_csv(f)
        df["battery_current_a"] = -df["battery_current_a"]
        df.to_parquet(dest / (f.stem + ".parquet"), row_group_size=700)
    return dest


def test_streamed_battery_sign_test_is_on_all_batches(chain_logs, tmp_path):
    """The flipped-current test reads every batch's sums, as the in-memory reader reads the
    whole log: a current whose sign is flipped is refused, naming the files."""
    folder, eq, _ = chain_logs["battery"]
    flipped = flipped_current(folder, tmp_path / "flipped")
    eqs = resolve_equations([str(eq)])
    with pytest.raises(UserError, match="falls where") as mem:
        load_measured([flipped], target="battery")
    cs, _ = run([flipped], partial(CompareStats, eqs, None, target="battery"), rows=1500)
    with pytest.raises(UserError, match="falls where") as streamed:
        cs.comparison()
    r = lambda e: str(e.value).split("r = ")[1].split(" ")[0]  # noqa: E731
    assert r(mem) == r(streamed) and "2 files" in str(streamed.value)


def test_streamed_chain_compare_refuses_an_equation_without_that_chain(chain_logs, tmp_path, capsys):
    """After the first batch (a log's own refusal comes first, as in memory), before the rest."""
    folder, eq, _ = chain_logs["fuel"]
    with pytest.raises(UserError, match="'vsp_ldv1999' .* has no energy chain predicting 'fuel'"):
        run([folder], partial(CompareStats, resolve_equations([str(eq), "vsp_ldv1999"]), target="fuel"))
    out = tmp_path / "x"
    assert cli_main(["compare", str(folder), "--equation", str(eq), "--equation", "vsp_ldv1999",
                     "--target", "fuel", "--out", str(out)]) == 2
    assert "vsp_ldv1999.toml) has no energy chain predicting 'fuel'" in capsys.readouterr().err
    assert not out.exists()


def test_merged_sign_sums_equal_the_correlation_of_all_samples():
    from sumo_drvpw.data.measured import merge_sign_sums

    rng = np.random.default_rng(5)
    d, y = rng.normal(0, 9000.0, 4000), rng.normal(0, 5000.0, 4000)
    y += 0.3 * d
    parts = np.split(np.arange(4000), [100, 1500, 1501, 3000])
    sums = None
    for p in parts:
        dd, yy = d[p], y[p]
        md, my = dd.mean(), yy.mean()
        sums = merge_sign_sums(sums, (len(p), md, my, float((dd - md) @ (dd - md)),
                                      float((yy - my) @ (yy - my)), float((dd - md) @ (yy - my))))
    r = sums[5] / math.sqrt(sums[3] * sums[4])
    assert sums[0] == 4000 and r == pytest.approx(np.corrcoef(d, y)[0, 1], rel=1e-12)


def test_dask_chain_comparison_equals_local_and_memory(chain_logs, tmp_path, capsys):
    """--engine dask on a 2-worker cluster (statistics pickled across processes, the Parquet
    file cut into Parts at trip starts): the same report as the local engine and as memory."""
    pytest.importorskip("distributed", reason="Dask not installed: pip install 'sumo-drvpw[dask]'")
    from distributed import LocalCluster

    from sumo_drvpw.data.stream import plan

    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0") as c:
        for kind in ("battery", "fuel"):
            folder, eq, _ = chain_logs[kind]
            eqs = resolve_equations(_specs(kind, eq))
            parts = plan([folder], part_rows=3000)
            assert len(parts) >= 3  # the Parquet file in Parts of whole trips, and the CSV
            make = partial(CompareStats, eqs, None, target=kind)
            a = run([folder], make, parts=parts, rows=2500)[0].comparison().to_json()
            b, info = run([folder], make, engine="dask", scheduler=c.scheduler_address, parts=parts, rows=2500)
            assert info.engine == "dask"
            _close(a, b.comparison().to_json())
        # the command line: the whole report.json of --engine dask equals --engine memory's
        folder, eq, _ = chain_logs["fuel"]
        docs = {}
        for e, extra in (("memory", []), ("dask", ["--scheduler", c.scheduler_address])):
            out = tmp_path / e
            assert cli_main(["compare", str(folder), "--equation", str(eq), "--out", str(out),
                             "--engine", e, *extra]) == 0
            docs[e] = json.loads((out / "report.json").read_text(encoding="utf-8"))
        assert "dask engine:" in capsys.readouterr().err
        assert docs["dask"]["settings"].pop("percentiles") == "exact"
        _close(docs["memory"], docs["dask"])
