"""The driving dynamics of standard driving cycles, measured as a SUMO run's trajectories are
(sumo_drvpw/sim/dynamics.py: EU RDE trip-dynamics figures per urban/rural/motorway part),
as a reference for the ``driving_dynamics`` a run reports.

    .venv/bin/python scripts/cycle_dynamics.py --data ../shared/data

Reads the cycles of ``DATA/cycles/`` (FASTSim's WLTC class 3 phases, UDDS, HWFET, US06;
carculator's CADC — the Common Artemis Driving Cycles, built from real European driving —
urban, road and motorway, and UITP's SORT bus test cycles; JC08 at 0.1 s) and prints a
Markdown table: per cycle and part its mean speed, the 95th percentile of v·a_pos against
the RDE's largest, and the relative positive acceleration against the RDE's smallest; per
cycle its positive kinetic energy per kg and km at its own resolution. A second or two.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.sim.dynamics import of_trajectory

#: (label, file, time column, speed column, speed unit factor to m/s, separator)
CYCLES = (
    ("WLTC class 3, low", "wltc_low_3.csv", "cycSecs", "cycMps", 1.0, ","),
    ("WLTC class 3, medium", "wltc_medium_3b.csv", "cycSecs", "cycMps", 1.0, ","),
    ("WLTC class 3, high", "wltc_high_3b.csv", "cycSecs", "cycMps", 1.0, ","),
    ("WLTC class 3, extra high", "wltc_extrahigh_3.csv", "cycSecs", "cycMps", 1.0, ","),
    ("CADC (Artemis) urban", "carculator_car_driving_cycles.csv", "Time (s)", "CADC Urban", 1 / 3.6, ";"),
    ("CADC (Artemis) road", "carculator_car_driving_cycles.csv", "Time (s)", "CADC Road", 1 / 3.6, ";"),
    ("CADC (Artemis) motorway", "carculator_car_driving_cycles.csv", "Time (s)", "CADC Motorway", 1 / 3.6, ";"),
    ("SORT 1 (bus, heavy urban)", "carculator_car_driving_cycles.csv", "Time (s)", "SORT 1", 1 / 3.6, ";"),
    ("SORT 2 (bus, easy urban)", "carculator_car_driving_cycles.csv", "Time (s)", "SORT 2", 1 / 3.6, ";"),
    ("SORT 3 (bus, suburban)", "carculator_car_driving_cycles.csv", "Time (s)", "SORT 3", 1 / 3.6, ";"),
    ("UDDS", "udds.csv", "cycSecs", "cycMps", 1.0, ","),
    ("HWFET", "hwfet.csv", "cycSecs", "cycMps", 1.0, ","),
    ("US06", "us06.csv", "cycSecs", "cycMps", 1.0, ","),
    ("JC08", "jc08_0p1s.csv", "Elapsed Time (s)", "Speed (kph)", 1 / 3.6, ","),
)


def rows(data: Path) -> list[str]:
    out = ["| cycle | part | mean speed km/h | v·a_pos 95th pct. m²/s³ (RDE max) | RPA m/s² (RDE min) | part's time s "
           "| cycle's kinetic energy J/(kg·km) |", "|---|---|---|---|---|---|---|"]
    for label, f, tc, vc, k, sep in CYCLES:
        df = pd.read_csv(data / "cycles" / f, sep=sep, encoding="utf-8-sig")
        t = df[tc].to_numpy(float)
        v = df[vc].to_numpy(float) * k
        end = np.flatnonzero(np.isfinite(v))  # carculator pads the shorter cycles
        t, v = t[: end[-1] + 1], v[: end[-1] + 1]
        doc = of_trajectory(t, v)
        for part, p in doc["parts"].items():
            if p["apos_samples"] < 10:
                continue
            out.append(f"| {label} | {part} | {p['mean_speed_kmh']:.1f} | {p['va_pos_95_m2ps3']:.1f} "
                       f"({p['rde_va_pos_95_max']:.1f}) | {p['rpa_mps2']:.3f} ({p['rde_rpa_min']:.3f}) | "
                       f"{p['time_s']:.0f} | {doc['kinetic_j_per_kg_km']:.0f} |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="../shared/data", help="the shared data folder (holds cycles/)")
    a = ap.parse_args(argv)
    print("\n".join(rows(Path(a.data))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
