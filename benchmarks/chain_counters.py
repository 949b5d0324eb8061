"""Time and peak memory of `calibrate --target battery` on the BMS's energy counters, against
the same calibration on the battery's V·I (the baseline, measured in the same run).

Usage: .venv/bin/python benchmarks/chain_counters.py [--hours 50] [--engine local] [--repeats 3]

Data: an EV's stop-and-go drive at 10 Hz in 30-min trips written here as Parquet, its
battery power from a planted chain (η_t 0.9, η_r 0.7, 400 W) on a road load (acc 1, v1 150,
v3 0.4), logged twice: as V·I, and as cumulative discharged and charged energy in steps of
2 Wh (7.2 kJ, the JLU car's). Each repeat runs in a fresh process, which reports its own peak
RSS (``VmHWM``): the calibration on the counters (their view of the log built per batch of
whole trips; the road load's design seen through it at each recuperation limit tried,
sumo_drvpw.data.counters) and, as baseline, on V·I. Last line:
``time_ratio=<counters / V·I, medians> rss_ratio=<counters / V·I, medians> rows=<N>``
(target: time ≤ 2, memory ≤ 1.5). Not part of the test suite.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from _child import compare, report

EQ = '[equation]\nname = "road"\n[terms]\nacc = 1.0\nv1 = 150.0\nv3 = 0.4\n'


def write_logs(folder: Path, hours: float) -> int:
    import numpy as np
    import pandas as pd

    n_trip = 18_000  # 30 min at 10 Hz
    trips = max(1, int(round(hours * 2)))
    rng = np.random.default_rng(0)
    vi, ctr = [], []
    for k in range(trips):
        t = np.arange(n_trip) * 0.1
        v = np.clip(12.0 + 9.0 * np.sin(2 * np.pi * t / rng.uniform(50, 90) + rng.uniform(0, 6))
                    + 3.0 * np.sin(2 * np.pi * t / 11.0), 0.0, None)
        a = np.gradient(v, t)
        wheel = 1500.0 * v * a + 150.0 * v + 0.4 * v ** 3
        batt = np.where(wheel > 0, wheel / 0.9, wheel * 0.7) + 400.0
        w = np.r_[np.diff(t), 0.0]
        q = 7200.0
        base = pd.DataFrame({"trip_id": f"T{k:04d}", "time_s": t, "speed_mps": v, "mass_kg": 1500.0})
        vi.append(base.assign(battery_voltage_v=350.0, battery_current_a=batt / 350.0))
        ctr.append(base.assign(battery_discharge_energy_j=np.floor(np.cumsum(np.clip(batt, 0, None) * w) / q) * q,
                               battery_charge_energy_j=np.floor(np.cumsum(np.clip(-batt, 0, None) * w) / q) * q))
    pd.concat(vi, ignore_index=True).to_parquet(folder / "vi.parquet", row_group_size=100_000)
    pd.concat(ctr, ignore_index=True).to_parquet(folder / "counters.parquet", row_group_size=100_000)
    (folder / "road.toml").write_text(EQ)
    return trips * n_trip


def child(kind: str, folder: str, engine: str) -> None:
    import tomllib

    from sumo_drvpw.cli import main as cli_main

    d = Path(folder)
    out = d / f"{kind}.toml"
    t0 = time.perf_counter()
    rc = cli_main(["calibrate", str(d / f"{kind}.parquet"), "--target", "battery", "--equation",
                   str(d / "road.toml"), "--out", str(out), "--name", kind, "--engine", engine, "--force"])
    secs = time.perf_counter() - t0
    assert rc == 0, rc
    ch = tomllib.loads(out.read_text())["chain"]
    import sys

    print(f"{kind}: η_t {ch['traction_efficiency']:.4f}, η_r {ch['recuperation_efficiency']:.4f}, "
          f"{ch['aux_power_w']:.0f} W", file=sys.stderr)
    report(kind, secs, 0)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--hours", type=float, default=50.0)
    ap.add_argument("--engine", default="local", choices=("local", "memory"))
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.child:
        child(*a.child)
        return
    with tempfile.TemporaryDirectory() as tmp:
        n = write_logs(Path(tmp), a.hours)
        print(f"{n} rows per log, engine {a.engine}")
        compare(__file__, "vi", "counters", [tmp, a.engine], a.repeats, n)


if __name__ == "__main__":
    main()
