"""Benchmark: `diagnose` on one million samples with twenty extra columns (< 60 s target).

The log is built from synthetic 8 Hz trips (sumo_drvpw.synth.track, truth drvpw_prius3, driving
power logged directly) tiled to 1e6 rows with distinct trip ids, plus twenty extra
columns (one planted A/C load and its flag, the rest distractors). Generation is not
timed; the timed part is what `sumo-drvpw diagnose LOG --vehicle prius3 --equation
drvpw_prius3 --out DIR --no-figures` does (read the log, trace, write the report).

    .venv/bin/python benchmarks/diagnose.py [--rows 1000000] [--stream yes]

Also runs the tracer without structural effects on the same log first and prints the ratio
(structural effects cost: N× the tracer without them). [--rows 500000,2000000 --profile 20]

With several sizes it prints the time ratio against the row ratio (linear: equal); with
--profile the functions with the most own time, to find what grows faster than the rows.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd


def build(rows: int, path: Path) -> None:
    import sumo_drvpw.synth.effects as E
    from sumo_drvpw.synth.track import Noise

    base, _ = E.synth_trips(4, 30.0, seed=1, effects=[E.AuxLoad(), E.LogPower()],
                            noise=Noise(process_w=200.0, process_rel=0.01))
    reps = int(np.ceil(rows / len(base)))
    frames = []
    for r in range(reps):
        f = base.copy()
        f["trip_id"] = f["trip_id"] + f"-r{r}"
        frames.append(f)
    df = pd.concat(frames, ignore_index=True).iloc[:rows].copy()
    rng = np.random.default_rng(0)
    n = len(df)
    v = df["speed_mps"].to_numpy()
    extra = {}
    for i in range(6):
        extra[f"walk_{i}"] = np.cumsum(rng.normal(0, 0.05, n))
    for i in range(6):
        extra[f"noise_{i}"] = rng.normal(0, 1, n)
    for i in range(3):
        extra[f"speedish_{i}"] = 40 + (0.5 + i) * v + rng.normal(0, 5, n)
    for i in range(3):
        extra[f"flag_{i}"] = rng.random(n) < 0.3
    for k, col in extra.items():
        df[k] = col
    keep_extra = ["ac_power_w", "ac_on"] + list(extra)
    assert len(keep_extra) == 20
    drop = [c for c in ("gps_elevation_m", "imu_accel_mps2", "heading_deg", "engine_on", "ev_mode", "phase")
            if c in df]
    df = df.drop(columns=drop)
    df.to_parquet(path)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", default="1000000",
                    help="rows, or a comma list of sizes to see how time grows (e.g. 500000,2000000)")
    ap.add_argument("--stream", choices=("no", "yes"), default="no",
                    help="trace in memory (no, default) or streamed in bounded memory (yes): "
                         "sumo_drvpw.fit.diagnose.stream_run, the same numbers")
    ap.add_argument("--profile", type=int, default=0, metavar="N",
                    help="also print the N functions with the most own time (cProfile) per size")
    a = ap.parse_args()
    from sumo_drvpw.data.log import read_log
    from sumo_drvpw.cli.diagnose import run
    from sumo_drvpw.fit.diagnose import DiagnoseOptions

    times = {}
    for rows in (int(float(r)) for r in a.rows.split(",")):
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "bench.parquet"
            build(rows, path)
            n_extra = len(read_log([path]).extra_columns)
            prof = None
            if a.profile:
                import cProfile

                prof = cProfile.Profile()
                prof.enable()
            # baseline in the same run: the tracer without structural effects (lag search,
            # regimes, air density, accelerometer grade)
            t0 = time.perf_counter()
            run([path], "prius3", "drvpw_prius3", Path(tmp) / "out0", DiagnoseOptions(structural=False),
                figures=False, stream=a.stream)
            dt0 = time.perf_counter() - t0
            t0 = time.perf_counter()
            res = run([path], "prius3", "drvpw_prius3", Path(tmp) / "out", DiagnoseOptions(),
                      figures=False, progress=print, stream=a.stream)
            dt = time.perf_counter() - t0
            if prof is not None:
                import pstats

                prof.disable()
                pstats.Stats(prof).sort_stats("tottime").print_stats(a.profile)
        r = res.report
        times[rows] = dt
        print(f"rows={rows} extra_columns_in_log={n_extra} findings={[f['term'] for f in r['findings']]} "
              f"rmse {r['baseline']['metrics']['rmse_w']:.1f} -> {r['final']['metrics']['rmse_w']:.1f} W")
        print(f"seconds={dt:.1f} rows_per_s={rows / dt:.0f} candidates_scored={res.n_candidates_scored}")
        print(f"structural effects cost: {dt / dt0:.2f}x the tracer without them ({dt0:.1f} s, same run)")
        from sumo_drvpw.cli.diagnose import resource_line

        print(resource_line(res), "(peak RSS of this process: both runs and the generator)")
    if len(times) > 1:
        (r0, t0), (r1, t1) = min(times.items()), max(times.items())
        print(f"time ratio {t1 / t0:.2f} for {r1 / r0:.2f}x the rows (linear: equal)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
