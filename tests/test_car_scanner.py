"""The Car Scanner ELM OBD2 adapter (``car-scanner``): both CSV layouts, the speed source,
the battery current's sign, midnight, bad files. Before it (and the channel alignment of
tests/test_async_logs.py) an import kept the speed rows only and every other channel of
such a log arrived empty.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.adapters import read
from sumo_drvpw.errors import UserError
from test_async_logs import PIDS, current_a, long_csv, polls, speed_kmh, wide_csv


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
