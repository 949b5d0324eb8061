"""``sumo-drvpw dynamics``: drive logs' driving dynamics, measured as a SUMO run measures
its trajectories (sim/dynamics.py), with a vType acceleration profile."""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.sim import dynamics as D


def _trip(seed: int, n: int = 8000, hz: float = 10.0) -> pd.DataFrame:
    """A stop-and-go trip at ``hz``: accelerations up to ~2 m/s², speeds 0–25 m/s."""
    rng = np.random.default_rng(seed)
    t = np.arange(n) / hz
    v = np.clip(12 + 11 * np.sin(t / 15.0 + seed) + np.cumsum(rng.normal(0, 0.05, n)), 0, 30)
    return pd.DataFrame({"time_s": t + 1000.0 * seed, "speed_mps": v, "trip_id": f"T{seed}"})


def test_a_log_reads_as_the_run_reads_trajectories(tmp_path, capsys):
    """Two trips of one file: dynamics.json
    holds what :class:`Dynamics` gives the trips added one by one — parts, kinetic energy
    and the acceleration profile — and a vType profile from the 95th percentiles; report.md
    shows them; the input is not touched."""
    df = pd.concat([_trip(1), _trip(2)], ignore_index=True)
    log = tmp_path / "log.csv"
    df.to_csv(log, index=False)
    before = log.read_bytes()
    assert cli_main(["dynamics", str(log), "--out", str(tmp_path / "o")]) == 0
    doc = json.loads((tmp_path / "o" / "dynamics.json").read_text(encoding="utf-8"))
    ref = D.Dynamics()
    for seed in (1, 2):
        tr = _trip(seed)
        ref.add_trajectory(tr.time_s.to_numpy(), tr.speed_mps.to_numpy(), "measured")
    want = json.loads(json.dumps(ref.summary()["measured"]))
    got = doc["driving_dynamics"]
    assert got.pop("logged_s") == pytest.approx(2 * 7999 / 10.0) and got.pop("median_step_s") == pytest.approx(0.1)
    assert got == want and doc["trips"] == 2 and doc["samples"] == len(df)
    out = capsys.readouterr().out
    assert "RPA" in out and "warning" not in out  # (10 Hz: the 1-Hz figures cover the log)
    prof = want["accel_profile"]
    assert len(prof) >= 3 and doc["sumo_vtype"] == D.sumo_profile(prof)
    assert doc["sumo_vtype"]["desAccelProfile"].split() == [f"{b['a_pos_95_mps2']:g}" for b in prof]
    md = (tmp_path / "o" / "report.md").read_text(encoding="utf-8")
    assert f'speedTable="{doc["sumo_vtype"]["speedTable"]}"' in md and "| measured | urban |" in md
    assert log.read_bytes() == before


def test_a_log_sampled_every_two_seconds_says_how_little_its_figures_rest_on(tmp_path, capsys):
    """A trip sampled every 2 s with a few 1-s steps (as carOBD's logs): the 1-Hz central
    differences exist only around those steps, so the figures rest on a sliver of the log —
    said on the console and in report.md; a 1-Hz log of the same drive is not warned of."""
    t = np.arange(0.0, 3600.0, 2.0)
    t = np.sort(np.concatenate([t, t[::100] + 1.0]))  # a 1-s step every 200 s
    v = np.clip(12 + 10 * np.sin(t / 40.0), 0, None)
    log = tmp_path / "log.csv"
    pd.DataFrame({"time_s": t, "speed_mps": v}).to_csv(log, index=False)
    assert cli_main(["dynamics", str(log), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    doc = json.loads((tmp_path / "o" / "dynamics.json").read_text(encoding="utf-8"))["driving_dynamics"]
    covered = sum(p["time_s"] for p in doc["parts"].values())
    assert 0 < covered < 0.1 * doc["logged_s"] and doc["median_step_s"] == 2.0
    assert "warning: the 1-Hz figures rest on" in out and "2 s apart" in out
    assert "**Warning:** the 1-Hz figures rest on" in (tmp_path / "o" / "report.md").read_text(encoding="utf-8")
    t1 = np.arange(0.0, 3600.0, 1.0)
    pd.DataFrame({"time_s": t1, "speed_mps": np.clip(12 + 10 * np.sin(t1 / 40.0), 0, None)}).to_csv(log, index=False)
    assert cli_main(["dynamics", str(log), "--out", str(tmp_path / "o1")]) == 0
    assert "warning" not in capsys.readouterr().out


@pytest.mark.parametrize("rows,needle", [
    ("time_s,speed_mps\n0,0\n1,0\n2,0\n3,0\n", "column 'speed_mps' is 0 on every row"),
    ("time_s,speed_mps,trip_id\n0,1,a\n1,2,a\n", "no 1-Hz figures"),
    # a log sampled every 2 s (carOBD's): the refusal says how far apart its samples are
    ("time_s,speed_mps\n" + "".join(f"{2 * k},{k % 7}\n" for k in range(60)),
     "its samples are 2 s apart (median): the RDE figures need a log sampled at 1 Hz or faster"),
    ("time_s,speed,trip_id\n0,1,a\n1,2,a\n2,3,a\n", "missing required column 'speed_mps'")])
def test_bad_logs_exit_2_in_one_line_and_write_nothing(tmp_path, capsys, rows, needle):
    log = tmp_path / "log.csv"
    log.write_text(rows, encoding="utf-8")
    assert cli_main(["dynamics", str(log), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert needle in err and str(log) in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_figures_on_too_few_samples_are_marked_not_judged(tmp_path, capsys):
    """A part with fewer than 100 samples is not judged against the RDE bound (dynamics.json
    said so, the console and report.md showed it as any other figure); now marked * with a
    note, and the whole log's kinetic energy is said once, not repeated in every part's row
    as if it were that part's (a rehearsal's Seat Leon log)."""
    t = np.arange(0.0, 900.0, 1.0)
    v = np.where(t < 800, np.clip(8 + 6 * np.sin(t / 20.0), 0, None), 24 + np.sin(t / 5.0))  # 100 s rural
    log = tmp_path / "log.csv"
    pd.DataFrame({"time_s": t, "speed_mps": v}).to_csv(log, index=False)
    assert cli_main(["dynamics", str(log), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    doc = json.loads((tmp_path / "o" / "dynamics.json").read_text(encoding="utf-8"))["driving_dynamics"]
    assert doc["parts"]["urban"]["va_pos_95_judged"] and not doc["parts"]["rural"]["va_pos_95_judged"]
    rural = next(ln for ln in out.splitlines() if ln.startswith("rural"))
    assert f"{doc['parts']['rural']['va_pos_95_m2ps3']:5.1f}* (RDE max" in rural
    assert "* not judged against the RDE bound" in out
    md = (tmp_path / "o" / "report.md").read_text(encoding="utf-8")
    assert md.count(f"{doc['kinetic_j_per_kg_km']:.0f} J/(kg·km)") == 1 and "| rural |" in md
    assert "not judged against the RDE bound" in md
