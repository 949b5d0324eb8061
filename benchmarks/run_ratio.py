"""A whole ``sumo-drvpw run`` against plain ``sumo`` on the same SUMO config: the wall time of
each as a fresh process, interleaved (the same machine load for both), medians of
``--repeats``, and their ratio.

Unlike benchmarks/loop_overhead.py (the stepping loop alone at 1,000–5,000 vehicles), this is
what a user waits for, start to end: the imports, the network's load, SUMO's start, the
loop, the outputs. With a few vehicles on a large network the plug-in's fixed costs — per
step and per run — dominate, so by default the scenario is that case (generated into a
temporary directory): a ``--grid``² netgenerate grid (default 26², 200-m blocks, 2 lanes each way, no
elevation) with ``--vehicles`` cars, each circling a rectangle of blocks for the whole run,
``--end`` s at 1-s steps. ``--config`` times a given SUMO config instead (e.g. DLR-TS
sumo-scenarios' port_lübeck ``port_tutorial.sumocfg``: a bare config, every vehicle by the
built-in equations of its vClass).

    .venv/bin/python benchmarks/run_ratio.py --repeats 3
    .venv/bin/python benchmarks/run_ratio.py --config path/to/x.sumocfg --repeats 3

Both commands: ``sumo -c CFG --no-step-log`` and ``sumo-drvpw run CFG --out DIR --no-figures
--no-progress``, wall and CPU time (user + system) of each; the plug-in's network table is
kept between runs (sim/net_cache.py; ``SUMO_DRVPW_CACHE=off`` times every run's full load —
the first repeat is a cold one unless the cache already holds the network). The last line is
``run_ratio=<plug-in / sumo>`` of the wall-time medians. Target: ≤ 3.0 on the default
scenario. Not part of the test suite.

``--baseline PATH`` times another ``sumo-drvpw`` executable (e.g. an earlier commit's checkout
in its own virtual environment) in the same rounds — sumo, baseline, this one, in turn — so a
change is measured before and after under the same machine load; its line is
``baseline_ratio=<baseline / sumo>``.
"""

from __future__ import annotations

import argparse
import os
import random
import resource
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
BLOCK = 200.0


def build(work: Path, grid: int, vehicles: int, end: float, seed: int = 1) -> Path:
    """The default scenario: grid network, ``vehicles`` cars circling, a SUMO config."""
    import sumolib

    net = work / "grid.net.xml"
    subprocess.run([sumolib.checkBinary("netgenerate"), "--grid", "--grid.number", str(grid),
                    "--grid.length", str(BLOCK), "--default.lanenumber", "2", "--no-turnarounds", "true",
                    "--default-junction-type", "traffic_light", "-o", str(net), "--no-warnings"],
                   check=True, capture_output=True)
    rng = random.Random(seed)
    node = lambda i, j: f"{chr(ord('A') + i)}{j}"  # noqa: E731  (netgenerate's names up to 26 columns)
    lines = ['<routes>', '  <vType id="car" vClass="passenger" mass="1625" emissionClass="HBEFA4/PC_petrol_Euro-4"/>']
    for k in range(vehicles):
        i0, i1 = sorted(rng.sample(range(grid), 2))
        j0, j1 = sorted(rng.sample(range(grid), 2))
        pts = ([(i, j0) for i in range(i0, i1)] + [(i1, j) for j in range(j0, j1)]
               + [(i, j1) for i in range(i1, i0, -1)] + [(i0, j) for j in range(j1, j0, -1)])
        nodes = pts + [pts[0]]
        edges = " ".join(f"{node(*a)}{node(*b)}" for a, b in zip(nodes[:-1], nodes[1:]))
        lines.append(f'  <vehicle id="v{k}" type="car" depart="{k}" departSpeed="0">'
                     f'<route edges="{edges}" repeat="{int(end // 60) + 1}"/></vehicle>')
    lines.append("</routes>")
    (work / "cars.rou.xml").write_text("\n".join(lines), encoding="utf-8")
    cfg = work / "grid.sumocfg"
    cfg.write_text(f"""<configuration>
    <input><net-file value="grid.net.xml"/><route-files value="cars.rou.xml"/></input>
    <time><begin value="0"/><end value="{end:g}"/><step-length value="1"/></time>
    <processing><time-to-teleport value="-1"/></processing>
    <random_number><seed value="1"/></random_number>
</configuration>
""", encoding="utf-8")
    return cfg


def timed(cmd: list[str]) -> tuple[float, float]:
    """Wall time and CPU time (user + system) of a child process [s]."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return wall, (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", help="a SUMO config to time (default: the generated grid)")
    ap.add_argument("--grid", type=int, default=26, choices=range(3, 27), metavar="3…26",
                    help="junctions per side of the grid")
    ap.add_argument("--vehicles", type=int, default=5)
    ap.add_argument("--end", type=float, default=3600.0, help="end of the generated scenario [s]")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--baseline", metavar="PATH", help="another sumo-drvpw executable timed in the same rounds")
    a = ap.parse_args(argv)
    import sumo
    import sumolib

    env = dict(os.environ, SUMO_HOME=sumo.SUMO_HOME)
    os.environ.update(env)
    sumo_bin = sumolib.checkBinary("sumo")
    cli = str(Path(sys.executable).with_name("sumo-drvpw"))
    times: dict[str, list[tuple[float, float]]] = {"sumo": [], **({"baseline": []} if a.baseline else {}),
                                                   "plugin": []}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        cfg = Path(a.config).resolve() if a.config else build(work, a.grid, a.vehicles, a.end)
        out = work / "out"
        for _ in range(a.repeats):
            times["sumo"].append(timed([sumo_bin, "-c", str(cfg), "--no-step-log", "true",
                                        "--duration-log.statistics", "false", "-v", "false"]))
            for name, exe in (("baseline", a.baseline), ("plugin", cli)):
                if exe:
                    shutil.rmtree(out, ignore_errors=True)
                    times[name].append(timed([exe, "run", str(cfg), "--out", str(out), "--no-figures",
                                              "--no-progress"]))
    med = {k: statistics.median(w for w, _ in v) for k, v in times.items()}
    cpu = {k: statistics.median(c for _, c in v) for k, v in times.items()}
    what = cfg.name if a.config else f"grid {a.grid}x{a.grid}, {a.vehicles} cars, {a.end:g} s"
    print(f"scenario: {what}; load average {os.getloadavg()[0]:.1f}; network cache: "
          f"{os.environ.get('SUMO_DRVPW_CACHE', 'default folder')}")
    for k, v in times.items():
        print(f"{k:7s} wall median {med[k]:.2f} s {[round(w, 2) for w, _ in v]}, "
              f"CPU median {cpu[k]:.2f} s {[round(c, 2) for _, c in v]}")
    if a.baseline:
        print(f"CPU ratio baseline / sumo: {cpu['baseline'] / cpu['sumo']:.2f}")
        print(f"baseline_ratio={med['baseline'] / med['sumo']:.2f}")
    print(f"CPU ratio plug-in / sumo: {cpu['plugin'] / cpu['sumo']:.2f}")
    print(f"run_ratio={med['plugin'] / med['sumo']:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
