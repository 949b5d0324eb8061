"""The driving dynamics of standard driving cycles and of the shared real drive logs,
measured as a SUMO run's trajectories are (sumo_drvpw/sim/dynamics.py: EU RDE
trip-dynamics figures per urban/rural/motorway part), as references for the
``driving_dynamics`` a run reports (docs/scenario.md, "Driving dynamics").

    .venv/bin/python scripts/driving_dynamics.py --data ../shared/data [--only cycles|logs|profile]

Cycles: ``DATA/cycles/`` (FASTSim's WLTC class 3 phases, UDDS, HWFET, US06; carculator's
CADC — the Common Artemis Driving Cycles, built from real European driving — urban, road and
motorway, and UITP's SORT bus test cycles; JC08 at 0.1 s), each one trajectory. Logs, read
in place through their adapters: the BMW i3 trips (Munich, TUM, 10 Hz), the JLU car's road
trips (Changchun, 20 Hz) and the Prius Gen 2 trips (Spokane, OBD about 1.4 Hz, irregular: a
whole second without a sample leaves its neighbours without a central difference), each
trip a trajectory of its car. Prints a Markdown table for each: per cycle or car and part
its mean speed, the 95th percentile of v·a_pos against the RDE's largest, the relative
positive acceleration against the RDE's smallest, the part's time, and per cycle or car
the positive kinetic energy per kg and km at its own rate. About 15 s.

``--only profile``: per car the median, 85th and 95th percentile of its trips' 1-Hz
accelerations above 0.1 m/s² in 5-m/s speed bins, as ``sumo-drvpw dynamics`` reads a log:
a SUMO vType's speed-dependent desired acceleration (``speedTable``/``desAccelProfile``)
from measured driving (docs/scenario.md, "Driving dynamics").
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.sim.dynamics import markdown_head, markdown_rows, of_log, of_trajectory
from sumo_drvpw.validation.chain_common import read_shared

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


#: (label, folder, adapter, vehicle)
LOGS = (("BMW i3, Munich", "bmw_i3_tum", "bmw-i3-tum", "bmw_i3"),
        ("JLU car, Changchun", "jlu_bev_road", "jlu-road", "jlu_bev"),
        ("Prius Gen 2, Spokane", "prius_gen2_torquepro", "torquepro-prius2", "prius2"))


def cycle_rows(data: Path) -> list[str]:
    out = markdown_head(["cycle"], kinetic=True)
    for label, f, tc, vc, k, sep in CYCLES:
        df = pd.read_csv(data / "cycles" / f, sep=sep, encoding="utf-8-sig")
        t = df[tc].to_numpy(float)
        v = df[vc].to_numpy(float) * k
        end = np.flatnonzero(np.isfinite(v))  # carculator pads the shorter cycles
        t, v = t[: end[-1] + 1], v[: end[-1] + 1]
        out += markdown_rows(of_trajectory(t, v), [label], min_apos=10, kinetic=True)
    return out


def log_rows(data: Path) -> list[str]:
    out = markdown_head(["logs", "trips"], kinetic=True)
    for label, folder, fmt, vehicle in LOGS:
        doc, trips = of_log(read_shared(data, folder, fmt, vehicle)[0].df)  # as `sumo-drvpw dynamics`
        out += markdown_rows(doc, [label, str(trips)], kinetic=True)
    return out


def profile_rows(data: Path) -> list[str]:
    out = ["| logs | speed m/s | samples with a > 0.1 m/s² | median m/s² | 85th pct. | 95th pct. |",
           "|---|---|---|---|---|---|"]
    for label, folder, fmt, vehicle in LOGS:
        df = read_shared(data, folder, fmt, vehicle)[0].df
        for b in of_log(df)[0]["accel_profile"]:  # as `sumo-drvpw dynamics` reads a log
            to = "…" if b["speed_to_mps"] is None else f"{b['speed_to_mps']:g}"
            out.append(f"| {label} | {b['speed_from_mps']:g}–{to} | {b['samples']} | {b['a_pos_50_mps2']:.2f} | "
                       f"{b['a_pos_85_mps2']:.2f} | {b['a_pos_95_mps2']:.2f} |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="../shared/data", help="the shared data folder (holds cycles/ and the logs)")
    ap.add_argument("--only", choices=("cycles", "logs", "profile"), help="print one table only")
    a = ap.parse_args(argv)
    data = Path(a.data)
    out = []
    if a.only in (None, "cycles"):
        out += ["Standard cycles:", "", *cycle_rows(data), ""]
    if a.only in (None, "logs"):
        out += ["Measured trips:", "", *log_rows(data), ""]
    if a.only in (None, "profile"):
        out += ["Accelerations by speed:", "", *profile_rows(data), ""]
    print("\n".join(out))
    return 0


if __name__ == "__main__":
    sys.exit(main())
