"""Benchmark: calibrate, compare (and diagnose) at fleet scale through the CLI (issue #14).

Generates canonical drive logs chunk by chunk on disk (8 Hz trips of 30 min: speed from a
smoothed random walk with stops, grade from a random road profile, a mass per trip, and
``power_w`` = drvpw_prius3 of the generator's own acceleration plus noise; the reader then
derives acceleration itself). The generator holds one chunk of whole trips (~1 M rows)
at a time; files of at most ``--file-rows`` rows, row groups of about 1 M rows, in a
temporary folder under ``--tmp`` that is deleted afterwards.

Each size is run through the CLI in a child process; time is wall-clock (the median of
``--repeat`` runs), CPU time is user + system of the child (on a shared machine the fairer
figure: wall time grows with other people's load), peak RSS is the
child's own (``os.wait4`` rusage; with ``--engine dask`` the worker processes are not in
it and are reported separately by Dask's own memory limits, not here).

    .venv/bin/python benchmarks/scale.py [--sizes 1e6,1e7] [--dask-workers 2] [--diagnose-max 1e6]

Targets (issue #14, this 2-core machine): peak RSS ≤ 1.5 GB at every size (flat in rows),
calibrate ≥ 2 M samples/s, diagnose ≥ 0.5 M samples/s, and the Dask run's coefficients
equal to the local run's. Last line:
``calibrate_peak_mb_100M=<n> calibrate_rows_per_s=<n> diagnose_peak_mb_100M=<n>`` (n/a when
that size or command was not run).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from pathlib import Path

import numpy as np

HZ = 8.0
TRIP_S = 1800.0
CHUNK_ROWS = 1_000_000
EXE = [sys.executable, "-m", "sumo_drvpw"]


def _trips(rng, n_trips: int, first_id: int):
    """Columns of ``n_trips`` whole trips (vectorized over all samples of the chunk)."""
    from sumo_drvpw.model.equations import load_equation
    from sumo_drvpw.model.terms import Inputs

    m = int(TRIP_S * HZ)
    n = n_trips * m
    dt = 1.0 / HZ
    # speed: a random walk of the target speed, smoothed, with stops (clipped at 0)
    target = np.cumsum(rng.normal(0.0, 0.35, (n_trips, m)), axis=1) + rng.uniform(8, 25, (n_trips, 1))
    k = int(4 * HZ)
    kern = np.ones(k) / k
    v = np.apply_along_axis(lambda r: np.convolve(r, kern, mode="same"), 1, target)
    v = np.clip(v, 0.0, 38.0)
    a = np.gradient(v, dt, axis=1)
    theta = np.apply_along_axis(lambda r: np.convolve(r, np.ones(400) / 400, mode="same"), 1,
                                rng.normal(0, 0.6, (n_trips, m))) * 0.5
    mass = np.repeat(rng.uniform(1450, 1750, n_trips), m)
    x = Inputs(v=v.ravel(), a=a.ravel(), theta=theta.ravel(), wind=np.zeros(n), mass=mass,
               rho=np.full(n, 1.2041))
    p = load_equation("drvpw_prius3").power(x) + rng.normal(0, 1500.0, n)
    ids = np.repeat(np.array([f"trip{first_id + i:07d}" for i in range(n_trips)]), m)
    t = np.tile(np.arange(m) * dt, n_trips)
    return {"trip_id": ids, "time_s": t, "speed_mps": x.v, "grade_rad": x.theta,
            "mass_kg": mass, "power_w": p}


def generate(folder: Path, rows: int, file_rows: int, seed: int = 0) -> int:
    """Write about ``rows`` samples as whole trips; returns the rows written."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    rng = np.random.default_rng(seed)
    per_trip = int(TRIP_S * HZ)
    trips_per_chunk = max(CHUNK_ROWS // per_trip, 1)
    total_trips = max(int(round(rows / per_trip)), 1)
    done = f = 0
    writer, in_file = None, 0
    while done < total_trips:
        nt = min(trips_per_chunk, total_trips - done)
        table = pa.table(_trips(rng, nt, done))
        if writer is None or in_file + table.num_rows > file_rows:
            if writer is not None:
                writer.close()
            writer = pq.ParquetWriter(folder / f"fleet_{f:04d}.parquet", table.schema)
            f += 1
            in_file = 0
        writer.write_table(table, row_group_size=CHUNK_ROWS)
        in_file += table.num_rows
        done += nt
    writer.close()
    return total_trips * per_trip


def _timed(argv, repeat: int = 1):
    """Median over ``repeat`` runs of (wall [s], peak RSS [MB], engine line, CPU [s], load)."""
    runs = sorted((_timed_once(argv) for _ in range(repeat)), key=lambda r: r[0])
    return runs[len(runs) // 2]


def _timed_once(argv):
    """Run and measure through os.wait4 (rusage of this one child): wall time, peak RSS,
    the engine's summary line, CPU time (user + system) and the 1-min load before."""
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    with open(os.devnull, "w") as devnull, tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen(EXE + argv, stdout=devnull, stderr=err)
        _, status, ru = os.wait4(proc.pid, 0)
        proc.returncode = os.waitstatus_to_exitcode(status)
        wall = time.perf_counter() - t0
        err.seek(0)
        tail = err.read()
    if proc.returncode != 0:
        raise SystemExit(f"sumo-drvpw {' '.join(argv)} failed ({proc.returncode}):\n{tail[-2000:]}")
    lines = [ln for ln in tail.splitlines() if "engine:" in ln or ln.startswith("diagnose:")]
    return wall, ru.ru_maxrss / 1024.0, (lines[-1] if lines else ""), ru.ru_utime + ru.ru_stime, load


def _coefs(path: Path) -> dict:
    return tomllib.loads(path.read_text())["terms"]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", default="1e6,1e7", help="comma list of sample counts (e.g. 1e6,1e7,1e8)")
    ap.add_argument("--file-rows", type=float, default=1e7, help="rows per Parquet file")
    ap.add_argument("--dask-workers", type=int, default=2, help="local Dask cluster at the largest size (0: skip)")
    ap.add_argument("--diagnose-max", type=float, default=1e6,
                    help="largest size diagnose (in memory) is run at")
    ap.add_argument("--tmp", default=tempfile.gettempdir(), help="where the logs are generated")
    ap.add_argument("--commands", default="calibrate,compare,diagnose",
                    help="which commands to run (comma list)")
    ap.add_argument("--repeat", type=int, default=1,
                    help="runs per command and size; the median wall time's run is reported")
    args = ap.parse_args()
    sizes = [int(float(s)) for s in args.sizes.split(",")]
    results = {}
    for size in sizes:
        top = Path(tempfile.mkdtemp(prefix="sumo_drvpw_scale_", dir=args.tmp))
        logs, d = top / "logs", top / "out"
        logs.mkdir()
        d.mkdir()
        try:
            t0 = time.perf_counter()
            rows = generate(logs, size, int(args.file_rows))
            gen_s = time.perf_counter() - t0
            mb = sum(f.stat().st_size for f in logs.iterdir()) / 1e6
            print(f"\n{rows:,} samples ({mb:,.0f} MB Parquet in {len(list(logs.iterdir()))} files, "
                  f"generated in {gen_s:.0f} s)", flush=True)
            r = {}
            cal = d / "cal_local.toml"
            cmds = args.commands.split(",")
            if "calibrate" in cmds:
                r["calibrate"] = _timed(["calibrate", str(logs), "--candidates", "indt-var-2",
                                         "--out", str(cal)], args.repeat)
            if "compare" in cmds:
                r["compare"] = _timed(["compare", str(logs), "--equation", "drvpw_prius3",
                                       "--equation", "vsp_ldv1999", "--out", str(d / "cmp")],
                                      args.repeat)
            if "diagnose" in cmds and rows <= args.diagnose_max:
                r["diagnose"] = _timed(["diagnose", str(logs), "--equation", "drvpw_prius3",
                                        "--out", str(d / "diag"), "--no-figures", "--quiet"])
            if args.dask_workers and size == max(sizes) and "calibrate" in cmds:
                cal_d = d / "cal_dask.toml"
                r["calibrate (dask)"] = _timed(["calibrate", str(logs), "--candidates", "indt-var-2",
                                                "--out", str(cal_d), "--engine", "dask",
                                                "--workers", str(args.dask_workers)])
                a, b = _coefs(cal), _coefs(cal_d)
                diff = max(abs(b[k] / a[k] - 1.0) for k in a) if set(a) == set(b) else float("inf")
                r["dask_equal"] = (set(a) == set(b) and diff <= 1e-9, diff)
            for cmd, val in r.items():
                if cmd == "dask_equal":
                    print(f"  dask coefficients equal to local: {val[0]} (max relative difference {val[1]:.1e})")
                    continue
                wall, peak, line, cpu, load = val
                print(f"  {cmd:<18} {wall:8.1f} s  {rows / wall / 1e6:6.2f} M rows/s  peak RSS {peak:7.0f} MB"
                      f"  CPU {cpu:6.1f} s ({rows / cpu / 1e6:5.2f} M rows per CPU-s)  load {load:.1f}",
                      flush=True)
                if cmd == "diagnose" and line:       # the tracer's own line: streamed, passes, on disk
                    print(f"    {line}", flush=True)
            results[rows] = r
        finally:
            shutil.rmtree(top, ignore_errors=True)
    big = {k: v for k, v in results.items() if k >= 99_000_000}
    b = next(iter(big.values()), None)
    largest = max(results)
    cal_rate = largest / results[largest]["calibrate"][0] if "calibrate" in results[largest] else float("nan")
    f = lambda r, k: f"{r[k][1]:.0f}" if r and k in r else "n/a"  # noqa: E731
    print(f"calibrate_peak_mb_100M={f(b, 'calibrate')} calibrate_rows_per_s={cal_rate:.0f} "
          f"diagnose_peak_mb_100M={f(b, 'diagnose')}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
