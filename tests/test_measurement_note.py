"""Comparing a built-in whose [measurement] needs an accelerometer (bmw_i3_battery: fused grade,
dropouts left out) on a log without one was refused after a note naming the correction but
not how to read the logs otherwise (a rehearsal on a public LeafSpy log); the note names it,
and that reading compares."""

import numpy as np
import pandas as pd


def test_the_measurement_note_says_how_to_read_the_logs_as_they_are(tmp_path, capsys):
    from sumo_drvpw.cli import main as cli_main

    t = np.arange(0.0, 900.0, 1.0)
    v = np.clip(14 + 8 * np.sin(t / 60.0), 0.0, None)
    p = 1500.0 * v * np.gradient(v, t) + 0.35 * v ** 3 + 150.0 * v + 600.0
    f = tmp_path / "ev.csv"
    pd.DataFrame({"trip_id": "T", "time_s": t, "speed_mps": v, "elevation_m": 100.0 + 0.01 * np.cumsum(v),
                  "ambient_c": 15.0, "battery_voltage_v": 360.0, "battery_current_a": p / 360.0}).to_csv(f, index=False)
    args = ["compare", str(f), "--vehicle", "bmw_i3", "--equation", "bmw_i3_battery"]
    assert cli_main(args + ["--out", str(tmp_path / "a")]) == 2
    out = capsys.readouterr()
    assert "accelerometer" in out.err
    note = next(ln for ln in out.out.splitlines() if ln.startswith("note: logs corrected as the [measurement]"))
    assert "--grade-source logged" in note and "--no-exclude-dropouts" in note
    # the grade read as logged, the dropouts still left out: refused naming the flag that keeps them
    assert cli_main(args + ["--grade-source", "logged", "--out", str(tmp_path / "c")]) == 2
    err = capsys.readouterr().err
    assert "leaving out logger dropouts needs" in err and "(--no-exclude-dropouts keeps them)" in err, err
    # each flag switches off its own setting only (cli/_measurement.py)
    assert cli_main(args + ["--grade-source", "logged", "--no-exclude-dropouts", "--out", str(tmp_path / "b")]) == 0
