"""Time and peak memory of `calibrate --target battery` on the BMS's energy counters, against
the same calibration on the battery's V·I (the baseline, measured in the same run).

Usage: .venv/bin/python benchmarks/chain_counters.py [--hours 50] [--engine local] [--repeats 3]

Data: an EV's stop-and-go drive at 10 Hz in 30-min trips written here as Parquet, its
battery power from a planted chain (η_t 0.9, η_r 0.7, 400 W) on a road load (acc 1, v1 150,
v3 0.4; sumo_drvpw.synth.effects.counter_drive), logged twice: as V·I, and as cumulative
discharged and charged energy in steps of 2 Wh (7.2 kJ, the JLU car's). Each repeat runs in a fresh process, which reports its own peak
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

from _child import compare, parse, report

EQ = '[equation]\nname = "road"\n[terms]\nacc = 1.0\nv1 = 150.0\nv3 = 0.4\n'


def write_logs(folder: Path, hours: float) -> int:
    from sumo_drvpw.data.counters import COUNTERS
    from sumo_drvpw.synth.effects import counter_drive

    df = counter_drive(trips=max(1, int(round(hours * 2))), seconds=1800.0).drop(columns="accel_mps2")
    vi = df.drop(columns=list(COUNTERS)).assign(battery_voltage_v=350.0, battery_current_a=df["true_battery_w"] / 350.0)
    vi.drop(columns="true_battery_w").to_parquet(folder / "vi.parquet", row_group_size=100_000)
    df.drop(columns="true_battery_w").to_parquet(folder / "counters.parquet", row_group_size=100_000)
    (folder / "road.toml").write_text(EQ)
    return len(df)


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
    a = parse(ap, child, 3)
    if a is None:
        return
    with tempfile.TemporaryDirectory() as tmp:
        n = write_logs(Path(tmp), a.hours)
        print(f"{n} rows per log, engine {a.engine}")
        compare(__file__, "vi", "counters", [tmp, a.engine], a.repeats, n)


if __name__ == "__main__":
    main()
