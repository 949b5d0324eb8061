"""Peak memory of `fcd` against the length of the FCD file: the streamed replay (#14).

Usage: .venv/bin/python benchmarks/fcd_memory.py [--trips 2000 20000] [--format parquet|xml]
       [--whole] [--chunk-rows N]

Data: a real SUMO run per size of the scenario of ``benchmarks/sim_memory.py`` (the
built-in city grid, a flow on each of its 80 edges departing every 8 s: about the same
≈ 150 vehicles at once whatever the trips; only the simulated time, hence the FCD's rows,
grows with ``--trips``), recording ``--fcd-output`` (Parquet by default, or XML). Each
size is booked by ``process_fcd`` (four equations, outputs written, figures off) in a
fresh process, which reports its peak RSS (``VmHWM`` of /proc/self/status: the process's
own high-water mark; ``ru_maxrss`` would carry over the parent's RSS at the fork, which ran
SUMO), the FCD rows and the wall time. ``--whole`` also runs the whole-file path (``chunk_rows=None``) for comparison.
Last line: ``peak_rss_ratio=<largest / smallest trips, streamed> rows=<largest>``
(target: flat, ≲ 1.1). Not part of the test suite.
"""

from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from sim_memory import scenario  # noqa: E402 (the same scenario as the live-run benchmark)


def record(work: Path, trips: int, fmt: str) -> tuple[Path, Path]:
    """The scenario of ``trips`` trips and its FCD, recorded by SUMO itself."""
    from sumo_drvpw.sim import run_scenario

    work.mkdir(parents=True, exist_ok=True)
    path = scenario(work, trips, 4)
    fcd = work / ("fcd.parquet" if fmt == "parquet" else "fcd.xml")
    run_scenario(path, None, progress=False, figures=False, equations=["vsp_ldv1999"],
                 options=["--fcd-output", str(fcd)]
                 + (["--precision", "6"] if fmt == "xml" else []))
    return path, fcd


def peak_rss_mb() -> float:
    """This process's peak resident memory [MB] since its exec (VmHWM; Linux)."""
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def child(path: str, fcd: str, out: str, chunk_rows: int | None) -> None:
    from sumo_drvpw.sim.fcd import process_fcd

    t0 = time.perf_counter()
    res = process_fcd(fcd, scenario=path, out_dir=out, chunk_rows=chunk_rows)
    rss = peak_rss_mb()
    print(json.dumps({"rows": res["source"]["rows"], "vehicles": res["vehicles"],
                      "held_peak": res["vehicles_in_memory_peak"], "peak_rss_mb": rss,
                      "seconds": time.perf_counter() - t0}))


def measure(path: Path, fcd: Path, out: Path, chunk_rows: int | None) -> dict:
    r = subprocess.run([sys.executable, __file__, "--child", str(path), str(fcd), str(out),
                        "--chunk-rows", str(chunk_rows or 0)], capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(r.stderr)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    from sumo_drvpw.sim.fcd_read import CHUNK_ROWS

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trips", type=int, nargs="+", default=[2000, 20000])
    ap.add_argument("--format", choices=("parquet", "xml"), default="parquet")
    ap.add_argument("--chunk-rows", type=int, default=CHUNK_ROWS,
                    help="rows per block of the streamed replay (0: the whole file)")
    ap.add_argument("--whole", action="store_true", help="also the whole-file path")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(*args.child, args.chunk_rows or None)
        return 0
    rows = {}
    with tempfile.TemporaryDirectory(prefix="drvpw-fcdmem-") as d:
        work = Path(d)
        for n in args.trips:
            t0 = time.perf_counter()
            path, fcd = record(work / str(n), n, args.format)
            print(f"trips={n:>7}: SUMO recorded {fcd.name} ({fcd.stat().st_size / 1e6:.1f} MB) "
                  f"in {time.perf_counter() - t0:.1f} s", flush=True)
            for label, chunk in [("streamed", args.chunk_rows)] + (
                    [("whole", None)] if args.whole else []):
                r = measure(path, fcd, work / f"out-{n}-{label}", chunk)
                rows[(n, label)] = r
                print(f"trips={n:>7} {label:>8}: {r['rows']:,} rows, {r['vehicles']} vehicles "
                      f"(held at most {r['held_peak']}), peak RSS {r['peak_rss_mb']:.0f} MB, "
                      f"{r['seconds']:.1f} s", flush=True)
    lo, hi = min(args.trips), max(args.trips)
    ratio = rows[(hi, "streamed")]["peak_rss_mb"] / rows[(lo, "streamed")]["peak_rss_mb"]
    if args.whole:
        w = rows[(hi, "whole")]["peak_rss_mb"] / rows[(lo, "whole")]["peak_rss_mb"]
        print(f"whole file: peak RSS ratio {hi}/{lo} trips = {w:.3f}")
    print(f"peak_rss_ratio={ratio:.3f} rows={rows[(hi, 'streamed')]['rows']} trips={hi}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
