"""A step's chain calls at a few vehicles, this checkout against another: SUMO's MMPEVEM motor
and battery (model/mmpevem.SumoMotor.battery), a chain booking some of the step's vehicles
(model/mmpevem.evaluate_where), an efficiency table (model/chain_values.Table), a step's whole
booking of a bare SUMO config's chains (sim/chain.ChainLedger.book: its petrol cars, each on its
own edge), a whole second's 1-Hz samples of them (sim/dynamics.Dynamics.add; and taken from their
speeds, each with its two earlier samples, Dynamics.sample) and their driving
power per equation and category (sim/ledger.EquationSet.category_powers). Each is
timed in a fresh process of each checkout in turn (``--baseline PYTHON``: another checkout's
interpreter, its own package installed), ``--rounds`` times, the median per call of each and
their ratio; the values of both are compared bit for bit. Not part of the test suite.

    .venv/bin/python benchmarks/chain_calls.py --baseline ../base/.venv/bin/python --rounds 5
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time

CASES = ("mmpevem_battery", "evaluate_where", "table", "ledger_book", "dynamics_add", "dynamics_sample", "category_powers")


def _one(case: str, n: int, calls: int) -> dict:
    """Time ``calls`` calls of ``case`` on ``n`` vehicles in this process; its values' bytes."""
    import numpy as np

    rng = np.random.default_rng(1)
    p, v = rng.normal(0.0, 2e4, n), rng.uniform(0.0, 30.0, n)
    sig = {"accel_mps2": rng.normal(0.0, 1.0, n)}
    if case == "mmpevem_battery":
        from sumo_drvpw.model.mmpevem import mmpevem_equation

        mo = mmpevem_equation("x", {"maximumRecuperationPower": "40000"}, 1500.0, "x")[0].chain.motor
        aux = np.full(n, 300.0)
        f = lambda: mo.battery(p, v, sig, aux)  # noqa: E731
    elif case == "evaluate_where":
        from sumo_drvpw.model.equations import load_equation
        from sumo_drvpw.model.mmpevem import evaluate_where

        ch, sel = load_equation("epa_gasoline_car").chain, np.arange(n) % 2 == 0  # (some of them)
        sig = {**sig, "grade_rad": np.zeros(n), "ambient_c": np.full(n, 20.0)}
        f = lambda: evaluate_where(ch, sel, p, v, 0.5, sig, None)  # noqa: E731
    elif case == "ledger_book":
        from sumo_drvpw.model.equations import load_equation
        from sumo_drvpw.sim.chain import chain_ledger
        from sumo_drvpw.sim.scenario import CONFIG_EQUATIONS

        eqs = [load_equation(e) for e in CONFIG_EQUATIONS]
        led = chain_ledger(eqs, 1000)
        app = np.array([[1.0 if "passenger" in (e.vclasses or ()) and (e.chain is None or e.name == "epa_gasoline_car")
                         else 0.0 for e in eqs]] * n)  # (petrol cars: booked by the wheel equations and one chain)
        pe, vi, ei = rng.normal(0.0, 2e4, (n, len(eqs))), np.arange(n), np.arange(n) * 7
        f = lambda: {"q": led.book(vi, ei, v, 1.0, pe, app=app, accel=sig["accel_mps2"], v_mean=v,  # noqa: E731
                                   grade=np.zeros(n)), "edge": led.edge, "veh_time": led.veh_time}
    elif case == "category_powers":
        from sumo_drvpw.model.equations import load_equation
        from sumo_drvpw.model.terms import Inputs
        from sumo_drvpw.sim.ledger import EquationSet
        from sumo_drvpw.sim.scenario import CONFIG_EQUATIONS

        eqs = [load_equation(e) for e in CONFIG_EQUATIONS]
        es, x = EquationSet(eqs), Inputs(v, sig["accel_mps2"], np.zeros(n), np.zeros(n), np.full(n, 1500.0), np.full(n, 1.2))
        app = np.array([[1.0 if "passenger" in (e.vclasses or ()) and (e.chain is None or e.name == "epa_gasoline_car")
                         else 0.0 for e in eqs]] * n)
        f = lambda: {"pc": es.category_powers(x, app)}  # noqa: E731
    elif case == "dynamics_sample":
        from types import SimpleNamespace

        from sumo_drvpw.sim.dynamics import Dynamics

        d, clock = Dynamics(), iter(range(10 ** 9))  # (one sample a second: each vehicle's is added)
        led = SimpleNamespace(veh_keep=np.ones(n, bool), veh_cls=np.zeros(n, np.int64), class_list=["passenger"],
                              veh_rde=np.full((n, 4), np.nan))
        f = lambda: (d.sample(led, np.arange(n), (v + (t := next(clock)) % 7) % 16.0, float(t)),  # noqa: E731
                     {"hist": d.hist.get("passenger", np.zeros(1)), "rde": led.veh_rde})[1]
    elif case == "dynamics_add":
        from sumo_drvpw.sim.dynamics import Dynamics

        d, lab, a, ones = Dynamics(), np.full(n, "passenger", dtype=object), sig["accel_mps2"], np.ones(n)
        f = lambda: (d.add(lab, v % 16.0, a, ones), {"hist": d.hist["passenger"], "sums": d.sums["passenger"],  # noqa: E731
                                                     "acc": d.acc_hist["passenger"]})[1]
    else:
        from sumo_drvpw.model.chain_values import Table

        t = Table(rng.uniform(0.7, 0.95, (6, 9)), np.linspace(0, 40, 6), np.linspace(0, 8e4, 9))
        f = lambda: {"eta": t(v, p)}  # noqa: E731
    out = f()
    t0 = time.perf_counter()
    for _ in range(calls):
        f()
    us = (time.perf_counter() - t0) / calls * 1e6
    return {"us": us, "values": {k: np.asarray(x, float).tobytes().hex() for k, x in sorted(out.items())}}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--baseline", metavar="PYTHON", help="another checkout's python, timed in turn")
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--vehicles", type=int, default=5)
    ap.add_argument("--calls", type=int, default=2000)
    ap.add_argument("--child", choices=CASES, help=argparse.SUPPRESS)
    a = ap.parse_args(argv)
    if a.child:
        print(json.dumps(_one(a.child, a.vehicles, a.calls)))
        return 0
    pythons = {"this": sys.executable, **({"baseline": a.baseline} if a.baseline else {})}
    for case in CASES:
        times: dict[str, list[float]] = {k: [] for k in pythons}
        values = {}
        for _ in range(a.rounds):
            for name, py in pythons.items():
                r = subprocess.run([py, __file__, "--child", case, "--vehicles", str(a.vehicles), "--calls",
                                    str(a.calls)], capture_output=True, text=True, check=True, cwd="/")
                got = json.loads(r.stdout)
                times[name].append(got["us"])
                values.setdefault(name, got["values"])
        med = {k: statistics.median(x) for k, x in times.items()}
        line = f"{case:16s} " + ", ".join(f"{k} median {m:.1f} µs {[round(t, 1) for t in times[k]]}" for k, m in med.items())
        if a.baseline:
            same = values["this"] == values["baseline"]
            line += f"; ratio this / baseline {med['this'] / med['baseline']:.2f}; values {'bit-identical' if same else 'DIFFER'}"
        print(line)
    return 0


if __name__ == "__main__":
    sys.exit(main())
