"""Defects found rehearsing public logs nobody here had used (2026-11-27, docs/adapters.md):
a Torque Pro export of several logging sessions out of order (cshell7/sample-obd-data) and
a LeafSpy log sampled every 15-25 s (corentinHuaulme/LeafSpyVisualizer). Synthetic files only."""

from __future__ import annotations

from sumo_drvpw.data.adapters import read


def _torque_csv(path, sessions):
    """A Torque Pro CSV export: one row per second of each (start 'HH:MM', seconds) session,
    written in the given order."""
    rows = ["GPS Time, Device Time,Speed (OBD)(mph),Engine RPM(rpm)"]
    for start, n in sessions:
        for k in range(n):
            rows.append(f"-,27-Jun-2020 {start}:{k:02d}.000,{30 + k},{1500 + 10 * k}")
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def test_sessions_out_of_order_are_named_with_where_and_how_to_keep_them(tmp_path):
    # the later session (15:19) first, then an earlier one (14:19) of 6 rows: all 6 go
    # backwards; the note says where, by how much, and how to keep them
    src = _torque_csv(tmp_path / "back.csv", [("15:19", 10), ("14:19", 6)])
    df, rep = read("torquepro", [src])
    f = rep["files"][0]
    assert f["dropped"] == {"time going backwards": 6}
    assert len(df) == 10
    note = [n for n in f["notes"] if n.startswith("time going backwards")]
    assert len(note) == 1, f["notes"]
    assert "6 row(s) dropped" in note[0] and "data row 10" in note[0]
    assert "3609 s" in note[0]                       # 15:19:09 → 14:19:00
    assert "file of its own" in note[0]


def test_a_clock_glitch_is_named_without_the_session_hint(tmp_path):
    # one sample 0.5 s back (a phone clock's correction): located, no session advice
    src = tmp_path / "glitch.csv"
    rows = ["GPS Time, Device Time,Speed (OBD)(mph),Engine RPM(rpm)"]
    for k, s in enumerate(["00.000", "01.000", "02.000", "01.500", "03.000"]):
        rows.append(f"-,27-Jun-2020 15:19:{s},{30 + k},1500")
    src.write_text("\n".join(rows) + "\n", encoding="utf-8")
    df, rep = read("torquepro", [src])
    f = rep["files"][0]
    assert f["dropped"] == {"time going backwards": 1}
    note = [n for n in f["notes"] if n.startswith("time going backwards")]
    assert note and "by 0.5 s at data row 3" in note[0] and "file of its own" not in note[0]


def _canonical(path, trip, step_s, n):
    import numpy as np
    import pandas as pd

    t = np.arange(n) * step_s
    v = 12.0 + 6.0 * np.sin(t / 90.0)          # whole mph steps would widen the window too
    pd.DataFrame({"trip_id": trip, "time_s": t, "speed_mps": np.round(v / 0.44704) * 0.44704,
                  "power_w": 400.0 * v}).to_csv(path, index=False)
    return path


def test_samples_far_apart_are_said_to_lose_the_inertial_power(tmp_path):
    # LeafSpy (corentinHuaulme/LeafSpyVisualizer @ 1c46bc8) logs every 15-25 s: the derived
    # acceleration spans ~34 s while the note claimed a 3.65-s moving average, and nothing
    # said why a per-sample fit could not be good
    from sumo_drvpw.data.log import read_log
    from sumo_drvpw.data.resolution import merge_accel_derivation

    coarse = _canonical(tmp_path / "coarse.csv", "coarse", 17.0, 200)
    fine = _canonical(tmp_path / "fine.csv", "fine", 1.0, 600)
    text = read_log([coarse], options=None).counts["accel_source"]
    assert "up to 17 s apart (median step)" in text and "inertial power" in text
    assert "apart" not in read_log([fine]).counts["accel_source"]     # a 1-Hz log: as before
    both = read_log([coarse, fine]).counts
    assert "up to 17 s apart on 1 of 2 trips" in both["accel_source"]
    # batches of whole trips (the streamed reader) merge to the same derivation
    merged = merge_accel_derivation(read_log([coarse]).counts["accel_derivation"],
                                    read_log([fine]).counts["accel_derivation"])
    assert merged == both["accel_derivation"]


def test_phone_altitude_is_the_elevation_of_a_torque_log_without_the_gps_altitude_pid(tmp_path):
    # cshell7/sample-obd-data @ c759cb3 logs the phone's ' Altitude' (m) but no 'GPS
    # Altitude' PID: the import kept it aside, and the commands then said the logs carry
    # no grade and to log the GPS altitude
    rows = ["GPS Time, Device Time, Altitude,Speed (OBD)(mph),Engine RPM(rpm)"]
    for k in range(8):
        alt = "-" if k == 3 else f"{1300 + 2.5 * k}"
        rows.append(f"-,27-Jun-2020 15:19:{k:02d}.000,{alt},{40 + k},2000")
    src = tmp_path / "phone_alt.csv"
    src.write_text("\n".join(rows) + "\n", encoding="utf-8")
    df, rep = read("torquepro", [src])
    assert "elevation_m" in df
    assert df["elevation_m"].iloc[7] == 1317.5 and df["elevation_m"].isna().sum() == 1
    assert any("phone's 'Altitude'" in n for n in rep["files"][0]["notes"])
    # with the PID, the PID wins and the phone's value only fills its gaps (as before)
    rows = ["GPS Time, Device Time,GPS Altitude(ft), Altitude,Speed (OBD)(mph),Engine RPM(rpm)"]
    rows += [f"-,27-Jun-2020 15:19:{k:02d}.000,{'-' if k == 2 else 1000},500,40,2000" for k in range(4)]
    src.write_text("\n".join(rows) + "\n", encoding="utf-8")
    df, rep = read("torquepro", [src])
    assert list(df["elevation_m"].round(2)) == [304.8, 304.8, 500.0, 304.8]
    assert not any("phone's 'Altitude'" in n for n in rep["files"][0]["notes"])


def test_torque_nissan_maf_in_gm_per_s_is_a_mass_flow(tmp_path):
    # cshell7/sample-obd-data: '[NADV] Mass Air Flow(gm/s)' was kept unconverted, 'unit not known'
    rows = ["GPS Time, Device Time,Speed (OBD)(mph),Engine RPM(rpm),[NADV] Mass Air Flow(gm/s)"]
    rows += [f"-,27-Jun-2020 15:19:{k:02d}.000,40,2000,{20 + k}" for k in range(4)]
    src = tmp_path / "maf.csv"
    src.write_text("\n".join(rows) + "\n", encoding="utf-8")
    df, rep = read("torquepro", [src])
    assert list(df["nadv_mass_air_flow_gps"]) == [20.0, 21.0, 22.0, 23.0]
    assert not any("not known" in n for n in rep["files"][0]["notes"])
