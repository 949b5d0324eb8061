"""`--flat-road`: a log read as a flat road, its grade and elevation set aside. A phone's GPS
altitude on a flat coastal drive (a real Torque Pro log: 177 of 2,649 samples steeper than
35 %) put its noise into the driving power; the note said "read the logs without
elevation_m", which no option did. On that log a fuel chain read 0.605 marginal efficiency
and 2.17 L/h idle (both flagged implausible); read flat, 0.369 and 1.43 L/h."""

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.model.equations import Equation, load_equation


def _flat_drive_with_gps_altitude(tmp_path):
    """A 1-Hz, 50-min drive on a flat road whose logged elevation is a phone's GPS altitude
    (a random walk of ±3 m a second around sea level, with jumps); power_w from acc 1.1,
    roll 0.012, aero 0.37 at 1300 kg."""
    rng = np.random.default_rng(5)
    n = 3000
    t = np.arange(n, dtype=float)
    v = np.clip(14 + 8 * np.sin(t / 45.0) + 3 * np.sin(t / 11.0), 0.0, None)
    v[:30] = 0.0
    z = np.cumsum(rng.normal(0, 3.0, n)) + np.where(rng.random(n) < 0.1, rng.normal(0, 30, n), 0.0)
    df = pd.DataFrame({"trip_id": "T1", "time_s": t, "speed_mps": v, "mass_kg": 1300.0})
    from sumo_drvpw.data.log import from_frame

    x = from_frame(df).inputs()              # the flat road's inputs, as the reader derives them
    df["power_w"] = Equation("truth", {"acc": 1.1, "roll": 0.012, "aero": 0.37}).power(x) \
        + rng.normal(0, 200.0, n)
    df["elevation_m"] = z
    f = tmp_path / "drive.csv"
    df.to_csv(f, index=False)
    return f


def test_flat_road_sets_the_noisy_elevation_aside(tmp_path, capsys):
    from sumo_drvpw.cli import main as cli_main

    log = _flat_drive_with_gps_altitude(tmp_path)
    assert cli_main(["calibrate", str(log), "--out", str(tmp_path / "a.toml")]) == 0
    said = capsys.readouterr().out
    assert "steeper than 35 % left out" in said and "(--flat-road)" in said   # the note names the way out
    noisy = load_equation(tmp_path / "a.toml").terms     # the noise's grade: the physics forced on it
    assert noisy["roll"] != pytest.approx(0.012, rel=0.5) or noisy["aero"] != pytest.approx(0.37, rel=0.5)
    eq = tmp_path / "flat.toml"
    assert cli_main(["calibrate", str(log), "--flat-road", "--out", str(eq)]) == 0
    said = capsys.readouterr().out
    assert "steeper than 35 %" not in said and "the logs carry no grade" not in said
    terms = load_equation(eq).terms
    assert "grade" not in terms
    assert terms["acc"] == pytest.approx(1.1, rel=0.03) and terms["roll"] == pytest.approx(0.012, rel=0.1)
    assert terms["aero"] == pytest.approx(0.37, rel=0.1)


def test_flat_road_and_a_grade_source_that_reads_the_elevation_are_refused(tmp_path, capsys):
    from sumo_drvpw.cli import main as cli_main

    log = _flat_drive_with_gps_altitude(tmp_path)
    assert cli_main(["calibrate", str(log), "--flat-road", "--grade-source", "fused",
                     "--out", str(tmp_path / "x.toml")]) == 2
    err = capsys.readouterr().err
    assert "--flat-road" in err and "fused" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x.toml").exists()


def test_flat_road_says_the_elevation_is_read_for_the_air_density_only(tmp_path):
    """--flat-road with --air-density altitude: the grade is set aside, the air density still
    reads elevation_m (the [measurement] says 'air density at the logged altitude'); the
    report's grade source said 'elevation_m not used'. It says what is not read: the grade."""
    import json

    from sumo_drvpw.cli import main as cli_main

    log = _flat_drive_with_gps_altitude(tmp_path)
    assert cli_main(["calibrate", str(log), "--flat-road", "--air-density", "altitude", "--out",
                     str(tmp_path / "eq.toml"), "--report", str(tmp_path / "rep")]) == 0
    assert load_equation(tmp_path / "eq.toml").measurement.air_density == "altitude"
    src = json.loads((tmp_path / "rep" / "report.json").read_text(encoding="utf-8"))["context"]["counts"]["grade_source"]
    assert src.startswith("none, set aside") and "not used" not in src and "not read as grade" in src
