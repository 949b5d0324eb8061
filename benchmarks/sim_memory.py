"""Peak memory of a SUMO run against its number of trips: the bounded ledger (#14).

Usage: .venv/bin/python benchmarks/sim_memory.py [--trips 2000 20000] [--equations 4]
       [--keep]

Scenario (generated into a temporary directory): the built-in city grid with one-edge
trips, a flow on each of its 80 edges departing every 8 s (10 trips/s, all inserted on
time), so about the same vehicles run at once (≈ 150) whatever the number of trips; only
the simulated time grows with ``--trips``. Each size runs ``run_scenario`` (outputs written, figures off) in a fresh
process and reports that process's peak RSS (``ru_maxrss``), the most vehicles the
ledger held at once, and the wall time. ``--keep`` also runs the old unbounded ledger
(``keep_vehicles=True``) for comparison. Its last line:
``peak_rss_ratio=<largest / smallest trips, bounded> held_peak=<n> trips=<largest>``
(target: ratio close to 1, e.g. ≤ 1.15). Not part of the test suite.
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

REPO = Path(__file__).resolve().parent.parent
NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"
PERIOD_S = 8.0
EQUATIONS = ["vsp_ldv1999", "vsp_prius3spec", "drvpw_prius3", "epa_prius3",
             "drvpw_prius3_var2", "moves_passenger_car"]


def scenario(work: Path, trips: int, n_eq: int) -> Path:
    """A scenario of ``trips`` one-edge trips: a flow on every edge of the city grid, one
    departure each ``PERIOD_S`` s (SUMO inserts them all on time: no insertion backlog,
    which would grow SUMO's own memory with the trips)."""
    import sumolib

    edges = [e.getID() for e in sumolib.net.readNet(str(NET)).getEdges()]
    per_flow = -(-trips // len(edges))
    flows = "\n".join(
        f'  <flow id="f{k}" type="car" from="{e}" to="{e}" begin="0" number="{per_flow}" '
        f'period="{PERIOD_S}" departSpeed="max"/>' for k, e in enumerate(edges))
    (work / "r.rou.xml").write_text(
        f'<routes>\n  <vType id="car" vClass="passenger" mass="1500"/>\n{flows}\n</routes>\n',
        encoding="utf-8")
    eqs = (EQUATIONS * 4)[:n_eq]
    names = [f'"{e}"' for e in eqs]
    path = work / f"s{trips}.toml"
    path.write_text(
        f'equations = [{", ".join(dict.fromkeys(names))}]\n[sumo]\nnet = "{NET}"\n'
        'routes = ["r.rou.xml"]\nstep_length = 0.5\noptions = ["--no-warnings", "true"]\n'
        '[outputs]\nfigures = false\nedgedata = true\n', encoding="utf-8")
    return path


def child(path: str, out: str, keep: bool) -> None:
    from sumo_drvpw.sim import run_scenario

    t0 = time.perf_counter()
    res = run_scenario(path, out, keep_vehicles=keep, progress=False)
    rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(json.dumps({"vehicles": res["vehicles"], "held_peak": res["vehicles_in_memory_peak"],
                      "peak_rss_mb": rss, "seconds": time.perf_counter() - t0}))


def measure(path: Path, out: Path, keep: bool) -> dict:
    r = subprocess.run([sys.executable, __file__, "--child", str(path), str(out)]
                       + (["--keep"] if keep else []), capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(r.stderr)
    return json.loads(r.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trips", type=int, nargs="+", default=[2000, 20000])
    ap.add_argument("--equations", type=int, default=4)
    ap.add_argument("--keep", action="store_true", help="also the unbounded ledger")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(args.child[0], args.child[1], args.keep)
        return 0
    rows = {}
    with tempfile.TemporaryDirectory(prefix="drvpw-simmem-") as d:
        work = Path(d)
        for n in args.trips:
            path = scenario(work, n, args.equations)
            for keep in ([False, True] if args.keep else [False]):
                label = "unbounded" if keep else "bounded"
                r = measure(path, work / f"out-{n}-{label}", keep)
                rows[(n, label)] = r
                print(f"trips={n:>7} {label:>9}: {r['vehicles']} vehicles, held at most "
                      f"{r['held_peak']}, peak RSS {r['peak_rss_mb']:.0f} MB, {r['seconds']:.1f} s",
                      flush=True)
    lo, hi = min(args.trips), max(args.trips)
    ratio = rows[(hi, "bounded")]["peak_rss_mb"] / rows[(lo, "bounded")]["peak_rss_mb"]
    if args.keep:
        ku = rows[(hi, "unbounded")]["peak_rss_mb"] / rows[(lo, "unbounded")]["peak_rss_mb"]
        print(f"unbounded: peak RSS ratio {hi}/{lo} trips = {ku:.3f}")
    print(f"peak_rss_ratio={ratio:.3f} held_peak={rows[(hi, 'bounded')]['held_peak']} trips={hi}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
