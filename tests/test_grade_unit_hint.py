"""A grade coefficient near 0.305 (or 3.28) is read as an elevation in the wrong length unit:
a real LeafSpy log (Wales) whose altitude is in feet, mapped as metres, calibrated to
grade 0.329 and was called 'attenuated (coarse or smoothed elevation)' only — in feet it
reads 0.82 and its constrained R² rises from −0.47 to 0.34."""

import numpy as np
import pandas as pd

from sumo_drvpw.fit.physical import physical_reading
from sumo_drvpw.model.constants import FT


def _hilly_log(tmp_path, elevation_scale: float):
    """One 40-min trip, 10 Hz, over hills (±5 % grade); power from acc 1.1, grade 1,
    roll 0.01, aero_rho 0.6 at 1500 kg; the elevation written × ``elevation_scale``."""
    rng = np.random.default_rng(3)
    n = 24000
    t = np.arange(n) * 0.1
    v = np.clip(15 + 5 * np.sin(t / 30.0) + rng.normal(0, 0.02, n), 0.5, None)
    s = np.cumsum(v * 0.1)
    z = 40.0 * np.sin(s / 800.0)           # grade up to 40/800 = 5 %
    df = pd.DataFrame({"trip_id": "T1", "time_s": t, "speed_mps": v, "mass_kg": 1500.0, "elevation_m": z})
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.model.equations import Equation

    x = from_frame(df).inputs()
    p = Equation("truth", {"acc": 1.1, "grade": 1.0, "roll": 0.01, "aero_rho": 0.6}).power(x)
    df["power_w"] = p + rng.normal(0, 300.0, n)
    df["elevation_m"] = z * elevation_scale
    f = tmp_path / "log.csv"
    df.to_csv(f, index=False)
    return f


def test_grade_coefficient_of_a_foot_elevation_is_read_as_one(tmp_path, capsys):
    from sumo_drvpw.cli import main as cli_main

    log = _hilly_log(tmp_path, 1 / FT)     # the altitude in feet under the name elevation_m
    assert cli_main(["calibrate", str(log), "--out", str(tmp_path / "eq.toml")]) == 0
    out = capsys.readouterr().out
    assert "grade = 0.3" in out           # the free fit: 0.3048 of the true 1
    assert "feet and read as metres" in out, out


def test_the_hint_only_near_the_unit_factors():
    for c, said in ((0.3, "feet and read as metres"), (3.3, "metres and read as feet")):
        assert said in physical_reading({"grade": c})["grade"]["note"]
    for c in (0.69, 0.94, 1.0, 1.5, 0.1):  # smoothing attenuates (the i3 as logged: 0.69)
        assert "feet" not in physical_reading({"grade": c})["grade"]["note"]
