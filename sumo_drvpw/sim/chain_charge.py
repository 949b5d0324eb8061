"""A plug-in hybrid's battery charge at departure, read as SUMO's battery device reads it.

A plug-in hybrid's chain ([chain.depleting], model/chain_plugin.py) spends its usable energy U
from each departure. A vehicle departs with the charge its SUMO battery device would start
with, in Wh of the usable energy left (read with libsumo 1.28.0, 2026-11-29, and
MSDevice_Battery::readParameterValue)::

    param actualBatteryCapacity (SUMO's old key) on the vehicle or its vType: the vehicle's, else the vType's
    else param device.battery.chargeLevel: the vehicle's, else the vType's
    (a <flow>'s params are its vehicles' <flow id>.<n>, as SUMO copies them)

The scenario's ``[vtypes.<id>] battery_charge_wh`` replaces what the vType's params say, its old
key too (as a vType's other scenario keys win over its params), not a vehicle's own; none of them: a charged
battery (U left). The energy spent at departure is then U − 3600 · charge [J];
a charge that is not a number, negative or above U is refused, naming the vehicle, its vType,
where the value was written and the key.

A vehicle already driving at a run's first step — an FCD replay from ``--begin``, a run resuming
a saved state — departed before it: what it spent since is in no FCD attribute nor route file
(SUMO's FCD can write its battery device's ``device.battery.chargeLevel`` through
``--fcd-output.params``, but for a plug-in's HBEFA class that device spends nothing: the value
stays the declared one), so its charge then is not known. It is booked from its charge at
departure (declared, else charged: an upper bound of what is left, its fuel a lower bound),
counted (``driving_at_begin``) and said once (:func:`begin_warning`).
"""

from __future__ import annotations

import math

import numpy as np

from sumo_drvpw.errors import UserError

#: SUMO's battery-device params of the charge at departure [Wh]: the key since SUMO 1.20, the old one
CHARGE_LEVEL, OLD_CHARGE = "device.battery.chargeLevel", "actualBatteryCapacity"
CHARGE_KEYS = (CHARGE_LEVEL, OLD_CHARGE)
#: the scenario's key of a vType's charge at departure [Wh]
SCENARIO_KEY = "battery_charge_wh"
WH = 3600.0


#: the route files' elements whose params declare a charge → the FileVTypes attribute they go in (sim/vtypes.py)
CHARGE_TAGS = {"vehicle": "vehicle_charge", "trip": "vehicle_charge", "flow": "flow_charge", "vType": "vtype_charge"}


def note_charge(out, path: str, tag: str, el) -> None:
    """The charge params of element ``el`` (its ``<param>`` children read; none but a
    :data:`CHARGE_TAGS` tag's) into ``out``'s (a :class:`~sumo_drvpw.sim.vtypes.FileVTypes`) dict
    of its tag, by id."""
    if not len(el) or tag not in CHARGE_TAGS or el.get("id") is None:  # (most <trip>s: no children)
        return
    got = {k: (p.get("value"), path) for p in el if (k := p.get("key")) in CHARGE_KEYS and p.get("value") is not None}
    if got:  # (children other than <param> have no key)
        out.__dict__.setdefault(CHARGE_TAGS[tag], {})[el.attrib["id"]] = got


class DepartureCharges:
    """Who declares a charge at departure: vehicles (id → {key: (value as written, file)}), flows (id →
    the same, for ids ``<flow>.<n>``), vTypes (id → the same), the scenario's vTypes (id → (Wh, its file))."""

    def __init__(self, vehicles=None, flows=None, vtypes=None, scenario=None, told=None):
        self.vehicles, self.flows = dict(vehicles or {}), dict(flows or {})
        self.vtypes, self.scenario = dict(vtypes or {}), dict(scenario or {})
        #: vehicle id → the charge [Wh] a TraCI script told (Accountant.set_battery_charge): first of all
        self.told = dict(told or {})
        #: vehicles that departed with a declared charge, booked by a plug-in chain, and their Wh
        self.departed, self.charge_wh = 0, 0.0
        #: vehicles a plug-in chain books that were driving at the run's first step (charge then unknown)
        self.at_begin = 0

    @classmethod
    def of_files(cls, fv, scenario=None) -> "DepartureCharges":
        """The charges route files declare (``fv``: :func:`~sumo_drvpw.sim.vtypes.read_vtypes`'s) and
        the scenario's vTypes (id → (Wh, its file))."""
        return cls(*(getattr(fv, CHARGE_TAGS[t], None) for t in ("vehicle", "flow", "vType")), scenario)

    def __bool__(self) -> bool:
        return bool(self.vehicles or self.flows or self.vtypes or self.scenario or self.told)

    def own(self, vid: str) -> dict:
        """The vehicle's own params (its flow's for ``<flow>.<n>``)."""
        if vid in self.vehicles:
            return self.vehicles[vid]
        flow, dot, n = vid.rpartition(".")
        return self.flows.get(flow, {}) if dot and n.isdigit() else {}

    def of(self, vid: str, vtype: str) -> tuple[str, str, str] | None:
        """(value as written, key, where) of vehicle ``vid`` of vType ``vtype``'s charge at
        departure [Wh], None for a charged battery (module doc: SUMO's order; a script's word first)."""
        if vid in self.told:
            return self.told[vid], "charge_wh", f"Accountant.set_battery_charge: vehicle '{vid}'"
        own, typ = self.own(vid), self.vtypes.get(vtype) or {}
        if vtype in self.scenario:  # the scenario's key replaces the vType's params, its old key too
            typ = {}
        key = OLD_CHARGE if OLD_CHARGE in own or OLD_CHARGE in typ else CHARGE_LEVEL  # the old key anywhere wins
        if key in own:
            return own[key][0], key, f"{own[key][1]}: vehicle '{vid}'"
        if vtype in self.scenario:  # (in place of the vType's params, as its other scenario keys)
            return self.scenario[vtype][0], f"[vtypes.{vtype}] {SCENARIO_KEY}", self.scenario[vtype][1]
        if key in typ:
            return typ[key][0], key, f"{typ[key][1]}: vType '{vtype}' (of vehicle '{vid}')"
        return None

    def depart(self, chain, vidx, ids, veh_type, veh_app, driving: bool = False) -> None:
        """Vehicle rows ``vidx`` (ids ``ids``) departed: each plug-in chain of ``chain`` (a
        :class:`~sumo_drvpw.sim.chain.ChainLedger`) that books one starts it with the energy
        spent that its declared charge leaves, U − 3600 · charge [J]. ``driving``: they were
        driving already at the run's first step (module doc): counted in :attr:`at_begin`."""
        plug = [(a, e, chain.chains[e].depleting.usable_j) for a, e in enumerate(chain.active) if chain.plug_in(e)]
        if not plug or not len(vidx):
            return
        chain._grow(int(np.max(vidx)) + 1)
        for i, vid in zip(np.asarray(vidx, np.int64).tolist(), ids):
            if driving and any(veh_app[i][e] > 0 for _, e, _ in plug):
                self.at_begin += 1
            said = self.of(vid, veh_type[i])
            if said is None:
                continue
            books = [(a, e, u) for a, e, u in plug if veh_app[i][e] > 0]
            if not books:
                continue
            val, key, where = said
            wh = _charge_wh(val, key, where)
            for a, e, u in books:
                if wh * WH > u * (1 + 1e-12):
                    raise UserError(f"{where}: {key} = {val!r} Wh is above the usable energy of {chain.names[e]}'s "
                                    f"plug-in battery ({u / WH:,.1f} Wh, [chain.depleting] usable_j), which books it: "
                                    "the charge at departure is the Wh left of that usable energy, not of the whole battery's capacity")
                chain._spent[i, a] = max(u - wh * WH, 0.0)
            self.departed += 1
            self.charge_wh += wh

    def summary(self) -> dict:
        """summary.json ``chain.departure_charge``."""
        return {"vehicles": self.departed, **({"driving_at_begin": self.at_begin} if self.at_begin else {}),
                "mean_charge_wh": round(self.charge_wh / self.departed, 6) if self.departed else None,
                "declared_by": {"vehicles": len(self.vehicles), "flows": len(self.flows), "vtypes": len(self.vtypes),
                                "scenario_vtypes": len(self.scenario), "script": len(self.told)},
                "rule": f"a plug-in hybrid departs with the Wh of its usable energy its SUMO battery device would: "
                        f"param {OLD_CHARGE} (vehicle, else vType), else {CHARGE_LEVEL} (vehicle, else the scenario's "
                        f"[vtypes.<id>] {SCENARIO_KEY}, which replaces the vType's params, else vType); none: charged; "
                        "a TraCI script's Accountant.set_battery_charge before all"}


def book_departures(chain, vidx, ids, veh_type, veh_app, driving: bool = False) -> None:
    """The loop's call at departures: :meth:`DepartureCharges.depart` on ``chain.charges``,
    made (empty) where none is declared but a plug-in chain books vehicles ``driving`` at the
    run's first step, so they are counted and said (:func:`begin_warning`)."""
    if chain.charges is None:
        if not (driving and any(chain.plug_in(e) for e in chain.active)):
            return
        chain.charges = DepartureCharges()
    chain.charges.depart(chain, vidx, ids, veh_type, veh_app, driving)


def begin_warning(charges: DepartureCharges | None) -> list[str]:
    """The warning, once, on the plug-in vehicles driving at the run's first step (module doc)."""
    n = charges.at_begin if charges is not None else 0
    if not n:
        return []
    return [f"{n} plug-in hybrid vehicle(s) were driving at the run's first step (an FCD replay from a begin "
            "time after the recording's start, or a resumed saved state): their battery charge then is not "
            "known (no FCD attribute nor route file holds what they spent before), so each is booked from its charge at departure (declared, else "
            "charged): their kWh are an upper bound, their fuel a lower bound (summary.json "
            "chain.departure_charge.driving_at_begin; replay from the recording's start to book them whole)"]


def _charge_wh(val, key: str, where: str) -> float:
    """A declared charge [Wh]: a finite number ≥ 0, else a UserError naming ``where`` and ``key``."""
    try:
        x = float(val)
    except (TypeError, ValueError):
        x = math.nan
    if not (math.isfinite(x) and x >= 0):
        raise UserError(f"{where}: {key} must be a number of Wh ≥ 0 (the battery's charge at departure), got {val!r}")
    return x
