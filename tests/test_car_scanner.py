"""The Car Scanner ELM OBD2 adapter (``car-scanner``): both CSV layouts, the speed source,
the battery current's sign, midnight, bad files. Before it (and the channel alignment of
tests/test_async_logs.py) an import kept the speed rows only and every other channel of
such a log arrived empty.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.adapters import read
from sumo_drvpw.errors import UserError
from test_async_logs import PIDS, clock, current_a, long_csv, polls, speed_kmh, wide_csv


def test_wide_layout_channels_on_the_speed_samples(tmp_path):
    df, rep = read("car-scanner", wide_csv(tmp_path / "trip1.csv", polls()))
    assert set(df["trip_id"]) == {"trip1"}
    n_speed = sum(1 for r in polls() if r[1] == PIDS[0])
    assert len(df) == n_speed
    t = df["time_s"].to_numpy()
    assert t[0] == 0.0 and np.all(np.diff(t) > 0)
    np.testing.assert_allclose(df["speed_mps"], np.round(speed_kmh(t)) / 3.6, atol=1e-9)
    inside = df["battery_current_a"].notna().to_numpy()
    assert inside.mean() > 0.98  # only before the first current sample
    np.testing.assert_allclose(df["battery_current_a"][inside], current_a(t[inside]), rtol=1e-9)
    np.testing.assert_allclose(df["battery_voltage_v"].dropna(), 400.0)
    np.testing.assert_allclose(df["ambient_c"].dropna(), 3.0)  # ℃ (U+2103) read as °C
    assert "battery_dc_min_voltage_v" in df  # a cell value: kept, not the traction voltage
    notes = " ".join(rep["files"][0]["notes"])
    assert "asynchronous log" in notes and "speed from 'Vehicle speed (km/h)'" in notes
    assert "positive when discharging as logged" in notes
    assert not any(c.startswith("unnamed") for c in df.columns)  # the trailing separator
    assert rep["dropped"] == {"rows without speed (their channels put onto the speed samples)":
                              len(polls()) - n_speed}
    assert rep["roles"]["ambient_c"] == "condition"


def test_long_layout_reads_as_the_wide_one(tmp_path):
    rows = polls()
    wide, _ = read("car-scanner", wide_csv(tmp_path / "a.csv", rows))
    long, rep = read("car-scanner", long_csv(tmp_path / "a2.csv", rows))
    for c in ("time_s", "speed_mps", "battery_current_a", "battery_voltage_v", "ambient_c"):
        np.testing.assert_allclose(long[c], wide[c], rtol=1e-6, atol=1e-9, err_msg=c)
    np.testing.assert_allclose(long["latitude_deg"], 49.2231)
    np.testing.assert_allclose(long["longitude_deg"], 18.7394)


def test_current_logged_negative_when_discharging_is_flipped(tmp_path):
    rows = [(tod, pid, -val if pid == PIDS[1] else val) for tod, pid, val in polls()]
    df, rep = read("car-scanner", wide_csv(tmp_path / "neg.csv", rows))
    t = df["time_s"].to_numpy()
    ok = df["battery_current_a"].notna().to_numpy()
    np.testing.assert_allclose(df["battery_current_a"][ok], current_a(t[ok]), rtol=1e-9)
    assert "sign flipped" in " ".join(rep["files"][0]["notes"])


def test_a_short_file_takes_the_current_sign_of_the_import(tmp_path):
    """Found by the second metamorphic sweep: the sign was decided file by file, so a trip
    exported in two files, the second an 87-s tail with 7 accelerating samples, kept that
    tail as logged (negative while discharging) beside a flipped first file: one log, two
    conventions. A file too short to tell takes the sign of the import's other files."""
    rows = [(tod, pid, -val if pid == PIDS[1] else val) for tod, pid, val in polls()]
    d = tmp_path / "trip"
    d.mkdir()
    wide_csv(d / "a_main.csv", rows)
    tail = [(tod, pid, -val if pid == PIDS[1] else val) for tod, pid, val in polls(seconds=20.0)]
    wide_csv(d / "b_tail.csv", [(tod + 400.0, pid, val) for tod, pid, val in tail])  # accelerating 0.8 m/s² from 0
    alone, rep_alone = read("car-scanner", d / "b_tail.csv")
    assert "kept as logged" in " ".join(rep_alone["files"][0]["notes"])
    df, rep = read("car-scanner", d)
    for f in rep["files"]:
        assert "sign flipped" in " ".join(f["notes"]), f["notes"]
    t = df[df.trip_id == "b_tail"]
    ok = t["battery_current_a"].notna().to_numpy()
    assert ok.any() and (t["battery_current_a"][ok] > 0).all()   # discharging: positive, as canonical


def test_a_long_gap_stays_missing(tmp_path):
    """A channel the app stopped polling for 20 s is not bridged (its median interval is
    about 1.35 s; the limit is 3 of them)."""
    rows = polls(skip=[(PIDS[1], 100.0, 120.0)])
    df, rep = read("car-scanner", wide_csv(tmp_path / "gap.csv", rows))
    t = df["time_s"].to_numpy()
    i = df["battery_current_a"].to_numpy()
    assert np.all(np.isnan(i[(t > 101.5) & (t < 118.5)]))
    far = (t > 5) & (t < 198) & ((t < 98.5) | (t > 121.5))  # the samples bracketing the gap are 1.35 s out
    np.testing.assert_allclose(i[far], current_a(t[far]), rtol=1e-9)
    assert "still missing: battery_current_a" in " ".join(rep["files"][0]["notes"])


def test_time_of_day_passes_midnight(tmp_path):
    rows = polls(seconds=120.0, start=86400.0 - 60.0)
    df, rep = read("car-scanner", wide_csv(tmp_path / "night.csv", rows))
    t = df["time_s"].to_numpy()
    assert np.all(np.diff(t) > 0) and 118.0 < t[-1] < 120.0
    assert "time going backwards" not in rep["dropped"]
    long, _ = read("car-scanner", long_csv(tmp_path / "night2.csv", rows))
    np.testing.assert_allclose(long["time_s"], t, atol=1e-3)


def test_gps_speed_when_the_obd_speed_is_not_logged(tmp_path):
    rows = [(tod, "Speed (GPS) (km/h)" if pid == PIDS[0] else pid, val) for tod, pid, val in polls(60.0)]
    p = long_csv(tmp_path / "gps.csv", rows)
    df, rep = read("car-scanner", p)
    assert "speed from 'Speed (GPS) (km/h)'" in " ".join(rep["files"][0]["notes"])
    assert df["speed_mps"].max() == pytest.approx(20.0)


@pytest.mark.parametrize("text, match", [
    ("time,\"Engine RPM (rpm)\"\n07:00:00.000,800\n07:00:01.000,900\n", "no speed"),
    ("time,\"Vehicle speed (km/h)\"\n07:00:00.000,10\nnoon,12\n", "data row 1 holds 'noon'"),
    ("when,\"Vehicle speed (km/h)\"\n07:00:00.000,10\n07:00:01.000,12\n", "first column is 'when'"),
    ("time,\"Vehicle speed (km/h)\"\n07:00:00.000,10\n07:00:01.000,fast\n",
     r"'Vehicle speed \(km/h\)' data row 1 holds 'fast'"),
    ('"SECONDS";"PID";"VALUE";"UNITS";\n"x";"Vehicle speed";"10";"km/h";\n', "column 'SECONDS' data row 0"),
    ("", "empty"),
])
def test_bad_files_name_file_and_row(tmp_path, text, match):
    p = tmp_path / "bad.csv"
    p.write_text(text, encoding="utf-8")
    with pytest.raises(UserError, match=match) as e:
        read("car-scanner", p)
    assert "bad.csv" in str(e.value)


def test_cli_import_then_battery_energy(tmp_path, capsys):
    """Through the CLI: the imported log's battery energy is the V·I the app logged,
    integrated over the speed samples (within the interpolation's share)."""
    rows = polls(400.0)
    src = wide_csv(tmp_path / "drive.csv", rows)
    out = tmp_path / "log.parquet"
    assert cli_main(["import", "car-scanner", str(src), "--out", str(out)]) == 0
    assert "asynchronous log" in capsys.readouterr().out
    df = pd.read_parquet(out)
    t = df["time_s"].to_numpy()
    p = (df["battery_voltage_v"] * df["battery_current_a"]).to_numpy()
    ok = np.isfinite(p)
    e = np.trapezoid(p[ok], t[ok])
    tt = np.linspace(t[ok][0], t[ok][-1], 100_001)
    exact = np.trapezoid(400.0 * current_a(tt), tt)
    assert e == pytest.approx(exact, rel=1e-6)


def test_long_layout_with_decimal_commas_reads_as_with_points(tmp_path):
    """A phone set to a language that writes decimal commas: the long layout's values read
    the same."""
    rows = polls(60.0)
    a = long_csv(tmp_path / "points.csv", rows)
    text = a.read_text(encoding="utf-8").splitlines()
    commas = [text[0]] + [";".join(c.replace(".", ",") if i in (0, 2) else c for i, c in enumerate(r.split(";")))
                          for r in text[1:]]
    b = tmp_path / "commas.csv"
    b.write_text("\n".join(commas) + "\n", encoding="utf-8")
    assert all("," in r.split(";")[0] for r in commas[1:]) and any("," in r.split(";")[2] for r in commas[1:])
    x, _ = read("car-scanner", a)
    y, _ = read("car-scanner", b)
    for c in ("time_s", "speed_mps", "battery_current_a"):
        np.testing.assert_allclose(y[c], x[c], rtol=1e-9, err_msg=c)


def test_wide_layout_with_dates_in_the_time_column(tmp_path):
    """Some exports write the date with the time: the same log, the same seconds."""
    rows = polls(60.0)
    a = wide_csv(tmp_path / "tod.csv", rows)
    lines = a.read_text(encoding="utf-8").splitlines()
    dated = [lines[0]] + ["2023-12-04 " + r for r in lines[1:]]
    b = tmp_path / "dated.csv"
    b.write_text("\n".join(dated) + "\n", encoding="utf-8")
    x, _ = read("car-scanner", a)
    y, _ = read("car-scanner", b)
    for c in ("time_s", "speed_mps", "battery_current_a"):
        np.testing.assert_allclose(y[c], x[c], rtol=1e-9, atol=1e-9, err_msg=c)


CELLS = ["", "0", "1.5", "12,5", "-3", "nan", "inf", "∞", "1e400", "abc", "72"]
TIMES = ["07:00:00.000", "07:00:00.500", "07:00:01.000", "06:59:59.000", "23:59:59.900", "00:00:00.100",
         "7:00", "", "noon"]
FUZZ_PIDS = ["Vehicle speed (km/h)", "Speed (GPS) (km/h)", "Battery DC Current (A)", "Battery DC Voltage (V)",
             "Ambient temperature (\u2103)", "Cell (V)"]


@st.composite
def scanner_files(draw):
    pids = draw(st.lists(st.sampled_from(FUZZ_PIDS), min_size=1, max_size=5, unique=True))
    n = draw(st.integers(min_value=0, max_value=30))
    long = draw(st.booleans())
    rows = []
    for k in range(n):
        t = draw(st.sampled_from(TIMES)) if draw(st.integers(0, 4)) == 0 else f"07:00:{k // 2:02d}.{(k % 2) * 500:03d}"
        pid = draw(st.sampled_from(pids))
        rows.append((t, pid, draw(st.sampled_from(CELLS))))
    if long:
        lines = ['"SECONDS";"PID";"VALUE";"UNITS";"LATITUDE";"LONGTITUDE";']
        for t, pid, v in rows:
            sec = t if draw(st.booleans()) else f"{25200 + rows.index((t, pid, v)) * 0.5:.3f}"
            name, unit = pid.rsplit(" (", 1)
            lines.append(f'"{sec}";"{name}";"{v}";"{unit[:-1]}";"49.2";"{draw(st.sampled_from(["18.7", "0", ""]))}";')
    else:
        lines = ["time," + ",".join(f'"{p}"' for p in pids)]
        lines += [t + "," + ",".join(v if p == pid else "" for p in pids) for t, pid, v in rows]
    return "\n".join(lines) + ("\n" if draw(st.booleans()) else "")


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(text=scanner_files())
def test_random_car_scanner_files_give_a_log_or_one_line(tmp_path, text):
    """Any file in either layout, with bad times, bad cells, missing PIDs: a drive log with
    increasing time and plausible speed, or one UserError line naming the file — never
    another exception and never a numpy warning."""
    import warnings

    p = tmp_path / "fuzz.csv"
    p.write_text(text, encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            df, _ = read("car-scanner", p)
        except UserError as e:
            assert "\n" not in str(e) and "fuzz.csv" in str(e)
            return
    t = df["time_s"].to_numpy(float)
    v = df["speed_mps"].to_numpy(float)
    assert np.all(np.diff(t) > 0) and np.all(np.isfinite(v)) and np.all((v >= 0) & (v <= 100))


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(text=scanner_files())
@example(text='time,"Vehicle speed (km/h)","Speed (GPS) (km/h)"\n,,\n07:00:00.500,0,\n'
              '07:00:01.000,,0\n07:00:01.500,,')  # a row without a time: a ValueError once
def test_random_asynchronous_files_through_a_mapping(tmp_path, text):
    """The same files through the generic format (its channel alignment): a log or one
    UserError line, never another exception, never a numpy warning. The example: a row
    without a time beside an asynchronous channel (the aligned column was one value short
    of the rows kept until the NaN-time drop: pandas' length mismatch, found by this test)."""
    import warnings

    if not text.startswith("time,") or "Vehicle speed" not in text.splitlines()[0]:
        return
    p = tmp_path / "fuzz.csv"
    p.write_text(text, encoding="utf-8")
    m = tmp_path / "map.toml"
    m.write_text('[options]\ntime_format = "%H:%M:%S.%f"\n[columns.time]\nname = "time_s"\nunit = "datetime"\n'
                 '[columns."Vehicle speed (km/h)"]\nname = "speed_mps"\nunit = "km/h"\n', encoding="utf-8")
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        try:
            df, _ = read("columns", p, columns=m)
        except UserError as e:
            assert "\n" not in str(e)
            return
    assert np.all(np.diff(df["time_s"].to_numpy(float)) > 0)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(["Speed", " Speed", "Speed ", "RPM", "Engine load", "", None]),
                          st.sampled_from(["km/h", "km/h ", "", None, "rpm", "%"])), min_size=1, max_size=60))
def test_pid_labels_from_category_codes_equal_the_row_strings(rows):
    """The long layout's "PID (unit)" labels come from the categories' codes (one label per
    distinct pair: the import of a 1.38 M-row log went from 1.48 to 0.98 s); they equal
    the labels built row by row from the stripped strings, codes and order of first
    appearance included, with blanks and missing values and PIDs equal after stripping."""
    from sumo_drvpw.data.adapters.car_scanner import _pid_labels

    pid = pd.Series([r[0] for r in rows], dtype=object).astype("category")
    unit = pd.Series([r[1] for r in rows], dtype=object).astype("category")
    codes, labels = _pid_labels(pid, unit)
    p = pid.astype("string").fillna("").str.strip()
    u = unit.astype("string").fillna("").str.strip()
    ref_codes, ref_labels = pd.factorize(p + np.where(u != "", " (" + u + ")", ""))
    assert list(labels) == list(ref_labels)
    np.testing.assert_array_equal(codes, ref_codes)


def test_a_kia_hyundai_log_without_current_books_its_energy_from_the_bms_counters(tmp_path, capsys):
    """Car Scanner's Hyundai/Kia EV PIDs "Cumulative Energy Discharged (CED)" and "...
    Charged (CEC)" (kWh, 0.1-kWh steps here) without the battery current: they map to the
    canonical counters, the import notes their steps, and compare --target battery books
    the trip's net energy as their change (the counters' power, sumo_drvpw.data.counters)."""
    from sumo_drvpw.data.counters import COUNTERS

    pids = ("Vehicle speed (km/h)", "Cumulative Energy Discharged (CED) (kWh)", "Cumulative Energy Charged (CEC) (kWh)")
    lines = ["time," + ",".join(f'"{p}"' for p in pids)]
    start = 9 * 3600.0
    for i in range(4000):  # 1000 s polled in turn every 0.25 s: 2 kW out, 0.5 kW back
        t = 0.25 * i
        k = i % 4
        val = {0: np.round(speed_kmh(t)), 1: 12345.6 + np.floor(2.0 * t / 3600 / 0.1) * 0.1,
               2: 2345.6 + np.floor(0.5 * t / 3600 / 0.1) * 0.1}.get(k)
        if val is None:
            continue
        cells = ["" if j != k else f"{val:.6f}" for j in range(3)]
        lines.append(clock(start + t) + "," + ",".join(cells))
    src = tmp_path / "kona.csv"
    src.write_text("\n".join(lines) + "\n", encoding="utf-8")
    df, rep = read("car-scanner", src)
    assert set(COUNTERS) <= set(df.columns)
    assert any(n.startswith("battery energy counters (discharged in steps of") for n in rep["files"][0]["notes"])
    out = tmp_path / "log.parquet"
    assert cli_main(["import", "car-scanner", str(src), "--out", str(out)]) == 0
    eq = tmp_path / "ev.toml"
    eq.write_text('[equation]\nname = "ev"\n[terms]\nv1 = 150.0\n[chain]\npredicts = "battery"\n'
                  "traction_efficiency = 0.9\nrecuperation_efficiency = 0.7\naux_power_w = 400.0\n", encoding="utf-8")
    capsys.readouterr()
    assert cli_main(["compare", str(out), "--equation", str(eq), "--target", "battery", "--vehicle", "bmw_i3",
                     "--out", str(tmp_path / "cmp")]) == 0
    import json

    rep = json.loads((tmp_path / "cmp" / "report.json").read_text(encoding="utf-8"))
    trip = rep["equations"]["ev"]["trip_net_energy"]["trips"]["kona"]
    d, c = (pd.read_parquet(out)[k].dropna() for k in COUNTERS)  # read from their first poll
    want = (d.iloc[-1] - d.iloc[0]) - (c.iloc[-1] - c.iloc[0])
    assert trip["measured_j"] == pytest.approx(want, rel=1e-6) and want == pytest.approx(0.4 * 3.6e6)
    assert "battery energy counters" in rep["context"]["counts"]["power_source"]


def test_a_refused_cut_short_file_leaves_no_note_on_its_next_read(tmp_path):
    """A file cut mid-row and refused for a bad time (before its report was started) left
    its 'cut short' mark behind: the same file, mended, then read 'truncated last row 1'
    (a newcomer's rehearsal through read(), 2026-11-29). Each read says its own."""
    path = wide_csv(tmp_path / "trip.csv", polls())
    good = path.read_text(encoding="utf-8")
    lines = good.splitlines()
    bad = lines[:5] + [lines[5].replace(lines[5].split(";")[0], "noon", 1)] + lines[6:]
    path.write_text("\n".join(bad)[:-3], encoding="utf-8")  # cut inside its last row, and a bad time in row 4
    with pytest.raises(UserError, match="data row 4 holds 'noon'"):
        read("car-scanner", path)
    path.write_text(good, encoding="utf-8")
    _, rep = read("car-scanner", path)
    assert "truncated last row" not in rep["files"][0]["dropped"], rep["files"][0]
    assert not any("cut short" in n for n in rep["files"][0]["notes"])
