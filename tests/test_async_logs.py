"""Asynchronous logs: loggers that write one value per row (phone OBD apps, CAN-bus
exports) have each channel on its own rows; the import puts every channel onto the speed
samples (``align.align_channels``) instead of keeping the speed rows with empty channels.

The logs are written here: a known speed profile and channels linear in time (so linear
interpolation onto the speed samples is exact), polled in turn as an OBD app does; the
same generator feeds tests/test_car_scanner.py.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
from hypothesis import given, settings
from hypothesis import strategies as st

from sumo_drvpw.data.adapters import read
from sumo_drvpw.data.adapters._common import new_report
from sumo_drvpw.data.adapters.align import ALIGN_MAX_GAP_INTERVALS, align_channels, faster, windows

PIDS = ("Vehicle speed (km/h)", "Battery DC Current (A)", "Battery DC Voltage (V)",
        "Ambient temperature (\u2103)", "Battery DC Min Voltage (V)")


def speed_kmh(t):
    """0 → 72 km/h at 0.8 m/s² (25 s), cruise, back to 0 at −1 m/s², twice per 100 s."""
    s = np.mod(t, 100.0)
    v = np.minimum(0.8 * s, 20.0)
    v = np.where(s > 70.0, np.maximum(20.0 - (s - 70.0), 0.0), v)
    return 3.6 * v


def current_a(t):
    return 10.0 + 0.5 * t  # linear in time: interpolation onto any sample time is exact


def polls(seconds=200.0, period=0.27, start=7 * 3600 + 13 * 60 + 32.604, jitter=None, skip=()):
    """(time of day [s], pid, value) rows, the PIDs polled in turn every ``period`` s."""
    rows, k, t = [], 0, 0.0
    rng = np.random.default_rng(1)
    while t < seconds:
        pid = PIDS[k % len(PIDS)]
        if not any(a <= t < b for p, a, b in skip if p == pid):
            val = {PIDS[0]: np.round(speed_kmh(t)), PIDS[1]: current_a(t), PIDS[2]: 400.0,
                   PIDS[3]: 3.0, PIDS[4]: 3.7}[pid]
            rows.append((start + t, pid, float(val)))
        k += 1
        t += period if jitter is None else period * (1 + jitter * rng.uniform(-1, 1))
    return rows


def clock(tod):
    tod = tod % 86400.0
    h, r = divmod(tod, 3600.0)
    m, s = divmod(r, 60.0)
    return f"{int(h):02d}:{int(m):02d}:{s:06.3f}"


def wide_csv(path, rows, trailing=True):
    lines = ["time," + ",".join(f'"{p}"' for p in PIDS) + ("," if trailing else "")]
    for tod, pid, val in rows:
        cells = ["" if p != pid else f"{val:.6g}" for p in PIDS]
        lines.append(clock(tod) + "," + ",".join(cells) + ("," if trailing else ""))
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def long_csv(path, rows):
    lines = ['"SECONDS";"PID";"VALUE";"UNITS";"LATITUDE";"LONGTITUDE";']
    for tod, pid, val in rows:
        name, unit = pid.rsplit(" (", 1)
        lines.append(f'"{tod:.3f}";"{name}";"{val:.6g}";"{unit[:-1]}";"49.2231";"18.7394";')
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def test_columns_format_keeps_an_asynchronous_log(tmp_path):
    """The generic format on an OBD app's wide export: the channels survive (they arrived
    empty before), the empty trailing column is left out, ℃ (U+2103) converts."""
    rows = polls()
    src = wide_csv(tmp_path / "cs.csv", rows)
    m = tmp_path / "map.toml"
    m.write_text('[options]\ntime_format = "%H:%M:%S.%f"\n\n[columns."time"]\nname = "time_s"\n'
                 'unit = "datetime"\n\n[columns."Vehicle speed (km/h)"]\nname = "speed_mps"\nunit = "km/h"\n'
                 '\n[columns."Battery DC Current (A)"]\nname = "battery_current_a"\nunit = "A"\n',
                 encoding="utf-8")
    df, rep = read("columns", src, columns=m)
    n_speed = sum(1 for r in rows if r[1] == PIDS[0])
    assert len(df) == n_speed
    t = df["time_s"].to_numpy()
    np.testing.assert_allclose(df["speed_mps"], np.round(speed_kmh(t)) / 3.6, atol=1e-9)
    ok = df["battery_current_a"].notna().to_numpy()
    assert ok.mean() > 0.98  # only the samples before the first current value
    np.testing.assert_allclose(df["battery_current_a"][ok], current_a(t[ok]), rtol=1e-9)
    np.testing.assert_allclose(df["ambient_temperature_c"].dropna(), 3.0)
    notes = " ".join(rep["files"][0]["notes"])
    assert "trailing separator" in notes and "asynchronous log" in notes
    assert not any(c.startswith("unnamed") for c in df.columns)
    assert rep["dropped"] == {"rows without speed (their channels put onto the speed samples)":
                              len(rows) - n_speed}


def test_columns_time_of_day_passes_midnight(tmp_path):
    src = tmp_path / "n.csv"
    src.write_text("t,v\n23:59:59.000,10\n23:59:59.500,11\n00:00:00.000,12\n00:00:00.500,13\n", encoding="utf-8")
    m = tmp_path / "map.toml"
    m.write_text('[options]\ntime_format = "%H:%M:%S.%f"\n[columns.t]\nname = "time_s"\nunit = "datetime"\n'
                 '[columns.v]\nname = "speed_mps"\nunit = "m/s"\n', encoding="utf-8")
    df, rep = read("columns", src, columns=m)
    np.testing.assert_allclose(df["time_s"], [0.0, 0.5, 1.0, 1.5])
    assert "passes midnight" in " ".join(rep["files"][0]["notes"])



def test_synchronous_log_is_not_touched():
    """A log whose channels sit on the speed rows (one row lost its speed) keeps its gaps:
    nothing is interpolated into it."""
    df = pd.DataFrame({"time_s": np.arange(10.0), "speed_mps": [1.0] * 4 + [np.nan] + [1.0] * 5,
                       "x": [1.0, 2.0, np.nan, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0]})
    rep = new_report("f.csv", "f", 10)
    out = align_channels(df, rep)
    assert out.equals(df) and rep["notes"] == [] and rep["dropped"] == {}



@settings(max_examples=40, deadline=None)
@given(st.floats(0.05, 0.9), st.floats(-3.0, 3.0), st.floats(-50.0, 50.0), st.integers(0, 10_000),
       st.floats(0.15, 0.6))
def test_aligned_values_are_linear_interpolation(jitter, slope, offset, seed, speed_share):
    """Any polling jitter and share of speed rows: a channel linear in time comes out exact
    at every speed sample inside its own time span, and only there."""
    rng = np.random.default_rng(seed)
    n = 300
    t = np.cumsum(rng.uniform(0.1, 0.1 + jitter, n))
    is_speed = rng.uniform(size=n) < speed_share
    df = pd.DataFrame({"time_s": t, "speed_mps": np.where(is_speed, 5.0, np.nan),
                       "x": np.where(is_speed, np.nan, offset + slope * t)})
    rep = new_report("f.csv", "f", n)
    out = align_channels(df, rep)
    assert len(out) == is_speed.sum()
    tx = t[~is_speed]
    ts = out["time_s"].to_numpy()
    x = out["x"].to_numpy()
    # a channel polled at least twice as often as the speed is its mean over each speed
    # interval: for a line, its value at the interval's middle; else the value at the sample
    lo, hi = windows(ts) if faster(ts, tx) else (ts, ts)
    inside = (lo >= tx.min()) & (hi <= tx.max())
    assert np.all(np.isnan(x[~inside]))
    gap = np.diff(tx).max() <= ALIGN_MAX_GAP_INTERVALS * np.median(np.diff(tx))
    if gap:
        np.testing.assert_allclose(x[inside], offset + slope * 0.5 * (lo + hi)[inside], rtol=1e-9, atol=1e-9)


def test_columns_aligns_within_each_trip_of_a_file(tmp_path):
    """A file of two trips (its own trip column), each asynchronous: a channel is put onto
    the speed samples of its own trip, never bridged from the other trip's samples."""
    lines = ["trip,t,v,i"]
    for trip, base in (("a", 0.0), ("b", 30.0)):  # b starts where a ends: bridging would show
        for k in range(60):
            t = base + 0.5 * k
            lines.append(f"{trip},{t},{10 + k % 5}," if k % 2 == 0 else f"{trip},{t},,{base + t}")
    src = tmp_path / "two.csv"
    src.write_text("\n".join(lines) + "\n", encoding="utf-8")
    m = tmp_path / "map.toml"
    m.write_text('[columns.trip]\nname = "trip_id"\n[columns.t]\nname = "time_s"\nunit = "s"\n'
                 '[columns.v]\nname = "speed_mps"\nunit = "m/s"\n[columns.i]\nname = "battery_current_a"\n'
                 'unit = "A"\n', encoding="utf-8")
    df, rep = read("columns", src, columns=m)
    assert sorted(df["trip_id"].unique()) == ["a", "b"] and len(df) == 60
    for trip, base in (("a", 0.0), ("b", 30.0)):  # b starts where a ends: bridging would show
        g = df[df["trip_id"] == trip]
        ok = g["battery_current_a"].notna().to_numpy()
        assert ok[1:-1].all() and not ok[0]          # before its first sample: missing
        t = g["time_s"].to_numpy()                  # the file's own seconds
        np.testing.assert_allclose(g["battery_current_a"].to_numpy()[ok], (base + t)[ok])
