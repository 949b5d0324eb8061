"""Torque Pro logs in the units their users chose (``torquepro``).

Torque writes each value in the unit set in the app: the shared Prius log is in mph, ft and
°F, a metric user's in km/h, m and °C. Before, a log whose OBD speed was not in mph was
refused ("missing column 'Speed (OBD)(mph)'"), and its other metric labels became extras.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.adapters import read
from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import FT, MPH

HEAD = ["GPS Time", "Device Time", "Speed (OBD)(km/h)", "GPS Altitude(m)", "Ambient air temp(°C)",
        "Engine RPM(rpm)", "Fuel flow rate/hour(l/hr)", "Cost per mile/km (Instant)($/km)"]


def metric_csv(path, n=40, repeat_header_at=None):
    rows = [", ".join(HEAD)]
    for i in range(n):
        if i == repeat_header_at:
            rows.append(", ".join(HEAD))
        t = pd.Timestamp("2024-05-04 10:00:00") + pd.Timedelta(seconds=0.7 * i)
        dev = t.strftime("%d-%b-%Y %H:%M:%S.") + f"{t.microsecond // 1000:03d}"
        cost = "∞" if i == 0 else f"{1.2 / (3.6 * i):.4f}"  # Torque's cost per km at standstill
        rows.append(f"-, {dev}, {min(3.6 * i, 90.0):.1f}, {300 + 0.5 * i:.1f}, 18.5, {800 + 40 * i}, 1.2, {cost}")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def test_metric_units_map_to_the_same_columns(tmp_path):
    df, rep = read("torquepro", metric_csv(tmp_path / "trip.csv"))
    assert len(df) == 40
    np.testing.assert_allclose(df["speed_mps"], np.minimum(np.arange(40.0), 25.0), atol=1e-9)
    np.testing.assert_allclose(df["elevation_m"], 300 + 0.5 * np.arange(40.0))
    np.testing.assert_allclose(df["ambient_c"], 18.5)
    np.testing.assert_allclose(df["ice_speed_rpm"], 800 + 40 * np.arange(40.0))
    np.testing.assert_allclose(df["time_s"], 0.7 * np.arange(40.0), atol=1e-3)
    np.testing.assert_allclose(df["fuel_flow_rate_hour_lph"], 1.2)  # "l/hr", the fuel target's column
    assert rep["roles"].get("ambient_c") == "condition"
    # '∞' (a real metric trackLog.csv writes it at standstill) is no reading, not a bad file
    cost = df["cost_per_mile_km_instant_km"].to_numpy()
    assert np.isnan(cost[0]) and np.isfinite(cost[1:]).all()
    assert "'∞' cells (no finite reading) read as NaN: cost_per_mile_km_instant_km 1" in " ".join(
        rep["files"][0]["notes"])
    assert not any("battery_current_a" in n for n in rep["notes"])  # no battery logged


def test_a_unit_whose_slash_an_export_replaced_is_read_as_the_unit(tmp_path):
    """PETS' third Prius trip (TO_REI_Actual_Data_3-24-17.json) writes 'Fuel flow
    rate_hour(gal_hr)' and 'GPS Speed (Meters_second)': the '/' of Torque's labels saved as
    '_' (the two shared trips of the same car save it as '-'). The units were unknown, the
    fuel flow kept in gal/h under another name, so the fuel target found no flow."""
    p = metric_csv(tmp_path / "trip.csv")
    text = p.read_text(encoding="utf-8").replace("Fuel flow rate/hour(l/hr)", "Fuel flow rate_hour(gal_hr)")
    lines = text.splitlines()
    lines[0] += ", GPS Speed (Meters_second)"
    lines[1:] = [r + f", {0.5 * i:.1f}" for i, r in enumerate(lines[1:])]
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    df, rep = read("torquepro", p)
    np.testing.assert_allclose(df["fuel_flow_rate_hour_lph"], 1.2 * 3.785411784, rtol=1e-12)  # US gallon
    np.testing.assert_allclose(df["gps_speed_phone_mps"], 0.5 * np.arange(40.0))
    notes = " ".join(rep["files"][0]["notes"])
    assert "gal_hr" not in notes and "Meters_second" not in notes  # not 'unit unknown'


def test_a_powertrain_field_that_never_answers_does_not_hold_the_link_down(tmp_path):
    """An EV has no engine speed: Torque writes '-' in every row of 'Engine RPM(rpm)'. The
    whole log was refused ("no sample left after dropping {'link not up (-)': …}", found by
    a sweep); the field now stays NaN and is named, and a field that starts answering
    later still marks the link as up from then on."""
    p = metric_csv(tmp_path / "ev.csv")
    lines = p.read_text(encoding="utf-8").splitlines()
    rows = [lines[0]] + [", ".join(c if k != 5 else "-" for k, c in enumerate(r.split(", "))) for r in lines[1:]]
    p.write_text("\n".join(rows) + "\n", encoding="utf-8")
    df, rep = read("torquepro", p)
    assert len(df) == 40 and df["ice_speed_rpm"].isna().all()
    assert "no value in the whole log (the car does not answer it): ice_speed_rpm" in " ".join(rep["files"][0]["notes"])
    late = metric_csv(tmp_path / "late.csv")
    lines = late.read_text(encoding="utf-8").splitlines()
    rows = [lines[0]] + [", ".join(c if (k != 5 or i >= 3) else "-" for k, c in enumerate(r.split(", ")))
                         for i, r in enumerate(lines[1:])]
    late.write_text("\n".join(rows) + "\n", encoding="utf-8")
    df, rep = read("torquepro", late)
    assert len(df) == 37 and rep["dropped"] == {"link not up (-)": 3}


def test_a_repeated_header_is_dropped_and_counted(tmp_path):
    df, rep = read("torquepro", metric_csv(tmp_path / "trip.csv", repeat_header_at=20))
    assert len(df) == 40
    assert rep["dropped"] == {"repeated header (a new logging session)": 1}


def test_no_obd_speed_in_any_unit_is_refused(tmp_path):
    p = metric_csv(tmp_path / "trip.csv")
    p.write_text(p.read_text(encoding="utf-8").replace("Speed (OBD)(km/h)", "Speed (GPS)(km/h)"),
                 encoding="utf-8")
    with pytest.raises(UserError, match=r"trip.csv: missing column 'Speed \(OBD\)\(mph\)' \(or the OBD speed"):
        read("torquepro", p)


@pytest.mark.shared_data
def test_shared_prius_log_in_metric_units_reads_the_same(shared_data, tmp_path):
    """The shared Prius log (mph, ft, °F) written again in km/h, m and °C as a metric user's
    Torque would: the same canonical values."""
    import json

    src = shared_data / "prius_gen2_torquepro" / "From_CdA_Act.json"
    recs = json.loads(src.read_text(encoding="utf-8"))
    ref, _ = read("torquepro-prius2", src)

    def conv(x, f, o=0.0):
        try:
            return f"{float(x) * f + o:.6f}"
        except (TypeError, ValueError):
            return x

    out = []
    for r in recs:
        r = dict(r)
        r["Speed (OBD)(km/h)"] = conv(r.pop("Speed (OBD)(mph)"), MPH / (1 / 3.6))
        r["GPS Altitude(m)"] = conv(r.pop("GPS Altitude(ft)"), FT)
        r["Ambient air temp(°C)"] = conv(r.pop("Ambient air temp(°F)"), 5 / 9, -32 * 5 / 9)
        out.append(r)
    p = tmp_path / "metric.json"
    p.write_text(json.dumps(out), encoding="utf-8")
    df, _ = read("torquepro", p)
    assert list(df.columns) == list(ref.columns)
    for c in ("speed_mps", "elevation_m", "ambient_c", "battery_current_a", "time_s"):
        np.testing.assert_allclose(df[c], ref[c], rtol=1e-6, atol=1e-6, err_msg=c)


def test_cli_format_name(tmp_path, capsys):
    out = tmp_path / "log.parquet"
    assert cli_main(["import", "torquepro", str(metric_csv(tmp_path / "trip.csv")), "--out", str(out)]) == 0
    assert "import torquepro" in capsys.readouterr().out
    assert len(pd.read_parquet(out)) == 40


def test_import_notes_are_folded_and_shortened_on_the_terminal_only(tmp_path, capsys):
    """A real Torque log has dozens of PIDs in units not known here and a '-' note naming
    180 columns: the import says one note for the units, shortens long notes on the
    terminal, and keeps every note whole in the log's import report."""
    from sumo_drvpw.cli.import_ import NOTE_CHARS, read_report

    p = metric_csv(tmp_path / "trip.csv")
    text = p.read_text(encoding="utf-8").splitlines()
    extra = [f"PID {i}(furlong/fortnight)" for i in range(60)]
    text = [text[0] + ", " + ", ".join(extra)] + [r + ", " + ", ".join(["-"] * 59 + ["1"]) for r in text[1:]]
    p.write_text("\n".join(text) + "\n", encoding="utf-8")
    out = tmp_path / "log.parquet"
    assert cli_main(["import", "torquepro", str(p), "--out", str(out)]) == 0
    shown = capsys.readouterr().out
    notes = read_report(out)["files"][0]["notes"]
    folded = [n for n in notes if "with a unit not known here" in n]
    assert len(folded) == 1 and folded[0].startswith("61 columns") and "PID 59(furlong/fortnight)" in folded[0]
    assert max(len(n) for n in notes) > NOTE_CHARS + 100
    assert all(len(line) < NOTE_CHARS + 80 for line in shown.splitlines()), shown
    assert "characters more" in shown and "read_report(LOG)" in shown


@pytest.mark.parametrize("label, column", [("Speed (OBD)(mph)", "speed_mps"), ("GPS Altitude(ft)", "elevation_m")])
def test_one_reading_in_two_units_is_refused(tmp_path, label, column):
    """A log holding a column in two units (Speed (OBD) in km/h and in mph, 99 against 20: a
    merged export) was read from the later label alone, the other dropped unsaid (speed
    27.5 m/s from the km/h column where the mph one said 8.9): refused naming both."""
    p = metric_csv(tmp_path / "trip.csv")
    lines = p.read_text(encoding="utf-8").splitlines()
    p.write_text("\n".join([lines[0] + f", {label}"] + [ln + ", 20" for ln in lines[1:]]) + "\n", encoding="utf-8")
    first = {"speed_mps": "Speed (OBD)(km/h)", "elevation_m": "GPS Altitude(m)"}[column]
    with pytest.raises(UserError, match=rf"trip.csv: columns '{re.escape(first)}' and '{re.escape(label)}' both give {column}"):
        read("torquepro", p)


def test_a_json_record_holding_a_key_twice_is_refused(tmp_path):
    """json keeps the last of a key given twice: a record's 'GPS Altitude(ft)' of 302 and 9e9
    was read as 9e9 ft, unsaid. Refused naming the data row and the key."""
    recs = [f'{{"Device Time": "25-Mar-2017 11:46:{i:02d}.000", "Speed (OBD)(mph)": 20, "GPS Altitude(ft)": 300'
            + (', "GPS Altitude(ft)": 9e9' if i == 3 else "") + "}" for i in range(20)]
    p = tmp_path / "t.json"
    p.write_text("[" + ",".join(recs) + "]", encoding="utf-8")
    with pytest.raises(UserError, match=r"t.json: data row 3 holds 'GPS Altitude\(ft\)' twice"):
        read("torquepro", p)
    p.write_text("[" + ",".join(r.replace(', "GPS Altitude(ft)": 9e9', "") for r in recs) + "]", encoding="utf-8")
    assert len(read("torquepro", p)[0]) == 20


def test_a_csv_header_holding_a_label_twice_is_refused(tmp_path):
    """pandas names a repeated label's second column 'X.1': the speed was read from the first
    'Speed (OBD)(km/h)', the second (99 km/h in every row) kept as an extra, unsaid."""
    p = metric_csv(tmp_path / "trip.csv")
    lines = p.read_text(encoding="utf-8").splitlines()
    p.write_text("\n".join([lines[0] + ", Speed (OBD)(km/h)"] + [ln + ", 99" for ln in lines[1:]]) + "\n",
                 encoding="utf-8")
    with pytest.raises(UserError, match=r"trip.csv: the header holds 'Speed \(OBD\)\(km/h\)' twice"):
        read("torquepro", p)


@pytest.mark.parametrize("unit", ["knots", "%", ""])
def test_an_obd_speed_in_a_unit_this_reader_lacks_is_named(tmp_path, unit):
    """'Speed (OBD)(knots)' was called missing ("missing column 'Speed (OBD)(mph)' (or the OBD
    speed in another unit)"): now the column and its unit are named."""
    p = metric_csv(tmp_path / "trip.csv")
    p.write_text(p.read_text(encoding="utf-8").replace("Speed (OBD)(km/h)", f"Speed (OBD)({unit})", 1), encoding="utf-8")
    with pytest.raises(UserError, match=rf"trip.csv: column 'Speed \(OBD\)\({re.escape(unit)}\)': unit '{re.escape(unit)}' "
                                        "is no speed this reader knows"):
        read("torquepro", p)
