"""``sumo-drvpw import columns SRC --list``: what a file offers, to write its mapping from
(sumo_drvpw/data/adapters/listing.py) — MDF channels with unit, samples and rate (raw CAN
decoded with the mapping's DBC files, ISO-TP responses reassembled), CSV columns with the
unit their label carries; nothing written; misuse in one line with exit 2."""

from __future__ import annotations

from pathlib import Path

import pytest

from sumo_drvpw.cli import main as cli_main

HERE = Path(__file__).resolve().parent / "data" / "mdf"


def _lines(capsys) -> list[str]:
    return capsys.readouterr().out.splitlines()


def _row(lines, label):
    return next(line.split() for line in lines if line.split() and line.split()[0] == label)


def test_a_raw_can_log_lists_its_frames_then_its_signals_with_the_dbc(tmp_path, capsys):
    pytest.importorskip("asammdf")
    assert cli_main(["import", "columns", str(HERE / "canmod_gps.MF4"), "--list"]) == 0
    out = _lines(capsys)
    assert out[0].endswith("(ASAM MDF): 11 channels") and _row(out, "CAN_DataFrame.ID")[1] == "5477"
    assert any("name the vehicle's DBC files as options.dbc" in line for line in out)
    # a mapping with its [options] alone (the [columns] not yet written) gives the DBC
    m = tmp_path / "map.toml"
    m.write_text(f'[options]\ndbc = ["{(HERE / "canmod-gps.dbc").as_posix()}"]\n', encoding="utf-8")
    assert cli_main(["import", "columns", str(HERE / "canmod_gps.MF4"), "--list", "--columns", str(m)]) == 0
    out = _lines(capsys)
    assert "decoded with canmod-gps.dbc): 39 channels" in out[0]
    assert _row(out, "Speed") == ["Speed", "m/s", "41", "1", "0.953"]      # the GNSS at 1 Hz, with a gap
    assert _row(out, "AccelerationX") == ["AccelerationX", "m/s^2", "4518", "100", "101"]  # the IMU at 100 Hz
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.toml"]        # nothing written


def test_iso_tp_responses_are_listed_as_signals(tmp_path, capsys):
    pytest.importorskip("asammdf")
    m = tmp_path / "map.toml"
    m.write_text(f'[options]\ndbc = ["{(HERE / "tp_uds.dbc").as_posix()}"]\n', encoding="utf-8")
    assert cli_main(["import", "columns", str(HERE / "kona_uds.MF4"), "--list", "--columns", str(m)]) == 0
    out = _lines(capsys)
    assert _row(out, "M_SID_0x220101_StateOfChargeBMS") == ["M_SID_0x220101_StateOfChargeBMS", "%", "120", "0.5",
                                                               "0.496"]
    assert any("ISO-TP responses reassembled" in line and "Battery 120" in line for line in out)


def test_a_csv_without_mapping_is_sniffed_and_its_units_read_from_the_labels(tmp_path, capsys):
    f = tmp_path / "log.csv"
    f.write_bytes("Zeit [s];Geschwindigkeit [km/h];Außentemperatur (°C);Fahrer\n0;0;3;A\n0.1;1.5;3;A\n"
                  "0.2;;3;A\n".encode("latin-1"))
    assert cli_main(["import", "columns", str(f), "--list"]) == 0
    out = _lines(capsys)
    assert out[0].endswith("(table): 4 columns")
    assert _row(out, "Geschwindigkeit") == ["Geschwindigkeit", "[km/h]", "km/h", "2", "2", "0"]
    assert _row(out, "Außentemperatur")[2:5] == ["°C", "3", "3"]
    assert _row(out, "Fahrer") == ["Fahrer", "3", "0", "A"]                  # text: no unit, no numbers
    assert any("read as latin-1, ';'-separated (sniffed)" in line for line in out)


def _sketch(lines: list[str]) -> str:
    return "\n".join(lines[next(i for i, line in enumerate(lines) if line.startswith("# from ")):]) + "\n"


def test_the_mapping_sketch_imports_the_file_it_was_listed_from(tmp_path, capsys):
    """The listing ends with a mapping guessed from labels and units; saved as it is, it
    imports the file: here a Latin-1, ';'-separated log with a speed in km/h, a battery's
    voltage and current beside a cell's voltage (not taken), an outside temperature."""
    import numpy as np

    from sumo_drvpw.data.log import read_log

    f = tmp_path / "drive.csv"
    t = np.arange(0.0, 30.0, 0.5)
    rows = [f"{a:g};{3.6 * min(a, 10.0):g};{395 - a:g};{3.9:g};{20 + a:g};4" for a in t]
    f.write_bytes(("Zeit [s];Geschwindigkeit [km/h];Battery Voltage [V];Cell Voltage Max [V];"
                   "Battery Current [A];Außentemperatur (°C)\n" + "\n".join(rows) + "\n").encode("latin-1"))
    assert cli_main(["import", "columns", str(f), "--list"]) == 0
    sk = _sketch(_lines(capsys))
    for want in ('[columns."Geschwindigkeit [km/h]"]\nname = "speed_mps"\nunit = "km/h"',
                 '[columns."Battery Voltage [V]"]\nname = "battery_voltage_v"',
                 '[columns."Außentemperatur (°C)"]\nname = "ambient_c"', 'sep = ";"', 'encoding = "latin-1"'):
        assert want in sk, sk
    assert "Cell Voltage" not in sk
    (tmp_path / "map.toml").write_text(sk, encoding="utf-8")
    assert cli_main(["import", "columns", str(f), "--columns", str(tmp_path / "map.toml"),
                     "--out", str(tmp_path / "drive.parquet")]) == 0
    df = read_log(tmp_path / "drive.parquet").df
    np.testing.assert_allclose(df["speed_mps"], np.minimum(t, 10.0))
    np.testing.assert_allclose(df["battery_current_a"], 20 + t)
    assert set(df["ambient_c"]) == {4.0}


def test_the_sketch_of_a_raw_can_log_names_its_dbc_and_imports(tmp_path, capsys):
    pytest.importorskip("asammdf")
    import shutil

    shutil.copy(HERE / "canmod-gps.dbc", tmp_path / "canmod-gps.dbc")
    m = tmp_path / "options.toml"
    m.write_text('[options]\ndbc = ["canmod-gps.dbc"]\n', encoding="utf-8")
    assert cli_main(["import", "columns", str(HERE / "canmod_gps.MF4"), "--list", "--columns", str(m)]) == 0
    sk = _sketch(_lines(capsys))
    assert 'dbc = ["canmod-gps.dbc"]' in sk and '[columns."Speed"]\nname = "speed_mps"' in sk, sk
    (tmp_path / "map.toml").write_text(sk, encoding="utf-8")
    assert cli_main(["import", "columns", str(HERE / "canmod_gps.MF4"), "--columns", str(tmp_path / "map.toml"),
                     "--out", str(tmp_path / "gps.parquet")]) == 0


@pytest.mark.parametrize("args, says", [
    (["import", "jlu-road", "x.parquet", "--list"], "--list is for format 'columns'"),
    (["import", "columns", "broken.parquet", "--list"], "broken.parquet: cannot be read as Parquet"),
    (["import", "columns", "x.csv", "--columns", "m.toml"], "--out LOG.parquet is required"),
])
def test_misuse_in_one_line(tmp_path, capsys, monkeypatch, args, says):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "broken.parquet").write_bytes(b"not parquet at all")
    assert cli_main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0]


@pytest.mark.parametrize("args, says", [
    (["import", "columns", "00000001.MFC", "--list"], "00000001.MFC: a CANedge log file compressed by the logger"),
    (["import", "columns", "LOG", "--columns", "m.toml", "--out", "o.parquet"],
     "00000002.MFE: a CANedge log file encrypted by the logger"),
    (["compare", "00000003.MFM", "--equation", "vsp_ldv1999", "--vehicle", "bmw_i3", "--out", "o"],
     "00000003.MFM: a CANedge log file compressed and encrypted by the logger"),
])
def test_a_canedge_packed_file_is_named_as_one(tmp_path, capsys, monkeypatch, args, says):
    """A CANedge's compressed (.MFC) or encrypted (.MFE, .MFM) MF4 — a rehearsal's J1939 log
    — was read as CSV and refused as "no data rows"; now it is named for what it is, with
    the converter that unpacks it, named or found in a folder, by every reader."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "LOG").mkdir()
    for f in ("00000001.MFC", "LOG/00000002.MFE", "00000003.MFM"):
        (tmp_path / f).write_bytes(b"\x00\x01packed")
    (tmp_path / "m.toml").write_text('[columns."Speed"]\nname = "speed_mps"\n', encoding="utf-8")
    assert cli_main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0] and "MF4 converters" in err[0]
    assert not (tmp_path / "o").exists() and not (tmp_path / "o.parquet").exists()


def test_labels_without_units_are_offered_as_comments(tmp_path, capsys):
    """A Parquet log whose labels carry no unit (as the JLU car's): the sketch maps nothing it
    cannot read a unit for, and names the likely columns in comments."""
    import pandas as pd

    f = tmp_path / "road.parquet"
    pd.DataFrame({"PhaseTime": [0.0, 0.05], "DAActualSpeed": [0.0, 1.2], "REESSVoltage": [392.3, 392.1],
                  "tempAmb": [21.5, 21.5]}).to_parquet(f)
    assert cli_main(["import", "columns", str(f), "--list"]) == 0
    sk = _sketch(_lines(capsys))
    assert "[columns." not in sk
    for want in ("# time_s: perhaps PhaseTime", "# speed_mps: perhaps DAActualSpeed",
                 "# battery_voltage_v: perhaps REESSVoltage", "# ambient_c: perhaps tempAmb"):
        assert want in sk, sk


def test_the_sketch_prefers_the_vehicle_speed_to_a_wheel_speed():
    """J1939's WheelBasedVehicleSpeed is the vehicle's speed; a single wheel's speed is not."""
    from sumo_drvpw.data.adapters.listing import sketch

    rows = [{"label": "WheelSpeedFL", "unit": "km/h"}, {"label": "EngineSpeed", "unit": "rpm"},
            {"label": "GpsSpeed", "unit": "km/h"}, {"label": "WheelBasedVehicleSpeed", "unit": "km/h"}]
    sk = sketch(rows, True, {})
    assert '[columns."WheelBasedVehicleSpeed"]\nname = "speed_mps"  # also fits: GpsSpeed' in sk, sk
    assert "WheelSpeedFL" not in sk and "EngineSpeed" not in sk


def test_the_sketch_prefers_the_channel_that_covers_the_log_to_a_bursty_one():
    """A J1939 log's tachograph speed (TCO1) came in bursts: 20 Hz between gaps, 2 Hz over the
    log; the wheel-based speed (CCVS) at a steady 10 Hz. Both name the vehicle's speed; the
    sketch mapped the one listed first — the bursty one. Now the mean rate over the log
    decides; a table's column with more values wins the same way."""
    from sumo_drvpw.data.adapters.listing import sketch

    rows = [{"label": "TachographVehicleSpeed", "unit": "km/h", "samples": 7200, "rate_hz": 20.0, "mean_rate_hz": 2.0},
            {"label": "WheelBasedVehicleSpeed", "unit": "km/h", "samples": 36000, "rate_hz": 10.0, "mean_rate_hz": 10.0}]
    sk = sketch(rows, True, {})
    assert '[columns."WheelBasedVehicleSpeed"]\nname = "speed_mps"  # also fits: TachographVehicleSpeed' in sk, sk
    table = [{"label": "Vehicle speed (km/h)", "unit": "km/h", "samples": 40},
             {"label": "Vehicle speed OBD (km/h)", "unit": "km/h", "samples": 4000}]
    assert '[columns."Vehicle speed OBD (km/h)"]' in sketch(table, False, {})


def test_the_sketch_maps_the_bms_state_of_charge_and_says_how_it_becomes_energy():
    """The BMS's SOC (not the displayed one, nor a minimum, maximum or health) is sketched as
    soc_pct, with the option that makes it the battery's energy where the log has no V·I."""
    from sumo_drvpw.data.adapters.listing import sketch

    rows = [{"label": "displayed SoC [%]", "unit": "%"}, {"label": "min. SoC [%]", "unit": "%"},
            {"label": "SoH [%]", "unit": "%"}, {"label": "SoC [%]", "unit": "%"}]
    sk = sketch(rows, False, {})
    assert '[columns."SoC [%]"]\nname = "soc_pct"\nunit = "%"\n# without battery V·I' in sk, sk
    assert "soc_capacity_kwh" in sk and "displayed" not in sk and "min. SoC" not in sk
    assert "soc_pct" not in sketch([{"label": "Throttle [%]", "unit": "%"}], False, {})
    for label in ("M_SID_0x220101_StateOfChargeBMS", "SOC_BMS", "State of Charge (BMS)"):  # UDS, DBC, apps
        assert f'[columns."{label}"]\nname = "soc_pct"' in sketch([{"label": label, "unit": "%"}], True, {})
    assert "soc_pct" not in sketch([{"label": "StateOfChargeDisplay", "unit": "%"},
                                    {"label": "SoH_BMS", "unit": "%"}], True, {})


def test_the_sketch_maps_a_bms_energy_counters():
    """A BMS's cumulative energy counters (Hyundai/Kia CED and CEC; the JLU car's tot_disc,
    tot_char) are the battery target of a log without V·I: the sketch maps each to its own
    counter, never the discharged one to the charged one, and not a power or a cell value."""
    from sumo_drvpw.data.adapters.listing import sketch

    rows = [{"label": "Cumulative Energy Discharged (CED) (kWh)", "unit": "kWh"},
            {"label": "Cumulative Energy Charged (CEC) (kWh)", "unit": "kWh"},
            {"label": "Max regen power (kW)", "unit": "kW"}]
    sk = sketch(rows, False, {})
    assert '[columns."Cumulative Energy Discharged (CED) (kWh)"]\nname = "battery_discharge_energy_j"\nunit = "kWh"' in sk, sk
    assert '[columns."Cumulative Energy Charged (CEC) (kWh)"]\nname = "battery_charge_energy_j"\nunit = "kWh"' in sk, sk
    jlu = sketch([{"label": "tot_disc", "unit": ""}, {"label": "tot_char", "unit": ""}], True, {})
    assert "# battery_discharge_energy_j: perhaps tot_disc" in jlu and "# battery_charge_energy_j: perhaps tot_char" in jlu, jlu


def test_a_label_whose_parenthesis_is_no_unit_is_offered_as_a_comment():
    """'Cumulative Energy Discharged (CED)' reads as unit 'CED' (the label's parenthesis), no
    unit known: it was left out of the sketch; now it is offered, to be given its unit."""
    from sumo_drvpw.data.adapters.listing import sketch

    sk = sketch([{"label": "Cumulative Energy Discharged (CED)", "unit": "CED"},
                 {"label": "Cumulative Energy Charged (CEC)", "unit": "CEC"}], False, {})
    assert "# battery_discharge_energy_j: perhaps Cumulative Energy Discharged (CED) (no unit recognised" in sk, sk
    assert "# battery_charge_energy_j: perhaps Cumulative Energy Charged (CEC) (no unit recognised" in sk, sk


def test_a_parquet_column_whose_first_values_are_missing_is_listed(tmp_path, capsys):
    """A Parquet log whose column starts with missing values (a float NaN, a string None): its
    first value is the first one present and its count leaves the missing ones out, as the
    CSV listing does. Before, the listing crashed with a traceback ('float' object is not
    subscriptable: pandas' str dtype keeps NaN a float) — found on an OBD Auto Doctor log
    whose ambient temperature arrived after the first rows."""
    import pandas as pd

    f = tmp_path / "obd.parquet"
    pd.DataFrame({"Time (s)": [0.0, 0.5, 1.0], "Speed (km/h)": [0.0, 3.6, 7.2],
                  "Ambient (°C)": [float("nan"), 4.0, 4.5], "Note": [None, None, "warm"]}).to_parquet(f)
    assert cli_main(["import", "columns", str(f), "--list"]) == 0
    rows = {ln.split()[0]: ln for ln in _lines(capsys) if ln.startswith("  ")}
    assert rows["Ambient"].split()[-3:] == ["2", "2", "4.0"], rows
    assert rows["Note"].split()[-3:] == ["1", "0", "warm"], rows


def test_a_speed_unit_declared_for_an_imported_log_is_refused(tmp_path, capsys):
    """`import` writes speed_mps in m/s; `--speed-unit km/h` on its output divided the speed by
    3.6 a second time (a rehearsal's Seat Leon calibrated at a top speed of 33 km/h, only the
    efficiency flagged). Refused in one line naming the log; a canonical Parquet written by
    other means still takes the unit."""
    import numpy as np
    import pandas as pd

    f = tmp_path / "drive.csv"
    t = np.arange(0.0, 60.0, 0.5)
    f.write_text("Time [s],Speed [km/h]\n" + "\n".join(f"{a:g},{3.6 * min(a, 20.0):g}" for a in t) + "\n", encoding="utf-8")
    (tmp_path / "m.toml").write_text('[columns."Time [s]"]\nname = "time_s"\n'
                                     '[columns."Speed [km/h]"]\nname = "speed_mps"\nunit = "km/h"\n', encoding="utf-8")
    log = tmp_path / "drive.parquet"
    assert cli_main(["import", "columns", str(f), "--columns", str(tmp_path / "m.toml"), "--out", str(log)]) == 0
    capsys.readouterr()
    assert cli_main(["dynamics", str(log), "--speed-unit", "km/h", "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(log) in err and "m/s already" in err, err
    assert not (tmp_path / "d").exists()
    plain = tmp_path / "plain.parquet"  # not the import's: the declared unit is read
    pd.DataFrame({"time_s": t, "speed_mps": 3.6 * np.minimum(t, 20.0)}).to_parquet(plain)
    from sumo_drvpw.data.log import ReadOptions, check_declared_unit

    check_declared_unit([plain], ReadOptions(speed_unit="km/h"))


def test_the_sketch_maps_clock_times_and_a_petrol_engines_air_and_fuel_flow(tmp_path, capsys):
    """An OBD Auto Doctor export (KIT's OBD-II dataset): its time column holds clock times
    ('17:58:02.288'), its fuel target is the mass air flow. The sketch said of the time
    "give its unit" (a unit that then failed as 'not numeric') and proposed no MAF; now it
    maps the clock times with [options] time_unit/time_format, the air flow as maf_gps and a
    fuel rate as fuel_rate_lph, and the sketch imports the file as it is."""
    import numpy as np

    from sumo_drvpw.data.log import read_log

    f = tmp_path / "obd.csv"
    t = np.arange(0.0, 30.0, 0.5)
    rows = [f"17:58:{2 + a:06.3f},{3.6 * min(a, 10.0):g},{6.5 + a:g},{0.8 + a / 10:g},{60 + a:g}" for a in t]
    f.write_text("Time,Vehicle Speed Sensor [km/h],Air Flow Rate from Mass Flow Sensor [g/s],"
                 "Fuel Rate [L/h],Average Fuel Economy [L/h]\n" + "\n".join(rows) + "\n", encoding="utf-8")
    assert cli_main(["import", "columns", str(f), "--list"]) == 0
    sk = _sketch(_lines(capsys))
    for want in ('time_unit = "datetime"', 'time_format = "%H:%M:%S.%f"', '[columns."Time"]\nname = "time_s"',
                 '[columns."Air Flow Rate from Mass Flow Sensor [g/s]"]\nname = "maf_gps"',
                 '[columns."Fuel Rate [L/h]"]\nname = "fuel_rate_lph"'):
        assert want in sk, sk
    assert "Average Fuel Economy" not in sk.split("fuel_rate_lph")[0].split("\n")[-2]
    (tmp_path / "map.toml").write_text(sk, encoding="utf-8")
    assert cli_main(["import", "columns", str(f), "--columns", str(tmp_path / "map.toml"),
                     "--out", str(tmp_path / "obd.parquet")]) == 0
    df = read_log(tmp_path / "obd.parquet").df
    np.testing.assert_allclose(df["time_s"] - df["time_s"].iloc[0], t, atol=1e-6)
    np.testing.assert_allclose(df["maf_gps"], 6.5 + t)
    np.testing.assert_allclose(df["fuel_rate_lph"], 0.8 + t / 10)


def test_rows_finer_than_the_time_column_are_said_when_they_are_dropped(tmp_path, capsys):
    """carOBD's logs: the time in whole seconds, 3–4 rows in each; 73 % of the rows were
    dropped as 'duplicate timestamp' with no word why. The import now says that the time
    column is coarser than the rows, and what would keep them; a few repeated times are not
    remarked on."""
    f = tmp_path / "obd.csv"
    rows = [f"{k // 4},{k % 40}" for k in range(400)]
    f.write_text("Run time (s),Speed (km/h)\n" + "\n".join(rows) + "\n", encoding="utf-8")
    (tmp_path / "m.toml").write_text('[columns."Run time (s)"]\nname = "time_s"\nunit = "s"\n'
                                     '[columns."Speed (km/h)"]\nname = "speed_mps"\nunit = "km/h"\n', encoding="utf-8")
    assert cli_main(["import", "columns", str(f), "--columns", str(tmp_path / "m.toml"),
                     "--out", str(tmp_path / "o.parquet")]) == 0
    out = capsys.readouterr().out
    assert "dropped: duplicate timestamp 300" in out
    assert ("300 of 400 rows share their time with the row before (the time column steps by 1 s, the rows "
            "come 4.0 per step)") in out
    f.write_text("Run time (s),Speed (km/h)\n" + "\n".join(f"{k},{k % 40}" for k in range(400)) + "\n0,1\n", encoding="utf-8")
    assert cli_main(["import", "columns", str(f), "--columns", str(tmp_path / "m.toml"),
                     "--out", str(tmp_path / "p.parquet")]) == 0
    assert "share their time" not in capsys.readouterr().out


def test_the_sketch_maps_a_motor_power_and_names_units_it_does_not_know(tmp_path, capsys):
    """A public Nissan Leaf log (d-EVD): 'Motor Pwr(w)' was listed with its unit but the
    sketch proposed no power_w, and 'Aux Pwr(100w)' (hundreds of watts) was not said to
    be a unit it does not know. Now the motor power is the sketch's power_w (with a word on
    traction-only logs), an auxiliary or charging power is not, and the unknown unit is
    named with the way to map it (unit and scale)."""
    f = tmp_path / "leaf.csv"
    f.write_text("time_s,speed(km/h),Motor Pwr(w),Aux Pwr(100w),Charge Power(kW)\n"
                 + "\n".join(f"{t},{10 + t},{1500 - 100 * t},{2},{0}" for t in range(20)) + "\n", encoding="utf-8")
    assert cli_main(["import", "columns", str(f), "--list"]) == 0
    sk = _sketch(_lines(capsys))
    assert '[columns."Motor Pwr(w)"]\nname = "power_w"' in sk, sk
    assert "Aux Pwr(100w)\"]" not in sk and "Charge Power" not in sk.split("# units")[0]
    assert "units not recognised" in sk and "Aux Pwr(100w) [100w]" in sk and "scale = 100" in sk


def test_the_sketch_offers_an_abbreviated_elevation_and_no_traction_only_power(tmp_path, capsys):
    """LeafSpy's CSV (and other apps') label the elevation 'Elv' or 'Alt' without a unit and
    log a 'Motor Pwr(w)' that never goes below 0 (traction only). The sketch offered no
    elevation and mapped the never-negative power as power_w, which no driving-power
    equation fits. Now such an elevation is offered in a comment (its unit is the user's: m
    or ft), and a power none of whose values read is negative is offered in a comment saying
    so, while a signed one beside it is mapped."""
    f = tmp_path / "leafspy.csv"
    f.write_text("Date/Time,Speed,Elv,Motor Pwr(w),Pack Volts,Pack Amps\n"
                 + "\n".join(f"2017-10-{t // 60 + 1:02d},{t % 50},{1100 + t},{max(0, 900 - 100 * t)},380.5,{12 - t}"
                             for t in range(20)) + "\n", encoding="utf-8")
    assert cli_main(["import", "columns", str(f), "--list"]) == 0
    sk = _sketch(_lines(capsys))
    assert "# elevation_m: perhaps Elv (no unit recognised" in sk, sk
    assert 'name = "power_w"' not in sk, sk
    assert "# power_w: perhaps Motor Pwr(w) (never negative in the 20 values read" in sk, sk
    from sumo_drvpw.data.adapters.listing import sketch

    rows = [{"label": "Motor Pwr(w)", "unit": "w", "samples": 20, "numbers": 20, "negatives": 0},
            {"label": "Drive Power (kW)", "unit": "kW", "samples": 20, "numbers": 20, "negatives": 7},
            {"label": "Alt (m)", "unit": "m", "samples": 20, "numbers": 20, "negatives": 0}]
    sk = sketch(rows, False, {})
    assert '[columns."Drive Power (kW)"]\nname = "power_w"' in sk, sk
    assert '[columns."Alt (m)"]\nname = "elevation_m"' in sk, sk
    # an MDF channel's values are not read for the listing: its power is mapped as before
    assert 'name = "power_w"' in sketch([{"label": "MotorPower", "unit": "W"}], True, {})
    # an alternator or altitude-hold is no elevation
    assert "elevation_m" not in sketch([{"label": "Alternator load (m)", "unit": "m"}], False, {})


def test_a_log_sampled_minutes_apart_is_said_at_import(tmp_path, capsys):
    """A log sampled every few minutes (a Leaf's owner summary, an app's minute export) was
    imported without a word and refused only by calibrate ('steps by 301.954 … more than 30
    s'). The import converts it still, and now says at once which file steps by how much
    (median within a trip) and what the commands will do with it; a file seconds apart
    beside it is not named."""
    import pandas as pd

    from sumo_drvpw.cli.import_ import read_report

    m = tmp_path / "m.toml"
    m.write_text('[columns."t (s)"]\nname = "time_s"\nunit = "s"\n'
                 '[columns."v (km/h)"]\nname = "speed_mps"\nunit = "km/h"\n', encoding="utf-8")
    slow, fast = tmp_path / "slow.csv", tmp_path / "fast.csv"
    slow.write_text("t (s),v (km/h)\n" + "\n".join(f"{301.954 * k:.3f},{20 + k % 7}" for k in range(30)) + "\n",
                    encoding="utf-8")
    fast.write_text("t (s),v (km/h)\n" + "\n".join(f"{k},{20 + k % 7}" for k in range(30)) + "\n", encoding="utf-8")
    log = tmp_path / "o.parquet"
    assert cli_main(["import", "columns", str(slow), str(fast), "--columns", str(m), "--out", str(log)]) == 0
    out = capsys.readouterr().out
    warn = [line for line in out.splitlines() if line.startswith("warning:")]
    assert len(warn) == 1 and str(slow) in warn[0] and "301.954 s" in warn[0] and "30 s" in warn[0], out
    assert len(pd.read_parquet(log)) == 60
    assert any("301.954 s" in w for w in read_report(log)["warnings"])


def test_the_sketch_takes_no_wind_or_air_speed_for_the_vehicle_speed():
    """A weather-augmented log (the RSK Twizy data set's 'WindSpeedAv' beside 'Speed'): a wind
    or air speed listed before the car's speed, in a speed unit and as well covered, was the
    sketch's speed_mps. Neither is the vehicle's speed."""
    from sumo_drvpw.data.adapters.listing import sketch

    rows = [{"label": "Wind speed (m/s)", "unit": "m/s", "samples": 20},
            {"label": "Airspeed (km/h)", "unit": "km/h", "samples": 20},
            {"label": "Speed (km/h)", "unit": "km/h", "samples": 20}]
    sk = sketch(rows, False, {})
    assert '[columns."Speed (km/h)"]\nname = "speed_mps"\n' in sk, sk
    assert "Wind" not in sk and "Airspeed" not in sk
    assert "WindSpeedAv" not in sketch([{"label": "Speed", "unit": ""}, {"label": "WindSpeedAv", "unit": ""}], False, {})


def test_a_doubly_encoded_degree_sign_is_read_as_the_unit(tmp_path, capsys):
    """OBD exports re-saved through Latin-1 write '°C' as 'Â°C' (the KIT Seat Leon logs, a
    BlueDriver export). lookup_unit meant to drop the 'Â' but lowered the label first ('â'),
    so such a unit was unknown: the temperatures were kept unconverted and the sketch offered
    no ambient_c. Now 'Â°C' and 'Â°F' read as °C and °F."""
    import pandas as pd

    from sumo_drvpw.data.adapters._common import lookup_unit

    assert lookup_unit("Â°C") == lookup_unit("°C") and lookup_unit("Â°F") == lookup_unit("°F")
    f = tmp_path / "leon.csv"
    f.write_text("Time,Vehicle Speed Sensor [km/h],Ambient Air Temperature [Â°C],Coolant [Â°F]\n"
                 + "\n".join(f"19:17:{t:02d}.418,{t},{20 + t % 2},{194}" for t in range(20)) + "\n", encoding="utf-8")
    assert cli_main(["import", "columns", str(f), "--list"]) == 0
    sk = _sketch(_lines(capsys))
    assert '[columns."Ambient Air Temperature [Â°C]"]\nname = "ambient_c"' in sk, sk
    assert "units not recognised" not in sk
    (tmp_path / "m.toml").write_text(sk, encoding="utf-8")
    log = tmp_path / "o.parquet"
    assert cli_main(["import", "columns", str(f), "--columns", str(tmp_path / "m.toml"), "--out", str(log)]) == 0
    df = pd.read_parquet(log)
    assert set(df["ambient_c"]) == {20.0, 21.0}
    assert df["coolant_c"].iloc[0] == 90.0, df.columns


def test_the_sketch_maps_a_unix_time_and_scales_a_leafspy_soc(tmp_path, capsys):
    """A LeafSpy export of a 2020 Nissan Leaf (ericthobbs/TripViewer @ a58aa42,
    examples/Log.csv; its header and first rows, columns cut): the sketch offered `Date/Time`
    (US month/day/year, whole seconds; other exports whole minutes) and `epoch time` both
    as 'perhaps, give its unit', and `SOC` — 869720, LeafSpy's 1/10000 % — as the state of
    charge without a word on its scale. Now the Unix time is mapped in seconds (it keeps
    the milliseconds: samples 5.136 s apart where the clock says 5 or 6), and the SOC's
    comment gives the scale that reads it as a per cent; the file imports through the sketch."""
    f = tmp_path / "Log.csv"
    f.write_text("Date/Time,Lat,Long,Elv,Speed,Gids,SOC,Pack Volts,Pack Amps,epoch time,Torque Nm,RPM\n"
                 "06/29/2025 21:09:36,34 11.28809,-117 25.75793,1932,68,412,869720,384.77,55.175,"
                 "1751256576.729,-1.50,7612\n"
                 "06/29/2025 21:09:41,34 11.23628,-117 25.8311,1938,64,412,869711,388.30,-9.856,"
                 "1751256581.865,1.75,7151\n"
                 "06/29/2025 21:09:46,34 11.18604,-117 25.90262,1942,63,412,869588,383.25,70.51,"
                 "1751256587.000,22.25,7008\n", encoding="utf-8")
    assert cli_main(["import", "columns", str(f), "--list"]) == 0
    sk = _sketch(_lines(capsys))
    assert '[columns."epoch time"]\nname = "time_s"  # Unix time [s]\nunit = "s"' in sk, sk
    assert "Date/Time\"]" not in sk, sk
    soc = next(ln for ln in sk.splitlines() if ln.startswith("# soc_pct:"))
    assert "869720 is no per cent: scale = 0.0001 reads it as 86.972 %" in soc, soc
    m = tmp_path / "m.toml"
    m.write_text(sk + '\n[columns."Speed"]\nname = "speed_mps"\nunit = "mph"\n', encoding="utf-8")
    out = tmp_path / "leaf.parquet"
    assert cli_main(["import", "columns", str(f), "--columns", str(m), "--out", str(out)]) == 0
    import pandas as pd

    t = pd.read_parquet(out)["time_s"].to_numpy()
    assert t[1] - t[0] == pytest.approx(5.136) and t[2] - t[1] == pytest.approx(5.135)
    # a per-cent column within 0–100 is given no scale; nor is a clock time taken for a Unix one
    from sumo_drvpw.data.adapters.listing import sketch

    rows = [{"label": "SOC", "unit": "", "first": "86.5"}, {"label": "time", "unit": "", "first": "21:09:36"}]
    sk = sketch(rows, False, {})
    assert "no per cent" not in sk and "Unix" not in sk, sk
    assert 'time_format = "%H:%M:%S"' in sk, sk
    # milliseconds since 1970
    assert 'unit = "ms"' in sketch([{"label": "timestamp", "unit": "", "first": "1751256576729"}], False, {})
