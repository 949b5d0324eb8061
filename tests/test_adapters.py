"""Adapters: real-data excerpts read at run time (../shared/data), broken files, CLI round trip."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sumo_drvpw.data.adapters import FORMATS, read
from sumo_drvpw.data.adapters._common import clean_time_and_speed, new_report
from sumo_drvpw.cli.import_ import read_report
from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.model.constants import RPM
from sumo_drvpw.errors import UserError
from sumo_drvpw.model.vehicles import load_vehicle

REPO = Path(__file__).resolve().parent.parent
DATA = Path(os.environ.get("SUMO_DRVPW_DATA", REPO.parent / "shared" / "data"))


def data(*parts) -> Path:
    p = DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"real data not found at {p} (set SUMO_DRVPW_DATA or provide ../shared/data)")
    return p


def assert_canonical(df: pd.DataFrame, report: dict):
    """Invariants every adapter output must satisfy (spec: ../shared/spec/drive-log.md)."""
    assert {"trip_id", "time_s", "speed_mps"} <= set(df.columns)
    assert list(df.columns[:3]) == ["trip_id", "time_s", "speed_mps"]
    for _, g in df.groupby("trip_id"):
        assert (np.diff(g["time_s"].to_numpy()) > 0).all()
    assert df["speed_mps"].between(0, 100).all()
    assert report["kept"] == len(df)
    assert report["rows_read"] == report["kept"] + sum(report["dropped"].values())
    for r in report["files"]:
        assert r["rows_read"] == r["kept"] + sum(r["dropped"].values())


# ---------------------------------------------------------------- BMW i3 (TUM)

@pytest.mark.shared_data
def test_bmw_trip_units_by_physics():
    df, rep = read("bmw-i3-tum", data("bmw_i3_tum", "TripB02.csv"))
    assert_canonical(df, rep)
    assert set(df["trip_id"]) == {"TripB02"}
    assert np.allclose(np.diff(df["time_s"]), 0.1)                  # 10 Hz
    assert 20 < df["speed_mps"].max() < 45                            # km/h → m/s (max 135 km/h)
    assert df["elevation_m"].between(400, 700).all()                  # Munich ≈ 450–600 m
    # the accelerometer is kept apart from the canonical dv/dt
    assert "imu_accel_mps2" in df and "accel_mps2" not in df
    # motor speed from v through the vehicle file: 10 m/s → 10/0.35·9.665/(2π/60) = 2637 rpm
    veh = load_vehicle("bmw_i3")
    i = int(np.argmin(abs(df["speed_mps"] - 10)))
    expect = df["speed_mps"].iat[i] / 0.35 * 9.665 * 60 / (2 * math.pi)
    assert df["motor_speed_rpm"].iat[i] == pytest.approx(expect, rel=1e-9)
    assert veh.powertrain["gear_ratio"] == 9.665
    # P_mech = τ·ω at steady 13–17 m/s is a few kW, of the size of a road-load estimate
    v = df["speed_mps"]
    a = np.gradient(v, df["time_s"])
    p_mech = df["motor_torque_nm"] * df["motor_speed_rpm"] * RPM
    cruise = (v > 13) & (v < 17) & (abs(a) < 0.05)
    assert cruise.sum() > 100
    road = v * (0.5 * 1.2 * 0.29 * 2.38 * v**2 + 0.008 * veh.mass_kg * 9.81)  # W, flat road
    ratio = p_mech[cruise].median() / road[cruise].median()
    assert 0.5 < ratio < 3.0, ratio
    # canonical current is positive when discharging: hard acceleration draws V·I > τ·ω
    hard = p_mech > 20_000
    assert (df["battery_current_a"][hard] > 0).mean() > 0.95
    eff = (p_mech / (df["battery_voltage_v"] * df["battery_current_a"]))[hard].median()
    assert 0.6 < eff < 1.0


@pytest.mark.shared_data
def test_bmw_extras_and_overview_join():
    src = data("bmw_i3_tum")
    df, rep = read("bmw-i3-tum", [src / "TripA01.csv", src / "TripB33.csv"])
    assert_canonical(df, rep)
    raw = pd.read_csv(src / "TripA01.csv", sep=";", encoding="latin-1", nrows=50)
    a01 = df[df.trip_id == "TripA01"].head(50)
    np.testing.assert_allclose(a01["heater_power_w"], 1000 * raw["Heating Power CAN [kW]"])
    np.testing.assert_allclose(a01["aircon_power_w"], 1000 * raw["AirCon Power [kW]"])
    np.testing.assert_allclose(a01["battery_current_a"], -raw["Battery Current [A]"])
    np.testing.assert_allclose(a01["speed_mps"], raw["Velocity [km/h]"] / 3.6)
    for c in ("ambient_c", "cabin_temp_c", "soc_pct", "battery_temp_c"):
        assert pd.api.types.is_float_dtype(df[c]), c
    by = df.groupby("trip_id").first()
    ov = pd.read_csv(src / "overview.csv").set_index("Trip")
    assert by.loc["TripA01", "season"] == "summer" and not by.loc["TripA01", "winter"]
    assert by.loc["TripB33", "season"] == "winter" and by.loc["TripB33", "winter"]
    assert by.loc["TripA01", "route"] == ov.loc["TripA01", "Route/Area"]
    assert by.loc["TripA01", "cabin_setpoint_c"] == ov.loc["TripA01", "Target Cabin Temperature"]
    # overview note "+ 160 kg" → added load on top of the vehicle file's mass
    mass = load_vehicle("bmw_i3").mass_kg
    assert by.loc["TripB33", "added_mass_kg"] == 160
    assert by.loc["TripB33", "mass_kg"] == mass + 160
    assert by.loc["TripA01", "mass_kg"] == mass


# ---------------------------------------------------------------- Prius Gen 2 (Torque Pro)

@pytest.mark.shared_data
def test_prius_units_and_power_split_kinematics():
    df, rep = read("torquepro-prius2", data("prius_gen2_torquepro", "From_CdA_Act.json"))
    assert_canonical(df, rep)
    assert rep["dropped"].get("link not up (-)", 0) >= 1       # first record has '-' powertrain fields
    dt = np.diff(df["time_s"])
    assert 0.5 < np.median(dt) < 1.0                          # ≈1.4 Hz, irregular
    v, gps = df["speed_mps"], df["gps_speed_mps"]
    ok = gps.notna()
    assert np.corrcoef(v[ok], gps[ok])[0, 1] > 0.99            # OBD and GPS agree after mph → m/s
    assert (v - gps)[ok].abs().median() < 1.0
    assert 20 < v.max() < 40                                  # highway, < 90 mph
    assert df["ambient_c"].between(5, 13).all()                # README: 7–10 °C; °F → °C
    assert df["elevation_m"].between(500, 800).all()           # Spokane ≈ 600 m; ft → m
    assert (df["elevation_m"] - df["altitude_phone_m"]).abs().median() < 1.0
    # Willis equation of the planetary set (sun 30, ring 78; ring = MG2 in Gen 2):
    # ω_ice·(30+78) = 30·ω_mg1 + 78·ω_mg2
    run = df["ice_speed_rpm"] > 1000
    pred = (30 * df["mg1_speed_rpm"] + 78 * df["mg2_speed_rpm"]) / 108
    assert ((pred - df["ice_speed_rpm"]) / df["ice_speed_rpm"])[run].abs().median() < 0.03
    # MG2 turns with the wheels: ω_mg2 / v = final drive / r ≈ 4.113 / 0.31 m ≈ 13.3 1/m
    moving = v > 5
    assert 12 < (df["mg2_speed_rpm"] * RPM / v)[moving].median() < 14.5
    # battery current positive when discharging: V·I equals the app's battery power
    pb = df["battery_voltage_v"] * df["battery_current_a"]
    assert (pb - df["battery_power_obd_w"]).abs().median() < 50


@pytest.mark.shared_data
def test_prius_time_going_backwards_counted():
    df, rep = read("torquepro-prius2", data("prius_gen2_torquepro", "To_CdA_Act.json"))
    assert_canonical(df, rep)
    assert rep["dropped"].get("time going backwards", 0) >= 1   # one Device Time step of −0.345 s


# ---------------------------------------------------------------- JLU dynamometer

@pytest.mark.shared_data
def test_jlu_udds_and_constant_speed_against_road_load():
    src = data("jlu_bev_dyno")
    files = [src / "UDDS_HWY_US06_NYCC_CSS__08_UDDS_1.parquet",
             src / "UDDS_HWY_US06_NYCC_CSS__13_CS_80_1.parquet"]
    df, rep = read("jlu-dyno", files)
    assert_canonical(df, rep)
    assert (df["grade_rad"] == 0).all() and (df["mass_kg"] == 1919).all()
    udds = df[df["cycle"] == "UDDS"]
    assert np.median(np.diff(udds["time_s"])) == pytest.approx(0.05)   # 20 Hz
    # UDDS peak speed is 56.7 mph = 91.2 km/h = 25.35 m/s (EPA schedule)
    assert udds["schedule_speed_mps"].max() == pytest.approx(25.35, abs=0.1)
    assert udds["speed_mps"].max() == pytest.approx(25.35, abs=0.5)
    # accelerating draws current: canonical positive when discharging
    a = np.gradient(udds["speed_mps"], udds["time_s"])
    assert (udds["battery_current_a"][(a > 0.5) & (udds["speed_mps"] > 3)] > 0).mean() > 0.95
    # at 80 km/h steady, battery power ≥ published road-load power at the wheels (F·v), and
    # within a plausible drivetrain efficiency: F = 179.4 + 0.28·80 + 0.0235·80² = 352.2 N
    cs = df[df["cycle"] == "CS_80"]
    steady = (cs["speed_mps"] * 3.6 - 80).abs() < 1
    p_bat = (cs["battery_voltage_v"] * cs["battery_current_a"])[steady].median()
    p_wheel = 352.2 * 80 / 3.6
    assert p_wheel < p_bat < 1.5 * p_wheel
    # PhaseTime stops at the schedule end while the logger runs on: tail dropped and counted
    cs_rep = [r for r in rep["files"] if "CS_80" in r["file"]][0]
    assert sum(cs_rep["dropped"].values()) >= 1
    assert cs["time_s"].max() <= 1200


@pytest.mark.shared_data
def test_jlu_road_trips_read_with_elevation_temperature_and_roles(tmp_path):
    """The dyno adapter's car on the road (issue #11 §6): text timestamps, elevation, ambient
    temperature; grade from elevation by the reader; counters stored with role response."""
    from sumo_drvpw.data import roles
    from sumo_drvpw.data.log import read_log

    src = data("jlu_bev_road", "001.parquet")
    out = tmp_path / "road.parquet"
    assert cli_main(["import", "jlu-road", str(src), "--out", str(out)]) == 0
    log = read_log([out])
    df = log.df
    assert np.median(np.diff(df["time_s"])) == pytest.approx(0.05)        # 20 Hz
    assert "schedule_speed_mps" not in df and "clock_s" in df
    assert df["ambient_c"].between(0, 40).all() and df["elevation_m"].between(100, 400).all()
    assert log.counts["grade_source"].startswith("elevation")
    assert np.abs(df["grade_rad"]).max() < 0.15 and df["grade_rad"].std() > 1e-4
    # ρ from ambient temperature at standard pressure: 1.17–1.22 kg/m³ at 7–26 °C
    assert df["air_density_kgm3"].between(1.15, 1.26).all()
    r = roles.of_log(log)
    assert r["battery_charge_energy_j"] == {"role": "response", "source": "declared"}
    assert r["ambient_c"]["role"] == "condition"
    # battery power positive when discharging: accelerating draws current
    a = df["accel_mps2"].to_numpy()
    p = (df["battery_voltage_v"] * df["battery_current_a"]).to_numpy()
    assert (p[(a > 0.5) & (df["speed_mps"] > 3)] > 0).mean() > 0.95


def test_jlu_road_text_time_and_bad_timestamp(tmp_path):
    n = 40
    base = {"PhaseTime": np.arange(n) * 0.05, "DAActualSpeed": np.linspace(0, 20, n),
            "DAScheduleSpeed": np.zeros(n, int), "REESSCurrent": np.full(n, -10.0),
            "REESSCurrent2": np.zeros(n, int), "REESSVoltage": np.full(n, 370.0),
            "REESSVoltage2": np.zeros(n, int), "tempAmb": np.full(n, 15.0),
            "elevation": np.full(n, 200), "gear": np.full(n, 4)}
    t = pd.Timestamp("2023-04-19 09:19:44.83") + pd.to_timedelta(np.arange(n) * 0.05, unit="s")
    pd.DataFrame(dict(base, Time=t.astype(str))).to_parquet(tmp_path / "a.parquet")
    df, rep = read("jlu-road", tmp_path / "a.parquet")
    assert df["clock_s"].iloc[0] == pytest.approx(t[0].timestamp())
    assert df["battery_current_a"].iloc[0] == 10.0 and "grade_rad" not in df
    assert rep["roles"]["gear"] == "response"
    bad = dict(base, Time=["not a time"] * n)
    pd.DataFrame(bad).to_parquet(tmp_path / "b.parquet")
    with pytest.raises(UserError, match="b.parquet: column 'Time'.*'not a time' at row 0"):
        read("jlu-road", tmp_path / "b.parquet")


def test_jlu_cycle_names():
    from sumo_drvpw.data.adapters.jlu_dyno import cycle_name
    assert cycle_name("WLTC_CADC_JC08_CSS__07_Artemis_rural_1") == "Artemis_rural"
    assert cycle_name("CLTC_CSS__03_CS_110_01") == "CS_110"
    assert cycle_name("UDDS_HWY_US06_NYCC_CSS__04_SPEED_65") == "SPEED_65"
    assert cycle_name("WLTC_CADC_JC08_CSS__13_Artemis_motorway_130_2") == "Artemis_motorway_130"


def test_jlu_vehicle_road_load_si_conversions():
    import tomllib
    doc = tomllib.loads((REPO / "sumo_drvpw/model/builtin/vehicles/jlu_bev.toml").read_text(encoding="utf-8"))
    rl = doc["road_load"]
    assert rl["b_n_per_mps"] == pytest.approx(rl["b_n_per_kmh"] * 3.6)
    assert rl["c_n_per_mps2"] == pytest.approx(rl["c_n_per_kmh2"] * 3.6**2)
    for key in ("vehicle.mass_kg", "road_load.a_n", "road_load.b_n_per_kmh", "road_load.c_n_per_kmh2"):
        assert key in doc["sources"]
    bmw = tomllib.loads((REPO / "sumo_drvpw/model/builtin/vehicles/bmw_i3.toml").read_text(encoding="utf-8"))
    for table, values in bmw.items():
        if table in ("sources",) or not isinstance(values, dict):
            continue
        for k, val in values.items():
            if isinstance(val, (int, float)) and not isinstance(val, bool):
                assert f"{table}.{k}" in bmw["sources"], f"bmw_i3.toml {table}.{k} lacks a source"


# ---------------------------------------------------------------- generic columns mapping

MAPPING = """
[options]
sep = ";"
decimal = ","
[columns.Zeit]
name = "time_s"
unit = "ms"
[columns.Tempo]
name = "speed_mps"
unit = "km/h"
[columns.Aussen]
name = "ambient_c"
unit = "°F"
[columns.Heizung]
name = "heater_power_w"
unit = "kW"
[columns.Hoehe]
name = "elevation_m"
unit = "ft"
[columns.Strom]
name = "battery_current_a"
unit = "A"
scale = -1
"""
CSV = ("Zeit;Tempo;Aussen;Heizung;Hoehe;Strom;Modus\n"
       "0;36;212;1,5;1000;-10;eco\n"
       "100;36;32;0;0;5;eco\n"
       "100;40;32;0;0;5;eco\n"       # duplicate timestamp
       "50;40;32;0;0;5;eco\n"        # time going backwards
       "200;;32;0;0;5;eco\n"         # NaN speed
       "300;72;-40;2;3280,84;0;sport\n")


def write(tmp_path, name, text, encoding="utf-8"):
    p = tmp_path / name
    p.write_text(text, encoding=encoding)
    return p


def test_columns_conversions_and_counts(tmp_path):
    m = write(tmp_path, "map.toml", MAPPING)
    src = write(tmp_path, "log1.csv", CSV)
    df, rep = read("columns", [src], columns=m)
    assert_canonical(df, rep)
    assert rep["dropped"] == {"NaN speed": 1, "duplicate timestamp": 1, "time going backwards": 1}
    np.testing.assert_allclose(df["time_s"], [0, 0.1, 0.3])
    np.testing.assert_allclose(df["speed_mps"], [10, 10, 20])                 # 36, 72 km/h
    np.testing.assert_allclose(df["ambient_c"], [100, 0, -40])                # 212, 32, −40 °F
    np.testing.assert_allclose(df["heater_power_w"], [1500, 0, 2000])
    np.testing.assert_allclose(df["elevation_m"], [304.8, 0, 1000.0], rtol=1e-6)  # ft
    np.testing.assert_allclose(df["battery_current_a"], [10, -5, 0])          # scale −1
    assert list(df["modus"]) == ["eco", "eco", "sport"]                       # unmapped text kept
    assert set(df["trip_id"]) == {"log1"}


@pytest.mark.shared_data
def test_columns_mapping_reproduces_jlu_adapter(tmp_path):
    src = data("jlu_bev_dyno", "UDDS_HWY_US06_NYCC_CSS__06_US06_1.parquet")
    m = write(tmp_path, "jlu.toml", """
[columns.PhaseTime]
name = "time_s"
unit = "s"
[columns.DAActualSpeed]
name = "speed_mps"
unit = "km/h"
[columns.REESSCurrent]
name = "battery_current_a"
unit = "A"
scale = -1
[columns.REESSVoltage]
name = "battery_voltage_v"
unit = "V"
""")
    a, ra = read("columns", src, columns=m)
    b, rb = read("jlu-dyno", src)
    assert ra["dropped"] == rb["dropped"]
    for c in ("time_s", "speed_mps", "battery_current_a", "battery_voltage_v"):
        np.testing.assert_allclose(a[c], b[c])


def _datetime_map(tmp_path, speed_unit: str, options: str = ""):
    """A columns mapping: datetime time t, speed v in ``speed_unit``, trip column."""
    return write(tmp_path, "map.toml", '[options]\ntime_unit = "datetime"\n' + options
                 + '[columns.t]\nname = "time_s"\n[columns.v]\nname = "speed_mps"\n'
                 f'unit = "{speed_unit}"\n[columns.trip]\nname = "trip_id"\n')


def test_columns_datetime_time_and_trip_column(tmp_path):
    m = _datetime_map(tmp_path, "mph", 'time_format = "%Y-%m-%d %H:%M:%S"\n')
    src = write(tmp_path, "x.csv", "t,v,trip\n2024-01-01 10:00:00,10,a\n2024-01-01 10:00:02,20,a\n"
                "2024-01-01 10:00:03,0,b\n2024-01-01 10:00:03,5,b\n")
    df, rep = read("columns", src, columns=m)
    assert_canonical(df, rep)
    assert rep["dropped"] == {"duplicate timestamp": 1}
    np.testing.assert_allclose(df["time_s"], [0, 2, 3])
    np.testing.assert_allclose(df["speed_mps"], [4.4704, 8.9408, 0])
    assert list(df["trip_id"]) == ["a", "a", "b"]


def test_columns_data_rows_ending_in_a_separator_keep_their_columns(tmp_path):
    """A logger that ends every data row with a comma, but not its header (eron93br/carOBD's
    Carloop CSVs, CRLF): pandas took the first column as the index and shifted every column
    by one, silently (time read from the speed, speed from the next column)."""
    m = write(tmp_path, "map.toml", '[columns.t]\nname = "time_s"\n[columns.v]\nname = "speed_mps"\n'
              'unit = "km/h"\n')
    src = write(tmp_path, "x.csv", "t,v,x\r\n0,10,1,\r\n1,12,2,\r\n2,14,3,\r\n3,16,4,\r\n")
    df, rep = read("columns", src, columns=m)
    np.testing.assert_allclose(df["time_s"], [0, 1, 2, 3])
    np.testing.assert_allclose(df["speed_mps"], np.array([10, 12, 14, 16]) / 3.6)
    assert any("more fields than the header line" in n for n in rep["files"][0]["notes"]), rep


def test_columns_two_labels_alike_but_for_a_space_keep_both_or_are_refused_by_name(tmp_path):
    """The shared i3's winter trips label two columns 'Temperature Vent right [°C] ' and
    'Temperature Vent right [°C]': read without their spaces they were one label, and
    `import columns` ended in a pandas TypeError traceback. Kept as two columns when not
    mapped; refused in one line, naming the file and the label, when the mapping maps it."""
    m = write(tmp_path, "map.toml", '[columns.t]\nname = "time_s"\n[columns.v]\nname = "speed_mps"\n'
              'unit = "m/s"\n')
    src = write(tmp_path, "x.csv", "t;v;Vent [°C] ;Vent [°C]\n0;1;20;21\n1;2;22;23\n2;3;24;25\n")
    m.write_text('[options]\nsep = ";"\n' + m.read_text(encoding="utf-8"), encoding="utf-8")
    df, _ = read("columns", src, columns=m)
    np.testing.assert_allclose(df["vent_c"], [20, 22, 24])
    np.testing.assert_allclose(df["vent_c_2"], [21, 23, 25])
    m.write_text(m.read_text(encoding="utf-8") + '[columns."Vent [°C]"]\nname = "cabin_c"\nunit = "°C"\n', encoding="utf-8")
    with pytest.raises(UserError, match=r"x.csv: 2 columns are labelled 'Vent \[°C\]'.*cannot tell them apart"):
        read("columns", src, columns=m)


def test_columns_brake_flag_held_or_refused(tmp_path):
    """``brake`` is a flag: on its own rows of an asynchronous log it is held (its last value)
    at each speed sample, never interpolated between 0 and 1 (a Ford OpenXC trace ended in a
    pandas TypeError traceback); a value other than 0 or 1 is refused naming file and column."""
    m = write(tmp_path, "map.toml", '[columns.t]\nname = "time_s"\n[columns.v]\nname = "speed_mps"\n'
              'unit = "m/s"\n[columns.b]\nname = "brake"\n')
    src = write(tmp_path, "a.csv", "t,v,b\n0,1,\n0.5,,0\n1,2,\n1.5,,1\n2,3,\n2.5,,1\n3,4,\n3.5,,0\n4,5,\n")
    df, _ = read("columns", src, columns=m)
    assert list(df["brake"]) == [False, False, True, True, False]
    bad = write(tmp_path, "h.csv", "t,v,b\n0,1,0\n1,2,0.5\n2,3,1\n")
    with pytest.raises(UserError, match=r"h.csv: column 'brake' holds 0.5 \(its first value not 0 or 1\)"):
        read("columns", bad, columns=m)


def test_columns_iso_times_with_changing_utc_offsets_and_fractions(tmp_path):
    """ISO 8601 timestamps as loggers write them: a file holding a summer (+02:00) and a
    winter (+01:00) trip, a trip across the end of daylight saving (02:59:59+02:00 is
    followed by 02:00:00+01:00), and Python's isoformat (no fraction on whole seconds)
    mixed with fractions. Each trip's clock runs on (read in UTC); they were a traceback
    ("Mixed timezones detected") or an error on a valid cell (found by a sweep)."""
    m = _datetime_map(tmp_path, "m/s")
    src = write(tmp_path, "x.csv", "t,v,trip\n"
                "2019-07-01T12:00:00+02:00,10,summer\n2019-07-01T12:00:00.500000+02:00,10,summer\n"
                "2019-10-27T02:59:59.500000+02:00,10,dst\n2019-10-27T02:00:00+01:00,10,dst\n"
                "2019-10-27T02:00:00.500000+01:00,10,dst\n"
                "2019-12-01T08:00:00+01:00,5,winter\n2019-12-01T08:00:01+01:00,5,winter\n")
    df, rep = read("columns", src, columns=m)
    assert_canonical(df, rep)
    got = {t: list(np.diff(g["time_s"])) for t, g in df.groupby("trip_id", sort=False)}
    assert got == {"summer": [0.5], "dst": [0.5, 0.5], "winter": [1.0]}
    assert df["time_s"].iloc[0] == 0.0


# ---------------------------------------------------------------- broken input → UserError

BMW_HEADER = ("Time [s];Velocity [km/h];Elevation [m];Motor Torque [Nm];"
              "Battery Voltage [V];Battery Current [A]\n")


@pytest.mark.parametrize("name,text,match", [
    ("TripX01.csv", "", "empty"),
    ("TripX02.csv", BMW_HEADER, "no data rows"),
    ("TripX03.csv", "Time [s];Velocity [km/h]\n0;1\n", "missing column 'motor torque'"),
    ("TripX04.csv", BMW_HEADER.replace(";", ",") + "0,1,500,0,390,-1\n", "not ';'-separated"),
    ("TripX05.csv", BMW_HEADER + "0;1;500;0;390;-1\n0.1;fast;500;0;390;-1\n",
     "'Velocity \\[km/h\\]' is not numeric: data row 1 holds 'fast'"),
    ("TripX06.csv", BMW_HEADER + "0;400;500;0;390;-1\n", "outside \\[0, 100\\] m/s"),
])
def test_bmw_broken_files(tmp_path, name, text, match):
    p = write(tmp_path, name, text, encoding="latin-1")
    with pytest.raises(UserError, match=match) as e:
        read("bmw-i3-tum", p)
    assert name in str(e.value)


def test_bmw_without_overview_still_reads(tmp_path):
    p = write(tmp_path, "TripZ01.csv", BMW_HEADER + "0;36;500;10;390;-1\n0.1;36;500;10;390;-1\n")
    df, rep = read("bmw-i3-tum", p)
    assert df["speed_mps"].tolist() == [10, 10]
    assert any("overview" in n for n in rep["files"][0]["notes"])
    # no heater voltage and current in the file: its electrical power is unknown, not 0
    assert df["heater_electric_w"].isna().all()
    assert any("heater_electric_w unknown" in n for n in rep["files"][0]["notes"])


def test_bmw_heater_electric_power_is_voltage_times_current(tmp_path):
    """heater_electric_w = Heater Voltage × Heater Current (a battery-side load, role 'load'),
    the column `calibrate --target battery --load heater_electric_w` documents; NaN where a
    row lacks either."""
    head = BMW_HEADER.rstrip("\n") + ";Heater Voltage [V];Heater Current [A]\n"
    p = write(tmp_path, "TripZ02.csv", head + "0;36;500;10;390;-1;380;5\n0.1;36;500;10;390;-1;;5\n")
    df, rep = read("bmw-i3-tum", p)
    assert df["heater_electric_w"].iloc[0] == 1900.0 and math.isnan(df["heater_electric_w"].iloc[1])
    assert rep["roles"]["heater_electric_w"] == "load"


@pytest.mark.parametrize("text,match", [
    ("", "empty"),
    ("{\"a\": 1}", "JSON list of records"),
    ("[{\"Device Time\": \"25-Mar-2017 11:46:29.523\"", "not valid JSON"),
    ("[{\"Device Time\": \"25-Mar-2017 11:46:29.523\", \"x\": 1}]", "missing column 'Speed \\(OBD\\)\\(mph\\)'"),
    ("[{\"Device Time\": \"yesterday\", \"Speed (OBD)(mph)\": 1}]", "'Device Time' data row 0"),
    ("[{\"Device Time\": \"25-Mar-2017 11:46:29.523\", \"Speed (OBD)(mph)\": \"n/a\"}]",
     "'Speed \\(OBD\\)\\(mph\\)' is not numeric"),
])
def test_prius_broken_files(tmp_path, text, match):
    p = write(tmp_path, "log.json", text)
    with pytest.raises(UserError, match=match):
        read("torquepro-prius2", p)


def test_jlu_broken_files(tmp_path):
    p = write(tmp_path, "bad.parquet", "not parquet")
    with pytest.raises(UserError, match="bad.parquet: cannot be read as Parquet"):
        read("jlu-dyno", p)
    q = tmp_path / "nocur.parquet"
    pd.DataFrame({"PhaseTime": [0.0, 0.05], "DAActualSpeed": [0.0, 1.0],
                  "REESSVoltage": [390.0, 390.0]}).to_parquet(q)
    with pytest.raises(UserError, match="nocur.parquet: missing column 'REESSCurrent'"):
        read("jlu-dyno", q)


@pytest.mark.parametrize("mapping,match", [
    ("[columns.a\nname=", "not a valid TOML"),
    ("[options]\nsep=';'", "no \\[columns"),
    ("[columns.v]\nname='speed_mps'\nunit='furlong/fortnight'", "columns.v.unit 'furlong/fortnight' is not a known unit"),
    ("[columns.t]\nname='time_s'\n[columns.v]\nname='speed_mps'\nunit='ft'", "unit 'ft' is a length"),
    ("[columns.v]\nname='speed_mps'\nunit='km/h'", "mapped to 'time_s'"),
    ("[options]\nseperator=';'\n[columns.v]\nname='speed_mps'", "unknown option 'options.seperator'"),
])
def test_columns_bad_mapping(tmp_path, mapping, match):
    m = write(tmp_path, "map.toml", mapping)
    src = write(tmp_path, "x.csv", "t,v\n0,1\n")
    with pytest.raises(UserError, match=match) as e:
        read("columns", src, columns=m)
    assert "map.toml" in str(e.value)


def test_columns_wrong_separator_and_missing_mapping(tmp_path):
    m = write(tmp_path, "map.toml", MAPPING)
    src = write(tmp_path, "x.csv", CSV.replace(";", "|"))
    with pytest.raises(UserError, match="missing column 'Zeit'.*wrong sep"):
        read("columns", src, columns=m)
    with pytest.raises(UserError, match="needs a mapping file"):
        read("columns", src)
    with pytest.raises(UserError, match="column mapping not found"):
        read("columns", src, columns=tmp_path / "nope.toml")


def test_unknown_format_and_missing_path(tmp_path):
    with pytest.raises(UserError, match="unknown format 'csv'"):
        read("csv", tmp_path)
    with pytest.raises(UserError, match="no such file or folder"):
        read("jlu-dyno", tmp_path / "missing")
    with pytest.raises(UserError, match="folder holds no"):
        read("jlu-dyno", tmp_path)
    assert set(FORMATS) == {"bmw-i3-tum", "torquepro", "torquepro-prius2", "jlu-dyno", "jlu-road", "car-scanner",
                            "columns"}


# ---------------------------------------------------------------- time cleaning property

@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.integers(0, 20), st.floats(0, 50)), min_size=1, max_size=40))
def test_clean_time_keeps_strictly_increasing_and_counts(samples):
    df = pd.DataFrame({"time_s": [float(t) for t, _ in samples], "speed_mps": [v for _, v in samples]})
    rep = new_report(Path("x"), "x", len(df))
    out = clean_time_and_speed(df, "x", rep)
    t = out["time_s"].to_numpy()
    assert (np.diff(t) > 0).all()
    assert len(out) + sum(rep["dropped"].values()) == len(df)
    # the running maximum is kept: every kept time is the largest seen so far
    assert t[0] == df["time_s"].iat[0] and t[-1] == df["time_s"].max()


# ---------------------------------------------------------------- CLI round trip

def test_cli_round_trip(tmp_path, capsys):
    m = write(tmp_path, "map.toml", MAPPING)
    src = write(tmp_path, "log1.csv", CSV)
    out = tmp_path / "out" / "log.parquet"
    assert cli_main(["import", "columns", str(src), "--columns", str(m), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "log1.csv: read 6, kept 3" in text and "duplicate timestamp 1" in text
    df = pd.read_parquet(out)
    assert {"trip_id", "time_s", "speed_mps", "ambient_c", "heater_power_w"} <= set(df.columns)
    rep = read_report(out)
    assert rep["kept"] == 3 and rep["rows_read"] == 6 and rep["format"] == "columns"
    assert json.loads(pq.read_schema(out).metadata[b"sumo_drvpw.import"])["out"] == str(out)
    src.write_text("", encoding="utf-8")                                             # broken input: exit 2, old file kept
    assert cli_main(["import", "columns", str(src), "--columns", str(m), "--out", str(out)]) == 2
    assert "file is empty" in capsys.readouterr().err
    assert len(pd.read_parquet(out)) == 3
    assert cli_main(["import", "nope", str(src), "--out", str(out)]) == 2
    assert cli_main(["import", "jlu-dyno", str(src), "--out", str(tmp_path / "x.csv")]) == 2


@pytest.mark.shared_data
def test_cli_real_prius(tmp_path, capsys):
    out = tmp_path / "prius.parquet"
    assert cli_main(["import", "torquepro-prius2", str(data("prius_gen2_torquepro")),
                     "--out", str(out)]) == 0
    df = pd.read_parquet(out)
    for c in ("ice_speed_rpm", "mg1_speed_rpm", "mg1_torque_nm", "mg2_speed_rpm", "mg2_torque_nm",
              "battery_voltage_v", "battery_current_a", "elevation_m", "ambient_c"):
        assert c in df and pd.api.types.is_float_dtype(df[c]), c
    rep = read_report(out)
    assert {Path(r["file"]).name for r in rep["files"]} == {"From_CdA_Act.json", "To_CdA_Act.json"}
    assert rep["kept"] == len(df)


def test_ved_layout_through_the_documented_mapping(tmp_path):
    """A file with the Vehicle Energy Dataset's header (gsoh/VED README: 22 columns, one CSV
    per week, rows of several trips, values missing where a PID was not logged) imports
    through the mapping docs/adapters.md gives; the car logs no fuel rate (its column is
    empty), so the fuel target is the mass-air-flow estimate with the trims."""
    import re as _re

    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.data.measured import load_measured
    from sumo_drvpw.model.constants import AFR_STOICH_GASOLINE, FUELS

    doc = (Path(__file__).resolve().parents[1] / "docs" / "adapters.md").read_text(encoding="utf-8")
    block = doc.split("### Example: the Vehicle Energy Dataset (VED)", 1)[1]
    mapping = _re.search(r"```toml\n(.*?)```", block, _re.S).group(1)
    (tmp_path / "ved.toml").write_text(mapping, encoding="utf-8")
    header = ["DayNum", "VehId", "Trip", "Timestamp(ms)", "Latitude[deg]", "Longitude[deg]",
              "Vehicle Speed[km/h]", "MAF[g/sec]", "Engine RPM[RPM]", "Absolute Load[%]", "OAT[DegC]",
              "Fuel Rate[L/hr]", "Air Conditioning Power[kW]", "Air Conditioning Power[Watts]",
              "Heater Power[Watts]", "HV Battery Current[A]", "HV Battery SOC[%]", "HV Battery Voltage[V]",
              "Short Term Fuel Trim Bank 1[%]", "Short Term Fuel Trim Bank 2[%]",
              "Long Term Fuel Trim Bank 1[%]", "Long Term Fuel Trim Bank 2[%]"]
    rows = []
    for trip in (706, 707):
        for k in range(60):
            rows.append({"DayNum": 1.2, "VehId": 8, "Trip": trip, "Timestamp(ms)": 1000 * k,
                         "Vehicle Speed[km/h]": min(2.0 * k, 60.0), "MAF[g/sec]": 2.0 + 0.2 * k,
                         "OAT[DegC]": 12.0, "Short Term Fuel Trim Bank 1[%]": 2.0,
                         "Long Term Fuel Trim Bank 1[%]": -4.0, "Engine RPM[RPM]": 900 + 20 * k})
    pd.DataFrame(rows).reindex(columns=header).to_csv(tmp_path / "VED_171101_week.csv", index=False)
    out = tmp_path / "ved.parquet"
    assert cli_main(["import", "columns", str(tmp_path / "VED_171101_week.csv"), "--columns",
                     str(tmp_path / "ved.toml"), "--out", str(out)]) == 0
    df = pd.read_parquet(out)
    assert sorted(df["trip_id"].unique()) == ["706", "707"] and len(df) == 120
    assert {"maf_gps", "ambient_c", "fuel_rate_lph", "short_term_fuel_trim_bank_1_pct"} <= set(df.columns)
    df["mass_kg"] = 1500.0
    df.to_parquet(tmp_path / "ved_mass.parquet")
    m = load_measured([tmp_path / "ved_mass.parquet"], None, target="fuel")
    assert m.source.startswith("ESTIMATE: fuel from the mass air flow maf_gps")
    want = df["maf_gps"].to_numpy() / 1000 / AFR_STOICH_GASOLINE * (1 - 0.02) * FUELS["gasoline"]["lhv_j_per_kg"]
    np.testing.assert_allclose(m.power_w, want, rtol=1e-12)


def test_d3_layout_through_the_documented_mapping_compares_with_a_fuel_chain(tmp_path, capsys):
    """A file with the labels of Argonne's D3 tests as FASTSim ships them (Time[s],
    Eng_FuelFlow_Direct_DI[ccps], Dyno_Spd[mph]) imports through the mapping docs/adapters.md
    gives, the flow in cc/s read as 3.6 L/h each; and `compare --target fuel` runs the
    built-in petrol chain on it although the log has no air temperature (a dynamometer test
    at the reference temperature): its warm-running factor is left out and the run says so
    (it used to refuse the log for the missing column)."""
    import re as _re

    from sumo_drvpw.cli import main as cli_main

    doc = (Path(__file__).resolve().parents[1] / "docs" / "adapters.md").read_text(encoding="utf-8")
    block = doc.split("### Example: Argonne's D3 dynamometer data", 1)[1]
    (tmp_path / "d3.toml").write_text(_re.search(r"```toml\n(.*?)```", block, _re.S).group(1), encoding="utf-8")
    t = np.arange(0.0, 300.0)
    mph = np.clip(np.minimum(t - 10, 200 - t) * 0.8, 0.0, 40.0)
    ccps = np.where(mph > 0, 0.25 + 0.03 * mph, 0.22)
    pd.DataFrame({"Time[s]": t, "Eng_FuelFlow_Direct_DI[ccps]": ccps, "Dyno_Spd[mph]": mph}).to_csv(
        tmp_path / "61811099 Test Data.txt", index=False)
    out = tmp_path / "d3.parquet"
    assert cli_main(["import", "columns", str(tmp_path / "61811099 Test Data.txt"), "--columns",
                     str(tmp_path / "d3.toml"), "--out", str(out)]) == 0
    df = pd.read_parquet(out)
    np.testing.assert_allclose(df["fuel_rate_lph"], ccps * 3.6, rtol=1e-12)
    np.testing.assert_allclose(df["speed_mps"], mph * 0.44704, rtol=1e-12)
    (tmp_path / "car.toml").write_text('[vehicle]\nname = "car"\nmass_kg = 1644.0\n', encoding="utf-8")
    capsys.readouterr()
    assert cli_main(["compare", str(out), "--vehicle", str(tmp_path / "car.toml"), "--equation",
                     "epa_gasoline_car", "--target", "fuel", "--out", str(tmp_path / "cmp")]) == 0
    said = capsys.readouterr().out
    assert "chain input 'ambient_c' unknown (NaN) on 300 of 300 samples" in said
    assert "no warm-running factor" in said
    trip = json.loads((tmp_path / "cmp" / "report.json").read_text(encoding="utf-8"))
    eq = trip["equations"][0] if isinstance(trip["equations"], list) else next(iter(trip["equations"].values()))
    (got,) = eq["trip_energy"]["trips"].values()
    from sumo_drvpw.model.constants import FUELS

    fp = FUELS["gasoline"]
    assert got["measured_j"] == pytest.approx((ccps / 1000 * fp["density_kg_per_l"] * fp["lhv_j_per_kg"]).sum(), rel=1e-3)


@pytest.mark.parametrize("unit, factor", [
    ("g", 9.80665),            # the unit g: standard gravity by definition (3rd CGPM, 1901), not the models' 9.81
    ("mph", 0.44704), ("km/h", 1 / 3.6), ("ft", 0.3048), ("lb", 0.45359237),  # exact by definition
    ("lbf", 4.4482216152605), ("hp", 745.69987158227022),
    ("rad/s", 60 / (2 * math.pi)),  # shaft speeds are canonical in rpm
])
def test_unit_factors_are_the_definitions(unit, factor):
    from sumo_drvpw.data.adapters._common import lookup_unit

    assert lookup_unit(unit)[1] == pytest.approx(factor, rel=1e-12)


def _tum(path, speed_label, heat_label, speed, heat):
    rows = ["Time [s];" + speed_label + ";Motor Torque [Nm];Battery Voltage [V];Battery Current [A];" + heat_label]
    for i in range(30):
        rows.append(f"{i * 0.1:.1f};{speed + 0.01 * i:.4f};50;380;-20;{heat}")
    path.write_bytes(("\n".join(rows) + "\n").encode("latin-1"))
    return path


def test_bmw_tum_reads_the_unit_its_header_writes(tmp_path):
    """Found by the second metamorphic sweep: the TUM reader keyed known columns on the name
    alone, with the data set's units (km/h, kW): a file writing 'Velocity [m/s]' imported 3.6×
    too slow and 'Heating Power CAN [W]' ×1000 (an 840-kW heater), without a note. The unit
    a header writes now converts; one of another quantity is refused."""
    ref, _ = read("bmw-i3-tum", _tum(tmp_path / "TripX1.csv", "Velocity [km/h]", "Heating Power CAN [kW]", 36.0, 0.84))
    d2 = tmp_path / "b"
    d2.mkdir()
    si, _ = read("bmw-i3-tum", _tum(d2 / "TripX1.csv", "Velocity [m/s]", "Heating Power CAN [W]", 10.0, 840.0))
    np.testing.assert_allclose(si["speed_mps"].to_numpy()[:1], ref["speed_mps"].to_numpy()[:1], rtol=1e-12)
    np.testing.assert_allclose(si["heater_power_w"], ref["heater_power_w"], rtol=1e-12)
    assert ref["heater_power_w"].iloc[0] == pytest.approx(840.0)
    np.testing.assert_allclose(si["battery_current_a"], 20.0)    # the data set's sign flip kept
    d3 = tmp_path / "c"
    d3.mkdir()
    with pytest.raises(UserError, match=r"Velocity \[kW\].*not a speed"):
        read("bmw-i3-tum", _tum(d3 / "TripX1.csv", "Velocity [kW]", "Heating Power CAN [kW]", 36.0, 0.84))


def test_vendor_files_with_an_extra_text_column_are_read(tmp_path):
    """A logger's own comment, driver or mode column (text) beside the vendor's columns is
    kept as text and noted, not a refusal of the file (dress rehearsal on unseen logs: a TUM
    trip with a 'Comment' column, a Torque log with 'Notes', a JLU file with 'Operator' were
    refused with 'is not numeric'); a known column with text stays an error."""
    tum = ("Time [s];Velocity [km/h];Comment;Motor Torque [Nm];Battery Voltage [V];"
           "Battery Current [A];Tyre Pressure [bar]\n"
           + "".join(f"{0.1 * i:.1f};{10 + i};ok;50;390;-20;2.4\n" for i in range(6)))
    df, rep = read("bmw-i3-tum", write(tmp_path, "TripX01.csv", tum))
    assert_canonical(df, rep)
    assert list(df["comment"]) == ["ok"] * 6
    np.testing.assert_allclose(df["tyre_pressure_kpa"], 240.0)         # bar → kPa, still numeric
    np.testing.assert_allclose(df["speed_mps"], (10 + np.arange(6)) / 3.6)
    assert any("'Comment' is not numeric" in n and "kept as text" in n for n in rep["files"][0]["notes"])
    with pytest.raises(UserError, match=r"TripX02.csv: column 'Motor Torque \[Nm\]' is not numeric: data row 0"):
        read("bmw-i3-tum", write(tmp_path, "TripX02.csv", tum.replace(";50;", ";fault;")))

    rec = [{"Device Time": f"25-Mar-2017 11:46:{29 + i}.500", "Speed (OBD)(mph)": 20.0 + i,
            "Notes": "x", "Trip Distance(miles)": str(0.1 * i)} for i in range(5)]
    df, rep = read("torquepro", write(tmp_path, "t.json", json.dumps(rec)))
    assert_canonical(df, rep)
    assert list(df["notes"]) == ["x"] * 5 and pd.api.types.is_float_dtype(df["trip_distance_m"])

    jlu = pd.DataFrame({"PhaseTime": [0.0, 0.05, 0.1], "DAActualSpeed": [0.0, 1.0, 2.0],
                        "REESSCurrent": [-1.0, -2.0, -3.0], "REESSVoltage": [390.0] * 3,
                        "Operator": ["A"] * 3, "RollerTemp": [30.0] * 3})
    jlu.to_parquet(tmp_path / "UDDS_01.parquet")
    df, rep = read("jlu-dyno", tmp_path / "UDDS_01.parquet")
    assert_canonical(df, rep)
    assert list(df["operator"]) == ["A"] * 3 and list(df["rollertemp"]) == [30.0] * 3
    np.testing.assert_allclose(df["battery_current_a"], [1.0, 2.0, 3.0])


def test_bmw_tum_trip_resaved_with_decimal_commas_reads_the_same(tmp_path):
    """Dress rehearsal: a TUM trip opened and saved by a German-locale spreadsheet keeps ';'
    between columns and writes '0,1' for 0.1; it was refused ("column 'Time [s]' is not
    numeric: data row 0 holds '0,0'"). It now reads as the original, noted."""
    header = ("Time [s];Velocity [km/h];Elevation [m];Motor Torque [Nm];Battery Voltage [V];"
              "Battery Current [A]\n")
    rows = [(0.1 * i, 10.5 + i, 520, 50.25, 390.4, -20.75) for i in range(8)]
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    dot = write(tmp_path / "a", "TripX01.csv", header + "".join(";".join(map(str, r)) + "\n" for r in rows))
    comma = write(tmp_path / "b", "TripX01.csv",
                  header + "".join(";".join(str(round(x, 2)).replace(".", ",") for x in r) + "\n" for r in rows))
    d1, _ = read("bmw-i3-tum", dot)
    d2, rep = read("bmw-i3-tum", comma)
    assert_canonical(d2, rep)
    pd.testing.assert_frame_equal(d1, d2)
    np.testing.assert_allclose(d2["battery_current_a"], 20.75)
    assert any("decimal comma" in n for n in rep["files"][0]["notes"])
    # a text cell in a column the format knows is still an error naming file, column and row
    bad = write(tmp_path / "b", "TripX02.csv", comma.read_text(encoding="utf-8").replace("50,25", "fault", 1))
    with pytest.raises(UserError, match=r"TripX02.csv: column 'Motor Torque \[Nm\]' is not numeric: data row 0"):
        read("bmw-i3-tum", bad)


def test_bmw_trips_in_sub_folders_find_the_overview_above_and_the_folder_says_where(tmp_path):
    """Dress rehearsal: TUM trips sorted into month folders under the data set's overview.csv.
    Importing the top folder said only "no trip file among [...]" (sub-folders are not
    searched): it now names the sub-folders that hold trips. Importing those folders joined no
    overview ("no overview.csv beside the trip": no season, no added mass): the overview
    a folder or more above is now joined when it lists the trip, and the import equals the
    flat layout's. An overview above that does not list the trip is not taken."""
    ov = ("Trip,Date,Route/Area,Weather,Note\n"
          "TripZ01,2019-06-25_13-21-14,Munich East,sunny,\n"
          "TripZ02,2019-12-02_08-00-00,Munich North,cloudy,+ 80 kg\n")
    trip = BMW_HEADER + "0;36;500;10;390;-1\n0.1;37;500;10;390;-1\n"
    flat = tmp_path / "flat"
    flat.mkdir()
    (flat / "overview.csv").write_text(ov, encoding="utf-8")
    for t in ("TripZ01", "TripZ02"):
        write(flat, f"{t}.csv", trip)
    top = tmp_path / "nested"
    for t, month in (("TripZ01", "2019/06"), ("TripZ02", "2019/12")):
        (top / month).mkdir(parents=True)
        write(top / month, f"{t}.csv", trip)
    (top / "overview.csv").write_text(ov, encoding="utf-8")
    with pytest.raises(UserError, match=r"its sub-folders hold 2 such file\(s\).*2019/06.*2019/12"):
        read("bmw-i3-tum", top)
    d_flat, _ = read("bmw-i3-tum", flat)
    d_nest, rep = read("bmw-i3-tum", [top / "2019/06", top / "2019/12"])
    pd.testing.assert_frame_equal(d_flat, d_nest)
    by = d_nest.groupby("trip_id").first()
    assert by.loc["TripZ02", "season"] == "winter" and by.loc["TripZ02", "added_mass_kg"] == 80
    assert by.loc["TripZ02", "mass_kg"] == load_vehicle("bmw_i3").mass_kg + 80
    assert all(any("a folder above the trip" in n for n in r["notes"]) for r in rep["files"])
    # an overview above that does not list the trip is not joined
    other = tmp_path / "other" / "x"
    other.mkdir(parents=True)
    (tmp_path / "other" / "overview.csv").write_text(ov.replace("TripZ01", "TripY01"), encoding="utf-8")
    d, rep = read("bmw-i3-tum", write(other, "TripZ01.csv", trip))
    assert "season" not in d and any("no trip metadata" in n for n in rep["files"][0]["notes"])


def test_bmw_trip_below_someone_elses_overview_csv_is_read(tmp_path):
    """Only an overview above the trip that lists it is joined, so another data set's
    overview.csv (no 'Trip' column) a few folders up is no reason to refuse the trip; it
    was ("…/overview.csv: missing column 'Trip'"). One beside the trip is still checked."""
    (tmp_path / "overview.csv").write_text("name,value\na,1\n", encoding="utf-8")
    (tmp_path / "tum" / "2019").mkdir(parents=True)
    f = write(tmp_path / "tum" / "2019", "TripZ01.csv", BMW_HEADER + "0;36;500;10;390;-1\n0.1;37;500;10;390;-1\n")
    d, rep = read("bmw-i3-tum", f)
    assert len(d) == 2 and "season" not in d
    assert any("no trip metadata" in n for n in rep["files"][0]["notes"])
    (tmp_path / "tum" / "2019" / "overview.csv").write_text("name,value\na,1\n", encoding="utf-8")
    with pytest.raises(UserError, match="missing column 'Trip'"):
        read("bmw-i3-tum", f)


def test_rows_wider_than_the_header_are_told_from_the_file_whatever_pandas_warns(tmp_path):
    """pandas 2.x reads a file whose data rows end with a separator without the
    ParserWarning pandas 3 gives (with dtype=str): the note "data rows hold more fields
    than the header line" depended on the pandas version (a rehearsal on pandas 2.1, the
    lower bound). The file itself says it; quoted separators are fields, not separators."""
    from sumo_drvpw.data.adapters._common import _wider_first_row

    wide = tmp_path / "wide.csv"
    wide.write_text("t,v\n0,1,\n1,2,\n", encoding="utf-8")
    plain = tmp_path / "plain.csv"
    plain.write_text('t,v\n0,"1,5"\n1,2\n', encoding="utf-8")
    semi = tmp_path / "semi.csv"
    semi.write_text("t;v\n0;1;\n", encoding="utf-8")
    assert _wider_first_row(wide, {}) and not _wider_first_row(plain, {})
    assert _wider_first_row(semi, {"sep": ";"}) and not _wider_first_row(semi, {})
    assert not _wider_first_row(wide, {"header": None})  # no header line to compare with


def test_columns_a_file_whose_rows_end_in_cr_only_reads_and_is_told_when_wider(tmp_path):
    """Rows ending in CR alone (old Mac-style loggers): the check of the first rows' widths
    read them with the csv module, which raised "new-line character seen in unquoted field"
    as a traceback (a review); pandas reads such a file, and so does the check."""
    m = write(tmp_path, "map.toml", '[columns.t]\nname = "time_s"\n[columns.v]\nname = "speed_mps"\n'
              'unit = "km/h"\n')
    for name, text, wider in (("cr.csv", "t,v\r0,10\r1,12\r2,14\r3,16\r", False),
                              ("crw.csv", "t,v,x\r0,10,1,\r1,12,2,\r2,14,3,\r3,16,4,\r", True)):
        df, rep = read("columns", write(tmp_path, name, text), columns=m)
        np.testing.assert_allclose(df["speed_mps"], np.array([10, 12, 14, 16]) / 3.6)
        assert any("more fields than the header line" in n for n in rep["files"][0]["notes"]) == wider


def test_torque_device_time_is_read_whatever_the_process_locale(tmp_path):
    """Torque's 'Device Time' names its month in English ('25-Mar-2017'); pandas reads a
    format's %b by the process's LC_TIME, so a notebook or application that had called
    ``locale.setlocale(LC_ALL, "")`` under German refused every row ('Mar' is no German
    month: 'Mär') and under Turkish the October rows. Read the same in any locale."""
    import locale

    rec = [{"Device Time": f"{d}-{m}-2017 11:46:{29 + i}.500", "Speed (OBD)(mph)": 20.0 + i}
           for i, (d, m) in enumerate([("25", "Mar"), ("31", "Oct"), ("01", "Dec"), ("02", "may")])]
    p = write(tmp_path, "t.json", json.dumps(rec))
    ref, _ = read("torquepro", p)
    assert np.all(np.diff(ref["time_s"]) != 0)  # four different days, in order of the rows
    old = locale.setlocale(locale.LC_TIME)
    tried = 0
    try:
        for name in ("de_DE.UTF-8", "tr_TR.UTF-8", "fr_FR.UTF-8"):
            try:
                locale.setlocale(locale.LC_TIME, name)
            except locale.Error:
                continue
            tried += 1
            df, _ = read("torquepro", p)
            np.testing.assert_array_equal(df["time_s"], ref["time_s"], err_msg=name)
    finally:
        locale.setlocale(locale.LC_TIME, old)
    if not tried:
        pytest.skip("no German, Turkish or French locale on this machine")


def test_a_boolean_where_a_number_is_due_is_refused_naming_its_row():
    """A JSON true/false (a Python or numpy bool among numbers) or a (nullable) bool column read
    where a number is due: refused naming the column and the first such row, not read as 1/0 (a
    Torque speed `true` read as 1 mph, exit 0: today's fuzz). Numbers and number texts '0'/'1' pass;
    a flag (``bools``) reads true/false as 1/0."""
    from sumo_drvpw.data.adapters._common import numeric  # (data/adapters/cells.py, re-exported)

    for col, row in ((pd.Series([20.0, "0", 1, True, 0.5], dtype=object), 3),
                     (pd.Series([20.0, "-", np.bool_(False)], dtype=object), 2),
                     (pd.Series([None, False, True], dtype="boolean"), 1),
                     (pd.Series([True, False]), 0)):
        with pytest.raises(UserError, match=rf"f\.json: column 'v' is not numeric: data row {row} holds (true|false) "):
            numeric(col, "f.json", "v")
        assert numeric(col, "f.json", "v", ("-",), bools=True).notna().sum() >= 2
    assert numeric(pd.Series([20.0, "0", 1, 0.0, "-"], dtype=object), "f", "v").tolist()[:4] == [20.0, 0.0, 1.0, 0.0]


def test_a_mapped_name_ending_in_another_spelling_of_its_si_unit_is_read(tmp_path):
    """A name whose suffix spells its quantity's SI unit another way ('coolant_celsius' from
    °C, 'throttle_percent' from %) holds the value in the unit it says: read, with no note
    (aff912d refused it as if it named another unit); a suffix naming another unit of the
    quantity ('coolant_k' from °C, written in °C) is still refused."""
    from sumo_drvpw.data.adapters._common import DIMENSIONS, UNITS
    from sumo_drvpw.data.adapters.columns import load_mapping

    si = {k: d for k, (d, f, o) in UNITS.items()
          if d != "dimensionless" and k.isidentifier() and k != DIMENSIONS[d] and (f, o) == (1.0, 0.0)}
    assert si  # (the unit table spells some SI units more than one way)
    base = '[columns."t"]\nname = "time_s"\nunit = "s"\n[columns."v"]\nname = "speed_mps"\nunit = "km/h"\n'
    for word, dim in si.items():
        unit = next(k for k, (d, f, o) in UNITS.items() if d == dim and (f, o) == (1.0, 0.0))
        p = tmp_path / f"{word}.toml"
        p.write_text(base + f'[columns."x"]\nname = "thing_{word}"\nunit = "{unit}"\n', encoding="utf-8")
        m = load_mapping(p)
        assert m["columns"]["x"]["factor"] == 1.0 and m["columns"]["x"]["offset"] == 0.0, word
        assert m["notes"] == [], word
    p = tmp_path / "k.toml"
    p.write_text(base + '[columns."x"]\nname = "coolant_k"\nunit = "degC"\n', encoding="utf-8")
    with pytest.raises(UserError, match="'coolant_k' ends in '_k'"):
        load_mapping(p)
