"""A plug-in hybrid's charge-depleting start (``[chain.depleting]`` of a fuel chain).

A plug-in hybrid drives on its grid-charged battery until a usable energy is spent, then
sustains its charge as a full hybrid does. As data in the equation file, beside the
charge-sustaining hybrid's fuel chain (``charge_sustaining = true``)::

    [chain.depleting]
    usable_j = 2.9e7                  # battery energy spent before it sustains charge [J] (≥ 10 kJ)
    traction_efficiency = 0.85        # battery → wheels, η_t of a battery chain
    recuperation_efficiency = 0.65    # wheels → battery, η_r
    recuperation_limit_w = 40000      # optional
    aux_power_w = 300                 # optional: default the chain's; its loads and HVAC too

Each sample's battery power P_bat (the battery chain's form, model/chain.py) is drawn from the
energy spent so far, s (0 at the start of a trip or of a vehicle's run: a charged battery)::

    s < U, P_bat·Δt ≤ U − s:   on the battery: share 1, s += P_bat·Δt  (recuperation lowers s, to 0: a
                               full battery takes no more, the rest goes to the friction brakes)
    s < U, P_bat·Δt > U − s:   share (U − s)/(P_bat·Δt) on the battery, the rest on fuel; s = U
    s = U:                     charge-sustaining: share 0 (its braking credit the fuel chain's own)

and the sample books share·P_bat of battery power (``battery_w``; ``battery_traction_w``,
``battery_recuperated_w``, ``battery_auxiliary_w``) and (1 − share) of the fuel chain's fuel.
Carried as the battery window is (model/chain_buffer.py): through a series, ``trip`` starting
each with a charged battery, or per vehicle from the energy ``spent_j`` before the sample.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain_buffer import _starts, battery_energy
from sumo_drvpw.model.chain_values import keyed_table

#: keys of [chain.depleting]
DEPLETING_KEYS = ("usable_j", "traction_efficiency", "recuperation_efficiency", "recuperation_limit_w",
                  "aux_power_w")
#: the fuel chain's outputs scaled by the share on fuel
FUEL_OUT = ("engine_w", "power_w", "fuel_lps", "co2_kgps", "given_back_w", "over_engine_w")


@dataclass
class Depleting:
    """A plug-in hybrid's battery chain and its usable energy ``usable_j`` [J]."""

    chain: object
    usable_j: float

    def to_dict(self) -> dict:
        d = {k: x for k, x in self.chain.to_dict().items() if k in DEPLETING_KEYS}
        return {"usable_j": float(self.usable_j), **d}


def depleting_from_dict(doc: dict, where: str) -> Depleting:
    """``[chain.depleting]`` of the fuel chain ``doc`` checked: a table of :data:`DEPLETING_KEYS`,
    ``usable_j`` > 0 and both efficiencies given, for a charge-sustaining fuel chain; its auxiliaries
    default to the chain's."""
    from sumo_drvpw.model.chain_toml import chain_from_dict

    dep = keyed_table(doc["depleting"], "chain.depleting", DEPLETING_KEYS, where, " (a plug-in hybrid's battery)")
    if doc.get("predicts") != "fuel" or doc.get("charge_sustaining") is not True:
        raise UserError(f"{where} [chain.depleting]: a plug-in hybrid's charge-depleting battery: only for "
                        "predicts = \"fuel\" with charge_sustaining = true (the hybrid it becomes once spent)")
    if "usable_j" not in dep:
        raise UserError(f"{where} [chain.depleting]: 'usable_j' (the battery energy it spends first) is required")
    usable = battery_energy(dep["usable_j"], "depleting.usable_j", where)
    lossless = [k for k in ("traction_efficiency", "recuperation_efficiency") if k not in dep]
    if lossless:  # (a battery chain's efficiencies default to 1: no plug-in's battery and motor are lossless)
        raise UserError(f"{where} [chain.depleting]: {' and '.join(repr(k) for k in lossless)} required (battery → "
                        "wheels and wheels → battery, e.g. 0.89 and 0.87, the built-in epa_gasoline_phev_car's): "
                        "without them the battery would drive and recuperate without loss")
    if not usable > 0:
        raise UserError(f"{where} [chain.depleting]: 'usable_j' must be > 0, got {dep['usable_j']!r}")
    hvac = {k: x for k, x in (doc.get("hvac") or {}).items() if k != "warmup_j_per_k"}
    bat = {"predicts": "battery", "aux_power_w": doc.get("aux_power_w", 0.0), "loads": doc.get("loads", {}),
           **({"hvac": hvac} if hvac else {}), **{k: x for k, x in dep.items() if k != "usable_j"}}
    try:
        return Depleting(chain_from_dict(bat, f"{where} [chain.depleting]"), usable)
    except UserError as e:  # (its errors name [chain] or [chain.<key>] after where: the table is [chain.depleting])
        head = f"{where} [chain.depleting] [chain"
        msg = str(e)
        if msg.startswith(head) and msg[len(head):len(head) + 1] in ("]", "."):
            msg = f"{where} [chain.depleting" + msg[len(head):]
        raise UserError(msg) from None


def on_battery(need_j, usable_j: float, spent_j=None, trip=None) -> tuple[np.ndarray, np.ndarray]:
    """(each sample's share on the battery, the energy spent after it [J]) from its battery
    energy ``need_j`` (NaN: none): one series (``spent_j`` None, a charged battery at each
    ``trip``'s start) or one vehicle a sample, ``spent_j`` before it."""
    need = np.nan_to_num(np.asarray(need_j, float), nan=0.0)
    if spent_j is not None:
        s0 = np.broadcast_to(np.asarray(spent_j, float), need.shape)
        room = usable_j - s0
        live = s0 < usable_j
        whole = need <= room
        part = np.divide(room, need, out=np.zeros_like(need), where=need > 0)
        share = np.where(live, np.where(whole, 1.0, part), 0.0)
        return share, np.where(live, np.where(whole, np.maximum(s0 + need, 0.0), usable_j), s0)
    share = np.zeros(need.size)
    after = np.empty(need.size)
    s = 0.0
    for i, (x, new) in enumerate(zip(need.tolist(), _starts(trip, need.size).tolist())):
        if new:
            s = 0.0
        if s < usable_j:
            if x <= usable_j - s:
                share[i], s = 1.0, max(s + x, 0.0)
            else:
                share[i], s = (usable_j - s) / x, usable_j
        after[i] = s
    return share, after


def fuel_share(chain, p_w, v_mps, dt_s, signals=None, trip=None) -> np.ndarray:
    """Each sample's share on fuel, 1 − its share on the battery, of a fuel chain through one
    series (each ``trip`` starting charged, as :func:`on_battery`); 1 without ``[chain.depleting]``."""
    if chain.depleting is None:
        return np.ones(np.shape(p_w))
    bat = chain.depleting.chain.evaluate(p_w, v_mps, signals=signals)["power_w"]
    return 1.0 - on_battery(bat * np.asarray(dt_s, float), chain.depleting.usable_j, None, trip)[0]


def plug_in(dep: Depleting, fuel_out: dict, bat: dict, share, spent, spent_before, dt) -> dict:
    """The fuel chain's outputs ``fuel_out`` on (1 − share), the battery chain's ``bat`` on
    ``share`` — where a full battery takes less than braking gives, on what it takes — and the
    energy ``spent_j`` after each sample."""
    out = {k: (x * (1.0 - share) if k in FUEL_OUT else x) for k, x in fuel_out.items()}
    out["engine_on"] = fuel_out["engine_on"] & (share < 1.0)
    p = bat["power_w"]
    took = np.divide(spent - spent_before, p * dt, out=np.ones_like(p), where=(p < 0) & (share > 0))
    k = share * np.where(p < 0, took, 1.0)
    for name in ("traction", "recuperated", "auxiliary"):
        out[f"battery_{name}_w"] = bat[f"{name}_w"] * k
    out.update(battery_w=p * k, spent_j=spent)
    return out
