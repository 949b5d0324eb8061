"""Streaming calibrate and compare (issue #14): equal to the in-memory path to 1e-9.

The logs are the bundled Prius test-track log (power-split signals, so measured power
needs per-trip shaft accelerations) cut into trips, written with row groups and read in
chunks smaller than a trip, so every trip crosses chunk boundaries; one variant derives
grade from elevation over distance (another per-trip derivation).
"""

import warnings

import numpy as np
import pandas as pd
import pytest
import statsmodels.api as sm
from hypothesis import given, settings
from hypothesis import strategies as st

from functools import partial

import corpus
from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.log import bundled_log
from sumo_drvpw.data.measured import load_measured, resolve_equations
from sumo_drvpw.data.stream import Part, plan, whole_trips
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
from sumo_drvpw.fit.compare import compare
from sumo_drvpw.fit.engine import run
from sumo_drvpw.fit.stream_compare import CompareStats
from sumo_drvpw.fit.stream import (CalibrationStats, Moments, calibrate_from_stats,
                                   ols_from_r)
from sumo_drvpw.model.equations import load_equation
from sumo_drvpw.model.vehicles import load_vehicle

RTOL = 1e-9
TRIPS = ("a", "b", "c", "d", "e")


def _trips_frame(elevation: bool = False) -> pd.DataFrame:
    """Five trips, each the bundled 20-minute log with its own load (mass + 40 kg per trip)
    and its own sub-sample offset, so the trips differ."""
    base = pd.read_parquet(bundled_log())
    frames = []
    for i, t in enumerate(TRIPS):
        df = base.iloc[i:len(base) - 2 * i].copy()
        df["trip_id"] = t
        df["mass_kg"] = df["mass_kg"] + 40.0 * i
        frames.append(df)
    df = pd.concat(frames, ignore_index=True)
    if elevation:  # grade from elevation over distance, per trip
        df = df.drop(columns=["grade_rad"]).rename(columns={"gps_elevation_m": "elevation_m"})
    return df


@pytest.fixture(scope="module")
def logs(tmp_path_factory):
    d = tmp_path_factory.mktemp("stream")
    df = _trips_frame()
    pq = d / "trips.parquet"
    df.to_parquet(pq, row_group_size=7000)           # trips cross row groups
    csv = d / "trips.csv"
    df.to_csv(csv, index=False)
    folder = d / "two_files"
    folder.mkdir()
    el = _trips_frame(elevation=True)
    el[el.trip_id.isin(["a", "b"])].to_parquet(folder / "f1.parquet", row_group_size=500)
    el[~el.trip_id.isin(["a", "b"])].to_parquet(folder / "f2.parquet", row_group_size=500)
    return {"parquet": pq, "csv": csv, "folder": folder}


def _close(a, b):
    """Every number equal to RTOL (corpus.assert_close_documents); ``b`` may carry more keys."""
    corpus.assert_close_documents(a, b, RTOL, same_keys=False)


def _in_memory_calibration(path, cands):
    m = load_measured([path], "prius3")
    return calibrate(m.inputs, m.power_w, cands, mask=m.usable, counts=m.counts,
                     reference_mass_kg=float(m.inputs.mass[m.usable].mean())), m


@pytest.mark.parametrize("kind,rows", [("parquet", 3333), ("parquet", 50_000), ("csv", 10_000),
                                       ("folder", 7777)])
def test_streamed_calibration_equals_in_memory(logs, kind, rows):
    cands = CANDIDATES["indt-var-2"]
    ref, _ = _in_memory_calibration(logs[kind], cands)
    st, info = run([logs[kind]], partial(CalibrationStats, cands), load_vehicle("prius3"), rows=rows)
    got = calibrate_from_stats(st)
    assert info.rows == st.rows == ref.counts["rows"]
    assert got.terms == ref.terms and got.n == ref.n
    assert sorted(st.trips) == sorted(TRIPS)
    for k in ("params", "std_err", "p_values"):
        for t in ref.terms:
            assert getattr(got, k)[t] == pytest.approx(getattr(ref, k)[t], rel=RTOL, abs=1e-300)
    for a in ("r2", "r2_uncentered", "reference_mass_kg"):
        assert getattr(got, a) == pytest.approx(getattr(ref, a), rel=RTOL)
    # the statsmodels results object reports the full-sample statistics (issue #9)
    for a in ("nobs", "df_resid", "df_model", "ssr", "llf", "aic", "bic", "rsquared",
              "condition_number", "scale"):
        assert getattr(got.results, a) == pytest.approx(getattr(ref.results, a), rel=RTOL), a
    np.testing.assert_allclose(got.results.tvalues, ref.results.tvalues, rtol=RTOL)
    np.testing.assert_allclose(got.results.conf_int(), ref.results.conf_int(), rtol=RTOL)
    assert list(got.results.model.exog_names) == ref.terms
    with warnings.catch_warnings():  # residual tests of the compact design: not meaningful
        warnings.simplefilter("ignore")
        assert "acc" in got.results.summary().as_text()
    # the same decisions; the selection statistics come from Gram matrices on both paths,
    # whose t-values of nearly collinear candidates (v1, roll, roll_v2) agree to ~1e-7
    assert [(t["action"], t["term"]) for t in got.trace] == [(t["action"], t["term"]) for t in ref.trace]
    for a, b in zip(got.trace, ref.trace):
        for k in ("t_value", "p_value"):
            if k in b:
                assert a[k] == pytest.approx(b[k], rel=1e-4, abs=1e-300)
    for k in ("rows", "trips", "usable", "used", "excluded_total", "excluded_brake"):
        assert got.counts[k] == ref.counts[k], k


def test_trip_subset_fit_equals_in_memory_fit_on_those_trips(logs):
    """Per-trip statistics allow a hold-out by trip without another pass over the data."""
    cands = CANDIDATES["indt-var-1"]
    st, _ = run([logs["parquet"]], partial(CalibrationStats, cands), load_vehicle("prius3"), rows=9000)
    got = calibrate_from_stats(st, trips=["a", "c", "e"])
    m = load_measured([logs["parquet"]], "prius3")
    mask = m.usable & np.isin(m.inputs.trip, ["a", "c", "e"])
    ref = calibrate(m.inputs, m.power_w, cands, mask=mask)
    for t in ref.terms:
        assert got.params[t] == pytest.approx(ref.params[t], rel=RTOL)
        assert got.std_err[t] == pytest.approx(ref.std_err[t], rel=RTOL)


@pytest.mark.parametrize("kind,rows", [("parquet", 6400), ("folder", 20_000)])
def test_streamed_comparison_equals_in_memory(logs, kind, rows):
    veh = load_vehicle("prius3")
    eqs = resolve_equations(["drvpw_prius3", "vsp_ldv1999", "vsp_spec", "epa_prius3"], veh)
    m = load_measured([logs[kind]], "prius3")
    u = m.usable
    ref = compare(m.power_w[u], m.inputs.take(u), eqs, dt_s=m.log.df["dt_s"].to_numpy()[u],
                  reference="drvpw_prius3", trip=m.inputs.trip[u]).to_json()
    cs, _ = run([logs[kind]], partial(CompareStats, eqs, "drvpw_prius3"), veh, rows=rows)
    got = cs.comparison().to_json()
    _close(ref, got)
    assert got["settings"]["percentiles"] == "exact"


def test_reservoir_is_the_same_whatever_the_chunks_and_percentiles_are_estimates(logs):
    """Beyond the reservoir, percentiles come from a uniform sample that does not depend on
    how the data were cut; exact sums (n, mean, RMSE) stay exact."""
    veh = load_vehicle("prius3")
    eqs = [load_equation("vsp_ldv1999")]
    runs = [run([logs["parquet"]], partial(CompareStats, eqs, None, 2000), veh, rows=r)[0]
            for r in (5000, 30_000)]
    k0, k1 = (np.sort(r.res.key) for r in runs)
    np.testing.assert_array_equal(k0, k1)
    a, b = (r.comparison().to_json() for r in runs)
    assert a["settings"]["percentiles"].startswith("estimated")
    _close(a, b)
    m = load_measured([logs["parquet"]], "prius3")
    u = m.usable
    ref = compare(m.power_w[u], m.inputs.take(u), eqs, dt_s=m.log.df["dt_s"].to_numpy()[u]).to_json()
    ra, rb = ref["equations"]["vsp_ldv1999"], a["equations"]["vsp_ldv1999"]
    for k in ("n", "r2", "rmse_w", "bias_w", "mae_w"):
        assert rb[k] == pytest.approx(ra[k], rel=RTOL)
    for x, y in zip(ra["speed_bins"], rb["speed_bins"]):
        assert (x["n"], x["mean_w"] is None) == (y["n"], y["mean_w"] is None)
        if x["n"] > 2000:  # a 2000-sample reservoir of ~45,000 samples: median within ±2 kW
            assert abs(y["median_w"] - x["median_w"]) < 2000.0


@settings(max_examples=40, deadline=None)
@given(st.lists(st.integers(1, 40), min_size=1, max_size=12), st.integers(1, 60))
def test_whole_trips_never_cut_a_trip(tmp_path_factory, lengths, rows):
    d = tmp_path_factory.mktemp("wt")
    trip = np.repeat([f"t{i}" for i in range(len(lengths))], lengths)
    df = pd.DataFrame({"trip_id": trip, "time_s": np.arange(len(trip), dtype=float)})
    p = d / "x.parquet"
    df.to_parquet(p, row_group_size=7)
    batches = list(whole_trips(Part(str(p)), rows=rows))
    back = pd.concat([b for b, _ in batches], ignore_index=True)
    pd.testing.assert_frame_equal(back, df)
    seen = [set(b.trip_id) for b, _ in batches]
    assert sum(len(s) for s in seen) == len(lengths)  # each trip in exactly one batch
    assert [o for _, o in batches] == list(np.cumsum([0] + [len(b) for b, _ in batches[:-1]]))


@settings(max_examples=30, deadline=None)
@given(st.integers(0, 2 ** 31), st.lists(st.integers(0, 50), min_size=1, max_size=8))
def test_moments_merge_equals_direct(seed, sizes):
    rng = np.random.default_rng(seed)
    x = rng.normal(1e4, 3e3, (sum(sizes), 3))
    acc = Moments.empty(3)
    lo = 0
    for s in sizes:
        acc = acc.merge(Moments.of(x[lo:lo + s]))
        lo += s
    assert acc.n == len(x)
    if len(x):
        np.testing.assert_allclose(acc.mean, x.mean(axis=0), rtol=1e-12)
        c = x - x.mean(axis=0)
        np.testing.assert_allclose(acc.m2, c.T @ c, rtol=1e-9, atol=1e-6)


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 2 ** 31), st.integers(20, 400), st.integers(1, 5))
def test_ols_from_factor_equals_statsmodels(seed, n, k):
    rng = np.random.default_rng(seed)
    x = rng.normal(0, 1, (n, k)) * rng.uniform(0.1, 1e3, k)
    y = x @ rng.normal(0, 2, k) + rng.normal(0, 5, n)
    ref = sm.OLS(y, x, hasconst=False).fit()
    # factors of two halves merged by stacking (TSQR), as trips are merged
    xy = np.column_stack([x, y])
    r = np.linalg.qr(np.vstack([np.linalg.qr(xy[: n // 2], mode="r"),
                                np.linalg.qr(xy[n // 2:], mode="r")]), mode="r")
    got = ols_from_r(r, list(range(k)), n)
    for a in ("params", "bse", "pvalues", "tvalues"):
        np.testing.assert_allclose(getattr(got, a), getattr(ref, a), rtol=1e-8)
    for a in ("nobs", "df_resid", "ssr", "llf", "aic", "bic", "rsquared", "condition_number"):
        assert getattr(got, a) == pytest.approx(getattr(ref, a), rel=1e-8), a


def test_plan_cuts_parquet_at_trip_starts_only(logs):
    df = pd.read_parquet(logs["parquet"])
    parts = plan([logs["parquet"]], part_rows=15_000)
    assert len(parts) > 1
    assert [p.start for p in parts] == [0] + [p.stop for p in parts[:-1]]
    assert parts[-1].stop == len(df)
    for p in parts:
        back = pd.concat([b for b, _ in whole_trips(p, rows=4000)], ignore_index=True)
        pd.testing.assert_frame_equal(back, df.iloc[p.start:p.stop].reset_index(drop=True))
        if p.start:  # a cut is a trip start
            assert df.trip_id.iloc[p.start] != df.trip_id.iloc[p.start - 1]
        assert p.stop - p.start >= 15_000 or p is parts[-1]


def test_a_trip_too_long_is_refused(logs):
    with pytest.raises(UserError, match=r"trip 'a' has more than 5000 rows.*trip_id"):
        list(whole_trips(Part(str(logs["parquet"])), rows=2000, max_trip_rows=5000))


def test_a_trip_in_two_files_is_refused(tmp_path):
    df = _trips_frame()
    df.iloc[:100].to_parquet(tmp_path / "x1.parquet")
    df.iloc[100:200].to_parquet(tmp_path / "x2.parquet")
    with pytest.raises(UserError, match=r"x2.parquet: trip_id 'a' is also in .*x1.parquet"):
        run([tmp_path], partial(CalibrationStats, ("acc",)), load_vehicle("prius3"))
    # also when the trip has no usable sample in the first file (the accumulator never saw it)
    bad = df.iloc[:100].copy()
    bad["brake"] = True
    bad.to_parquet(tmp_path / "x1.parquet")
    with pytest.raises(UserError, match=r"x2.parquet: trip_id 'a' is also in .*x1.parquet"):
        run([tmp_path], partial(CalibrationStats, ("acc",)), load_vehicle("prius3"))


def test_cli_streamed_equals_memory_engine(logs, tmp_path, capsys):
    from sumo_drvpw.model.equations import load_equation as load

    outs = {}
    for engine in ("local", "memory"):
        out = tmp_path / f"{engine}.toml"
        assert cli_main(["calibrate", str(logs["folder"]), "--vehicle", "prius3", "--candidates",
                         "indt-var-2", "--out", str(out), "--engine", engine]) == 0
        outs[engine] = load(str(out))
    assert "local engine:" in capsys.readouterr().err
    a, b = outs["memory"], outs["local"]
    assert list(a.terms) == list(b.terms)
    # the same physical reading decides the same way (a constrained refit has no std_err)
    assert a.provenance["physical"]["used"] == b.provenance["physical"]["used"]
    assert set(a.std_err) == set(b.std_err)
    for t in a.terms:
        assert b.terms[t] == pytest.approx(a.terms[t], rel=RTOL)
    for t in a.std_err:
        assert b.std_err[t] == pytest.approx(a.std_err[t], rel=RTOL)
    assert b.speed_range_mps == pytest.approx(a.speed_range_mps, rel=RTOL)
    assert b.accel_range_mps2 == pytest.approx(a.accel_range_mps2, rel=RTOL)


def test_cli_compare_report_streamed(logs, tmp_path):
    import json

    docs = {}
    for engine in ("local", "memory"):
        out = tmp_path / engine
        assert cli_main(["compare", str(logs["parquet"]), "--vehicle", "prius3", "--equation",
                         "drvpw_prius3", "--equation", "vsp_spec", "--out", str(out),
                         "--engine", engine]) == 0
        docs[engine] = json.loads((out / "report.json").read_text(encoding="utf-8"))
        assert (out / "fig8_error_speed.png").stat().st_size > 0
    _close(docs["memory"]["equations"], docs["local"]["equations"])
    assert docs["local"]["n_samples"] == docs["memory"]["n_samples"]


@pytest.mark.parametrize("argv,msg", [
    (["--scheduler", "tcp://127.0.0.1:1"], "--scheduler goes with --engine dask"),
    (["--engine", "dask", "--workers", "0"], "--workers must be from 1 to 256"),
])
def test_engine_flag_errors_exit_2(logs, tmp_path, capsys, argv, msg):
    rc = cli_main(["calibrate", str(logs["parquet"]), "--vehicle", "prius3",
                   "--out", str(tmp_path / "x.toml"), *argv])
    assert rc == 2
    assert msg in capsys.readouterr().err
    assert not (tmp_path / "x.toml").exists()


def test_tall_r_handles_zero_duplicate_and_nearly_collinear_columns():
    """A flat trip (grade column zero), still air at one density (aero = c·v³) and
    v1 against roll (nearly collinear at one mass) all occur per trip in real logs."""
    from sumo_drvpw.fit.stream import tall_r

    rng = np.random.default_rng(3)
    v = rng.uniform(0, 35, 5000)
    cols = [v, v ** 2, v ** 3, 0.37 * v ** 3, np.zeros_like(v),
            v * np.cos(rng.normal(0, 0.01, v.size)), rng.normal(0, 1e3, v.size)]
    a = np.column_stack(cols)
    r = tall_r(a)
    scale = np.sqrt(np.outer(np.diag(a.T @ a), np.diag(a.T @ a))) + 1e-300
    assert np.max(np.abs(r.T @ r - a.T @ a) / scale) < 1e-13
    y = 3.0 * v + 0.2 * v ** 3 + rng.normal(0, 50, v.size)
    ry = tall_r(np.column_stack([a, y]))
    keep = [0, 2, 5, 6]
    ref = sm.OLS(y, a[:, keep], hasconst=False).fit()
    got = ols_from_r(ry, keep, len(y))
    np.testing.assert_allclose(got.params, ref.params, rtol=1e-8)
    np.testing.assert_allclose(got.bse, ref.bse, rtol=1e-8)


def test_signal_candidates_are_read_and_other_extra_columns_are_not(logs):
    """Calibrate reads the canonical columns plus the signals its candidates name; the
    result equals the in-memory path, which reads every column."""
    cands = ("acc", "grade", "aero", "roll", "[engine_on]")
    ref, _ = _in_memory_calibration(logs["parquet"], cands)
    make = partial(CalibrationStats, cands)
    assert "engine_on" in make().columns() and "heading_deg" not in make().columns()
    st, _ = run([logs["parquet"]], make, load_vehicle("prius3"), rows=20_000)
    got = calibrate_from_stats(st)
    assert got.terms == ref.terms
    for t in ref.terms:
        assert got.params[t] == pytest.approx(ref.params[t], rel=RTOL)
    batch = next(whole_trips(Part(str(logs["parquet"])), rows=20_000, columns=make().columns()))[0]
    assert "engine_on" in batch and "heading_deg" not in batch and "speed_mps" in batch


def test_prefetched_keeps_order_raises_the_producers_error_and_stops_early():
    """The read-ahead thread of the local engine: items in order, a producer's error
    (e.g. a bad batch's UserError) raised in the consumer, and no thread left behind when
    the consumer stops early."""
    import threading

    from sumo_drvpw.fit.engine import prefetched

    assert list(prefetched(iter(range(50)))) == list(range(50))

    def bad():
        yield 1
        raise UserError("x.parquet: column 'speed_mps' is 300 at row 7")

    got = []
    with pytest.raises(UserError, match="row 7"):
        for v in prefetched(bad()):
            got.append(v)
    assert got == [1]

    made = []

    def endless():
        i = 0
        while True:
            made.append(i)
            yield i
            i += 1

    it = prefetched(endless())
    assert [next(it) for _ in range(3)] == [0, 1, 2]
    it.close()
    assert not any(t.name == "sumo-drvpw-prefetch" and t.is_alive() for t in threading.enumerate())
    assert len(made) <= 3 + 2  # one item queued, one in production: bounded read-ahead


@settings(max_examples=25, deadline=None)
@given(st.lists(st.integers(1, 40), min_size=1, max_size=10), st.integers(1, 60))
def test_whole_trips_categorical_ids_are_the_same_trips(tmp_path_factory, lengths, rows):
    """Dictionary-encoded trip ids (what the streamed reader uses): categorical frames
    whose ids, rows and cuts equal the text read, across chunk and row-group boundaries."""
    d = tmp_path_factory.mktemp("wtc")
    trip = np.repeat([f"t{i}" for i in range(len(lengths))], lengths)
    df = pd.DataFrame({"time_s": np.arange(len(trip), dtype=float), "trip_id": trip})
    p = d / "x.parquet"
    df.to_parquet(p, row_group_size=9)
    cat = list(whole_trips(Part(str(p)), rows=rows, categorical=True))
    assert all(isinstance(b["trip_id"].dtype, pd.CategoricalDtype) for b, _ in cat)
    back = pd.concat([b.astype({"trip_id": str}) for b, _ in cat], ignore_index=True)
    pd.testing.assert_frame_equal(back, df, check_dtype=False)
    seen = [set(b.trip_id) for b, _ in cat]
    assert sum(len(s) for s in seen) == len(lengths)  # each trip in exactly one batch
    assert [o for _, o in cat] == list(np.cumsum([0] + [len(b) for b, _ in cat[:-1]]))


def test_streamed_calibration_reads_the_ambient_temperature_of_cold_terms(tmp_path):
    """A ``cold`` factor reads ``ambient_c`` without naming it as a ``[col]`` signal; the
    streamed reader selects columns, so it must still read it (regression: the streamed
    calibration dropped ``cold*v^2`` as "zero on these data")."""
    import sumo_drvpw.synth.effects as E
    from sumo_drvpw.model.terms import parse_term

    assert parse_term("cold*v^2").columns == ("ambient_c",) and parse_term("cold*v^2").signals == ()
    df, _ = E.synth_trips(3, 5.0, seed=4, effects=[E.LogPower()])
    # trips at different temperatures, and a drag that rises in the cold (planted)
    amb = np.repeat([-5.0, 10.0, 25.0], len(df) // 3 + 1)[:len(df)]
    df["ambient_c"] = amb
    df["power_w"] = df["power_w"] + 0.2 * (20.0 - amb) * df["speed_mps"] ** 2
    path = tmp_path / "cold.parquet"
    df.to_parquet(path)
    got = {}
    for engine in ("local", "memory"):
        eq = tmp_path / f"{engine}.toml"
        assert cli_main(["calibrate", str(path), "--vehicle", "prius3", "--candidates", "acc,grade,aero,roll,cold*v^2",
                         "--engine", engine, "--out", str(eq)]) == 0
        from sumo_drvpw.fileio import read_toml

        got[engine] = read_toml(eq, "equation")["terms"]
    assert got["local"]["cold*v^2"] == pytest.approx(got["memory"]["cold*v^2"], rel=1e-9)
    assert got["local"]["cold*v^2"] == pytest.approx(0.2, rel=0.1)


@pytest.mark.parametrize("command", ["calibrate", "compare"])
@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_streamed_repeated_trip_id_names_the_file(tmp_path, capsys, command, suffix):
    """Found by the metamorphic sweep: the streamed engines refused a trip id met again
    after another trip without naming the file (the in-memory reader names it)."""
    t = np.arange(0.0, 120.0, 0.5)
    v = 10 + 3 * np.sin(t / 10)
    df = pd.DataFrame({"trip_id": "T7", "time_s": t, "speed_mps": v, "power_w": 300 * v, "mass_kg": 1400.0})
    f = tmp_path / f"log{suffix}"
    both = pd.concat([df, df.assign(trip_id="T8"), df], ignore_index=True)
    both.to_csv(f, index=False) if suffix == ".csv" else both.to_parquet(f)
    args = (["calibrate", str(f), "--out", str(tmp_path / "e.toml")] if command == "calibrate" else
            ["compare", str(f), "--equation", "vsp_ldv1999", "--out", str(tmp_path / "o")])
    assert cli_main(args) == 2
    err = capsys.readouterr().err
    assert f"{f}: trip_id 'T7' appears in more than one place" in err and "Traceback" not in err


@pytest.mark.parametrize("ext", ["parquet", "csv"])
def test_a_missing_required_column_names_the_files_own_columns(tmp_path, capsys, ext):
    """The streamed reader reads only the columns a run needs; a file without 'time_s' was
    refused listing those ("columns: trip_id" for a vendor file of 15 columns). It names
    the file's own columns, as the in-memory reader does."""
    df = pd.DataFrame({"Time": [0.0, 0.1, 0.2], "DAActualSpeed": [1.0, 1.1, 1.2], "REESSCurrent": [3.0, 3.0, 3.0]})
    p = tmp_path / f"vendor.{ext}"
    df.to_parquet(p) if ext == "parquet" else df.to_csv(p, index=False)
    for engine in ("local", "memory"):
        code = cli_main(["calibrate", str(p), "--vehicle", "prius3", "--out", str(tmp_path / "eq.toml"),
                         "--engine", engine])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == 2 and len(err) == 1, err
        # both readers list the file's own columns only (the in-memory one listed the trip_id it adds)
        assert "missing required column 'time_s' (columns: Time, DAActualSpeed, REESSCurrent)" in err[0], err
