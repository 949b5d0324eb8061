"""The driving dynamics of the shared real drive logs, measured as a SUMO run's trajectories
are (sumo_drvpw/sim/dynamics.py: EU RDE trip-dynamics figures per urban/rural/motorway
part), as measured references for the ``driving_dynamics`` a run reports.

    .venv/bin/python scripts/log_dynamics.py --data ../shared/data

Reads, in place and through their adapters, the BMW i3 trips (Munich, TUM, 10 Hz), the JLU
car's road trips (Changchun, 20 Hz) and the Prius Gen 2 trips (Spokane, OBD about 1.4 Hz,
irregular: a whole second without a sample leaves its neighbours without a central
difference), each trip a trajectory of its car, and prints a Markdown table: per car and
part its mean speed, the 95th percentile of v·a_pos against the RDE's largest, the relative
positive acceleration against the RDE's smallest, and per car the positive kinetic energy
per kg and km at the logs' own rate. About a minute.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from sumo_drvpw.sim.dynamics import Dynamics
from sumo_drvpw.validation.chain_common import read_shared

#: (label, folder, adapter, vehicle)
LOGS = (("BMW i3, Munich", "bmw_i3_tum", "bmw-i3-tum", "bmw_i3"),
        ("JLU car, Changchun", "jlu_bev_road", "jlu-road", "jlu_bev"),
        ("Prius Gen 2, Spokane", "prius_gen2_torquepro", "torquepro-prius2", "prius2"))


def rows(data: Path) -> list[str]:
    out = ["| logs | trips | part | mean speed km/h | v·a_pos 95th pct. m²/s³ (RDE max) | RPA m/s² (RDE min) "
           "| part's time s | kinetic energy J/(kg·km) |", "|---|---|---|---|---|---|---|---|"]
    for label, folder, fmt, vehicle in LOGS:
        log, _ = read_shared(data, folder, fmt, vehicle)
        df = log.df
        d = Dynamics()
        trips = df["trip_id"].astype(str).to_numpy()
        t, v = df["time_s"].to_numpy(float), df["speed_mps"].to_numpy(float)
        for trip in dict.fromkeys(trips):
            s = (trips == trip) & np.isfinite(v) & np.isfinite(t)
            d.add_trajectory(t[s], v[s], label)
        doc = d.summary()[label]
        for part, p in doc["parts"].items():
            out.append(f"| {label} | {len(set(trips))} | {part} | {p['mean_speed_kmh']:.1f} | "
                       f"{p['va_pos_95_m2ps3']:.1f} ({p['rde_va_pos_95_max']:.1f}) | {p['rpa_mps2']:.3f} "
                       f"({p['rde_rpa_min']:.3f}) | {p['time_s']:.0f} | {doc['kinetic_j_per_kg_km']:.0f} |")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--data", default="../shared/data", help="the shared data folder")
    a = ap.parse_args(argv)
    print("\n".join(rows(Path(a.data))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
