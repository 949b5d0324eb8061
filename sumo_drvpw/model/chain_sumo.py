"""An energy chain (:mod:`sumo_drvpw.model.chain`) as SUMO's Energy-model parameters: what
the model can take of a battery or powertrain-output chain, and what it cannot express
(used to write an equation as a vType, ``sim/export.py``, and to drive SUMO's own models
along logged trips, ``validation/chain_sumo.py``)."""

from __future__ import annotations

import numpy as np


def chain_energy_params(chain, air_c: float | None = None, drive=None) -> tuple[dict, list[str]]:
    """SUMO Energy-model values of a battery or powertrain-output chain (for ``sim.export``
    and ``validation.chain_sumo``): ({param: value}, [what the model cannot express, with
    why]). ``air_c``: the run's air temperature [°C], at which the chain's HVAC power joins
    ``constantPowerIntake`` (None: left out, listed). A table efficiency becomes the constant
    booking its energy on ``drive`` = (v [m/s], driving power [W], Δt [s]): traction
    Σ P⁺Δt / Σ (P⁺/η)Δt, recuperation Σ η·P⁻Δt / Σ P⁻Δt (no drive: the cells' mean)."""
    p: dict = {}
    missing: list[str] = []
    if chain.predicts == "fuel":
        return p, ["the fuel chain: SUMO's Energy model is electric, so SUMO alone books this vType's "
                   "energy at the wheels as electricity (efficiencies 1); the plug-in's run and fcd book "
                   "its litres through the vType's drvpw.equation"]
    if chain.motor is not None:  # its own model: written as efficiencies 1 it would book no loss
        return p, ["the MMPEVEM motor, loss map and battery of the chain (write its vType with "
                   "emissionClass MMPEVEM and those parameters instead)"]
    for key, attr in (("propulsionEfficiency", "traction_efficiency"),
                      ("recuperationEfficiency", "recuperation_efficiency")):
        v = getattr(chain, attr)
        if isinstance(v, (int, float)):
            p[key] = float(v)
            continue
        how = "its cells' mean"
        p[key] = float(np.mean(v.values))
        if drive is not None:
            sp, pw, dt = (np.asarray(a, float) for a in drive)
            eta = np.asarray(v(sp, pw), float)
            if attr == "traction_efficiency" and np.sum(np.maximum(pw, 0) * dt) > 0:
                p[key] = float(np.sum(np.maximum(pw, 0) * dt) / np.sum(np.maximum(pw, 0) / eta * dt))
                how = "the table's traction energy on the drive"
            elif attr == "recuperation_efficiency" and np.sum(np.minimum(pw, 0) * dt) < 0:
                p[key] = float(np.sum(eta * np.minimum(pw, 0) * dt) / np.sum(np.minimum(pw, 0) * dt))
                how = "the table's recuperation on the drive"
        missing.append(f"{attr} is a table (SUMO takes a constant: {p[key]:.4g} written, {how})")
    aux = 0.0
    if chain.predicts == "battery":
        h = chain.hvac or {}
        if h and air_c is None:
            missing.append("the HVAC power over the air temperature (give the air temperature to add it "
                           "to constantPowerIntake)")
        # the constant power, plus the HVAC's at air_c (unknown: none), logged loads as 0
        sig = {c: np.zeros(1) for c in chain.loads}
        if h:
            sig[h.get("column", "ambient_c")] = np.array([np.nan if air_c is None else float(air_c)])
        aux = float(chain.auxiliary(1, sig)[0])
        if h.get("warmup_j_per_k"):
            missing.append("the cabin's warm-up at cold starts (a per-trip energy; the plug-in books it)")
        if chain.loads:
            missing.append(f"logged loads {', '.join(chain.loads)} (no signal in SUMO)")
        if chain.standstill_aux_w:
            missing.append(f"the standing draw {chain.standstill_aux_w:g} W (SUMO's Energy model has "
                           "one constantPowerIntake, booked standing and moving alike)")
    if chain.recuperation_limit_w is not None:
        missing.append(f"the recuperation limit {chain.recuperation_limit_w / 1000:.1f} kW (the Energy model "
                       "recuperates without one)")
    if chain.recuperation_by_decel_mps2:  # SUMO's own parameter for it
        p["recuperationEfficiencyByDecel"] = float(chain.recuperation_by_decel_mps2)
    p["constantPowerIntake"] = aux
    return p, missing
