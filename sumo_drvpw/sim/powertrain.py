"""A vType's powertrain from its emissionClass, and which fuel chains' powertrains book it
(sim/resolver.py): a plug-in hybrid's (a chain with ``[chain.depleting]``, model/chain_plugin.py),
a full hybrid's (sim/vtypes.is_hybrid_chain) or a conventional engine's."""

from __future__ import annotations

import re

from sumo_drvpw.sim.vtypes import is_hybrid_class

#: a vType's powertrain → the fuel chains' powertrains that book it, the first present of each
POWERTRAIN_ORDER = {"plug-in hybrid": ("plug-in hybrid", "hybrid", "conventional"),
                    "hybrid": ("hybrid", "plug-in hybrid", "conventional"),
                    "conventional": ("conventional", "hybrid", "plug-in hybrid")}


def powertrain_of_class(emission_class: str | None) -> str:
    """A SUMO emissionClass's powertrain: ``plug-in hybrid`` (the word PHEV: HBEFA 4's
    ``PC_PHEV_petrol_Euro-6d_(P)``), ``hybrid`` (:func:`~sumo_drvpw.sim.vtypes.is_hybrid_class`), else
    ``conventional``."""
    if "phev" in re.split(r"[^a-z0-9]+", (emission_class or "").lower()):
        return "plug-in hybrid"
    return "hybrid" if is_hybrid_class(emission_class) else "conventional"
