"""The virtual test track: patterns, declared truth, planted effects through the CLI."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.model.constants import KMH
from sumo_drvpw.synth.track import SynthOptions, synthesize


def test_patterns_and_signals():
    df, truth = synthesize(SynthOptions(minutes=15, seed=4))
    assert len(df) == 15 * 60 * 8
    assert np.allclose(np.diff(df["time_s"]), 0.125)
    # the paper's analytical patterns are all driven
    assert {"max_accel", "max_brake", "cruise", "coast", "const_accel", "free", "ev_max"} <= set(df["phase"])
    assert df["speed_mps"].max() > 155 * KMH  # cruise up to 160 km/h
    assert df.loc[df["phase"] == "ev_max", "ice_speed_rpm"].abs().max() == 0  # EV mode: engine off
    assert df["brake"].any() and not df["brake"].all()
    # planetary kinematics hold in the logged speeds (Willis: 30·ω_MG1 + 78·ω_R = 108·ω_ice)
    ring = df["mg2_speed_rpm"] / 2.6363636
    assert np.abs(30 * df["mg1_speed_rpm"] + 78 * ring - 108 * df["ice_speed_rpm"]).median() < 60
    assert truth["equation"] == "drvpw_prius3" and truth["mass_kg"] == 1625


def test_truth_in_parquet_metadata_and_csv_sidecar(tmp_path):
    p = tmp_path / "s.parquet"
    assert cli_main(["synth", "--out", str(p), "--minutes", "2", "--seed", "9"]) == 0
    meta = pq.read_schema(p).metadata
    truth = json.loads(meta[b"sumo_drvpw.truth"])
    assert truth["terms"]["acc"] == pytest.approx(1624 / 1625)
    c = tmp_path / "s.csv"
    assert cli_main(["synth", "--out", str(c), "--minutes", "2", "--seed", "9"]) == 0
    assert json.loads((tmp_path / "s.truth.json").read_text(encoding="utf-8"))["seed"] == 9


def test_same_seed_same_log():
    a, _ = synthesize(SynthOptions(minutes=3, seed=5))
    b, _ = synthesize(SynthOptions(minutes=3, seed=5))
    c, _ = synthesize(SynthOptions(minutes=3, seed=6))
    assert a.equals(b) and not a["speed_mps"].equals(c["speed_mps"])


def test_planted_load_found_by_diagnose_through_the_cli(tmp_path):
    """synth --plant → diagnose (power-split path, acceleration from speed) names the load."""
    log = tmp_path / "planted.parquet"
    assert cli_main(["synth", "--out", str(log), "--minutes", "6", "--trips", "3", "--plant", "ac,distractors"]) == 0
    out = tmp_path / "diag"
    assert cli_main(["diagnose", str(log), "--vehicle", "prius3", "--out", str(out), "--no-figures", "--quiet"]) == 0
    rep = json.loads((out / "trace.json").read_text(encoding="utf-8"))
    assert [f["signals"] for f in rep["findings"]] == [["ac_power_w"]]
    f = rep["findings"][0]
    assert f["coefficient"] == pytest.approx(1.0, rel=0.15)  # planted gain 1 W per W
    assert f["metrics_after"]["rmse_w"] < f["metrics_before"]["rmse_w"]


def test_bad_synth_options(tmp_path, capsys):
    assert cli_main(["synth", "--out", str(tmp_path / "x.parquet"), "--plant", "gremlins"]) == 2
    assert "gremlins" in capsys.readouterr().err
    assert cli_main(["synth", "--out", str(tmp_path / "x.txt")]) == 2
    assert cli_main(["synth", "--out", str(tmp_path / "x.parquet"), "--minutes", "0"]) == 2


def test_one_table_of_plants_cli_names_match(tmp_path):
    from sumo_drvpw.cli.synth import PLANT_NAMES
    from sumo_drvpw.synth.effects import PLANTS

    assert set(PLANT_NAMES) == set(PLANTS) - {"log-power"}
    p = tmp_path / "s.parquet"
    assert cli_main(["synth", "--out", str(p), "--minutes", "2", "--plant", "power-lag,pedal"]) == 0
    assert "throttle_pct" in pq.read_schema(p).names
    assert cli_main(["synth", "--out", str(p), "--minutes", "2", "--plant", "nope"]) == 2
