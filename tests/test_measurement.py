"""Measurement corrections as data (issue #11 §3): declared by an equation's [measurement],
applied to logs by data/corrections.py, written by calibrate and diagnose, read back by
compare — planted effects recovered, round trips, bad input."""

from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import sumo_drvpw.synth.effects as E
from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.corrections import (distance_mean, fused_sin_grade, fused_sin_grade_distance,
                                         grade_elevation_gaps, shift_within_trips)
from sumo_drvpw.data.log import ReadOptions
from sumo_drvpw.data.measured import load_measured
from sumo_drvpw.errors import UserError
from sumo_drvpw.model.equations import equation_from_dict, load_equation
from sumo_drvpw.model.measurement import Measurement, measurement_from_dict
from sumo_drvpw.synth.track import Noise

NOISE = Noise(process_w=200.0, process_rel=0.01)
TRUTH = "drvpw_prius3"
LAG_S = 1.5
#: the logged grade is the true one smoothed over this [s] (coarse elevation); the fusion's
#: crossover must lie above it to give the accelerometer the band the smoothing removed
SMOOTH_S = 60.0
TAU_S = 240.0


@pytest.fixture(scope="module")
def planted(tmp_path_factory):
    """4 synthetic trips whose power lags speed by 1.5 s and whose logged grade is smoothed
    over 60 s, with a true accelerometer column (synth.effects)."""
    df, _ = E.synth_trips(4, 8.0, seed=21, noise=NOISE,
                          effects=[E.AttenuatedGrade(1.0, SMOOTH_S), E.PowerLag(LAG_S), E.LogPower()])
    path = tmp_path_factory.mktemp("meas") / "log.parquet"
    df.to_parquet(path)
    return path


def _terms(path):
    from sumo_drvpw.fileio import read_toml

    return read_toml(path, "equation")


# ------------------------------------------------------------------ the declaration


@settings(max_examples=40, deadline=None)
@given(lag=st.floats(-60, 60, allow_nan=False), tau=st.floats(0.5, 3600),
       grade=st.sampled_from(["logged", "fused", "accelerometer"]), rho=st.sampled_from(["logged", "altitude"]),
       drop=st.booleans())
def test_measurement_round_trips_through_the_equation_file(lag, tau, grade, rho, drop):
    doc = {"equation": {"name": "e"}, "terms": {"acc": 1.0},
           "measurement": {"power_lag_s": lag, "grade": grade, "fusion_tau_s": tau, "air_density": rho,
                           "exclude_dropouts": drop}}
    eq = equation_from_dict(doc)
    again = equation_from_dict(eq.to_dict())
    assert again.measurement == eq.measurement
    assert eq.measurement.power_lag_s == lag and eq.measurement.grade == grade
    assert eq.measurement.identity == (lag == 0 and grade == "logged" and rho == "logged" and not drop)


@pytest.mark.parametrize("table, key", [({"grade": "gps"}, "grade"), ({"power_lag_s": "1"}, "power_lag_s"),
                                        ({"power_lag_s": 120.0}, "power_lag_s"), ({"fusion_tau_s": 0}, "fusion_tau_s"),
                                        ({"air_density": "sea"}, "air_density"), ({"lag": 1.0}, "lag"),
                                        ({"power_lag_s": math.nan}, "power_lag_s"),
                                        ({"exclude_dropouts": 1}, "exclude_dropouts")])
def test_bad_measurement_table_names_the_key(table, key):
    with pytest.raises(UserError, match=f"f.toml \\[measurement\\].*{key}"):
        measurement_from_dict(table, "f.toml")


# ------------------------------------------------------------------ the corrections


def test_shift_and_fusion_stay_inside_trips():
    codes = np.repeat([0, 1], 5)
    y = np.arange(10.0)
    s = shift_within_trips(y, codes, 2)
    # y(i + 2) inside the trip, NaN where that leaves it (hand calculation)
    np.testing.assert_array_equal(s[:3], [2, 3, 4])
    assert np.isnan(s[3:5]).all() and np.isnan(s[8:]).all()
    # fusion: a constant logged grade and an accelerometer with a constant offset (mounting
    # pitch) give the logged grade: the offset is in the accelerometer's slow part only
    acc = np.full(10, 0.05)
    fused = fused_sin_grade(acc + 0.02, np.full(10, 0.05), codes, 1.0, tau_s=3.0)
    np.testing.assert_allclose(fused, 0.05, atol=1e-12)


def _stop_and_go(n_cycles=40, drive_s=60.0, stand_s=60.0, dt=0.1, v_cruise=12.0):
    """Speed [m/s] of a stop-and-go trip: ramps of 6 s to and from v_cruise, standing between."""
    ramp = np.linspace(0.0, v_cruise, int(6.0 / dt))
    cyc = np.r_[ramp, np.full(int((drive_s - 12.0) / dt), v_cruise), ramp[::-1], np.zeros(int(stand_s / dt))]
    return np.tile(cyc, n_cycles)


def test_distance_fusion_keeps_the_elevation_change_where_a_fusion_in_time_drifts():
    """Planted: a hilly road driven stop-and-go; the logged grade is the true one smoothed
    over 100 m of road (coarse elevation); the accelerometer reads the true grade plus its
    mounting pitch (0.02) plus a pitch while the car stands (0.05 m/s² / g: it stands
    nose-down on its brakes), an error that follows the driving state, not the road. Over
    distance the fusion keeps the trip's elevation change (its slow part weights each sample
    by the road it drove; standing samples weigh nothing); in time the standing pitch leaks
    into the driven samples' slow part and the grade integrates tens of metres off."""
    dt = 0.1
    v = _stop_and_go()
    d = np.cumsum(v * dt) - v * dt / 2
    slope = lambda x: (0.02 * np.cos(2 * np.pi * x / 3000.0)            # noqa: E731
                       + 0.03 * np.cos(2 * np.pi * x / 400.0))          # dh/dx of a road
    true = slope(d)
    grid = np.arange(-200.0, d[-1] + 200.0, 1.0)                        # elevation smoothed over 100 m
    smooth = np.convolve(slope(grid), np.ones(101) / 101, mode="same")
    logged = np.interp(d, grid, smooth)
    acc = true + 0.02 + np.where(v < 0.1, 0.05 / 9.81, 0.0)
    codes = np.zeros(v.size, int)
    h = np.interp(d, grid, np.cumsum(slope(grid)))                      # the logged elevation
    dist = fused_sin_grade_distance(acc, logged, v, dt, codes, 1000.0)
    timed = fused_sin_grade(acc, logged, codes, dt, tau_s=300.0)
    trip, path = np.zeros(v.size, str), np.ones(v.size, bool)
    gap = lambda s: grade_elevation_gaps(s, v, np.full(v.size, dt), trip, h, path)[""]  # noqa: E731
    assert abs(gap(dist)) < 3.0 < 15.0 < abs(gap(timed))
    moving = v > 0.1
    err = lambda s: float(np.sqrt(np.mean((s - true)[moving] ** 2)))  # noqa: E731
    assert err(dist) < 0.3 * min(err(logged), err(acc))
    assert err(dist) < err(timed)


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), length=st.floats(20.0, 2000.0), stand=st.integers(1, 50))
def test_distance_mean_ignores_standing_samples_and_never_crosses_trips(seed, length, stand):
    """Properties of data.corrections.distance_mean: a constant stays that constant;
    standing samples inserted anywhere change nothing at the moving samples (they carry no
    weight) and take the mean of where the car stands; two trips never mix."""
    rng = np.random.default_rng(seed)
    n = 200
    v = rng.uniform(0.5, 30.0, n)
    x = rng.normal(size=n)
    codes = np.r_[np.zeros(n // 2, int), np.ones(n - n // 2, int)]
    np.testing.assert_allclose(distance_mean(np.full(n, 0.7), v, 0.5, codes, length), 0.7, rtol=1e-12)
    base = distance_mean(x, v, 0.5, codes, length)
    at = int(rng.integers(1, n // 2))
    v2 = np.insert(v, at, np.zeros(stand))
    x2 = np.insert(x, at, rng.normal(size=stand) * 100.0)
    c2 = np.insert(codes, at, np.zeros(stand, int))
    got = distance_mean(x2, v2, 0.5, c2, length)
    keep = np.ones(v2.size, bool)
    keep[at:at + stand] = False
    np.testing.assert_allclose(got[keep], base, rtol=1e-9, atol=1e-12)
    assert np.all(np.isfinite(got[~keep]))
    second = distance_mean(np.r_[x[: n // 2], x[n // 2:] + 1e6], v, 0.5, codes, length)
    np.testing.assert_allclose(second[: n // 2], base[: n // 2], rtol=1e-9)
    # a mounting pitch (a constant offset of the accelerometer) drops out of the fusion
    np.testing.assert_allclose(fused_sin_grade_distance(x * 0.01 + 0.02, x * 0.01, v, 0.5, codes, length),
                               np.clip(x * 0.01, -0.3, 0.3), atol=1e-9)


@pytest.mark.parametrize("given_, key, value", [("fused:1000m", "fusion_distance_m", 1000.0),
                                                ("fused:60s", "fusion_tau_s", 60.0),
                                                ("fused:60", "fusion_tau_s", 60.0),
                                                ("fused", "fusion_tau_s", 60.0)])
def test_grade_source_crossover_over_distance_or_in_time(planted, tmp_path, given_, key, value):
    eq = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(planted), "--vehicle", "prius3", "--out", str(eq),
                     "--grade-source", given_]) == 0
    meas = _terms(eq)["measurement"]
    assert meas["grade"] == "fused" and meas[key] == value
    other = ({"fusion_tau_s", "fusion_distance_m"} - {key}).pop()
    assert other not in meas                  # one crossover, in time or over distance
    with pytest.raises(UserError, match="fusion_distance_m"):
        measurement_from_dict({"grade": "fused", "fusion_tau_s": 60, "fusion_distance_m": 500}, "f.toml")


def test_planted_lag_and_smoothed_grade_recovered_by_the_corrections(planted):
    truth = load_equation(TRUTH).terms
    terms = ["acc", "grade", "aero", "roll"]
    from sumo_drvpw.model.terms import term_matrix

    def fit(meas):
        m = load_measured([planted], "prius3", ReadOptions(measurement=meas))
        X = term_matrix(terms, m.inputs)
        X = np.column_stack([X[t] for t in terms]) if isinstance(X, dict) else np.asarray(X)
        b = np.linalg.lstsq(X[m.usable], m.power_w[m.usable], rcond=None)[0]
        return dict(zip(terms, b)), m

    raw, _ = fit(None)
    fixed, m = fit(Measurement(power_lag_s=LAG_S, grade="fused", fusion_tau_s=TAU_S))
    assert m.counts["measurement"]["grade"] == "fused"
    for t in ("acc", "grade", "aero"):
        assert fixed[t] == pytest.approx(truth[t], rel=0.05), (t, fixed[t], truth[t])
    # as read, the lag and the smoothed grade bend the coefficients well away from the truth
    assert abs(raw["acc"] / truth["acc"] - 1) > 0.05


# ------------------------------------------------------------------ the commands


def test_calibrate_writes_the_corrections_and_compare_reads_them_back(planted, tmp_path, capsys):
    eq = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(planted), "--vehicle", "prius3", "--out", str(eq),
                     "--power-lag", str(LAG_S), "--grade-source", f"fused:{TAU_S:g}"]) == 0
    doc = _terms(eq)
    assert doc["measurement"] == {"power_lag_s": LAG_S, "grade": "fused", "fusion_tau_s": TAU_S,
                                  "air_density": "logged", "exclude_dropouts": False}
    assert doc["terms"]["acc"] == pytest.approx(load_equation(TRUTH).terms["acc"], rel=0.05)
    capsys.readouterr()
    # compare without flags reads the log as the equation declares, and says so
    assert cli_main(["compare", str(planted), "--vehicle", "prius3", "--equation", str(eq),
                     "--out", str(tmp_path / "auto")]) == 0
    assert "[measurement] of" in capsys.readouterr().out
    # the same with the flags given by hand, and worse on the log as read
    assert cli_main(["compare", str(planted), "--vehicle", "prius3", "--equation", str(eq), "--power-lag",
                     str(LAG_S), "--grade-source", f"fused:{TAU_S:g}", "--out", str(tmp_path / "hand")]) == 0
    assert cli_main(["compare", str(planted), "--vehicle", "prius3", "--equation", str(eq), "--power-lag", "0",
                     "--grade-source", "logged", "--out", str(tmp_path / "raw")]) == 0  # (each flag: its own setting)
    r = {k: json.loads((tmp_path / k / "report.json").read_text(encoding="utf-8"))["equations"]["eq"]["r2"]
         for k in ("auto", "hand", "raw")}
    assert r["auto"] == pytest.approx(r["hand"], rel=1e-12)
    assert r["auto"] > 0.99 > r["raw"]


def test_streamed_and_in_memory_calibration_apply_the_same_corrections(planted, tmp_path):
    out = {}
    for engine in ("local", "memory"):
        p = tmp_path / f"{engine}.toml"
        assert cli_main(["calibrate", str(planted), "--vehicle", "prius3", "--out", str(p), "--engine", engine,
                         "--power-lag", str(LAG_S), "--grade-source", f"fused:{TAU_S:g}"]) == 0
        out[engine] = _terms(p)
    for t, c in out["memory"]["terms"].items():
        assert out["local"]["terms"][t] == pytest.approx(c, rel=1e-9)
    assert out["local"]["measurement"] == out["memory"]["measurement"]


def test_diagnose_writes_the_lag_it_found_on_top_of_the_one_read(planted):
    from sumo_drvpw.fit.diagnose import DiagnoseOptions, diagnose

    # read with 1.0 s of the 1.5 s corrected: the tracer finds the rest, and the traced
    # equation declares the whole lag its logs need
    m = load_measured([planted], "prius3", ReadOptions(measurement=Measurement(power_lag_s=1.0)))
    res = diagnose(m, load_equation(TRUTH), DiagnoseOptions(max_findings=1))
    lag = [f for f in res.report["findings"] if f.get("kind") == "timing"]
    assert lag and lag[0]["coefficient"] == pytest.approx(0.5, abs=0.125)
    assert res.equation.measurement.power_lag_s == pytest.approx(LAG_S, abs=0.125)
    again = equation_from_dict(res.equation.to_dict())
    assert again.measurement == res.equation.measurement


def test_bad_corrections_are_one_line_exit_2(planted, tmp_path, capsys):
    import pandas as pd

    no_acc = tmp_path / "noacc.parquet"
    pd.read_parquet(planted).drop(columns=["imu_accel_mps2"]).to_parquet(no_acc)
    cases = [
        (["calibrate", str(no_acc), "--vehicle", "prius3", "--grade-source", "fused", "--out",
          str(tmp_path / "a.toml")], "imu_accel_mps2"),
        (["calibrate", str(planted), "--vehicle", "prius3", "--grade-source", "gps", "--out",
          str(tmp_path / "b.toml")], "--grade-source gps"),
        (["calibrate", str(planted), "--vehicle", "prius3", "--grade-source", "fused:x", "--out",
          str(tmp_path / "c.toml")], "--grade-source fused:x"),
        (["calibrate", str(planted), "--vehicle", "prius3", "--grade-source", "fused:-5m", "--out",
          str(tmp_path / "c2.toml")], "fusion_distance_m"),
        (["calibrate", str(planted), "--vehicle", "prius3", "--power-lag", "600", "--out",
          str(tmp_path / "d.toml")], "power_lag_s"),
    ]
    for argv, needle in cases:
        assert cli_main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert needle in err and len(err.splitlines()) == 1 and "Traceback" not in err
    # two equations calibrated on differently corrected logs: choose, do not guess
    e1, e2 = tmp_path / "e1.toml", tmp_path / "e2.toml"
    for p, lag in ((e1, "1.5"), (e2, "1.0")):
        assert cli_main(["calibrate", str(planted), "--vehicle", "prius3", "--power-lag", lag, "--out", str(p)]) == 0
    capsys.readouterr()
    assert cli_main(["compare", str(planted), "--vehicle", "prius3", "--equation", str(e1), "--equation",
                     str(e2), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "differently corrected" in err and "--power-lag" in err
    assert not (tmp_path / "o").exists()


def test_air_density_at_altitude_restores_the_aero_coefficient(tmp_path):
    df, _ = E.synth_trips(6, 6.0, seed=5, noise=NOISE, effects=[E.AltitudeAir(), E.LogPower()])
    path = tmp_path / "alt.parquet"
    df.drop(columns=["pressure_kpa"]).to_parquet(path)
    from sumo_drvpw.model.air import air_density

    # the truth's aero term v·(v − w)² has no ρ; at the synthetic log's own air (its ambient
    # temperature and 100.8 kPa, synth.track) it is ½·ρ·C_d·A, so C_d·A = 2·aero/ρ
    rho_state = air_density(float(df["ambient_c"].mean()), float(df["pressure_kpa"].mean()))
    cda = 2.0 * load_equation(TRUTH).terms["aero"] / rho_state
    got = {}
    for rho in ("logged", "altitude"):
        eq = tmp_path / f"{rho}.toml"
        assert cli_main(["calibrate", str(path), "--vehicle", "prius3", "--candidates", "acc,grade,aero_rho,roll",
                         "--air-density", rho, "--out", str(eq)]) == 0
        got[rho] = _terms(eq)["terms"]["aero_rho"]
    # sea-level ρ where the car drove at up to 1500 m: C_d·A absorbs the thinner air; at
    # the altitude's pressure it is the vehicle's again (the ρ-free ``aero`` term cannot
    # tell: use aero_rho where the air density varies)
    assert abs(got["altitude"] / cda - 1) < abs(got["logged"] / cda - 1)
    assert abs(got["altitude"] / cda - 1) < 0.03


def test_exclude_dropouts_leaves_out_a_planted_logger_hold(tmp_path, capsys):
    df, _ = E.synth_trips(2, 6.0, seed=9, noise=NOISE, effects=[E.LogPower()])
    planted_rows = E.plant_dropout(df, "synth-2", 60.0, 45.0, mode="hold")
    path = tmp_path / "drop.parquet"
    df.to_parquet(path)
    m0 = load_measured([path], "prius3")
    m1 = load_measured([path], "prius3", ReadOptions(measurement=Measurement(exclude_dropouts=True)))
    assert not m1.usable[planted_rows].any() and m0.usable[planted_rows].all()
    assert m1.counts["excluded_dropouts"] >= planted_rows.sum()
    assert m1.counts["measurement"]["exclude_dropouts"] is True
    # outside the hold and its grade-smoothing margin nothing else is taken out
    assert (m0.usable & ~m1.usable).sum() == m1.counts["excluded_dropouts"]
    assert m1.counts["excluded_dropouts"] < planted_rows.sum() + 2 * 200
    # and a log without an accelerometer cannot say: one line naming the columns, exit 2
    no_acc = tmp_path / "noacc.parquet"
    df.drop(columns=["imu_accel_mps2"]).to_parquet(no_acc)
    assert cli_main(["calibrate", str(no_acc), "--vehicle", "prius3", "--exclude-dropouts", "--out",
                     str(tmp_path / "e.toml")]) == 2
    err = capsys.readouterr().err
    assert "imu_accel_mps2" in err and len(err.strip().splitlines()) == 1


def test_calibrate_hints_the_accelerometer_grade_when_the_grade_is_implausible(tmp_path, capsys):
    df, _ = E.synth_trips(3, 6.0, seed=3, noise=NOISE, effects=[E.AttenuatedGrade(0.4, 30.0), E.LogPower()])
    path, no_acc = tmp_path / "g.parquet", tmp_path / "g_noacc.parquet"
    df.to_parquet(path)
    df.drop(columns=["imu_accel_mps2"]).to_parquet(no_acc)
    for log, engine, hinted in ((path, "local", True), (path, "memory", True), (no_acc, "local", False)):
        assert cli_main(["calibrate", str(log), "--vehicle", "prius3", "--engine", engine,
                         "--out", str(tmp_path / "e.toml")]) == 0
        out = capsys.readouterr().out
        assert "implausible" in out and "grade" in out
        assert ("hint:" in out and "--grade-source fused" in out) == hinted, out


def test_diagnose_names_the_calibrate_flags_that_correct_its_measurement_findings(planted, tmp_path, capsys):
    assert cli_main(["diagnose", str(planted), "--vehicle", "prius3", "--equation", TRUTH, "--no-figures",
                     "--max-findings", "2", "--out", str(tmp_path / "d")]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if "sumo-drvpw calibrate" in ln)
    assert "--power-lag 1.5" in line and "--grade-source fused " in line + " "
    eq = _terms(tmp_path / "d" / "final_equation.toml")
    assert eq["measurement"]["power_lag_s"] == pytest.approx(LAG_S, abs=0.125)


@pytest.mark.parametrize("stream", ["no", "yes"])
def test_diagnose_in_memory_and_streamed_declare_the_whole_lag(planted, tmp_path, stream):
    out = tmp_path / stream
    assert cli_main(["diagnose", str(planted), "--vehicle", "prius3", "--equation", TRUTH, "--power-lag", "1.0",
                     "--stream", stream, "--no-figures", "--max-findings", "1", "--out", str(out)]) == 0
    assert _terms(out / "final_equation.toml")["measurement"]["power_lag_s"] == pytest.approx(LAG_S, abs=0.125)


def test_calibrate_hints_the_power_lag_when_acc_reads_below_one(tmp_path, capsys):
    """A planted 1.5-s lag of the power behind the speed pulls the acc coefficient below 1:
    calibrate says a lag is the usual cause and how to correct it in the data; given
    --power-lag, or on a log without a lag, it does not."""
    df, _ = E.synth_trips(3, 6.0, seed=5, noise=NOISE, effects=[E.PowerLag(1.5), E.LogPower()])
    path = tmp_path / "lag.parquet"
    df.to_parquet(path)
    assert cli_main(["calibrate", str(path), "--vehicle", "prius3", "--out", str(tmp_path / "e.toml")]) == 0
    out = capsys.readouterr().out
    assert "acc = " in out and "hint:" in out and "--power-lag" in out, out
    assert cli_main(["calibrate", str(path), "--vehicle", "prius3", "--power-lag", "1.5",
                     "--out", str(tmp_path / "f.toml")]) == 0
    assert "--power-lag S" not in capsys.readouterr().out
    clean, _ = E.synth_trips(3, 6.0, seed=5, noise=NOISE, effects=[E.LogPower()])
    clean.to_parquet(tmp_path / "clean.parquet")
    assert cli_main(["calibrate", str(tmp_path / "clean.parquet"), "--vehicle", "prius3",
                     "--out", str(tmp_path / "g.toml")]) == 0
    assert "--power-lag" not in capsys.readouterr().out


# ------------------------------------------------------------------ the logger's accelerometer offset

#: planted mounting pitch of the logger [m/s²] (about 0.9°)
MOUNT_MPS2 = 0.15
#: planted per-trip error of the logged elevation change [m] (GPS elevation settling):
#: a ramp along each trip, as large as the true elevation range of a trip
ELEV_DRIFT_M = (-30.0, 25.0, -15.0, 35.0, -25.0, 10.0, 0.0)


@pytest.fixture(scope="module")
def mounted(tmp_path_factory):
    """7 synthetic trips whose accelerometer carries a mounting offset and whose logged
    elevation drifts by a different amount on each trip; no grade column (the grade is read
    from the elevation)."""
    df, _ = E.synth_trips(len(ELEV_DRIFT_M), 6.0, seed=40, noise=NOISE, effects=[E.LogPower()])
    ramp = np.zeros(len(df))
    for tid, drift in zip(pd.unique(df["trip_id"]), ELEV_DRIFT_M):
        i = np.flatnonzero(df["trip_id"].to_numpy() == tid)
        ramp[i] = drift * np.linspace(0.0, 1.0, len(i))
    df = df.drop(columns=["grade_rad"]).rename(columns={"gps_elevation_m": "elevation_m"})
    df["elevation_m"] = df["elevation_m"] + ramp
    df["imu_accel_mps2"] = df["imu_accel_mps2"] + MOUNT_MPS2
    path = tmp_path_factory.mktemp("mount") / "log.parquet"
    df.to_parquet(path)
    return path


def test_logger_offset_recovered_and_its_grade_beats_the_per_trip_offsets(mounted):
    from sumo_drvpw.data.corrections import driven_path, logger_offset_mps2
    from sumo_drvpw.fit.compare import trip_energy
    from sumo_drvpw.fit.input_checks import accelerometer_offsets

    m = load_measured([mounted], "prius3")
    df = m.log.df
    per = accelerometer_offsets(df["imu_accel_mps2"], m.inputs.a, df["speed_mps"], df["elevation_m"],
                                df["dt_s"], df["trip_id"], driven_path(m.log, m.inputs.v))
    offs = [d["offset_elevation"] for d in per.values()]
    # each trip's elevation error moves its own offset (≥ 0.01 m/s² on some trips) ...
    assert max(abs(o - MOUNT_MPS2) for o in offs) > 0.01
    est = logger_offset_mps2(offs, [d["distance_m"] for d in per.values()])
    # ... the median over trips keeps the mounting pitch
    assert est == pytest.approx(MOUNT_MPS2, abs=0.005)
    truth = load_equation(TRUTH)

    def trip_errors(meas):
        mm = load_measured([mounted], "prius3", ReadOptions(measurement=meas))
        u = mm.usable & np.isfinite(np.sin(mm.inputs.theta))
        te = trip_energy(truth.power(mm.inputs)[u], mm.power_w[u], mm.log.df["dt_s"].to_numpy()[u],
                         mm.log.df["trip_id"].to_numpy()[u])
        return np.array([abs(t["error"]) for t in te["trips"].values()])

    fixed = trip_errors(Measurement(grade="accelerometer", accelerometer_offset_mps2=est))
    per_trip = trip_errors(Measurement(grade="accelerometer"))
    logged = trip_errors(None)
    # the true equation on the logger-offset grade books every trip's energy as measured;
    # the per-trip offsets carry each trip's elevation error into its grade
    assert fixed.max() < 0.01, fixed
    assert per_trip.max() > 2 * fixed.max() and per_trip.mean() > fixed.mean()
    assert logged.mean() > fixed.mean()


def test_accelerometer_offset_declared_round_trips_and_bad_values_name_the_key(tmp_path):
    doc = {"equation": {"name": "e"}, "terms": {"acc": 1.0},
           "measurement": {"grade": "accelerometer", "accelerometer_offset_mps2": 0.12}}
    eq = equation_from_dict(doc)
    assert equation_from_dict(eq.to_dict()).measurement == eq.measurement
    assert "fixed offset of +0.12 m/s²" in eq.measurement.describe()
    # unset, the key is left out of the file (TOML has no null)
    assert "accelerometer_offset_mps2" not in Measurement(grade="accelerometer").to_dict()
    for table in ({"grade": "fused", "accelerometer_offset_mps2": 0.1},
                  {"grade": "accelerometer", "accelerometer_offset_mps2": 3.0},
                  {"grade": "accelerometer", "accelerometer_offset_mps2": "0.1"}):
        with pytest.raises(UserError, match="f.toml \\[measurement\\] accelerometer_offset_mps2"):
            measurement_from_dict(table, "f.toml")


def test_grade_source_option_takes_the_logger_offset(mounted, tmp_path, capsys):
    out = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(mounted), "--vehicle", "prius3", "--out", str(out),
                     "--grade-source", f"accelerometer:{MOUNT_MPS2}"]) == 0
    doc = _terms(out)
    assert doc["measurement"]["grade"] == "accelerometer"
    assert doc["measurement"]["accelerometer_offset_mps2"] == MOUNT_MPS2
    assert doc["terms"]["grade"] == pytest.approx(load_equation(TRUTH).terms["grade"], rel=0.05)
    capsys.readouterr()
    for bad in ("logged:3", "accelerometer:x"):
        assert cli_main(["compare", str(mounted), "--vehicle", "prius3", "--equation", str(out),
                         "--grade-source", bad, "--out", str(tmp_path / "r")]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and f"--grade-source {bad}" in err


def test_grade_elevation_gap_by_hand_and_reported(mounted, tmp_path, capsys):
    """data.corrections.grade_elevation_gaps: Σ v·sin θ·Δt over a trip minus its logged
    elevation change. The per-trip-offset accelerometer grade keeps every trip's elevation
    change by construction (no trip reported); a long fusion in time need not, and the
    reader counts, and compare names, the trips it misses by more than 20 m."""
    from sumo_drvpw.data.corrections import GRADE_GAP_NOTE_M, grade_elevation_gaps

    n = 100
    gaps = grade_elevation_gaps(np.full(n, 0.01), np.full(n, 10.0), np.ones(n), np.array(["T"] * n),
                                np.linspace(0.0, 4.0, n), np.ones(n, bool))
    assert gaps == {"T": pytest.approx(10.0 - 4.0)}
    per_trip = load_measured([mounted], "prius3", ReadOptions(measurement=Measurement(grade="accelerometer")))
    assert per_trip.log.counts["grade_elevation_gap_trips"] == 0
    # a fusion in time weights its slow part by time, the grade power by distance: with a
    # crossover as long as the trips it misses some trips' elevation change by tens of metres
    fused = load_measured([mounted], "prius3", ReadOptions(measurement=Measurement(grade="fused",
                                                                                  fusion_tau_s=3600.0)))
    c = fused.log.counts
    assert c["grade_elevation_gap_trips"] >= 1
    assert all(abs(g) > GRADE_GAP_NOTE_M for g in c["grade_elevation_gap_m"].values())
    eq = tmp_path / "e.toml"
    eq.write_text('[equation]\nname = "e"\n[terms]\nacc = 1.0\nroll = 0.01\ngrade = 1.0\n'
                  '[measurement]\ngrade = "fused"\nfusion_tau_s = 3600.0\n', encoding="utf-8")
    capsys.readouterr()
    assert cli_main(["compare", str(mounted), "--vehicle", "prius3", "--equation", str(eq),
                     "--out", str(tmp_path / "r")]) == 0
    out = capsys.readouterr().out
    assert f"on {c['grade_elevation_gap_trips']} trip(s) the corrected grade integrates" in out


@pytest.mark.parametrize("h_m, p_kpa", [(0.0, 101.325), (1000.0, 89.875), (2000.0, 79.496), (3000.0, 70.109)])
def test_standard_atmosphere_pressure_matches_the_icao_table(h_m, p_kpa):
    """model/air.py's pressure at altitude against the ICAO standard atmosphere (ICAO Doc 7488,
    ISO 2533) at geopotential altitudes 0, 1, 2, 3 km: 101.325, 89.875, 79.496, 70.109 kPa
    (the tables' values, rounded to 89.88, 79.50, 70.11 kPa in short tables). To 0.02 kPa:
    the g = 9.81 m/s² of constants.py where the ISA has 9.80665 lowers p(3 km) by 0.009 kPa
    (by hand: the exponent g·M/(R·L) grows by 0.0018, times ln(1 − 0.0065·3000/288.15) =
    −0.070). With the ISA sea-level temperature of 15 °C, ρ at 0 m is the ISA's 1.2250 kg/m³."""
    from sumo_drvpw.model.air import air_density, pressure_at_altitude_kpa

    assert float(pressure_at_altitude_kpa(h_m)) == pytest.approx(p_kpa, abs=0.02)
    if h_m == 0.0:
        assert air_density(15.0, float(pressure_at_altitude_kpa(h_m))) == pytest.approx(1.2250, abs=1e-4)
