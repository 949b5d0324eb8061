"""The reserved equation ``vtype_energy``: each vType's own SUMO Energy-model parameters,
booked as an equation with a battery chain (:mod:`sumo_drvpw.model.energy_params`), or
its MMPEVEM parameters (``emissionClass="MMPEVEM…"``: road load, motor, loss map and battery
as SUMO computes them, :mod:`sumo_drvpw.model.mmpevem`; booked whatever params it writes,
since SUMO's defaults are then a whole car, its VW ID.3; its mass SUMO's, plus riders as SUMO adds them).

``vtype_energy`` may stand wherever an equation name goes (a scenario's ``equations``,
``vtypes.<id>.equations``, ``vclasses.<c>.equations``, a vType's ``drvpw.equation``, a
run's or an FCD replay's equations). The run replaces it by one equation per vType of the
route/additional files read that SUMO runs on its Energy model (``emissionClass``
``Energy/…`` or ``Energy``; none, with SUMO's battery device on: :func:`not_booked_why`)
and that writes a ``mass`` or at least one Energy-model parameter, named ``vtype_energy.<vType id>`` and booking only that
vType: the ledger evaluates one coefficient row per equation for every vehicle
(:class:`~sumo_drvpw.sim.ledger.EquationSet`), so per-vType coefficients are per-vType
equations, and the outputs name the vType with the energy. Other vTypes are not booked by
it and are listed (summary.json ``assumptions.vtype_energy``).

The plug-in's own equations (a bare SUMO config, ``fcd`` without equations:
:data:`~sumo_drvpw.sim.scenario.CONFIG_EQUATIONS`) bring it too: such a vType is booked by
its ``vtype_energy.<id>`` beside its class's equations — an electric car so by two battery
chains, its own and the i3's (alternatives: the resolver's ``also_booked``, summary.json
``assumptions.vtype_energy.also_booked_by``).

Mass: the vType's Energy-model mass (``mass`` attribute, else param ``vehicleMass``, plus
``loading``). Where the run books the vType at that same mass (no ``drvpw.mass``, no
scenario ``vtypes.<id>.mass_kg``) the equation takes the vehicle's booked mass, so riding
persons count as in SUMO's ``getTotalMass``, and the rotating mass stays the vType's (the
acc coefficient 1 + m_rot/m at the vType's mass; the ledger takes the riders' share of it
back, :class:`~sumo_drvpw.sim.ledger.EquationSet`, as SUMO books (m + riders + m_rot)·v̄·a);
otherwise (and at SUMO's default 1830 kg) the mass is fixed to SUMO's, without riders.
"""

from __future__ import annotations

import re

import numpy as np

from sumo_drvpw.model.energy_params import ENERGY_PARAMS, energy_params_equation, radial_drag_note
from sumo_drvpw.model.mmpevem import is_mmpevem_class, mmpevem_equation
from sumo_drvpw.model.equations import SUMO_VCLASSES, Equation

#: the reserved equation name
VTYPE_ENERGY = "vtype_energy"
#: provenance key that marks the placeholder and, with the vType id, its equations
_KEY = "vtype_energy"


def placeholder() -> Equation:
    """The stand-in a scenario holds for ``vtype_energy`` until the run reads the vTypes."""
    return Equation(name=VTYPE_ENERGY, terms={"acc": 1.0}, vclasses=SUMO_VCLASSES,
                    description="each vType's own SUMO Energy-model parameters",
                    provenance={_KEY: None})


def reserved_name(eq, where: str) -> None:
    """UserError when an equation loaded from a file or a built-in name is named
    ``vtype_energy`` or ``vtype_energy.…``: the names of the run's own (its outputs would
    give another equation's energy under them)."""
    if eq.name == VTYPE_ENERGY or eq.name.startswith(VTYPE_ENERGY + "."):
        from sumo_drvpw.errors import UserError

        raise UserError(f"{eq.path or where}: equation name '{eq.name}' is reserved (vtype_energy: each "
                        "vType's own SUMO Energy-model parameters); rename the equation")


def is_placeholder(eq) -> bool:
    return isinstance(eq, Equation) and eq.provenance.get(_KEY, 0) is None


def energy_vtype_of(equations) -> dict[str, str]:
    """Equation name → vType id of the run's ``vtype_energy`` equations."""
    return {e.name: e.provenance[_KEY] for e in equations
            if isinstance(e, Equation) and e.provenance.get(_KEY)}


def is_energy_class(ec: str | None) -> bool:
    """Whether an emissionClass names SUMO's Energy model (``Energy/…``, or the bare
    ``Energy``, which SUMO 1.28 reads as ``Energy/default``)."""
    return bool(ec) and (ec == "Energy" or ec.startswith("Energy/"))


def battery_switch(sc) -> str:
    """Which vTypes without an emissionClass SUMO's battery device puts on its Energy model
    in the run of scenario ``sc`` (its SUMO options, else its config): "none" with
    ``device.battery.track-fuel`` (the device then tracks the fuel of the vType's default
    class, which stays: probed with libsumo 1.28.0, also for a vType with
    has.battery.device), "all" with ``device.battery.probability`` ≥ 1, else "param" (those
    with param has.battery.device)."""
    from sumo_drvpw.sim.sumo_start import scenario_option
    from sumo_drvpw.sim.vtypes import is_true

    if sc is None or not hasattr(sc, "sumo_args"):
        return "param"
    if is_true(scenario_option(sc, "device.battery.track-fuel")):
        return "none"
    try:
        return "all" if float(scenario_option(sc, "device.battery.probability") or 0) >= 1.0 else "param"
    except ValueError:
        return "param"  # SUMO refuses it itself


#: what SUMO 1.28's vehicletype.getEmissionClass reads for a vType that writes no
#: emissionClass and has the battery device (probed with libsumo 1.28.0, 2026-11-27)
BATTERY_DEVICE_CLASS = "Energy/default"


def run_emission_class(info, switch: str) -> str | None:
    """The emissionClass SUMO runs a vType of the files on: the written one; where it
    writes none and the battery device is on for it (``switch``, :func:`battery_switch`:
    "param" those with param has.battery.device, "all" every vType, "none" none, the device
    tracking fuel) the Energy model's, :data:`BATTERY_DEVICE_CLASS`; else None (SUMO's
    default for its vClass)."""
    if info.emission_class:
        return info.emission_class
    if switch != "none" and (getattr(info, "battery_device", False) or switch == "all"):
        return BATTERY_DEVICE_CLASS
    return None


def replay_emission_classes(file_vtypes: dict, switch: str) -> tuple[dict, str]:
    """What an FCD replay answers for ``vehicletype.getEmissionClass`` as SUMO did in the
    recorded run: vType → :func:`run_emission_class` (where it names one); and the class of
    a vType the files do not hold (SUMO's default type: the Energy model's with the device
    on every vehicle, else "" — SUMO's default)."""
    out = {vt: ec for vt, i in file_vtypes.items() if (ec := run_emission_class(i, switch))}
    return out, BATTERY_DEVICE_CLASS if switch == "all" else ""


def not_booked_why(info, switch: str = "param") -> str | None:
    """Why ``vtype_energy`` does not book a vType of the files (None: it does).

    SUMO runs a vType on its Energy model when its emissionClass is ``Energy/…`` (or
    ``Energy``), and, when it writes no emissionClass, when the battery device is on for it
    (``switch``, :func:`battery_switch`: "param" those with param has.battery.device, "all"
    every vType, "none" none, the device tracking fuel): SUMO 1.28 warns "The emission class
    Energy/unknown will be used" (probed with libsumo 1.28.0, 2026-11-27: getEmissionClass
    reads Energy/default, the emissions device's electricity equals the battery device's)."""
    ec = run_emission_class(info, switch)
    if is_mmpevem_class(ec):  # its defaults are a whole car (SUMO's VW ID.3): booked with none written
        return None
    if not is_energy_class(ec):
        return (f"emissionClass {ec} is not SUMO's Energy model or MMPEVEM" if ec
                else "no emissionClass written and SUMO's battery device tracks fuel "
                     "(device.battery.track-fuel): its default class stays" if switch == "none"
                else "no emissionClass written and no battery device (SUMO's default is then not "
                     "the Energy model)")
    if not any(k in (info.energy_params or {}) for k in ENERGY_PARAMS) and getattr(info, "mass_attr_kg", None) is None:
        return "writes no Energy-model parameter"  # (a mass is one: SUMO's Energy model takes it)
    return None


def own_name(vt: str) -> str:
    """The name of vType ``vt``'s ``vtype_energy`` equation (before a clash's suffix)."""
    return (VTYPE_ENERGY + "." + re.sub(r"[^A-Za-z0-9_.-]", "_", vt))[:64]


def named_in_table(e: str, table: str, key: str, names: list[str], where: str) -> bool:
    """Whether ``e``, named in a scenario's ``[table.key] equations`` but not among its
    equations, is the ``vtype_energy`` equation the run makes for that vType (``[vtypes.<id>]``
    naming ``vtype_energy.<id>``, with ``vtype_energy`` among the scenario's equations):
    True; False when ``e`` is no ``vtype_energy.…`` name. A UserError when it names another
    vType's, or ``vtype_energy`` is not among the equations, or it stands under ``vclasses``."""
    from sumo_drvpw.errors import UserError

    if not e.startswith(VTYPE_ENERGY + "."):
        return False
    at = f"{where}: {table}.{key}.equations names '{e}'"
    if table != "vtypes":
        raise UserError(f"{at}: a vtype_energy equation books its own vType only; name "
                        "'vtype_energy' there (each vType of the class by its own parameters)")
    if e != own_name(key):
        raise UserError(f"{at}: a vtype_energy equation books its own vType only; name "
                        f"'vtype_energy' or '{own_name(key)}' for vType '{key}'")
    if VTYPE_ENERGY not in names:
        raise UserError(f"{at}: list 'vtype_energy' among the scenario's equations (it makes '{e}')")
    return True


def _name(vt: str, taken: set[str]) -> str:
    base = own_name(vt)
    name, k = base, 2
    while name in taken:
        name = f"{base[:60]}-{k}"
        k += 1
    taken.add(name)
    return name


def _named_elsewhere(vt: str, info, vdata: dict) -> str | None:
    """Why a vType the scenario or its own ``drvpw.equation`` gives other equations is not
    booked by its Energy-model parameters (the resolver books it by those: an exported
    vType names its equation so), else None."""
    named = (vdata.get(vt) or {}).get("equations")
    if named is not None:
        if any(str(e) == VTYPE_ENERGY or str(e).startswith(VTYPE_ENERGY + ".") for e in named):
            return None
        return f"the scenario's vtypes.{vt}.equations names its equations"
    if info.equation and not str(info.equation).startswith(VTYPE_ENERGY):
        return f"its drvpw.equation names its equation ({info.equation})"
    return None


def vtype_equations(file_vtypes, sc=None, step_s: float | None = None) -> tuple[list[Equation], dict]:
    """One equation per vType of ``file_vtypes`` that writes SUMO's Energy model (the
    scenario's ``vehicles.vtypes`` filter applies), for the run's step length ``step_s``
    [s] (its radial drag; None: left out); returns (equations, listing) with
    listing = {"booked": {vType: {equation, mass_kg, defaults, not_expressed}},
    "not_booked": {vType: why}}."""
    vfilter = getattr(sc, "vtype_filter", None)
    vdata = getattr(sc, "vtype_data", {}) or {}
    switch = battery_switch(sc)
    eqs: list[Equation] = []
    booked: dict[str, dict] = {}
    not_booked: dict[str, str] = {}
    taken: set[str] = set()
    for vt, info in file_vtypes.items():
        if vfilter is not None and vt not in vfilter:
            continue
        why = not_booked_why(info, switch)
        if why is not None:
            not_booked[vt] = why
            continue
        where = f"{info.source}: vType '{vt}'"
        mmp = is_mmpevem_class(info.emission_class)
        if mmp:
            eq, notes = mmpevem_equation(_name(vt, taken), info.energy_params or {}, info.mass_attr_kg,
                                         where, (info.vclass or "passenger",))
        else:
            eq, notes = energy_params_equation(_name(vt, taken), info.energy_params or {}, info.mass_attr_kg,
                                               where, (info.vclass or "passenger",), step_s=step_s)
        model = eq.chain.provenance["sumo_mmpevem" if mmp else "sumo_energy_model"]
        eq.provenance = {_KEY: vt}
        eq.path = str(info.source)
        same_mass = (not mmp and model["mass"]["from"] != "SUMO default" and not info.drvpw_mass
                     and vdata.get(vt, {}).get("mass_kg") is None)
        if same_mass:  # the vehicle's booked mass: the same, plus riders as SUMO adds them, but
            eq.mass_kg = None  # its rotating mass does not grow with them (sim/ledger.py)
            eq.provenance["rotating_mass_fixed"] = True
            eq.provenance["rotating_mass_kg"] = model["rotatingMass"]["value"]  # (nor with a setMass)
        eqs.append(eq)
        booked[vt] = {"equation": eq.name,
                      "emission_class": info.emission_class or "none written: Energy/unknown, as SUMO "
                                                               "takes it with the battery device on",
                      "model": "MMPEVEM" if mmp else "Energy",
                      "mass_kg": model["mass"]["value"] + model["loading"]["value"],
                      "mass": "the vehicle's (riders included)" if same_mass else
                      "SUMO's MMPEVEM mass (riders included)" if mmp else "fixed (no riders)",
                      "defaults": {k: d["value"] for k, d in model.items() if d["from"] == "SUMO default"},
                      "not_expressed": notes}
        if "radial" in eq.terms:
            booked[vt]["radial_drag"] = radial_drag_note(model["radialDragCoefficient"]["value"], step_s)
    return eqs, {"booked": booked, "not_booked": not_booked}


def own_energy(names: list[str], energy_of: dict[str, str], vt: str, chosen, app: np.ndarray) -> np.ndarray:
    """``app`` with each ``vtype_energy`` equation booking its own vType only: when
    ``chosen`` (the equations the scenario or the vType names) holds ``vtype_energy`` or
    the equation's name, or when none are named (``chosen`` None: the equations made for
    the class, which bring it)."""
    if not energy_of:
        return app
    app = np.array(app, float)
    for i, n in enumerate(names):
        own = energy_of.get(n)
        if own is not None:
            app[i] = float(own == vt and (chosen is None or VTYPE_ENERGY in chosen or n in chosen))
    return app


def listing_warning(listing: dict) -> str | None:
    """The console line on what ``vtype_energy`` booked (None: nothing to say)."""
    booked, nb = listing.get("booked", {}), listing.get("not_booked", {})
    if not booked:
        return None
    parts = []
    for vt, b in sorted(booked.items()):
        d = ", ".join(f"{k} {v:g}" for k, v in b["defaults"].items())
        parts.append(f"{vt} as {b['equation']} ({b['mass_kg']:g} kg"
                     + (f"; SUMO's defaults {d}" if d else "") + ")")
    left = [vt for vt, w in nb.items() if w == "writes no Energy-model parameter"]
    radial = sorted(vt for vt, b in booked.items() if b.get("radial_drag"))
    return ("vTypes with SUMO's Energy model or MMPEVEM were booked by their own parameters as a battery "
            "chain (vtype_energy): " + "; ".join(parts)
            + ("; beside the class's battery chains, which book the same vehicles (alternatives, not more "
               "vehicles: a class's or fleet's kWh takes one of them): " + ", ".join(
                   f"{e} and {' and '.join(o)}" for e, o in sorted(also.items())) if (also := listing.get("also_booked_by"))
               else "")
            + (f"; Energy vTypes without parameters not booked by it: {', '.join(sorted(left))}" if left else "")
            + (f"; the radial drag in curves of {', '.join(radial)} booked per step as SUMO books it, so it "
               "grows as the step shortens (×10 from 1 s to 0.1 s)" if radial else "")
            + " (summary.json assumptions.vtype_energy: what it books and cannot express)")


def expand(equations: list, file_vtypes, sc, step_s: float | None = None) -> tuple[list, dict]:
    """The run's equations with ``vtype_energy`` replaced by the vTypes' own equations
    (appended to the plug-in's own equations, :data:`~sumo_drvpw.sim.scenario.CONFIG_EQUATIONS`,
    when the files declare such vTypes), and the listing of :func:`vtype_equations` ({}
    when the run has no ``vtype_energy``). UserError when it was the run's only equation
    and no vType of the files writes SUMO's Energy model."""
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.sim.scenario import CONFIG_EQUATIONS

    has = any(is_placeholder(e) for e in equations)
    own = [e.name for e in getattr(sc, "equations", [])] == list(CONFIG_EQUATIONS)
    if not (has or own):
        return equations, {}
    eqs, listing = vtype_equations(file_vtypes, sc, step_s)
    vdata = getattr(sc, "vtype_data", {}) or {}
    for vt in list(listing.get("booked", {})):  # the run books these by the equations they name
        why = _named_elsewhere(vt, file_vtypes[vt], vdata)
        if why is not None:
            eqs = [e for e in eqs if e.name != listing["booked"].pop(vt)["equation"]]
            listing["not_booked"][vt] = why
    if own and not has and not eqs:  # the plug-in's own equations, no Energy vType: nothing to say
        return equations, {}
    taken = {e.name for e in equations if not is_placeholder(e)}
    clash = sorted(taken & {e.name for e in eqs})
    if clash:
        raise UserError(f"equation name(s) {clash} of the run clash with the vtype_energy equations "
                        "of the vTypes of those names: rename the equation files")
    out = [x for e in equations for x in (eqs if is_placeholder(e) else [e])]
    if own and not has:
        out += eqs
    if not out:  # (the Energy vTypes' reasons first: those a user asks vtype_energy for)
        why = sorted(listing["not_booked"].items(), key=lambda x: (x[1].startswith(("emissionClass ", "no emissionClass")), x[0]))
        raise UserError("equation vtype_energy: no vType of the route/additional files read runs SUMO's "
                        "MMPEVEM or writes its Energy model (emissionClass Energy/…, or none with SUMO's battery "
                        "device on, and at least one of its parameters: "
                        + ", ".join(f"{vt}: {w}" for vt, w in why[:5])
                        + (f", and {len(why) - 5} more" if len(why) > 5 else "") + "); name another equation")
    return out, listing
