"""Loop overhead of the plug-in: bare libsumo stepping vs the plug-in with four equations.

Usage: .venv/bin/python benchmarks/loop_overhead.py [--sizes 1000 5000] [--steps 200]
       [--repeats 3] [--connection libsumo|traci]

``--connection traci`` runs SUMO as a server and every variant through the traci client
(the plug-in inside a user's TraCI script): each getter is a socket round trip, so the
plug-in reads every vehicle from one context subscription on the simulation.

Scenario (generated into a temporary directory, same for every variant): a 12 × 12
traffic-light grid (netgenerate, 300 m blocks, 2 lanes) with N cars each circling a
random rectangle of blocks for ever (route ``repeat``), so N vehicles are in the network
at once. The network is warmed up once per size and saved with ``simulation.saveState``;
every timed run loads that state and steps the same ``--steps`` steps:

- ``bare``: ``simulationStep`` only;
- ``plugin``: the sumo-drvpw loop with default settings: 4 equations, wind 3 m/s, robust
  slope, ledger; per vehicle and step only ``getSpeed`` is called, acceleration is
  (v_t − v_t−1)/Δt, lane and position are tracked (read at edge ends and every 25 steps),
  heading and front-to-back slope come from the lane shape;
- ``plugin_getangle``: the defaults but the wind projected on ``vehicle.getAngle``
  (``wind.heading = "getangle"``, one getter more per vehicle and step);
- ``plugin_getters``: the defaults but everything read from SUMO every step
  (``acceleration = "getter"``, ``positions = "getter"``, ``slope.reference =
  "getslope"``, ``wind.heading = "getangle"``: six getters per vehicle and step);
- ``plugin_radial``: the defaults plus a fifth equation with SUMO's radial drag (the term
  ``radial``, as ``vtype_energy`` books a vType's radialDragCoefficient): ``getAngle`` read
  per vehicle and step, the yaw rate from its change;
- ``emissions``: bare stepping with SUMO's own ``--device.emissions.probability 1``.

Prints median wall times of ``--repeats`` runs (variants interleaved), then the ratios;
the final line is ``overhead_ratio=<plugin / bare at the largest size>`` (target ≤ 1.25).
Not part of the test suite.
"""

from __future__ import annotations

import argparse
import os
import random
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

GRID, BLOCK = 12, 300.0


def _equations():
    from sumo_drvpw.model.equations import Equation, load_equation
    from sumo_drvpw.errors import UserError

    out = []
    for name in ("vsp_ldv1999", "vsp_prius3spec", "drvpw_prius3", "drvpw_prius3_var2"):
        try:
            out.append(load_equation(name))
        except UserError:  # built-in not written yet: a stand-in of the same shape
            out.append(Equation(name, {"acc": 1.0, "grade": 1.0, "aero": 0.9, "roll": 0.013}))
    return out


def build_network(work: Path) -> Path:
    import sumo
    import sumolib

    net = work / "grid.net.xml"
    subprocess.run([sumolib.checkBinary("netgenerate"), "--grid", "--grid.number", str(GRID),
                    "--grid.length", str(BLOCK), "--default.lanenumber", "2",
                    "--default.speed", "13.89", "--default-junction-type", "traffic_light",
                    "--no-turnarounds", "true", "-o", str(net)],
                   check=True, env=dict(os.environ, SUMO_HOME=sumo.SUMO_HOME),
                   stdout=subprocess.DEVNULL)
    return net


def _node(i, j):
    return f"{chr(ord('A') + i)}{j}"


def build_routes(work: Path, n: int, seed: int = 1) -> Path:
    """n cars, each circling a random rectangle of blocks (closed route, repeated)."""
    rng = random.Random(seed)
    lines = ['<routes>', '  <vType id="car" mass="1625" sigma="0.5" emissionClass="HBEFA4/PC_petrol_Euro-4"/>']
    for k in range(n):
        i0, i1 = sorted(rng.sample(range(GRID), 2))
        j0, j1 = sorted(rng.sample(range(GRID), 2))
        pts = ([(i, j0) for i in range(i0, i1)] + [(i1, j) for j in range(j0, j1)]
               + [(i, j1) for i in range(i1, i0, -1)] + [(i0, j) for j in range(j1, j0, -1)])
        if rng.random() < 0.5:
            pts = pts[::-1]
        nodes = pts + [pts[0]]
        edges = [f"{_node(*a)}{_node(*b)}" for a, b in zip(nodes[:-1], nodes[1:])]
        rot = rng.randrange(len(edges))
        edges = edges[rot:] + edges[:rot]
        lines.append(f'  <vehicle id="v{k}" type="car" depart="{k * 60.0 / n:.3f}" '
                     f'departPos="random_free" departLane="free" departSpeed="0">'
                     f'<route edges="{" ".join(edges)}" repeat="8"/></vehicle>')
    lines.append("</routes>")
    p = work / f"cars{n}.rou.xml"
    p.write_text("\n".join(lines), encoding="utf-8")
    return p


def _start(net, routes, extra):
    import sumolib

    conn = __import__(_start.connection)  # libsumo, or the traci client of a SUMO server
    conn.start([sumolib.checkBinary("sumo"), "-n", str(net), "-r", str(routes),
                "--no-step-log", "true", "--no-warnings", "true", "--step-length", "0.5",
                "--time-to-teleport", "-1", "--seed", "1", *extra])
    return conn


_start.connection = "libsumo"


def warm_up(net, routes, state: Path, warm_s: float) -> int:
    conn = _start(net, routes, [])
    try:
        conn.simulationStep(warm_s)
        n = conn.vehicle.getIDCount()
        conn.simulation.saveState(str(state))
    finally:
        conn.close()
    return n


class _Resolver:
    """Every vType a 1625 kg passenger car; with ``skip_person`` like the run's resolver,
    so the loop also makes its per-step person-departure call."""

    def __init__(self, app):
        self.app = app

    def __call__(self, vt, vid):
        return (1625.0, self.app, True, "passenger")

    def skip_person(self, vt):
        pass


def timed(variant: str, net, routes, state, steps: int, eqs) -> float:
    from sumo_drvpw.sim.ledger import EquationSet, Ledger
    from sumo_drvpw.sim.loop import Physics
    from sumo_drvpw.sim.stepping import run_loop
    from sumo_drvpw.sim.network import load_network
    from sumo_drvpw.sim.scenario import RoadClassRule

    extra = ["--load-state", str(state)]
    if variant == "emissions":
        extra += ["--device.emissions.probability", "1"]
    if variant.startswith("plugin"):
        table = timed.nets.get(str(net)) or load_network(Path(net), RoadClassRule())
        timed.nets[str(net)] = table
    conn = _start(net, routes, extra)
    try:
        t_begin = conn.simulation.getTime()
        end = t_begin + steps * conn.simulation.getDeltaT()
        if variant.startswith("plugin"):
            if variant == "plugin_radial":
                from sumo_drvpw.model.equations import Equation

                eqs = [*eqs, Equation("radial", {"acc": 1.0, "aero": 0.5, "m_v1": 0.1, "radial": 0.1})]
            eqset = EquationSet(eqs)
            led = Ledger(len(table.edge_ids), len(eqs), capacity=8192)
            app = np.ones(len(eqs))
            t0 = time.perf_counter()
            getters = {"plugin_getters": dict(slope_reference="getslope", acceleration="getter",
                                              heading="getangle", positions="getter"),
                       "plugin_getangle": dict(heading="getangle")}.get(variant, {})
            phys = Physics(wind_speed=3.0, wind_from_deg=270.0, **getters)
            run_loop(conn, table, eqset, led, phys, _Resolver(app), end=end,
                     use_subscriptions=_start.connection == "traci")
            dt = time.perf_counter() - t0
            assert led.samples > 0
            timed.reads[variant] = (led.position_reads / led.samples, led.position_mismatches)
        else:
            t0 = time.perf_counter()
            for _ in range(steps):
                conn.simulationStep()
            dt = time.perf_counter() - t0
    finally:
        conn.close()
    return dt


timed.nets = {}
timed.reads = {}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=int, nargs="+", default=[1000, 5000])
    ap.add_argument("--steps", type=int, default=200)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--warm", type=float, default=120.0, help="warm-up [s] before the state")
    ap.add_argument("--connection", choices=("libsumo", "traci"), default="libsumo")
    args = ap.parse_args(argv)
    _start.connection = args.connection
    import sumo

    os.environ.setdefault("SUMO_HOME", sumo.SUMO_HOME)
    eqs = _equations()
    results = {}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        net = build_network(work)
        for n in args.sizes:
            routes = build_routes(work, n)
            state = work / f"state{n}.xml.gz"
            running = warm_up(net, routes, state, args.warm)
            times = {"bare": [], "plugin": [], "plugin_getangle": [], "plugin_radial": [],
                     "plugin_getters": [], "emissions": []}
            for _ in range(args.repeats):
                for variant in times:
                    times[variant].append(timed(variant, net, routes, state, args.steps, eqs))
            med = {k: statistics.median(v) for k, v in times.items()}
            results[n] = (running, med)
            share, bad = timed.reads["plugin"]
            print(f"N={n} plugin: lane/position read for {100 * share:.1f} % of vehicle-steps, "
                  f"{bad} disagreements at full reads", flush=True)
            print(f"N={n} (running at state: {running}) steps={args.steps}: " + ", ".join(
                f"{k} {v:.3f} s ({1e3 * v / args.steps:.2f} ms/step)" for k, v in med.items()),
                flush=True)
    print(f"connection: {args.connection}; equations: {', '.join(e.name for e in eqs)}")
    for n, (running, med) in results.items():
        print(f"ratios N={n}: plugin/bare={med['plugin'] / med['bare']:.3f} "
              f"plugin_getangle/bare={med['plugin_getangle'] / med['bare']:.3f} "
              f"plugin_radial/plugin={med['plugin_radial'] / med['plugin']:.3f} "
              f"plugin_getters/bare={med['plugin_getters'] / med['bare']:.3f} "
              f"emissions/bare={med['emissions'] / med['bare']:.3f}")
    big = max(results)
    print(f"overhead_ratio={results[big][1]['plugin'] / results[big][1]['bare']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
