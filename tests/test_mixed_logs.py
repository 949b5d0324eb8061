"""A folder of drive logs from different loggers reads the same in memory and streamed, and
each file as it would be read alone (README: "Each trip is derived on its own ... so logs
of different loggers may share a folder"): its own wind, air density, grade and power
columns, whatever the other files carry, and the sources said of all files.

Each test plants two or three small logs that differ in one kind of column, reads the
folder in memory, each file alone and the folder streamed in small batches (``ROWS``: every
file takes several), with either file first.
"""

from functools import partial

import numpy as np
import pandas as pd
import pytest

import corpus
from sumo_drvpw.data.measured import load_measured, resolve_equations
from sumo_drvpw.fit.compare import compare
from sumo_drvpw.fit.engine import run
from sumo_drvpw.fit.stream import CalibrationStats
from sumo_drvpw.fit.stream_compare import CompareStats
from sumo_drvpw.model.constants import RHO_DEFAULT
from sumo_drvpw.model.equations import load_equation

ROWS = 700  # rows per streamed batch
#: counts that describe where the inputs came from and which samples are used
KEYS = ("usable", "excluded_total", "excluded_nan_wind_mps", "excluded_nan_air_density_kgm3",
        "excluded_nan_grade_rad", "wind_source", "air_density_source", "grade_source",
        "grade_filled_rows", "grade_flat_trips", "air_density_default_samples",
        "elevation_missing_samples", "power_source", "wind_rows", "air_density_rows", "grade_rows",
        "power_rows")


def _drive(letter, hz=10.0, n_s=75.0, seed=0):
    """A file's two trips (``letter`` 1 and 2) of smooth stop-and-go driving, 750 rows each
    (so each is a batch of its own), the wheel power a road load (every sample usable)."""
    rng = np.random.default_rng(seed)
    out = []
    for k in (1, 2):
        t = np.arange(0.0, n_s, 1.0 / hz)
        v = 12.0 + 6.0 * np.sin(2 * np.pi * t / 40.0 + rng.uniform(0, 6)) + 2.0 * np.sin(2 * np.pi * t / 7.0)
        a = np.gradient(v, t)
        out.append(pd.DataFrame({"trip_id": f"{letter}{k}", "time_s": t, "speed_mps": v,
                                 "power_w": 1500.0 * v * a + 150.0 * v + 0.4 * v ** 3, "mass_kg": 1500.0}))
    return pd.concat(out, ignore_index=True)


def _file_of(m) -> np.ndarray:
    """Each sample's file letter (its trip's first character)."""
    return np.array([t[0] for t in m.inputs.trip])


def _folder(tmp_path, logs: dict, first: str):
    """``logs`` (name → frame) written as CSV, the one named ``first`` sorting first."""
    d = tmp_path / "logs"
    d.mkdir()
    for name, df in logs.items():
        df.to_csv(d / f"{'a' if name == first else 'z'}_{name}.csv", index=False)
    return d


def _pick(counts):
    return {k: counts[k] for k in KEYS if k in counts}


def _each_file_as_alone(d, m):
    """Every file's samples in the folder read in memory as the file read alone: the same
    samples used and the same inputs and measured power."""
    trip = m.log.df["trip_id"].to_numpy()
    for f in sorted(d.iterdir()):
        alone = load_measured([f])
        rows = np.isin(trip, pd.unique(alone.log.df["trip_id"]))
        assert rows.sum() == len(alone.log)
        np.testing.assert_array_equal(m.usable[rows], alone.usable, err_msg=f.name)
        for x in ("wind", "rho", "theta", "a", "v"):
            np.testing.assert_allclose(getattr(m.inputs, x)[rows], getattr(alone.inputs, x), rtol=0,
                                       atol=1e-12, err_msg=f"{f.name}: {x}")
        np.testing.assert_allclose(m.power_w[rows], alone.power_w, rtol=0, atol=1e-9, err_msg=f.name)


def _streamed_as_in_memory(d, m):
    """The streamed paths (compare, calibrate, diagnose) report the in-memory counts, and
    the comparison is the in-memory one."""
    from sumo_drvpw.fit.diagnose.stream_run import diagnose_stream

    eqs = resolve_equations(["vsp_ldv1999"])
    cs, _ = run([d], partial(CompareStats, eqs, None), None, rows=ROWS)
    st, _ = run([d], partial(CalibrationStats, ("acc", "roll", "aero")), None, rows=ROWS)
    res = diagnose_stream([d], None, load_equation("vsp_ldv1999"), rows=ROWS, sample_rows=ROWS)
    ref = _pick(m.counts)
    for got in (cs.counts, st.counts, res.details["reader_counts"]):
        corpus.assert_close_documents(ref, _pick(got), 1e-9)
    assert cs.source == st.source == res.equation.provenance["power_source"] == m.source
    u = m.usable
    mem = compare(m.power_w[u], m.inputs.take(u), eqs, dt_s=m.log.df["dt_s"].to_numpy()[u],
                  trip=m.inputs.trip[u]).to_json()
    corpus.assert_close_documents(mem, cs.comparison().to_json(), 1e-9, same_keys=False)
    return ref


@pytest.mark.parametrize("first", ["column", "none"])
def test_wind_of_each_file_as_read_alone(tmp_path, first):
    """Found by review: in memory, a file without wind_mps read with one that has it got NaN
    wind, so all its rows were left out (excluded_nan_wind_mps 1500, usable 1500), while the
    streamed paths read it as still air (0 and 3000). A file that logs no wind is still air,
    one that logs the air speed has speed − air speed, in memory and streamed."""
    a = _drive("A", seed=1)
    logs = {"column": a.assign(wind_mps=1.0 + 0.5 * np.sin(a["time_s"] / 9.0)),
            "airspeed": _drive("B", seed=2).assign(airspeed_mps=lambda x: x["speed_mps"] + 2.0),
            "none": _drive("C", seed=3)}
    d = _folder(tmp_path, logs, first)
    m = load_measured([d])
    assert m.counts["usable"] == 4500 and not m.counts["excluded_nan_wind_mps"]
    wind = pd.Series(m.inputs.wind).groupby(_file_of(m)).agg(["min", "max"])
    assert wind.loc["C"].tolist() == [0.0, 0.0]
    np.testing.assert_allclose(wind.loc["B"].tolist(), [-2.0, -2.0], rtol=0, atol=1e-12)
    _each_file_as_alone(d, m)
    ref = _streamed_as_in_memory(d, m)
    assert ref["wind_source"] == ("wind_mps column for 1500 rows; speed − airspeed_mps for 1500 rows; "
                                  "none (still air assumed) for 1500 rows")


@pytest.mark.parametrize("first", ["column", "none"])
def test_air_density_of_each_file_as_read_alone(tmp_path, first):
    """Found by review (as the wind): a file without air_density_kgm3 read with one that has
    it got NaN density in memory and was left out. A file with ambient_c gets the ideal gas
    (standard pressure where none is logged; the default density where no temperature is),
    one with neither the default density, as read alone."""
    b = _drive("B", seed=2).assign(ambient_c=25.0)
    b.loc[:99, "ambient_c"] = np.nan  # 10 s without a temperature: the default density there
    logs = {"column": _drive("A", seed=1).assign(air_density_kgm3=1.1), "ambient": b,
            "none": _drive("C", seed=3)}
    d = _folder(tmp_path, logs, first)
    m = load_measured([d])
    assert m.counts["usable"] == 4500 and not m.counts["excluded_nan_air_density_kgm3"]
    rho = pd.Series(m.inputs.rho).groupby(_file_of(m)).agg(["min", "max"])
    assert rho.loc["A"].tolist() == [1.1, 1.1] and rho.loc["C"].tolist() == [RHO_DEFAULT, RHO_DEFAULT]
    # 101.325 kPa / (287.05 J/(kg·K) · 298.15 K) = 1.184 kg/m³
    np.testing.assert_allclose(rho.loc["B", "min"], 1.184, atol=1e-3)
    assert m.counts["air_density_default_samples"] == 100
    _each_file_as_alone(d, m)
    ref = _streamed_as_in_memory(d, m)
    # (B logs no pressure: standard pressure, said so; its 100 rows without a temperature
    # take the default density and are counted there — both were said as 'ideal gas from
    # ambient_c and pressure_kpa for 1500 rows', a rehearsal's OBD log without pressure)
    assert ref["air_density_source"] == ("air_density_kgm3 column for 1500 rows; ideal gas from ambient_c "
                                         "at standard pressure (101.325 kPa) for 1400 rows; default "
                                         f"{RHO_DEFAULT} kg/m³ for 1600 rows")


@pytest.mark.parametrize("first", ["rad", "pct"])
def test_grade_of_each_file_from_its_own_column(tmp_path, first):
    """Found by review: in memory, a file with only grade_pct read with one that has grade_rad
    had its grade_pct ignored (its grade taken from elevation, or read flat); streamed used
    it. Each file's own grade column is used: grade_rad, else grade_pct, else elevation, else
    a flat road, as read alone."""
    b, c = _drive("B", seed=2), _drive("C", seed=3)
    logs = {"rad": _drive("A", seed=1).assign(grade_rad=0.02),
            "pct": b.assign(grade_pct=3.0, elevation_m=100.0 - 0.01 * np.cumsum(b["speed_mps"] * 0.1)),  # not read
            "elev": c.assign(elevation_m=100.0 + 0.04 * np.cumsum(c["speed_mps"] * 0.1)),
            "none": _drive("D", seed=4)}
    d = _folder(tmp_path, logs, first)
    m = load_measured([d])
    theta = pd.Series(m.inputs.theta).groupby(_file_of(m))
    np.testing.assert_allclose(theta.min()[["A", "B"]], [0.02, np.arctan(0.03)], rtol=1e-12)
    np.testing.assert_allclose(theta.median()["C"], np.arctan(0.04), rtol=0.05)  # climbs 4 %
    assert theta.max()["D"] == 0.0 == theta.min()["D"]
    _each_file_as_alone(d, m)
    ref = _streamed_as_in_memory(d, m)
    assert ref["grade_filled_rows"] == 3000 and ref["grade_flat_trips"] == ["D1", "D2"]
    assert ref["grade_source"] == ("grade_rad column for 1500 rows; grade_pct column for 1500 rows; "
                                   "elevation_m over distance: 1 m grid, 100 m moving average, gradient "
                                   "for 1500 rows")


@pytest.mark.parametrize("first", ["power", "motor"])
def test_measured_power_of_each_file_from_its_own_columns(tmp_path, first):
    """Found by review: in memory, a file with only motor torque and speed read with one that
    has power_w got NaN power (all its rows left out), while the streamed paths used its
    motor power and said the source of whichever batch came first ('direct (power_w)' or
    'single motor ...'). Each file's power comes from its own columns, as read alone, and
    the source says both, in memory and streamed."""
    from sumo_drvpw.model.constants import RPM

    b = _drive("B", seed=2)
    w = b["speed_mps"] / 0.3 * 8.0  # motor speed [rad/s]: wheel radius 0.3 m, gear ratio 8
    motor = b.assign(motor_speed_rpm=w / RPM, motor_torque_nm=b["power_w"] / w)
    logs = {"power": _drive("A", seed=1), "motor": motor.drop(columns="power_w")}
    d = _folder(tmp_path, logs, first)
    m = load_measured([d])
    rows = _file_of(m) == "B"
    assert m.counts["usable"] == 3000
    np.testing.assert_allclose(m.power_w[rows], b["power_w"], rtol=1e-12)
    _each_file_as_alone(d, m)
    ref = _streamed_as_in_memory(d, m)
    assert ref["power_source"] == ("direct (power_w) for 1500 rows; single motor (motor torque × motor speed) "
                                   "for 1500 rows")


@pytest.mark.parametrize("first", ["flags", "none"])
def test_brake_and_reverse_flags_of_each_file_as_read_alone(tmp_path, first):
    """Found while fixing the above: in memory, a file without the brake and reverse columns
    read with one that has them got NaN there, read as set: all its rows were left out as
    braking and reversing (excluded_brake 1500, usable 1500; streamed 0 and 3000). A file
    that marks no braking has none marked, as read alone."""
    a = _drive("A", seed=1).assign(brake=False, reverse=0)
    a.loc[:99, "brake"] = True  # 10 s of braking: left out
    d = _folder(tmp_path, {"flags": a, "none": _drive("B", seed=2)}, first)
    m = load_measured([d])
    assert (m.counts["excluded_brake"], m.counts["excluded_reverse"], m.counts["usable"]) == (100, 0, 2900)
    _each_file_as_alone(d, m)
    ref = _streamed_as_in_memory(d, m)
    cs, _ = run([d], partial(CompareStats, resolve_equations(["vsp_ldv1999"]), None), None, rows=ROWS)
    assert (cs.counts["excluded_brake"], cs.counts["excluded_reverse"]) == (100, 0) and ref["usable"] == 2900


BATTERY_EQ = """[equation]
name = "ev"
[terms]
acc = 1.0
v1 = 150.0
v3 = 0.4
[chain]
predicts = "battery"
traction_efficiency = 0.9
recuperation_efficiency = 0.7
aux_power_w = 400.0
"""


def _battery(df, volts=355.0):
    """The battery V and I of a wheel power: its chain (90 % out, 70 % back, 400 W aux)."""
    p = df["power_w"].to_numpy()
    return df.assign(battery_voltage_v=volts,
                     battery_current_a=(np.where(p > 0, p / 0.9, p * 0.7) + 400.0) / volts)


def _compare_streamed_and_in_memory(tmp_path, capsys, monkeypatch, d, target, equation=BATTERY_EQ):
    """report.json of `compare --target` with ``equation`` streamed (batches of ROWS) and
    --engine memory: equal to 1e-9."""
    import json

    import sumo_drvpw.fit.engine as engine
    from sumo_drvpw.cli import main as cli_main

    eq = tmp_path / "eq.toml"
    eq.write_text(equation, encoding="utf-8")
    monkeypatch.setattr(engine, "run", partial(engine.run, rows=ROWS))
    docs = {}
    for e in ("memory", "local"):
        out = tmp_path / e
        rc = cli_main(["compare", str(d), "--equation", str(eq), "--target", target, "--out", str(out),
                       "--engine", e])
        assert rc == 0, capsys.readouterr().err
        capsys.readouterr()
        docs[e] = json.loads((out / "report.json").read_text(encoding="utf-8"))
    docs["local"]["settings"].pop("percentiles")
    corpus.assert_close_documents(docs["memory"], docs["local"], 1e-9)
    return docs["memory"]


@pytest.mark.parametrize("first", ["power", "motor"])
def test_battery_target_of_a_mixed_folder_streamed_as_in_memory(tmp_path, capsys, monkeypatch, first):
    """The battery target of a folder of different loggers (one logs power_w and wind, one
    motor torque and speed, one its elevation; each its battery V and I): `compare --target
    battery` streamed is the in-memory report, counts and sources included."""
    from sumo_drvpw.model.constants import RPM

    b = _drive("B", seed=2)
    w = b["speed_mps"] / 0.3 * 8.0
    c = _drive("C", seed=3)
    logs = {"power": _battery(_drive("A", seed=1)).assign(wind_mps=1.0),
            "motor": _battery(b).assign(motor_speed_rpm=w / RPM, motor_torque_nm=b["power_w"] / w)
                                .drop(columns="power_w"),
            "elev": _battery(c).assign(elevation_m=100.0 + 0.04 * np.cumsum(c["speed_mps"] * 0.1))}
    d = _folder(tmp_path, logs, first)
    m = load_measured([d], target="battery")
    assert m.counts["usable"] == 4500
    doc = _compare_streamed_and_in_memory(tmp_path, capsys, monkeypatch, d, "battery")
    c = doc["context"]["counts"]
    assert c["power_source"] == "battery V·I (current positive = discharge)"
    assert c["power_rows"] == {"battery V·I (current positive = discharge)": 4500}
    assert c["wind_source"].startswith("wind_mps column for 1500 rows")


@pytest.mark.parametrize("target", ["wheel", "battery", "fuel"])
@pytest.mark.parametrize("first", ["with", "without"])
def test_a_file_that_cannot_give_the_target_is_refused_by_name(tmp_path, capsys, target, first):
    """Found by review: a file of a folder without any column of the target (wheel: no power
    column at all; battery: no battery V and I; fuel: no fuel or air flow), read with one
    that has them, was read in
    memory as NaN (all its rows left out, counted), streamed or alone refused. A file that
    cannot give the target is a file the user must drop or map; it is refused as read alone,
    one line naming it, in memory and streamed (the CLI: exit 2, nothing written)."""
    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.errors import UserError

    a = _drive("A", seed=1)
    has = {"wheel": a, "battery": _battery(a), "fuel": a.assign(fuel_rate_gps=0.5)}[target]
    logs = {"with": has,
            "without": _drive("B", seed=2).drop(columns="power_w")}
    d = _folder(tmp_path, logs, first)
    bad = next(f for f in d.iterdir() if f.name.endswith("_without.csv"))
    with pytest.raises(UserError) as mem:
        load_measured([d], target=target)
    with pytest.raises(UserError) as streamed:
        eq = {"wheel": "vsp_ldv1999", "battery": "bmw_i3_battery", "fuel": "epa_gasoline_car"}[target]
        run([d], partial(CompareStats, resolve_equations([eq]), None, target=target), None, rows=ROWS)
    with pytest.raises(UserError) as alone:
        load_measured([bad], target=target)
    assert str(mem.value) == str(streamed.value) == str(alone.value)
    assert str(mem.value).startswith(f"{bad}: ") and "\n" not in str(mem.value)
    if target != "wheel":  # an equation without measurement corrections
        (tmp_path / "ev.toml").write_text(BATTERY_EQ if target == "battery" else FUEL_EQ, encoding="utf-8")
        eq = str(tmp_path / "ev.toml")
    for e in ("memory", "local"):
        out = tmp_path / e
        assert cli_main(["compare", str(d), "--equation", eq, "--target", target, "--out", str(out),
                         "--engine", e]) == 2
        assert capsys.readouterr().err.strip().endswith(str(mem.value)) and not out.exists()


@pytest.mark.parametrize("second", ["elevation", "pressure"])
def test_diagnose_air_density_at_altitude_decided_on_all_files(tmp_path, second):
    """Found by review: streamed diagnose decided whether to offer air density at altitude
    from the first batch's columns and air density source, in memory from the whole log.
    Planted: the air's density at ±30 m relief with the pressure not logged (sea level
    assumed). A folder where only the second file logs its elevation: not offered (the
    first file's altitude is unknown), in memory and streamed; where the second file logs
    its pressure: not offered in memory (the log's ρ is of a measured pressure), but it was
    streamed (found, in the first file's batches' columns). Now both decide on all files."""
    import sumo_drvpw.synth.effects as E
    from sumo_drvpw.fit.diagnose import DiagnoseOptions, diagnose
    from sumo_drvpw.fit.diagnose.stream_run import diagnose_stream
    from sumo_drvpw.synth.track import Noise

    df, _ = E.synth_trips(4, 8.0, seed=11, effects=[E.AltitudeAir(), E.LogPower()],
                          noise=Noise(process_w=200.0, process_rel=0.01))
    df = df.drop(columns="pressure_kpa")
    first = df["trip_id"].isin(df["trip_id"].unique()[:2])
    a, b = df[first], df[~first]
    if second == "elevation":
        a = a.drop(columns="elevation_m")
    else:
        b = b.assign(pressure_kpa=100.8)
    d = tmp_path / "logs"
    d.mkdir()
    a.to_parquet(d / "a.parquet")
    b.to_parquet(d / "b.parquet")
    eq, opt = load_equation("drvpw_prius3"), DiagnoseOptions(max_findings=2)
    mem = diagnose(load_measured([d], "prius3"), eq, opt)
    st = diagnose_stream([d], "prius3", eq, opt, rows=2500)
    got = [[f["term"] for f in r.report["findings"]] for r in (mem, st)]
    assert got[0] == got[1] and not any("air_density_altitude" in t for t in got[0])
    assert "air_density_altitude" not in mem.details["structural"]
    assert "air_density_altitude" not in st.details["structural"]


FUEL_EQ = """[equation]
name = "ice"
[terms]
acc = 1.0
v1 = 150.0
v3 = 0.4
[chain]
predicts = "fuel"
traction_efficiency = 0.9
aux_power_w = 300.0
idle_fuel_power_w = 3000.0
marginal_efficiency = 0.33
engine_off_below_w = 0.0
fuel = "gasoline"
"""


@pytest.mark.parametrize("first", ["gps", "maf"])
def test_fuel_flow_of_each_file_and_its_source_said_of_all(tmp_path, capsys, monkeypatch, first):
    """Found by review: in memory, the fuel flow was chosen on the whole table, so a file
    with only fuel_rate_lph read with one that has fuel_rate_gps got NaN (all its rows left
    out: usable 1500 of 3000), while streamed each file used its own flow and the source
    said was the first batch's. Each file's flow is its own (a third file: only its mass
    air flow, the petrol estimate), as read alone, and the source says each with its rows,
    in memory and streamed (`compare --target fuel`)."""
    from sumo_drvpw.model.constants import FUELS

    gas = FUELS["gasoline"]

    def fuel_w(df):  # the chain's fuel power of the wheel power: idle + wheel / 0.9 / 0.33
        return 3000.0 + np.maximum(df["power_w"].to_numpy() / 0.9 + 300.0, 0.0) / 0.33

    from sumo_drvpw.model.constants import AFR_STOICH_GASOLINE

    a, b, c = _drive("A", seed=1), _drive("B", seed=2), _drive("C", seed=3)
    logs = {"gps": a.assign(fuel_rate_gps=fuel_w(a) / gas["lhv_j_per_kg"] * 1000.0),
            "lph": b.assign(fuel_rate_lph=fuel_w(b) / gas["lhv_j_per_kg"] / gas["density_kg_per_l"] * 3600.0),
            "maf": c.assign(maf_gps=fuel_w(c) / gas["lhv_j_per_kg"] * 1000.0 * AFR_STOICH_GASOLINE)}
    d = _folder(tmp_path, logs, first)
    m = load_measured([d], target="fuel")
    assert m.counts["usable"] == 4500
    for f, df in (("B", b), ("C", c)):
        np.testing.assert_allclose(m.power_w[_file_of(m) == f], fuel_w(df), rtol=1e-12)
    doc = _compare_streamed_and_in_memory(tmp_path, capsys, monkeypatch, d, "fuel", FUEL_EQ)
    assert doc["context"]["counts"]["power_source"] == (
        "fuel flow fuel_rate_gps × LHV of gasoline for 1500 rows; "
        "fuel flow fuel_rate_lph × LHV of gasoline for 1500 rows; "
        f"ESTIMATE: fuel from the mass air flow maf_gps / {AFR_STOICH_GASOLINE:.2f} (stoichiometric "
        "petrol) × LHV of gasoline (deceleration fuel cut reads as air: an overestimate there) for 1500 rows")
