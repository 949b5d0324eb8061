"""Defects found rehearsing a public heavy-duty truck log nobody here had used (2026-11-29,
docs/adapters.md): Virginia Tech's PEMS export of two diesel trucks (Torreskai0722/FEAD,
``VT-Dataset/veh00N_all.csv``: one row per second, no time column, ``vel (mph)``,
``fuel (g/s)``, ``elevation (m)``, a ``phase_num`` that recurs), and the Vehicle Energy
Dataset's trip number, unique only with its vehicle. Synthetic files only."""

from __future__ import annotations

import numpy as np
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.adapters import read
from sumo_drvpw.errors import UserError

HEADER = "CO2 (g/s),vel (mph),fuel (g/s),engine (rpm),elevation (m),phase_num"


def _pems_csv(path, phases):
    """A VT-style export: rows one second apart, no time column; ``phases`` = [(phase, n)]
    written in that order (a phase number may recur)."""
    rows = [HEADER]
    for phase, n in phases:
        for k in range(n):
            rows.append(f"{2.0 + k / 10:g},{min(k, 40):g},{0.6 + k / 100:g},{650 + 20 * k:g},{100 + k / 10:g},{phase}")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def _mapping(path, options="time_step_s = 1\n", time=""):
    path.write_text("[options]\n" + options + time
                    + '[columns."vel (mph)"]\nname = "speed_mps"\nunit = "mph"\n'
                    + '[columns."fuel (g/s)"]\nname = "fuel_rate_gps"\nunit = "g/s"\n'
                    + '[columns."phase_num"]\nname = "trip_id"\n', encoding="utf-8")
    return path


def test_a_table_without_a_time_column_takes_its_time_from_the_row_number(tmp_path):
    # the export had no time column, and the mapping no way to say 'one row a second': the
    # user had to add a column by hand. options.time_step_s gives time_s = data row × step;
    # a phase that recurs after other rows keeps the pause between its runs
    src = _pems_csv(tmp_path / "veh.csv", [(1, 30), (2, 20), (1, 25)])
    df, rep = read("columns", [src], _mapping(tmp_path / "map.toml", "time_step_s = 0.5\n"))
    assert rep["rows_read"] == 75 and rep["kept"] == 75
    one = df[df["trip_id"] == "1"]["time_s"].to_numpy()
    np.testing.assert_allclose(one, np.r_[np.arange(30), np.arange(50, 75)] * 0.5)
    np.testing.assert_allclose(df[df["trip_id"] == "2"]["time_s"], np.arange(30, 50) * 0.5)
    assert any("time_step_s = 0.5 s" in n for n in rep["files"][0]["notes"]), rep["files"][0]["notes"]


@pytest.mark.parametrize("options,time,says", [
    ("time_step_s = 0\n", "", "options.time_step_s must be the seconds between a table's rows (> 0, ≤ 30"),
    ("time_step_s = 60\n", "", "options.time_step_s must be the seconds between a table's rows (> 0, ≤ 30"),
    ("time_step_s = true\n", "", "options.time_step_s must be"),
    ("time_step_s = 1\n", '[columns."engine (rpm)"]\nname = "time_s"\n', "map no column to 'time_s' beside it"),
    ("", "", "no source column is mapped to 'time_s' (required; a table whose rows follow at a fixed rate "
             "without a time column: options.time_step_s"),
])
def test_the_time_step_is_checked_and_offered_when_no_time_is_mapped(tmp_path, options, time, says):
    src = _pems_csv(tmp_path / "veh.csv", [(1, 10)])
    with pytest.raises(UserError) as e:
        read("columns", [src], _mapping(tmp_path / "map.toml", options, time))
    assert says in str(e.value) and "map.toml" in str(e.value)


def test_the_sketch_maps_vel_and_a_fuel_mass_flow_and_offers_the_time_step(tmp_path, capsys):
    # the sketch saw no speed in 'vel (mph)', no fuel target in 'fuel (g/s)' (it guessed a
    # fuel rate in L/h only) and said of the time only 'map one'
    src = _pems_csv(tmp_path / "veh.csv", [(1, 20)])
    assert cli_main(["import", "columns", str(src), "--list"]) == 0
    out = capsys.readouterr().out
    sk = out[out.index("# from "):]
    for want in ('[columns."vel (mph)"]\nname = "speed_mps"\nunit = "mph"',
                 '[columns."fuel (g/s)"]\nname = "fuel_rate_gps"\nunit = "g/s"',
                 "[options] time_step_s = <seconds between rows>"):
        assert want in sk, sk
    assert "CO2" not in sk
    (tmp_path / "map.toml").write_text("[options]\ntime_step_s = 1\n" + sk, encoding="utf-8")
    assert cli_main(["import", "columns", str(src), "--columns", str(tmp_path / "map.toml"),
                     "--out", str(tmp_path / "veh.parquet")]) == 0
    from sumo_drvpw.data.log import read_log

    df = read_log(tmp_path / "veh.parquet").df
    np.testing.assert_allclose(df["time_s"], np.arange(20.0))
    np.testing.assert_allclose(df["fuel_rate_gps"], 0.6 + np.arange(20) / 100)


def test_two_recordings_under_one_trip_id_are_named_not_only_counted(tmp_path):
    # VED numbers trips per vehicle ("each combination of VehId, Trip is unique"): two cars'
    # trip 706 in one weekly file, mapped by Trip alone, lost the second car's rows as 'time
    # going backwards' with nothing but the count — a trip column's notes were dropped
    rows = ["DayNum,VehId,Trip,Timestamp(ms),Vehicle Speed[km/h]"]
    for veh in (8, 10):
        rows += [f"1.{veh},{veh},706,{i * 1000},{10 + i}" for i in range(20)]
    src = tmp_path / "VED_171101_week.csv"
    src.write_text("\n".join(rows) + "\n", encoding="utf-8")
    m = tmp_path / "map.toml"
    m.write_text('[options]\ntime_unit = "ms"\n[columns."Trip"]\nname = "trip_id"\n[columns."Timestamp(ms)"]\n'
                 'name = "time_s"\n[columns."Vehicle Speed[km/h]"]\nname = "speed_mps"\nunit = "km/h"\n',
                 encoding="utf-8")
    df, rep = read("columns", [src], m)
    f = rep["files"][0]
    assert len(df) == 20 and f["dropped"]["time going backwards"] == 19
    note = [n for n in f["notes"] if "time going backwards" in n]
    assert len(note) == 1, f["notes"]
    assert note[0].startswith("trip 706: ") and "starts over at data row 20" in note[0]
    assert "two recordings share this trip id" in note[0]


def _truck(tmp_path, mass_kg):
    veh = tmp_path / f"truck{mass_kg}.toml"
    veh.write_text(f'[vehicle]\nname = "truck"\nmass_kg = {mass_kg}\n[body]\ndrag_coefficient = 0.62\n'
                   'frontal_area_m2 = 10.0\nrolling_coefficient = 0.0065\n[powertrain]\ntype = "direct"\n'
                   'fuel = "diesel"\ndisplacement_l = 15.0\n', encoding="utf-8")
    return veh


def _truck_log(tmp_path, mass_kg):
    """Two 1-Hz trips with a planted wheel power of a ``mass_kg`` vehicle and its fuel."""
    import pandas as pd

    frames = []
    for trip in ("a", "b"):
        t = np.arange(1200.0)
        v = (12 + 8 * np.sin(t / 60.0 + (trip == "b"))) * np.clip((t - 30.0) / 60.0, 0.0, 1.0)  # 30 s standing
        a = np.gradient(v, t)
        p = mass_kg * v * (1.05 * a + 9.81 * 0.0065) + 3.7 * v ** 3
        fuel_w = 30000.0 + np.maximum(p, 0.0) / 0.4
        frames.append(pd.DataFrame({"trip_id": trip, "time_s": t, "speed_mps": v, "power_w": p,
                                    "fuel_rate_gps": fuel_w / 43.1e3}))
    log = tmp_path / f"log{mass_kg}.csv"
    pd.concat(frames).to_csv(log, index=False)
    return log


@pytest.mark.parametrize("mass_kg,extra,warned", [
    (30000, [], True),                                                            # road load, truck
    (30000, ["--target", "fuel", "--equation", "vsp_spec"], True),                # fuel chain, truck
    (30000, ["--target", "fuel", "--equation", "moves_combination_truck"], False),  # says 'trailer'
    (1500, [], False),                                                            # a car
])
def test_an_equation_calibrated_on_a_heavy_vehicle_that_declares_the_car_classes_is_said(
        tmp_path, capsys, mass_kg, extra, warned):
    # the rehearsal's truck chain, written without vclasses, booked every car of the built-in
    # highway (161 passenger cars, 23.7 L/100 km), and nothing said: the default classes of
    # an equation file are the car classes
    out = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(_truck_log(tmp_path, mass_kg)), "--vehicle", str(_truck(tmp_path, mass_kg)),
                     "--out", str(out), *extra]) == 0
    said = [x for x in capsys.readouterr().out.splitlines() if "declares the car classes" in x]
    assert bool(said) == warned, said
    if warned:
        assert said[0].startswith(f"warning: eq is calibrated on a {mass_kg:,}-kg vehicle") and str(out) in said[0]
        assert 'vclasses = ["trailer"]' in said[0]


@pytest.mark.parametrize("extra", [[], ["--engine", "memory"], ["--target", "fuel"],
                                   ["--target", "fuel", "--engine", "memory"]])
def test_a_heavy_log_with_its_own_mass_column_is_said_without_a_vehicle_file(tmp_path, capsys, extra):
    # a log that carries mass_kg needs no --vehicle; the warning read only the vehicle file's
    # mass, so a 30-t truck's equation was written for the car classes without a word
    import pandas as pd

    log = _truck_log(tmp_path, 30000)
    pd.read_csv(log).assign(mass_kg=30000.0).to_csv(log, index=False)
    out = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(log), "--out", str(out), *extra]) == 0
    said = [x for x in capsys.readouterr().out.splitlines() if "declares the car classes" in x]
    assert said and said[0].startswith("warning: eq is calibrated on a 30,000-kg vehicle"), said


def test_a_one_sample_speed_step_is_left_out_not_read_as_a_deceleration(tmp_path, capsys):
    # the VT logs splice recordings without a mark: 33.8 mph → 0 in one second (15.1 m/s).
    # The central difference halved it to −7.5 m/s² on two samples, under the 8 m/s² outlier
    # limit, and a 30-t truck's acceleration term booked −3.4 MW there: on a power planted on
    # veh002's speeds the acc coefficient read 1.031 for 1.074 without the splices. Here a
    # trip of two recordings (the first ends at 15 m/s, the second starts standing)
    import pandas as pd

    rng = np.random.default_rng(3)
    m = 30000.0

    def recording(n, v0, phase):
        t = np.arange(n, dtype=float)
        v = np.clip(v0 + 9 * np.sin(t / 45.0 + phase) + 6 * t / n, 0, None)
        a = np.gradient(v, t)
        return v, m * v * (1.08 * a + 9.81 * 0.0065) + 3.7 * v ** 3

    parts = [recording(600, 9.0, 5 * np.pi - 599 / 45.0), recording(600, 0.0, -np.pi / 2),
             recording(1200, 14.0, 1.0)]
    v = np.concatenate([p[0] for p in parts])
    p = np.concatenate([p[1] for p in parts]) + rng.normal(0, 2e3, len(v))
    assert v[599] == pytest.approx(15.0, abs=0.1) and v[600] == 0.0  # the splice: 15 m/s to standstill
    trip = np.r_[np.repeat("a", 1200), np.repeat("b", 1200)]
    t = np.r_[np.arange(1200.0), np.arange(1200.0)]
    log = tmp_path / "spliced.csv"
    pd.DataFrame({"trip_id": trip, "time_s": t, "speed_mps": v, "power_w": p}).to_csv(log, index=False)
    out = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(log), "--vehicle", str(_truck(tmp_path, 30000)), "--out", str(out)]) == 0
    said = capsys.readouterr().out
    from sumo_drvpw.model.equations import load_equation

    assert load_equation(out).terms["acc"] == pytest.approx(1.08, rel=0.01)
    note = [x for x in said.splitlines() if "one-sample speed step" in x]
    assert note and note[0].startswith("note: 2 sample(s) left out around 1 one-sample speed step(s) "
                                       "steeper than 8.0 m/s²"), said


def test_compares_console_line_names_the_worst_of_the_trips_it_scores():
    # compare's report.md left the truck's small trips out of mean and worst (veh002_s03_p4:
    # 0.050 L measured, +860 %), but the console's line named that trip as the worst while
    # printing the mean without it: 'mean 55.3 %, worst +860.2 % (veh002_s03_p4)' beside
    # report.md's '55.3 % / 207.8 % (veh002_s09_p5)'
    from sumo_drvpw.cli.compare import trip_energy_line
    from sumo_drvpw.fit.trip_energy import trip_energy_doc

    doc = trip_energy_doc(["s01", "s03", "s09", "s11"], [6.6e7, 1.8e6, 2.0e7, 6.6e7], [1.16e8, 1.72e7, 6.1e7, 5.8e7])
    assert doc["small_trips"] == ["s03"]
    line = trip_energy_line({"trip_energy": doc, "trip_net_energy": doc})
    assert line.startswith("per trip (4; 1 small, left out of mean and worst): traction energy |error| mean ")
    assert f"worst +{100 * (6.1e7 / 2.0e7 - 1):.1f} % (s09)" in line and "s03" not in line
    assert trip_energy_line({"trip_energy": trip_energy_doc(["a", "b"], [1.0, 1.0], [1.1, 0.8])}) == \
        "per trip (2): traction energy |error| mean 15.0 %, worst -20.0 % (b)"


@pytest.mark.parametrize("target", ["fuel", "battery"])
@pytest.mark.parametrize("engine", ["local", "memory"])
def test_a_heavy_log_s_chain_on_a_given_road_load_is_said_streamed_as_in_memory(tmp_path, capsys, target, engine):
    # `calibrate --target fuel|battery --equation ROAD` on a 30-t log with its own mass column
    # and no --vehicle: the in-memory path warned that the equation declares the car classes,
    # the streamed path (the default engine) said nothing — it took the log's mass only from
    # a road load fitted on the log, and with --equation none is
    import pandas as pd

    log = _truck_log(tmp_path, 30000)
    d = pd.read_csv(log).assign(mass_kg=30000.0)
    if target == "battery":  # an electric truck: the battery's V·I from the wheel power
        p = d["power_w"].to_numpy()
        d = d.drop(columns="fuel_rate_gps").assign(
            battery_voltage_v=650.0, battery_current_a=np.where(p > 0, p / 0.9, p * 0.8) / 650.0 + 8.0)
    d.to_csv(log, index=False)
    road = tmp_path / "road.toml"
    road.write_text('[equation]\nname = "road"\n[terms]\nacc = 1.05\ngrade = 1.0\nroll = 0.0065\naero = 3.7\n',
                    encoding="utf-8")
    out = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(log), "--target", target, "--equation", str(road), "--out", str(out),
                     "--engine", engine]) == 0
    said = [x for x in capsys.readouterr().out.splitlines() if "declares the car classes" in x]
    assert said and said[0].startswith("warning: eq is calibrated on a 30,000-kg vehicle"), said
