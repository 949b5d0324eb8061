"""An equation as a vType for SUMO's own Energy model (``emissionClass="Energy/unknown"``).

SUMO's Energy model (src/utils/emissions/HelpersEnergy.cpp, SUMO 1.28) computes per step

    P = m·g·sin θ·v + ½(m + m_rot)(v² − v_prev²)/Δt + ½·ρ·A·C_d·v³ + c_r·g·m·v
        + radial drag,

with ρ = 1.2041 kg/m³ and g = 9.80665 m/s², then divides traction by the propulsion
efficiency, multiplies recuperation by the recuperation efficiency and adds the constant
power intake (after the efficiency, probed in SUMO 1.28: :mod:`sumo_drvpw.model.energy_params`,
which reads such a vType back as an equation). Our terms map onto it as follows (m: the
equation's fixed mass, else the vehicle's):

============  ==========================================  =============================
term          coefficient c means                          Energy-model parameter
============  ==========================================  =============================
acc           c·m·v̄·a = ½·c·m·Δ(v²)/Δt                    rotatingMass = (c − 1)·m (c ≥ 1)
grade         c·m·g·v·sin θ                                 exact only for c = 1
aero_rho      ½·ρ·c·v³ (no wind)                            A·C_d = c
aero          c·v³ (no wind)                                A·C_d = 2c/ρ_SUMO
m_v3, v3      c·m·v³, c·v³                                  A·C_d = 2c·m/ρ_SUMO, 2c/ρ_SUMO
roll          c·m·g·v·cos θ                                 rollDragCoefficient = c (no cos θ)
m_v1, v1      c·m·v, c·v                                    c_r = c/g, c/(g·m), SUMO's g
one           c                                             constantPowerIntake = c [W]
============  ==========================================  =============================

Anything else (``v2``, ``roll_v2``, products, log columns) has no counterpart: it is left
out and listed. ``frontSurfaceArea`` is the vehicle's frontal area when known (then
``airDragCoefficient`` = A·C_d / A), else 1 m² (then ``airDragCoefficient`` carries A·C_d).

An equation with a battery (or powertrain-output) chain brings its chain
(:func:`chain_energy_params`): ``propulsionEfficiency`` = η_t, ``recuperationEfficiency`` =
η_r, ``constantPowerIntake`` += P_aux,0, plus its HVAC at a given air temperature; the
equation's own constant term c, driving power that the chain draws through the drivetrain
(c/η_t while the vehicle drives or stands), is written as c/η_t, as SUMO adds
constantPowerIntake after the efficiency (listed: while recuperating the chain books η_r·c); what the
Energy model has no counterpart for (efficiency tables, a recuperation limit, logged loads,
a standing draw, the cabin's warm-up at cold starts) is listed. Without a chain the
efficiencies are 1: the vType books the driving energy at the wheels.
"""

from __future__ import annotations

import os
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain_sumo import chain_energy_params
from sumo_drvpw.model.constants import RHO_DEFAULT
from sumo_drvpw.model.energy_params import G_SUMO
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.model.terms import parse_term

#: SUMO's fixed air density in the Energy model [kg/m³] (HelpersEnergy.cpp)
RHO_SUMO = RHO_DEFAULT


def _has_table(chain) -> bool:
    return not all(isinstance(getattr(chain, a), (int, float)) for a in ("traction_efficiency",
                                                                       "recuperation_efficiency"))


def _bundled_drive(eq: Equation, mass_kg: float):
    """(v, driving power, Δt) of ``eq`` at ``mass_kg`` on the bundled 8-Hz test-track drive
    (city, rural and motorway speeds): the drive a table efficiency is weighed on; None where
    the equation needs a signal that log lacks."""
    from sumo_drvpw.data.log import bundled_log, read_log

    log = read_log([bundled_log()])
    x = log.inputs(mass_kg).with_mass(mass_kg)
    try:
        p = eq.power(x)
    except (UserError, KeyError):
        return None
    ok = np.isfinite(p)
    return x.v[ok], p[ok], log.df["dt_s"].to_numpy(float)[ok]


def energy_model_params(eq: Equation, mass_kg: float | None = None,
                        frontal_area_m2: float | None = None,
                        air_c: float | None = None) -> tuple[dict, list[str]]:
    """SUMO Energy-model vType values for ``eq``: ({attribute/param: value}, [terms or
    factors it cannot express, with why]).

    Parameters
    ----------
    eq : the equation
    mass_kg : vehicle mass [kg] (needed unless the equation fixes one)
    frontal_area_m2 : frontal area A [m²] to split A·C_d (default 1 m²)
    air_c : air temperature [°C] for a battery chain's HVAC (:func:`chain_energy_params`)
    """
    m = eq.mass_kg if eq.mass_kg is not None else mass_kg
    if m is None or not m > 0:
        raise UserError(f"equation '{eq.name}' has no fixed mass: give the vehicle's mass "
                        "(a vehicle file with mass_kg, or a mass)")
    m = float(m)
    cda = 0.0
    cr = 0.0
    rot = 0.0
    const = 0.0
    missing: list[str] = []
    for t, c in eq.terms.items():
        term = parse_term(t)
        f = term.factors
        if len(f) != 1:
            missing.append(f"{t} (a product of factors)")
            continue
        f = f[0]
        if f == "acc":
            if c < 1.0:
                missing.append(f"acc coefficient {c:g} < 1 (SUMO adds rotating mass only; "
                               "exported as rotatingMass 0)")
            rot = max(0.0, (c - 1.0) * m)
        elif f == "grade":
            if abs(c - 1.0) > 1e-9:
                missing.append(f"grade coefficient {c:g} (SUMO's grade term is m·g·v·sin θ, "
                               "coefficient 1)")
        elif f == "aero_rho":
            cda += c
        elif f == "aero":
            cda += 2.0 * c / RHO_SUMO
        elif f == "m_v3":
            cda += 2.0 * c * m / RHO_SUMO
        elif f in ("v3", "v^3"):
            cda += 2.0 * c / RHO_SUMO
        elif f == "roll":
            cr += c
        elif f == "m_v1":  # SUMO's rolling term c_r·g·m·v with its g (9.80665)
            cr += c / G_SUMO
        elif f in ("v1", "v^1"):
            cr += c / (G_SUMO * m)
        elif f in ("one", "v^0", "moving"):
            # constantPowerIntake: SUMO 1.28 books it standing too (at v = 0 without the
            # efficiency; docs/scenario.md), which is `v^0`; a `moving` constant exported
            # here is booked by SUMO also while the vehicle stands
            const += c
            if f == "moving" and c:
                missing.append(f"{t} {c:g} W drawn only while moving (SUMO books "
                               "constantPowerIntake standing too: queues and red lights get it)")
        elif f == "radial":  # SUMO books radialDragCoefficient·m·v·|ω| per step: c/Δt as a power
            missing.append(f"radial coefficient {c:g} m/s: SUMO books radialDragCoefficient × the "
                           f"centripetal force per step, so it is {c:g}·Δt for a run at step length Δt "
                           f"(written 0; e.g. {c:g} at 1 s, {0.1 * c:g} at 0.1 s)")
        else:
            missing.append(f"{t} (no Energy-model counterpart)")
    if cda < 0 or cr < 0:
        raise UserError(f"equation '{eq.name}': negative drag ({cda:g} m²) or rolling "
                        f"({cr:g}) coefficient cannot be exported to SUMO's Energy model")
    area = float(frontal_area_m2) if frontal_area_m2 else 1.0
    params = {"mass": m, "frontSurfaceArea": area, "airDragCoefficient": cda / area,
              "rollDragCoefficient": cr, "rotatingMass": rot, "constantPowerIntake": const,
              "radialDragCoefficient": 0.0, "propulsionEfficiency": 1.0,
              "recuperationEfficiency": 1.0}
    chain = getattr(eq, "chain", None)
    if chain is not None and chain.predicts != "wheel":
        cp, cm = chain_energy_params(chain, air_c, _bundled_drive(eq, m) if _has_table(chain) else None)
        params.update({k: v for k, v in cp.items() if k != "constantPowerIntake"})
        if const:  # driving power: through the drivetrain in the chain, after it in SUMO
            eta_t, eta_r = params["propulsionEfficiency"], params["recuperationEfficiency"]
            missing.append(f"the equation's constant {const:g} W is driving power, which the chain draws "
                           f"through the drivetrain: written as {const:g}/η_t = {const / eta_t:.6g} W, exact "
                           f"while the vehicle drives or stands (SUMO adds constantPowerIntake after the "
                           f"efficiency); while it recuperates the chain books η_r·{const:g} = "
                           f"{eta_r * const:.6g} W")
            params["constantPowerIntake"] = const / eta_t
        params["constantPowerIntake"] += cp.get("constantPowerIntake", 0.0)
        missing += cm
    return params, missing


def equation_ref(eq: Equation, out=None) -> str:
    """What a vType's ``drvpw.equation`` names for ``eq``: a built-in's name, else its file's
    path — relative to the folder of ``out`` (the additional file written) when given — so
    that a run finds it (a bare name of a user's equation is no built-in: the run refused it)."""
    from sumo_drvpw.model.equations import BUILTIN_DIR

    p = getattr(eq, "path", None)
    if not p or Path(p).resolve().parent == BUILTIN_DIR.resolve():
        return eq.name
    if out is None:
        return str(Path(p).resolve())
    return Path(os.path.relpath(Path(p).resolve(), Path(out).resolve().parent)).as_posix()


def energy_vtype_xml(eq: Equation, vtype_id: str, mass_kg: float | None = None,
                     frontal_area_m2: float | None = None,
                     vclass: str | None = None, air_c: float | None = None, out=None) -> tuple[str, list[str]]:
    """An additional file with one Energy-model vType for ``eq`` (an MMPEVEM one when its
    chain is SUMO's MMPEVEM motor: :func:`mmpevem_vtype_xml`); returns (XML, missing)."""
    if getattr(getattr(eq, "chain", None), "motor", None) is not None:
        return mmpevem_vtype_xml(eq, vtype_id, mass_kg, frontal_area_m2, vclass, out)
    params, missing = energy_model_params(eq, mass_kg, frontal_area_m2, air_c)
    attrs = (f"id={quoteattr(vtype_id)} emissionClass=\"Energy/unknown\" "
             f"mass=\"{params['mass']:.6g}\"")
    if vclass:
        attrs += f" vClass={quoteattr(vclass)}"
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f"<!-- sumo-drvpw export-vtype: equation {eq.name} ({eq.predicts}) as SUMO's "
             "Energy model (HelpersEnergy). -->"]
    if missing:
        lines.append("<!-- not expressible in SUMO's Energy model, left out: "
                     + "; ".join(m.replace("--", "- -") for m in missing) + " -->")
    lines += ["<additional>", f"    <vType {attrs}>",
              f'        <param key="drvpw.equation" value={quoteattr(equation_ref(eq, out))}/>',
              f'        <param key="drvpw.mass" value="{params["mass"]:.6g}"/>']
    for k in ("frontSurfaceArea", "airDragCoefficient", "rollDragCoefficient", "rotatingMass",
              "constantPowerIntake", "radialDragCoefficient", "propulsionEfficiency",
              "recuperationEfficiency", "recuperationEfficiencyByDecel"):
        if k in params:
            lines.append(f'        <param key="{k}" value="{params[k]:.9g}"/>')
    lines += ["    </vType>", "</additional>", ""]
    return "\n".join(lines), missing


def mmpevem_vtype_xml(eq: Equation, vtype_id: str, mass_kg: float | None = None,
                      frontal_area_m2: float | None = None, vclass: str | None = None,
                      out=None) -> tuple[str, list[str]]:
    """An additional file with one vType on SUMO's MMPEVEM (``emissionClass="MMPEVEM"``) for
    an equation whose chain is SUMO's MMPEVEM motor (:func:`~sumo_drvpw.model.mmpevem.mmpevem_params`,
    the inverse of the equation ``vtype_energy`` makes of such a vType); returns (XML, missing)."""
    from sumo_drvpw.model.mmpevem import mmpevem_params

    params, missing = mmpevem_params(eq, frontal_area_m2)
    if mass_kg is not None and abs(float(mass_kg) - params["mass"]) > 1e-9 * params["mass"]:
        missing.append(f"the mass given, {float(mass_kg):g} kg: MMPEVEM's is the motor's {params['mass']:g} kg "
                       "(its mass factor and holding force are at it)")
    attrs = f'id={quoteattr(vtype_id)} emissionClass="MMPEVEM" mass="{params["mass"]:.9g}"'
    if vclass:
        attrs += f" vClass={quoteattr(vclass)}"
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f"<!-- sumo-drvpw export-vtype: equation {eq.name} (battery) as SUMO's MMPEVEM (HelpersMMPEVEM). -->"]
    if missing:
        lines.append("<!-- not expressible in SUMO's MMPEVEM, left out: "
                     + "; ".join(m.replace("--", "- -") for m in missing) + " -->")
    lines += ["<additional>", f"    <vType {attrs}>",
              f'        <param key="drvpw.equation" value={quoteattr(equation_ref(eq, out))}/>']
    for k, v in params.items():
        if k != "mass":
            lines.append(f'        <param key="{k}" value={quoteattr(v if isinstance(v, str) else f"{v:.12g}")}/>')
    lines += ["    </vType>", "</additional>", ""]
    return "\n".join(lines), missing
