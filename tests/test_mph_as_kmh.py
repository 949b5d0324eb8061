"""A speed logged in mph and read as km/h: m·v·a falls by 1/1.609², so the free acc reads
2.6–3.1 — below the scale check's 5 and above the plausible 1.4, where the constraints set
no bound: a LeafSpy log mapped so was written with acc 2.262 and roll 0.054 under the words
'physically constrained' (active: none), the acc left unflagged after it. Now the note says
mph, and what is written implausible beyond the constraints is a warning."""

import numpy as np
import pandas as pd

from sumo_drvpw.fit.physical import physical_reading
from sumo_drvpw.model.constants import KMH, MPH


def test_mph_read_as_kmh_is_named_and_the_written_acc_warned(tmp_path, capsys):
    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.vehicles import load_vehicle

    rng = np.random.default_rng(2)
    t = np.arange(0.0, 1800.0, 0.5)
    v = np.clip(16 + 9 * np.sin(t / 50.0) + 4 * np.sin(t / 9.0), 0.0, None)
    m = load_vehicle("bmw_i3").mass_kg
    x = from_frame(pd.DataFrame({"trip_id": "T", "time_s": t, "speed_mps": v, "mass_kg": m})).inputs()
    p = Equation("truth", {"acc": 1.05, "roll": 0.01, "aero": 0.35}).power(x) + rng.normal(0, 200, len(t))
    f = tmp_path / "mph_as_kmh.csv"      # the log as a mapping with unit km/h made it of a mph speed
    pd.DataFrame({"trip_id": "T", "time_s": t, "speed_mps": v / MPH * KMH, "power_w": p}).to_csv(f, index=False)
    assert cli_main(["calibrate", str(f), "--vehicle", "bmw_i3", "--out", str(tmp_path / "eq.toml")]) == 0
    said = capsys.readouterr().out
    assert "logged in mph and read as km/h" in said
    warn = next(ln for ln in said.splitlines() if ln.startswith("warning: implausible as written"))
    assert "acc = 2." in warn


def test_the_mph_hint_only_near_its_factor():
    assert "mph" in physical_reading({"acc": 2.7})["acc"]["note"]
    for c in (1.5, 1.9, 4.0, 0.4):
        assert "mph" not in physical_reading({"acc": c})["acc"]["note"]
