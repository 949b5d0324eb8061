"""scripts/d3_camry.py end to end on planted files in the layout of FASTSim's copy of
Argonne's D3 tests: the key-off soak is cut and splits its test into two trips, the files
import through the documented mapping, and the chain calibrated on three tests books the
fourth's planted fuel (a Willans line on the script's own road load) within 2 %; a folder
without the four files is refused in one line, exit 2."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
from script_module import load_script

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "d3_camry.py"


def _load():
    return load_script("d3_camry")


def _schedule(rng, n_hills: int) -> np.ndarray:
    """Speed [m/s] at 1 Hz: hills of accelerate – cruise – brake – stand."""
    v = [np.zeros(10)]
    for _ in range(n_hills):
        top = rng.uniform(8.0, 30.0)
        v += [np.arange(0.0, top, rng.uniform(0.8, 2.0)), np.full(int(rng.uniform(10, 60)), top),
              np.arange(top, 0.0, -rng.uniform(0.8, 2.0)), np.zeros(int(rng.uniform(8, 25)))]
    return np.concatenate(v)


def test_the_d3_script_on_planted_tests(tmp_path, monkeypatch):
    import sumo_drvpw.report.comparison as comparison
    from sumo_drvpw.model.constants import FUELS

    monkeypatch.setattr(comparison, "FIGURES", {})  # 12 comparisons' figures: not what is tested here

    d3 = _load()
    fp = FUELS["gasoline"]
    j_per_l = fp["lhv_j_per_kg"] * fp["density_kg_per_l"]
    etw = d3.ETW_LB * d3.LB
    a, b, c = d3.A_LBF * d3.LBF, d3.B_LBF_MPH * d3.LBF / d3.MPH, d3.C_LBF_MPH2 * d3.LBF / d3.MPH ** 2
    rng = np.random.default_rng(7)
    for k, hills in enumerate((8, 10, 9, 11)):
        v = _schedule(rng, hills)
        soak = slice(v.size, v.size + 600)
        if k == 0:  # an FTP-like test: a ten-minute key-off soak between two runs
            v = np.concatenate([v, np.zeros(600), _schedule(rng, hills)])
        t = np.arange(v.size, dtype=float)
        p = (a + b * v + c * v * v) * v + etw * np.gradient(v, t) * v
        fuel_w = 6_000.0 + np.maximum(p, 0.0) / 0.33
        ccps = fuel_w / j_per_l * 1000.0 * (1 + rng.normal(0, 0.02, v.size))
        if k == 0:
            ccps[soak] = 0.0
        ccps[-20:] = 0.0  # the engine switched off at the end of the test
        v[-20:] = 0.0
        pd.DataFrame({"Time[s]": t, "Eng_FuelFlow_Direct_DI[ccps]": ccps, "Dyno_Spd[mph]": v / d3.MPH}).to_csv(
            tmp_path / f"6181101{k + 1} Test Data.txt", index=False)
    out = tmp_path / "d3.md"
    assert d3.main(["--data", str(tmp_path), "--out", str(out)]) == 0
    md = out.read_text(encoding="utf-8")
    assert "61811011a" in md and "61811011b" in md
    per_trip = md.split("## Fuel per trip", 1)[1].split("## The calibrated chains", 1)[0]
    rows = {m.group(1): m.group(2)
            for m in re.finditer(r"^\| (618110\d\d\w?)(?: \(cold start\))? \|(.*)$", per_trip, re.M)}
    assert set(rows) >= {"61811011a", "61811011b", "61811012", "61811013", "61811014"}
    for trip in ("61811011b", "61811012", "61811013", "61811014"):
        calibrated = float(rows[trip].split("|")[3].strip().rstrip("%"))
        assert abs(calibrated) < 2.0, (trip, rows[trip])
    # the soak and the test's end were cut: 600 + 20 s (at most a second more at each edge)
    key_off = float(re.search(r"^\| 61811011 \| \d+ \| (\d+) \|", md, re.M).group(1))
    assert 618 <= key_off <= 624
    r = subprocess.run([sys.executable, str(SCRIPT), "--data", str(tmp_path / "none"), "--out",
                        str(tmp_path / "x.md")], capture_output=True, text=True)
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
