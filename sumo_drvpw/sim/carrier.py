"""A vType's energy carrier and hybrid powertrain as its SUMO emissionClass names them,
SUMO's own emissionClass of a vType that sets none, and what an equation's chain books."""

from __future__ import annotations

import re

#: SUMO's own emissionClass of a vType that sets none, per vClass (SUMO 1.28,
#: ``vehicletype.getEmissionClass``); any other vClass: ``HBEFA4/PC_petrol_Euro-4``
SUMO_DEFAULT_EMISSION_CLASS = {
    "delivery": "HBEFA4/LCV_diesel_N1-III_Euro-6ab", "emergency": "HBEFA4/LCV_diesel_N1-III_Euro-6ab",
    "truck": "HBEFA4/RT_le7.5t_Euro-VI_A-C", "trailer": "HBEFA4/TT_AT_gt34-40t_Euro-VI_A-C",
    "bus": "HBEFA4/UBus_Std_gt15-18t_Euro-VI_A-C", "coach": "HBEFA4/Coach_3-Axes_gt18t_Euro-VI_A-C",
    "motorcycle": "HBEFA4/MC_4S_gt250cc_preEuro", "moped": "HBEFA4/Moped_le50cc_Euro-2",
    "evehicle": "Zero/default", "bicycle": "Zero/default", "pedestrian": "Zero/default",
}
SUMO_DEFAULT_EMISSION_CLASS_OTHER = "HBEFA4/PC_petrol_Euro-4"
#: words of an emission-class name → energy carrier, first match wins (electricity before
#: the fuels: HBEFA 4's ``PC_BEV``, ``UBus_Electric_…``; gas before petrol and diesel)
CARRIER_WORDS = (
    # "el": HBEFA4's electric mode of a plug-in hybrid (``PC_PHEV_petrol_Euro-6d_(El)``)
    ("electricity", {"bev", "electric", "ev", "zero", "el"}),
    ("hydrogen", {"fcev", "h2", "hydrogen", "fuelcell"}),
    ("gas", {"cng", "lng", "lpg", "gas"}),
    ("ethanol", {"ethanol", "e85"}),
    ("diesel", {"d", "diesel"}),
    ("gasoline", {"g", "petrol", "gasoline", "benzin"}),
)
#: the mode a HBEFA 4 class of a bi-fuel, flex-fuel or plug-in vehicle describes, written
#: last in parentheses → its carrier (``PC_CNG_petrol_Euro-4_(P)``: the petrol share of a
#: CNG car; ``LCV_FFV_N1-II_Euro-6__(P)``; ``RigidTruck_PHEV_le7_5t_Euro-VI-(D)``); a last
#: parenthesis of another kind (``(DPF)``, ``(CI)``) names none
MODE_CARRIERS = {"p": "gasoline", "d": "diesel", "el": "electricity", "cng": "gas", "lpg": "gas",
                 "lng": "gas", "e85": "ethanol"}
#: emission-class models that are electric whatever the name (SUMO's Energy and MMPEVEM
#: models, and Zero: no exhaust)
ELECTRIC_MODELS = ("energy", "mmpevem", "zero")
#: heavy-duty HBEFA/PHEMlight names without a fuel word are diesel (HBEFA's default for
#: trucks and buses: ``HBEFA4/RT_le7.5t_Euro-VI_A-C``, ``HBEFA3/Bus``, ``HBEFA3/HDV``)
DIESEL_BODIES = ("hdv", "hgv", "rt", "rigidtruck", "tt", "ubus", "bus", "coach", "lcv", "ldv")
#: and motorcycle and moped names are petrol (``HBEFA4/MC_4S_gt250cc_preEuro``)
PETROL_BODIES = ("mc", "moped")


def energy_carrier(emission_class: str | None) -> str | None:
    """The energy carrier a SUMO emissionClass names: ``electricity``, ``gasoline``,
    ``diesel``, ``gas``, ``ethanol``, ``hydrogen``, or None when it names none (no class, or a name of
    no known pattern). Read from the model (``Energy/…``, ``MMPEVEM/…``, ``Zero/…``, or
    the bare model name, as SUMO's shipped ``data/emissions/MMPEVEM`` files write it:
    electricity) and the words of the name (``PC_petrol_Euro-4``, ``PC_G_EU4``: gasoline;
    ``LCV_diesel_…``, ``PC_D_EU6``: diesel; ``PC_BEV``, a plug-in hybrid's electric mode
    ``PC_PHEV_petrol_Euro-6d_(El)``: electricity; ``PC_FuelCell``: hydrogen; the mode a
    bi-fuel, flex-fuel or plug-in class names last first: ``PC_CNG_petrol_Euro-4_(P)``,
    the petrol share of a CNG car, is gasoline, :data:`MODE_CARRIERS`); a heavy-duty
    name without a fuel word is diesel."""
    if not emission_class:
        return None
    model, _, name = emission_class.strip().partition("/")
    if not name:  # a bare name: SUMO's own MMPEVEM files write emissionClass="MMPEVEM"
        model, name = ("", model) if model.strip().lower() not in ELECTRIC_MODELS else (model, "")
    if model.strip().lower() in ELECTRIC_MODELS:
        return "electricity"
    mode = re.search(r"\(([A-Za-z0-9]+)\)\s*$", name)
    if mode and mode.group(1).lower() in MODE_CARRIERS:
        return MODE_CARRIERS[mode.group(1).lower()]
    words = [w for w in re.split(r"[^a-z0-9]+", name.lower()) if w]
    for carrier, keys in CARRIER_WORDS:
        if any(w in keys for w in words):
            return carrier
    if words and words[0] in DIESEL_BODIES:
        return "diesel"
    if words and words[0] in PETROL_BODIES:
        return "gasoline"
    return None


def equation_carrier(eq) -> str | None:
    """What an equation's chain books: its fuel (``gasoline``, ``diesel``), ``electricity``
    for a battery chain; None for driving power (no chain, or wheel / powertrain output)."""
    ch = getattr(eq, "chain", None)
    if ch is None:
        return None
    if ch.predicts == "fuel":
        return ch.fuel
    return "electricity" if ch.predicts == "battery" else None


#: words of an emission-class name that make it a hybrid's (HBEFA 4's plug-in hybrids,
#: ``PC_PHEV_petrol_Euro-6d_(P)``: the share they drive on petrol)
HYBRID_WORDS = {"phev", "hev", "hybrid"}


def is_hybrid_class(emission_class: str | None) -> bool:
    """Whether a SUMO emissionClass names a hybrid (:data:`HYBRID_WORDS`)."""
    return any(w in HYBRID_WORDS for w in re.split(r"[^a-z0-9]+", (emission_class or "").lower()))


def is_hybrid_chain(eq) -> bool | None:
    """For an equation whose chain books fuel: whether it is a hybrid's (charge-sustaining,
    the engine off below a positive driving power: the battery drives; a conventional
    engine's start-stop, off at P ≤ 0, is not); None for any other equation."""
    ch = getattr(eq, "chain", None)
    if ch is None or ch.predicts != "fuel":
        return None
    return bool(ch.charge_sustaining and ch.engine_off_below_w > 0)
