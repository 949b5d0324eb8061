"""A vType's own SUMO Energy-model parameters as an equation with a battery chain (the
inverse of :mod:`sumo_drvpw.sim.export`).

SUMO's Energy model (``emissionClass="Energy/…"``, src/utils/emissions/HelpersEnergy.cpp)
computes per step, with m the vType's mass plus its ``loading`` (and riding persons),
g = 9.80665 m/s² (SUMO's GRAVITY) and ρ = 1.2041 kg/m³ fixed::

    P = m·g·sin θ·v + ½(m + m_rot)(v² − v_prev²)/Δt + ½·ρ·A·C_d·v³ + c_r·g·m·v
        + radialDragCoefficient·m·v·|Δψ|/Δt²  (curves only; Δψ the step's heading change)
    P_bat = P/η_t (P > 0) or η_r·exp(−k/|a|)·P (P ≤ 0; k recuperationEfficiencyByDecel, the
            factor only where a ≠ 0), plus constantPowerIntake

As our terms (:mod:`sumo_drvpw.model.terms`; G = 9.81 in the basis):

=====================  =================================================================
term                   coefficient
=====================  =================================================================
acc (m·v̄·a)            1 + rotatingMass / m   (½(m + m_rot)Δ(v²)/Δt = (m + m_rot)·v̄·a)
grade (m·G·v·sin θ)    g_SUMO / G = 9.80665 / 9.81
aero (v·v_air·|v_air|)  ½·1.2041·frontSurfaceArea·airDragCoefficient (SUMO's fixed ρ)
m_v1 (m·v)             rollDragCoefficient·g_SUMO (SUMO's rolling term has no cos θ)
radial (m·v·|ω|)       radialDragCoefficient / Δt (ω = Δψ/Δt; the run's step length Δt)
=====================  =================================================================

SUMO's radial drag is radialDragCoefficient × the centripetal force m·v·|ω| booked as
energy per step (probed with SUMO 1.28.0, 2026-11-27, :func:`sumo_drvpw.sim.reader.yaw_rate`):
as a power it is divided by Δt, so the same curve driven at 0.1-s steps costs ten times
what it costs at 1-s steps. The equation books it as SUMO does, for the run's Δt (a note
says so); a tyre's cornering drag is ``radial*v1`` (:mod:`sumo_drvpw.model.terms`).

and a battery chain: traction efficiency = propulsionEfficiency, recuperation efficiency
= recuperationEfficiency (times exp(−k/|a|) with k = recuperationEfficiencyByDecel, the
chain's ``recuperation_by_decel_mps2``), auxiliary power = constantPowerIntake, no
recuperation limit.
The equation's mass is fixed to the vType's (``mass`` attribute, else the deprecated
``vehicleMass`` param, plus ``loading``).

SUMO 1.28 adds constantPowerIntake after the efficiency, standing and moving alike, which
is the chain's form (probed with libsumo 1.28.0, 2026-11-27: a vType with
constantPowerIntake 1000 W and the default propulsionEfficiency reads 1000 W at constant
speed without road load, and ½m·Δ(v²)/Δt / 0.98 + 1000 W while accelerating).

Defaults of a parameter the vType leaves out: SUMO's own, from
src/utils/emissions/EnergyParams.cpp (``EnergyParams::EnergyParams``, the Kia Soul EV 2020
of sumo.dlr.de/docs/Models/Electric.html): mass 1830 kg (``SUMO_ATTR_MASS`` = 1830 for an
``Energy/`` class, whatever the vClass), frontSurfaceArea 2.6 m², airDragCoefficient 0.35,
rotatingMass 40 kg, radialDragCoefficient 0.1, rollDragCoefficient 0.01,
constantPowerIntake 100 W, propulsionEfficiency 0.98, recuperationEfficiency 0.96,
recuperationEfficiencyByDecel 0 (SUMO's key, SUMOXMLDefinitions.cpp; SUMO 1.28 ignores a
longer ``recuperationEfficiencyByDeceleration``, and so does this); the deprecated ``internalMomentOfInertia`` is
read as rotatingMass when that is not given (the same file: "Use 'rotatingMass'
instead"). Each value was checked against SUMO 1.28.0 itself (libsumo,
getElectricityConsumption at set speeds, one parameter left out at a time; tests/
test_energy_params.py repeats it), g = 9.80665 (``GRAVITY``) likewise.

What the equation cannot carry is listed as notes: the radial drag when the step length
is not known, and the ``maximumPower``. (A vType on MMPEVEM: :mod:`sumo_drvpw.model.mmpevem`.)
"""

from __future__ import annotations

import math
from typing import Mapping

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.model.constants import G, G_UNIT, RHO_DEFAULT
from sumo_drvpw.model.equations import DEFAULT_VCLASSES, Equation

#: SUMO's g in the Energy model (GRAVITY, src/utils/common/StdDefs.h) [m/s²]
G_SUMO = G_UNIT
#: SUMO's fixed air density in the Energy model (HelpersEnergy.cpp) [kg/m³]
RHO_SUMO = RHO_DEFAULT
#: SUMO 1.28's value of each Energy-model parameter a vType leaves out (module docstring)
SUMO_DEFAULTS = {
    "mass": 1830.0, "frontSurfaceArea": 2.6, "airDragCoefficient": 0.35, "rotatingMass": 40.0,
    "radialDragCoefficient": 0.1, "rollDragCoefficient": 0.01, "constantPowerIntake": 100.0,
    "propulsionEfficiency": 0.98, "recuperationEfficiency": 0.96,
    "recuperationEfficiencyByDecel": 0.0,
}
#: the vType params SUMO's Energy model reads (besides the ``mass`` attribute and ``loading``)
ENERGY_PARAMS = ("vehicleMass", "frontSurfaceArea", "airDragCoefficient", "rotatingMass",
                 "internalMomentOfInertia", "radialDragCoefficient", "rollDragCoefficient",
                 "constantPowerIntake", "propulsionEfficiency", "recuperationEfficiency",
                 "recuperationEfficiencyByDecel")
#: params that must lie in (0, 1]
_EFFICIENCIES = ("propulsionEfficiency", "recuperationEfficiency")


def _value(params: Mapping, key: str, where: str) -> float | None:
    """The param ``key`` as a number (None: not given); UserError naming it when it is no
    finite number, is negative, or (an efficiency) lies outside (0, 1]."""
    raw = params.get(key)
    if raw is None:
        return None
    try:
        x = float(raw)
    except (TypeError, ValueError):
        raise UserError(f"{where}: param {key} is not a number: {raw!r}") from None
    if not math.isfinite(x):
        raise UserError(f"{where}: param {key} must be a finite number, got {raw!r}")
    if key in _EFFICIENCIES and not 0.0 < x <= 1.0:
        raise UserError(f"{where}: param {key} must lie in (0, 1], got {raw!r}")
    if x < 0.0:
        raise UserError(f"{where}: param {key} must not be negative, got {raw!r}")
    return x


def energy_model_values(params: Mapping, mass_kg: float | None = None,
                        where: str = "vType") -> dict[str, tuple[float, str]]:
    """SUMO's Energy-model values of one vType: {parameter: (value, "given" or "SUMO
    default")} for mass (the ``mass`` attribute ``mass_kg``, else param vehicleMass, else
    SUMO's default), loading and every key of :data:`SUMO_DEFAULTS`; rotatingMass from
    internalMomentOfInertia where only that is given (as SUMO 1.28 reads it)."""
    got = {k: _value(params, k, where) for k in ENERGY_PARAMS + ("loading",)}
    out: dict[str, tuple[float, str]] = {}
    if mass_kg is not None:
        if not (math.isfinite(float(mass_kg)) and float(mass_kg) > 0):
            raise UserError(f"{where}: mass must be a positive number, got {mass_kg!r}")
        out["mass"] = (float(mass_kg), "given")
    elif got["vehicleMass"] is not None:
        if not got["vehicleMass"] > 0:
            raise UserError(f"{where}: param vehicleMass must be positive, got "
                            f"{params.get('vehicleMass')!r}")
        out["mass"] = (got["vehicleMass"], "given (param vehicleMass)")
    else:
        out["mass"] = (SUMO_DEFAULTS["mass"], "SUMO default")
    out["loading"] = (got["loading"] or 0.0, "given" if got["loading"] is not None else "none")
    if got["rotatingMass"] is None and got["internalMomentOfInertia"] is not None:
        got["rotatingMass"] = got["internalMomentOfInertia"]
    for k, d in SUMO_DEFAULTS.items():
        if k != "mass":
            out[k] = (got[k], "given") if got.get(k) is not None else (d, "SUMO default")
    return out


def radial_drag_note(c_rad: float, step_s: float) -> str:
    """What booking SUMO's radialDragCoefficient ``c_rad`` at step length ``step_s`` [s] means."""
    return (f"radialDragCoefficient {c_rad:g} booked as SUMO 1.28 books it, c × the centripetal "
            f"force m·v·|ω| per step: the term radial at c/Δt = {c_rad / step_s:.4g} for Δt = {step_s:g} s "
            "(it grows as the step shortens: SUMO's form, not a tyre's)")


def energy_params_equation(name: str, params: Mapping, mass_kg: float | None = None,
                           where: str = "vType", vclasses=DEFAULT_VCLASSES,
                           source: str = "", step_s: float | None = None) -> tuple[Equation, list[str]]:
    """One vType's SUMO Energy-model parameters as an :class:`Equation` with a battery
    chain (mapping and defaults in the module docstring); returns (equation, notes on what
    it cannot express).

    Parameters
    ----------
    name : the equation's name
    params : the vType's params as written (key → value string or number; others ignored)
    mass_kg : the vType's ``mass`` attribute [kg] (None: not written)
    where : names the file and vType in errors (e.g. ``"f.rou.xml: vType 'ebus'"``)
    vclasses : the vClasses the equation is made for
    source : the equation's source text (default: ``where``)
    step_s : the run's step length Δt [s], which SUMO's radial drag divides by (None: the
        radial drag is not booked, and a note says so)
    """
    val = energy_model_values(params, mass_kg, where)
    m = val["mass"][0] + val["loading"][0]
    f = {k: v for k, (v, _) in val.items()}
    terms = {"acc": 1.0 + f["rotatingMass"] / m, "grade": G_SUMO / G}
    cda = f["frontSurfaceArea"] * f["airDragCoefficient"]
    if cda:
        terms["aero"] = 0.5 * RHO_SUMO * cda
    if f["rollDragCoefficient"]:
        terms["m_v1"] = f["rollDragCoefficient"] * G_SUMO
    c_rad = f["radialDragCoefficient"]
    if c_rad and step_s:
        terms["radial"] = c_rad / float(step_s)
    chain = EnergyChain(predicts="battery", traction_efficiency=f["propulsionEfficiency"],
                        recuperation_efficiency=f["recuperationEfficiency"],
                        recuperation_limit_w=None, aux_power_w=f["constantPowerIntake"],
                        recuperation_by_decel_mps2=f["recuperationEfficiencyByDecel"],
                        provenance={"sumo_energy_model": {k: {"value": v, "from": s}
                                                          for k, (v, s) in val.items()}})
    notes = []
    if c_rad and not step_s:
        notes.append(f"radialDragCoefficient {c_rad:g} ({val['radialDragCoefficient'][1]}): SUMO books "
                     "its drag in curves per step, and the step length is not known here: not booked")
    if params.get("maximumPower") is not None:
        notes.append("maximumPower: SUMO's Energy model does not cap the power with it either")
    defaults = sorted(k for k, (_, s) in val.items() if s == "SUMO default")
    desc = ("SUMO Energy-model parameters of " + where + " (HelpersEnergy.cpp as terms and a "
            "battery chain; SUMO 1.28 defaults for " + (", ".join(defaults) or "none") + ")"
            + (f"; {radial_drag_note(c_rad, step_s)}" if "radial" in terms else ""))
    eq = Equation(name=name, terms=terms, mass_kg=m, description=desc, source=source or where,
                  chain=chain, vclasses=tuple(vclasses))
    return eq, notes
