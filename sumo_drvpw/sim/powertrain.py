"""A vType's powertrain from its emissionClass, and which fuel chains' powertrains book it
(sim/resolver.py): a plug-in hybrid's (a chain with ``[chain.depleting]``, model/chain_plugin.py),
a full hybrid's (sim/carrier.is_hybrid_chain) or a conventional engine's."""

from __future__ import annotations

import re

from sumo_drvpw.sim.carrier import is_hybrid_class

#: a vType's powertrain → the fuel chains' powertrains that book it, the first present of each
POWERTRAIN_ORDER = {"plug-in hybrid": ("plug-in hybrid", "hybrid", "conventional"),
                    "hybrid": ("hybrid", "plug-in hybrid", "conventional"),
                    "conventional": ("conventional", "hybrid", "plug-in hybrid")}


def powertrain_of_class(emission_class: str | None) -> str:
    """A SUMO emissionClass's powertrain: ``plug-in hybrid`` (the word PHEV: HBEFA 4's
    ``PC_PHEV_petrol_Euro-6d_(P)``), ``hybrid`` (:func:`~sumo_drvpw.sim.carrier.is_hybrid_class`), else
    ``conventional``."""
    if "phev" in re.split(r"[^a-z0-9]+", (emission_class or "").lower()):
        return "plug-in hybrid"
    return "hybrid" if is_hybrid_class(emission_class) else "conventional"


def no_hybrid_chain_warning(powertrains: dict[str, dict]) -> str | None:
    """One line, or None: the vTypes whose emissionClass names a hybrid but which only
    conventional engines' fuel chains book (sim/resolver ``no_hybrid_chain``): they idle
    at every stop and recuperate nothing, so their fuel is overstated in town."""
    from sumo_drvpw.sim.resolver import few

    hits = {vt: p for vt, p in sorted(powertrains.items()) if p.get("no_hybrid_chain")}
    if not hits:
        return None
    parts = [f"{vt} ({p['emission_class']}: {', '.join(p['no_hybrid_chain'])})" for vt, p in hits.items()]
    return ("vTypes whose emissionClass names a hybrid were booked by a conventional engine's fuel "
            "chain, as no hybrid chain is made for their vClass: " + few(parts, 5)
            + " — that chain idles at every stop and recuperates nothing, so it books a hybrid's town "
            "driving high (full hybrid cars burn 33–56 % less than their petrol twins on the EPA's hot "
            "UDDS, docs/epa-hybrid.md); give these vTypes a hybrid chain (a fuel chain calibrated on "
            "such a vehicle's logs) in the scenario's equations (summary.json assumptions.powertrain)")
