"""Stepping SUMO and booking each step: :func:`step_until` drives a :class:`~sumo_drvpw.sim.loop.Stepper`
(the run, the FCD replay and a user's Accountant book through it), :func:`run_loop` builds one and steps.
"""

from __future__ import annotations

import sys
from typing import Callable

import numpy as np

from sumo_drvpw.sim.ledger import EquationSet, Ledger
from sumo_drvpw.sim.loop import Physics, Stepper
from sumo_drvpw.sim.network import Network
from sumo_drvpw.sim.sumo_start import signals_deferred


def run_loop(conn, net: Network, eqset: EquationSet, ledger: Ledger, physics: Physics,
             resolve: Callable[[str, str], tuple[float, np.ndarray, bool]],
             end: float | None = None, progress: bool = False, trace=None,
             use_subscriptions: bool = False) -> dict:
    """Step the simulation to ``end`` [s] (or until no vehicle is left) and book energies.

    Parameters: as :class:`Stepper` and :func:`step_until`.
    """
    stepper = Stepper(conn, net, eqset, ledger, physics, resolve, trace, use_subscriptions)
    return step_until(conn, stepper, end, progress)


def step_until(conn, stepper: Stepper, end: float | None = None, progress: bool = False,
               period: float | None = None, period_from: str = "outputs.period") -> dict:
    """Call ``simulationStep`` and book each step until ``end`` [s] (None: until
    ``getMinExpectedNumber`` is 0).

    Parameters
    ----------
    conn, stepper : the connection the :class:`Stepper` reads, and the stepper
    end : simulation end time [s]
    progress : tqdm progress bar on a TTY
    period : edgeData interval [s]: edge totals are kept every ``period`` from the first step's
        time (the run's begin), as SUMO's own edgeData intervals; ``period_from`` names where it
        was given, for the message when it is no whole number of steps

    Returns ``{"interrupted": bool, "end_time_s": t, "step_length_s": Δt,
    "step_method": "euler"|"ballistic"}``; Ctrl-C stops the loop cleanly so that every
    output of the partial run can still be written.
    """
    ledger, dt = stepper.ledger, stepper.dt
    if period and dt and (period < dt - 1e-9 or abs(period / dt - round(period / dt)) > 1e-6):
        from sumo_drvpw.errors import UserError

        raise UserError(f"{period_from}: edgeData period {period:g} s: an interval is a whole number of the run's {dt:g}-s "
                        f"steps (its edges' totals are kept at a step); give {max(1, round(period / dt)) * dt:g} s")
    interrupted = False
    bar, steps0 = None, ledger.steps
    if progress and sys.stderr.isatty():  # (no end: steps counted, no total)
        from tqdm import tqdm

        t0 = conn.simulation.getTime()
        bar = tqdm(total=None if end is None else max(0, int(round((end - t0) / dt))), unit="step",
                   file=sys.stderr)
    next_cut = None
    if period:
        t0 = conn.simulation.getTime()
        next_cut = t0 + period  # SUMO's meandata intervals run from the run's begin
    try:
        while True:
            t = conn.simulation.getTime()
            if end is not None and t >= end - 1e-9:
                break
            if end is None and conn.simulation.getMinExpectedNumber() <= 0:
                break
            with signals_deferred():  # a step and its booking are one: none booked in part
                conn.simulationStep()
                stepper.after_step()
                if next_cut is not None and conn.simulation.getTime() >= next_cut - 1e-9:
                    ledger.snapshot(next_cut)
                    next_cut += period
            if bar is not None and (ledger.steps - steps0) % 50 == 0:
                bar.update(50)
    except KeyboardInterrupt:
        interrupted = True
    finally:
        if bar is not None:
            bar.update(max(0, ledger.steps - steps0 - bar.n))  # (the last < 50 steps)
            bar.close()
    return {"interrupted": interrupted, "end_time_s": stepper.now(),
            "step_length_s": dt, "step_method": stepper.step_method}
