"""Which equations the SUMO loop evaluates on the step's inputs as SUMO's own models read
them, and those inputs: an equation whose chain is SUMO's MMPEVEM motor at the step's mean
speed (:func:`at_mean_speed`), a ``vtype_energy`` equation at SUMO's slope of the vehicle and
its Energy model's radius (:func:`as_sumo`, :func:`as_sumo_inputs`).
:class:`~sumo_drvpw.sim.ledger.EquationSet` groups the equations by them."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sumo_drvpw.model.terms import Inputs


def at_mean_speed(eq) -> bool:
    """Whether the SUMO loop evaluates equation ``eq`` at the step's mean speed v̄ = v − a·Δt/2
    in every term (not only ``acc``): one whose chain is SUMO's MMPEVEM motor, as MMPEVEM
    evaluates its forces (model/mmpevem.py)."""
    ch = getattr(eq, "chain", None)
    return ch is not None and getattr(ch, "motor", None) is not None


def as_sumo(eq) -> bool:
    """Whether the SUMO loop evaluates equation ``eq`` on the inputs as SUMO's own model
    reads them: a ``vtype_energy`` equation (booked as SUMO's Energy model or MMPEVEM books
    its vType). Its grade is taken at SUMO's slope of the vehicle (the signal
    ``sumo_slope_rad``, getSlope: from its back to its front after the step) rather than at
    the rise of the step, and its radial drag at the radius SUMO's Energy model takes: the
    step's v·Δt/|Δψ| held within [10⁻⁴, 10⁴] m wherever the heading changed at all
    (HelpersEnergy::compute), so a heading change below v·Δt/10⁴ rad — a lane whose shape
    is not quite straight, the rounding of the angle — books the 10-km radius."""
    return bool(getattr(eq, "provenance", {}).get("vtype_energy"))


def as_sumo_inputs(x: Inputs) -> Inputs:
    """``x`` as SUMO's Energy model reads it (:func:`as_sumo`)."""
    sig, theta = x.signals, x.theta
    if "sumo_slope_rad" in sig:  # SUMO's getSlope where it gave one
        s = np.asarray(sig["sumo_slope_rad"], float)
        theta = np.where(np.isnan(s), theta, s)
    w = sig.get("yaw_rate_rps")
    if w is not None:  # radius v·Δt/|Δψ| within [1e-4, 1e4] m: |ω| within [v/1e4, v·1e4]
        w = np.asarray(w, float)
        v = np.abs(np.asarray(x.v, float))
        sig = {**sig, "yaw_rate_rps": np.where(w != 0.0, np.clip(np.abs(w), v * 1e-4, v * 1e4), 0.0)}
    return replace(x, theta=theta, signals=sig)
