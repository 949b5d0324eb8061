"""vType data from SUMO route/additional files: explicit mass and drvpw.* parameters.

"Without mass" means: the vType definition carries neither a ``mass`` attribute nor a
``<param key="drvpw.mass">``, and the scenario gives no ``vtypes.<id>.mass_kg``. SUMO
itself would then use a default (``vehicletype.getMass`` says 1500 kg, the Energy model
1830 kg), so asking SUMO cannot tell an explicit mass from a default one; the files are
read instead.
"""

from __future__ import annotations

import gzip
import re
import xml.etree.ElementTree as ET
import zlib
from dataclasses import dataclass
from pathlib import Path

from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import open_maybe_gzip
from sumo_drvpw.model.energy_params import ENERGY_PARAMS
from sumo_drvpw.model.mmpevem import MMPEVEM_PARAMS
from sumo_drvpw.sim.carrier import SUMO_DEFAULT_EMISSION_CLASS, SUMO_DEFAULT_EMISSION_CLASS_OTHER
from sumo_drvpw.sim.chain_charge import note_charge
from sumo_drvpw.sim.scenario import NON_ROAD_CLASSES, NON_ROAD_MASS_MAX_KG, ON_FOOT_MASS_MAX_KG
from sumo_drvpw.sim.shutoff import SHUT_OFF_PARAMS
from sumo_drvpw.sim.sumo_outputs import INCLUDE_DEPTH


#: Default mass per SUMO vClass [kg] for vTypes that give none: the MOVES source mass of
#: the source type whose road load the class's built-in equation uses (docs/sources.md
#: [MOVES-ST]; sourceTypeID in brackets), but a moped's own (MOVES has none; kerb + rider:
#: :data:`DEFAULT_MASS_SOURCE`). Used only when neither the vType nor the scenario
#: gives a mass; every use is listed in summary.json ``assumptions``.
DEFAULT_MASS_KG = {
    "passenger": 1478.8, "private": 1478.8, "taxi": 1478.8, "hov": 1478.8,  # (21)
    "vip": 1478.8, "evehicle": 1478.8, "authority": 1478.8,                 # (21)
    "motorcycle": 285.0, "moped": 92.0 + 75.0,                              # (11), C2W
    "delivery": 2059.7, "emergency": 2059.7,                                # (32)
    "bus": 16556.0, "coach": 19593.0,                                       # (42), (41)
    "truck": 8538.9, "army": 8538.9,                                        # (52)
    "trailer": 24419.0,                                                     # (62)
}
#: MOVES source type behind each default mass (for the summary's assumptions).
DEFAULT_MASS_SOURCE = {
    **{c: "MOVES source type 21 (passenger car) source mass" for c in (
        "passenger", "private", "taxi", "hov", "vip", "evehicle", "authority")},
    "motorcycle": "MOVES source type 11 (motorcycle) source mass",
    "moped": "a 50-cm³ petrol scooter (EU L1e) with its rider: kerb 92 kg (carculator_two_wheeler's petrol "
             "scooter < 4 kW, 91-94 kg, manufacturers' data) + the 75-kg driver of EU L-category approval",
    **{c: "MOVES source type 32 (light commercial truck) source mass" for c in ("delivery", "emergency")},
    "bus": "MOVES source type 42 (transit bus) source mass",
    "coach": "MOVES source type 41 (intercity bus) source mass",
    **{c: "MOVES source type 52 (single unit short-haul truck) source mass" for c in ("truck", "army")},
    "trailer": "MOVES source type 62 (combination long-haul truck) source mass",
}


#: vClasses that say what a vehicle may use, not what it is: SUMO's ``ignoring`` (ignores
#: lane permissions) and the user-defined ``custom1``/``custom2`` (e.g. the DLR scenarios'
#: "restricted" delivery vans and trucks). A vType of these classes is booked as the road
#: vehicle its own ``emissionClass``, ``guiShape`` or id names (:func:`body_vclass`).
GENERIC_VCLASSES = ("ignoring", "custom1", "custom2")

#: Emission-class name prefixes (after the model, e.g. ``HBEFA3/``) → the vClass whose
#: vehicle they describe, a specific prefix before a general one: HBEFA 2 (``P_``, ``LDV``, ``HDV``), HBEFA 3
#: (``PC``, ``LDV``, ``HDV``, ``Bus``, ``Coach``, ``MC``, ``Moped``), HBEFA 4 (``PC``,
#: ``LCV``, ``RT`` rigid truck, ``TT`` tractor-trailer, ``UBus``, ``Coach``, ``MC``,
#: ``Moped``) and PHEMlight (``PC``, ``LCV``, ``HDV_RB``/``HDV_RT`` rigid, ``HDV_TT``
#: tractor-trailer, ``Bus``, ``Coach``, ``MC``) as SUMO's emission-model pages list them.
#: Classes that name no body (``Energy/…``, ``MMPEVEM/…``, ``zero``) are not here.
EMISSION_CLASS_BODY = (
    ("hdv_tt", "trailer"), ("hdv_rb", "truck"), ("hdv_rt", "truck"), ("ubus", "bus"),
    ("coach", "coach"), ("moped", "moped"), ("bus", "bus"), ("ldv", "delivery"),
    ("lcv", "delivery"), ("hdv", "truck"), ("rt_", "truck"), ("tt_", "trailer"),
    ("pc", "passenger"), ("pkw", "passenger"), ("p_", "passenger"), ("mc_", "motorcycle"),
    ("mc", "motorcycle"),
)
#: SUMO ``guiShape`` values (its vehicle shapes) → the vClass whose vehicle they draw
GUI_SHAPE_BODY = {
    "passenger": "passenger", "passenger/sedan": "passenger",
    "passenger/hatchback": "passenger", "passenger/wagon": "passenger",
    "passenger/van": "passenger", "taxi": "passenger", "police": "passenger",
    "evehicle": "passenger", "delivery": "delivery", "emergency": "emergency",
    "firebrigade": "truck", "truck": "truck", "truck/semitrailer": "trailer",
    "truck/trailer": "trailer", "bus": "bus", "bus/city": "bus", "bus/flexible": "bus",
    "bus/trolley": "bus", "bus/overland": "coach", "bus/coach": "coach",
    "motorcycle": "motorcycle", "moped": "moped", "scooter": "moped",
}


#: Whole words of a vType id → the vClass whose vehicle they name (the last hint: DLR's
#: "restricted_delivery_3.5t_evehicle" is vClass custom1 with emissionClass Energy/unknown)
ID_WORD_BODY = {
    "passenger": "passenger", "car": "passenger", "pkw": "passenger", "taxi": "passenger",
    "delivery": "delivery", "van": "delivery", "lcv": "delivery", "ldv": "delivery",
    "truck": "truck", "lkw": "truck", "hgv": "truck", "trailer": "trailer",
    "semitrailer": "trailer", "bus": "bus", "coach": "coach", "motorcycle": "motorcycle",
    "moped": "moped",
}


def body_vclass(emission_class: str | None, gui_shape: str | None,
                vtype_id: str | None = None) -> tuple[str, str] | None:
    """The road vClass whose vehicle a vType's ``emissionClass`` (first: it is what the
    modeller chose for energy; a generic heavy-duty ``HDV`` class with an id that says
    trailer, bus or coach: that), else its ``guiShape``, else the words of its id name (only
    when they name one vehicle), with where it came from; None when none names one (e.g.
    ``Energy/unknown``, no shape, an id like "type1")."""
    by_id = None
    if vtype_id:
        words = {w for w in re.split(r"[^a-z]+", vtype_id.lower()) if w in ID_WORD_BODY}
        named = {ID_WORD_BODY[w] for w in words}
        if len(named) == 1:
            by_id = named.pop(), f"the word {sorted(words)[0]!r} in its id"
    if emission_class:
        name = emission_class.split("/", 1)[-1].strip().lower()
        for prefix, vclass in EMISSION_CLASS_BODY:
            if name.startswith(prefix):
                if prefix == "hdv" and by_id is not None and by_id[0] in ("trailer", "bus", "coach"):
                    # a generic heavy-duty class (HBEFA 2/3 HDV): the id may say which
                    return by_id[0], f"emissionClass {emission_class} (heavy duty) and {by_id[1]}"
                return vclass, f"emissionClass {emission_class}"
    if gui_shape and gui_shape.strip().lower() in GUI_SHAPE_BODY:
        return GUI_SHAPE_BODY[gui_shape.strip().lower()], f"guiShape {gui_shape}"
    return by_id


#: Light and heavy road vehicles: a vType whose vClass is in one and whose written
#: emissionClass names a vehicle of the other has its vClass for lane permissions (Bologna's
#: acosta_persontrips: 5-m sedans with emissionClass HBEFA2/P_7_7 in vClass bus, for the
#: bus lanes); its energy is the emission class's vehicle, as in SUMO's emission models.
LIGHT_VCLASSES = ("passenger", "private", "taxi", "hov", "vip", "evehicle", "authority",
                  "delivery", "emergency", "motorcycle", "moped")
HEAVY_VCLASSES = ("truck", "army", "trailer", "bus", "coach")


#: Heavy vClasses → the longest written vType length [m] that is a van or minibus, not
#: that vehicle: SUMO's default lengths are bus 12 m, coach 14 m, truck 7.1 m, delivery
#: 6.5 m (SUMO vehicle-type defaults); a demand-responsive shuttle written as vClass bus
#: for the bus lanes, 6 m long with 5 seats (SUMO's DRT game), is a van.
VAN_LENGTH_M = {"bus": 7.5, "coach": 7.5, "truck": 6.5}
#: a bus or coach of at most this many passengers (a minibus that drives on a car licence
#: in the EU: up to 8 passenger seats) and at most :data:`MINIBUS_LENGTH_M` long is a van
#: too (the DRT game's 8-m, 9-person shuttle)
MINIBUS_CAPACITY = 9
MINIBUS_LENGTH_M = 9.0
#: Car vClasses whose vType may be a two-wheeler: a motorcycle taxi (an ojek, a boda boda)
#: written as vClass taxi with guiShape motorcycle and a 2-m length (the user scenario
#: ErinDelaRosa/MotortaxiTraCI) is booked as the motorcycle its shape and length say, when
#: it is no longer than TWO_WHEELER_MAX_LENGTH_M (SUMO 1.28's default motorcycle is 2.2 m,
#: moped 2.1 m, every car class 5 m)
CAR_VCLASSES = ("passenger", "private", "taxi", "hov", "vip", "evehicle", "authority")
TWO_WHEELER_MAX_LENGTH_M = 3.0
#: a car vType written shorter than this [m] is a microcar or a pod, not the mid-size car
#: whose mass a car class's default is (SUMO's default car is 5 m; a two-seater city car is
#: about 2.7 m and under 1 t)
SHORT_CAR_M = 3.0
#: a car vType whose guiShape draws a heavy vehicle and whose written length is at least
#: this [m] (longer than any car; SUMO's default truck is 7.1 m) is that heavy vehicle: SUMO's
#: taxi test devices/taxi/basic/1container writes its container taxi as vClass taxi, guiShape
#: truck, 7.1 m long (booked as a 1,478.8-kg car before)
HEAVY_SHAPE_MIN_LENGTH_M = 6.5
#: a van weighs at most this [kg] (EU categories N1 and M1, the car-licence limit): a short
#: bus, coach or truck whose vType declares a larger mass stays heavy (a 6-m, 7.5-t rigid truck)
VAN_MAX_MASS_KG = 3500.0


def default_mass_warnings(assumptions: dict) -> list[str]:
    """The run's warnings on the default masses it took (``VTypeResolver.assumptions``):
    which vTypes took one, and which of them are written far shorter than the car whose
    mass they took (``length_m`` in their assumption: :data:`SHORT_CAR_M`)."""
    if not assumptions:
        return []
    out = ["vTypes without a mass took their vClass's default mass: " + ", ".join(
        f"{vt} ({a['vclass']}, {a['mass_kg']:g} kg)" for vt, a in sorted(assumptions.items()))
        + " (summary.json assumptions; set vtypes.<id>.mass_kg or vclasses.<vClass>.mass_kg to override)"]
    capped = {vt: a for vt, a in sorted(assumptions.items()) if a.get("capped_from_kg") is not None}
    if capped:  # (sim/resolver.class_mass_limit_kg)
        out[0] += ("; capped at the gross weight their emissionClass names: " + ", ".join(
            f"{vt} ({a['emission_class']}: {a['capped_from_kg']:g} → {a['mass_kg']:g} kg)" for vt, a in capped.items()))
    short = {vt: a for vt, a in sorted(assumptions.items()) if a.get("length_m") is not None}
    if short:
        out.append("vTypes written far shorter than a car took a mid-size car's default mass all the "
                   "same: " + ", ".join(f"{vt} ({a['vclass']}, {a['length_m']:g} m long, {a['mass_kg']:g} kg)"
                                        for vt, a in short.items())
                   + f" — a car under {SHORT_CAR_M:g} m is a microcar or a pod (a 2.7-m two-seater weighs "
                   "under 1 t): give their mass, or their energy is overstated")
    return out


def vehicle_body(vclass: str, info: "VTypeInfo | None", vtype_id: str) -> tuple[str, str] | None:
    """The road vehicle a vType is booked as when its vClass does not say it (None: the
    vClass does), with why: for a generic vClass (:data:`GENERIC_VCLASSES`) what
    :func:`body_vclass` reads; for a light or heavy vClass whose written emissionClass
    names a vehicle of the other weight, that vehicle; for a car vClass whose guiShape is a
    two-wheeler's and whose written length is one's (:data:`TWO_WHEELER_MAX_LENGTH_M`), that
    two-wheeler; for a bus, coach or truck written
    no longer than a van (:data:`VAN_LENGTH_M`) and with no emissionClass naming a
    vehicle nor a mass above a van's (:data:`VAN_MAX_MASS_KG`), a van (delivery)."""
    if info is None:
        return None
    if vclass in GENERIC_VCLASSES:
        return body_vclass(info.emission_class, info.gui_shape, vtype_id)
    ec = body_vclass(info.emission_class, None)
    if ec is None:
        if info.mass_kg is not None and info.mass_kg > VAN_MAX_MASS_KG:
            return None  # its mass says heavy, whatever its length
        L, cap = info.length_m, info.person_capacity
        shape = GUI_SHAPE_BODY.get((info.gui_shape or "").strip().lower())
        if (vclass in CAR_VCLASSES and shape in ("motorcycle", "moped") and L is not None
                and L <= TWO_WHEELER_MAX_LENGTH_M):
            return shape, (f"guiShape {info.gui_shape} and length {L:g} m: a two-wheeler (a "
                           f"{vclass} car is longer), e.g. a motorcycle taxi")
        if (vclass in CAR_VCLASSES and shape in HEAVY_VCLASSES + ("delivery",) and L is not None
                and L >= HEAVY_SHAPE_MIN_LENGTH_M):
            return shape, (f"guiShape {info.gui_shape} and length {L:g} m: a {shape}, not the car a "
                           f"vClass {vclass} is (a car is shorter), e.g. a taxi that carries containers")
        if L is not None and L <= VAN_LENGTH_M.get(vclass, 0.0):
            return "delivery", (f"length {L:g} m: a van or minibus (a {vclass} is longer; "
                                f"SUMO's default {vclass} is {SUMO_DEFAULT_LENGTH_M[vclass]:g} m)")
        if (vclass in ("bus", "coach") and L is not None and L <= MINIBUS_LENGTH_M
                and cap is not None and cap <= MINIBUS_CAPACITY):
            return "delivery", f"length {L:g} m and personCapacity {cap}: a minibus, not a {vclass}"
        own = body_vclass(SUMO_DEFAULT_EMISSION_CLASS.get(vclass, SUMO_DEFAULT_EMISSION_CLASS_OTHER), None)
        if (own and own[0] in LIGHT_VCLASSES and vclass in HEAVY_VCLASSES and info.emission_class is None
                and (L is None or L < HEAVY_SHAPE_MIN_LENGTH_M)):  # army: SUMO's is a car, 5 m, 1500 kg
            return own[0], f"nothing written says heavy, and SUMO's own {vclass} vehicle is light: its default {own[1]}"
        return None
    light = {c: True for c in LIGHT_VCLASSES} | {c: False for c in HEAVY_VCLASSES}
    if vclass in light and ec[0] in light and light[vclass] != light[ec[0]]:
        return ec[0], (f"{ec[1]}: a {'light' if light[ec[0]] else 'heavy'} vehicle, while vClass "
                       f"{vclass} (a {'light' if light[vclass] else 'heavy'} one) only grants its lanes")
    return None


@dataclass
class VTypeInfo:
    """What the files say about one vType: mass [kg] (None: not given), equation, source,
    vClass (None: not given; SUMO's default is passenger)."""

    id: str
    mass_kg: float | None
    equation: str | None
    source: str
    vclass: str | None = None
    #: SUMO's ``loading`` param [kg], the payload its emission models add to the mass;
    #: included in :attr:`mass_kg` when that comes from SUMO's mass, added by the run to a
    #: class mass when the vType gives none
    loading_kg: float = 0.0
    #: the ``emissionClass`` and ``guiShape`` attributes as written (None: not given)
    emission_class: str | None = None
    gui_shape: str | None = None
    #: the ``length`` attribute as written [m] (None: not given, SUMO's class default)
    length_m: float | None = None
    #: the ``personCapacity`` attribute as written (None: not given)
    person_capacity: int | None = None
    #: param ``drvpw.cold_start``: the share of its trips that start a cold engine (None:
    #: not given; the scenario's vType, vClass or run-wide share applies)
    cold_start: float | None = None
    #: SUMO's emission-model params that switch a vehicle off (``shutOffStopDuration``,
    #: ``shutOffAutoDuration``: :data:`SHUT_OFF_PARAMS`) as written: what an FCD replay's
    #: vehicletype.getParameter answers (:mod:`sumo_drvpw.sim.shutoff` reads them as SUMO)
    shut_off: dict | None = None
    #: SUMO's Energy-model params as written (:data:`sumo_drvpw.model.energy_params.ENERGY_PARAMS`,
    #: ``loading``, ``maximumPower``; key → value string), None when it writes none of them
    energy_params: dict | None = None
    #: the ``mass`` attribute as written [kg] (None: not given; the Energy model then takes
    #: the vehicleMass param, else its default)
    mass_attr_kg: float | None = None
    #: whether param ``drvpw.mass`` (the plug-in's own mass) is written
    drvpw_mass: bool = False
    #: whether param ``has.battery.device`` is true (SUMO then runs a vType without an
    #: emissionClass on its Energy model: "The emission class Energy/unknown will be used")
    battery_device: bool = False
    #: its car-following attributes as written (:data:`CF_KEYS`; a ``<carFollowing-X>``
    #: child's over the vType's own, and model X), None when it writes none of them
    driving: dict | None = None
    #: the ``actionStepLength`` attribute as written [s] (None: not given, the step length)
    action_step_s: float | None = None


#: the vTypes SUMO declares itself, and their vClasses (SUMO 1.28,
#: ``vehicletype.getVehicleClass``): what an FCD replay, which has no SUMO to ask, reads
#: for a vehicle of such a type that no file redeclares
SUMO_DEFAULT_VTYPES = {"DEFAULT_VEHTYPE": "passenger", "DEFAULT_PEDTYPE": "pedestrian",
                       "DEFAULT_BIKETYPE": "bicycle", "DEFAULT_TAXITYPE": "taxi",
                       "DEFAULT_RAILTYPE": "rail", "DEFAULT_CONTAINERTYPE": "container"}
SUMO_DEFAULT_LENGTH_M = {"bus": 12.0, "coach": 14.0, "truck": 7.1}  # SUMO's default lengths of heavy vTypes [m] (the booking note; army: 5 m, a car's, below)

#: SUMO's mass of a vType that gives none, per vClass [kg] (SUMOVTypeParameter::
#: VClassDefaultValues; libsumo 1.28 vehicletype.getMass agrees for every vClass,
#: tests/test_containers_said.py); any other vClass (passenger, the vClass of a vType that
#: names none, container, ignoring …): :data:`SUMO_VEH_MASS_KG`
SUMO_VCLASS_MASS_KG = {
    "pedestrian": 70.0, "wheelchair": 90.0, "bicycle": 10.0, "scooter": 10.0, "moped": 80.0,
    "motorcycle": 200.0, "truck": 4500.0, "trailer": 13000.0, "bus": 12000.0, "coach": 25000.0,
    "tram": 37900.0, "rail_urban": 59000.0, "subway": 59000.0, "rail": 79500.0,
    "rail_electric": 83000.0, "rail_fast": 409000.0, "delivery": 5000.0, "emergency": 5000.0,
    "ship": 100000.0}
SUMO_VEH_MASS_KG = 1500.0  # (DEFAULT_VEH_MASS)
#: the masses of SUMO's own vTypes [kg] (their vClasses': a person's DEFAULT_PEDTYPE 70 kg,
#: a container's DEFAULT_CONTAINERTYPE 1,500 kg …)
SUMO_DEFAULT_TYPE_MASS_KG = {vt: SUMO_VCLASS_MASS_KG.get(vc, SUMO_VEH_MASS_KG) for vt, vc in SUMO_DEFAULT_VTYPES.items()}


def sumo_type_mass(files, vt: str) -> float | None:
    """The mass SUMO gives vType ``vt`` [kg] (``vehicletype.getMass``), as the route files
    ``files`` (:func:`~sumo_drvpw.sim.vtypes.read_vtypes`) declare it: its ``mass``, else its
    ``vehicleMass`` param, else its vClass's default (:data:`SUMO_VCLASS_MASS_KG`; no vClass:
    a passenger's, for a person's vType too — SUMO warns it "implicitly uses unsuitable vClass
    'passenger'", and for SUMO's own ``DEFAULT_PEDTYPE`` … redeclared without one: SUMO 1.28
    gives it 1,500 kg); SUMO's own vTypes where no file redeclares them; None for a vType of
    no file. What a rider adds to its vehicle (EnergyParams::
    getTransportableMass: its vType's mass; neither ``loading`` nor ``drvpw.mass``)."""
    info = files.get(vt)
    if info is None:
        return SUMO_DEFAULT_TYPE_MASS_KG.get(vt)
    if info.mass_attr_kg is not None:
        return info.mass_attr_kg
    try:
        return float((info.energy_params or {})["vehicleMass"])
    except (KeyError, ValueError):
        pass
    return SUMO_VCLASS_MASS_KG.get(info.vclass or "passenger", SUMO_VEH_MASS_KG)


def _length(val: str | None) -> float | None:
    """A written vType length [m]; None when absent or not a positive number (SUMO itself
    refuses a bad one)."""
    try:
        x = float(val) if val is not None else None
    except ValueError:
        return None
    return x if x is not None and x > 0 else None


def _capacity(val: str | None) -> int | None:
    try:
        x = int(val) if val is not None else None
    except ValueError:
        return None
    return x if x is not None and x >= 0 else None


ROAD_MASS_MAX_KG = 1.0e6  #: the heaviest mass [kg] of a road vClass's vType (road trains: some 200 t)
NOT_ROAD_VCLASSES = frozenset().union(*NON_ROAD_CLASSES.values())  # the vClasses of no road edge


def _mass(where: str, key: str, val: str | None, zero: bool = False) -> float | None:
    """A mass [kg] from a vType attribute or param (None when absent); > 0 (≥ 0 with
    ``zero``), else a UserError naming the vType and the key."""
    if val is None:
        return None
    try:
        x = float(val)
    except ValueError:
        raise UserError(f"{where}: {key} is not a number: {val!r}") from None
    if not (x >= 0 if zero else x > 0) or x == float("inf"):  # (inf: SUMO reads it; 'inf L' booked)
        raise UserError(f"{where}: {key} must be a finite number {'≥' if zero else '>'} 0, got {val!r}")
    return x


def _cold_share(where: str, val: str | None) -> float | None:
    """Param ``drvpw.cold_start``: true/false or a share 0–1."""
    if val is None:
        return None
    s = val.strip().lower()
    if s in ("true", "false"):
        return 1.0 if s == "true" else 0.0
    try:
        x = float(s)
    except ValueError:
        x = float("nan")
    if not 0.0 <= x <= 1.0:
        raise UserError(f"{where}: drvpw.cold_start must be true, false or a share from 0 to 1, got {val!r}")
    return x


def _vehicle_share(out: FileVTypes, path: Path, tag: str, el) -> None:
    """A ``<vehicle>``/``<trip>``/``<flow>`` element's own ``drvpw.cold_start`` into ``out``."""
    for p in el:
        if p.tag.split("}")[-1] == "param" and p.attrib.get("key") == "drvpw.cold_start":
            vid = el.attrib.get("id")
            if vid is not None:
                share = _cold_share(f"{path}: {tag} '{vid}'", p.attrib.get("value", ""))
                getattr(out, VEHICLE_TAGS[tag])[vid] = share


class FileVTypes(dict):
    """vType id → :class:`VTypeInfo` of the route/additional files (:func:`read_vtypes`),
    plus the cold-start shares the files give single vehicles: ``vehicle_cold_start``
    (``<vehicle>`` / ``<trip>`` id → share) and ``flow_cold_start`` (``<flow>`` id → share,
    for its vehicles ``<flow id>.<n>``, as SUMO names them and copies the flow's params)."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.vehicle_cold_start: dict[str, float] = {}
        self.flow_cold_start: dict[str, float] = {}
        #: ``<container>``/``<containerFlow>`` elements of the files: their count, id → vType (a
        #: flow's containers are ``<id>.<n>``) and vTypes (SUMO's tabular FCD writes them as persons)
        self.containers, self.container_of, self.container_types = 0, {}, set()
        #: ids of the files' ``<vTypeDistribution>`` elements (vehicles name them as a type)
        self.distributions: set[str] = set()


#: the vType params of SUMO's Energy model and MMPEVEM a file's vType keeps (:attr:`VTypeInfo.energy_params`)
ENERGY_KEYS = tuple(dict.fromkeys(ENERGY_PARAMS + ("loading", "maximumPower") + MMPEVEM_PARAMS))

#: the values SUMO reads as true (StringUtils::toBool, case-insensitive; each checked with
#: libsumo 1.28.0 as has.battery.device, 2026-11-27)
SUMO_TRUE = ("1", "yes", "true", "on", "x", "t")


def is_true(val: str | None) -> bool:
    """Whether SUMO reads a param or option value as true."""
    return val is not None and val.strip().lower() in SUMO_TRUE


#: the car-following attributes a file's vType keeps (:attr:`VTypeInfo.driving`)
CF_KEYS = ("carFollowModel", "accel", "decel", "sigma", "sigmaStep", "speedTable", "desAccelProfile",
           "maxAccelProfile")
CF_CHILD = "carFollowing-"


def _action_step(text: str | None) -> float | None:
    """:attr:`VTypeInfo.action_step_s` from the attribute (None: not given or not a number,
    which SUMO refuses itself)."""
    try:
        return None if text is None else float(text)
    except ValueError:
        return None


def _driving(el) -> dict | None:
    """:attr:`VTypeInfo.driving` of a ``<vType>`` element (its children still attached)."""
    out = {k: el.attrib[k] for k in CF_KEYS if el.attrib.get(k) is not None}
    for ch in el:
        tag = ch.tag.split("}")[-1]
        if tag.startswith(CF_CHILD):
            out.update({k: ch.attrib[k] for k in CF_KEYS if ch.attrib.get(k) is not None})
            out["carFollowModel"] = tag[len(CF_CHILD):]
    return out or None


VEHICLE_TAGS = {"vehicle": "vehicle_cold_start", "trip": "vehicle_cold_start", "flow": "flow_cold_start"}  # (vehicles' own params)


def read_vtypes(files: list[Path]) -> FileVTypes:
    """Read every ``<vType>`` of the given route/additional files, and the param
    ``drvpw.cold_start`` of their ``<vehicle>``, ``<trip>`` and ``<flow>`` elements
    (:class:`FileVTypes`).

    Mass: param ``drvpw.mass`` (the plug-in's: the vehicle's whole mass) > attribute ``mass``
    (else the deprecated param ``vehicleMass``, which SUMO reads as the mass) plus param
    ``loading``, the payload SUMO's emission models add to it (EnergyParams::getTotalMass).
    """
    out = FileVTypes()
    for path in files:
        _read_vtypes(Path(path), out, 0)
    return out


def _read_vtypes(path: Path, out: FileVTypes, depth: int) -> None:
    """:func:`read_vtypes` of one file, and of the files it ``<include href>``s (relative
    to it, as SUMO resolves them), in document order."""
    try:
        with open_maybe_gzip(path) as fh:
            for _, el in ET.iterparse(fh, events=("end",)):
                tag = el.tag.split("}")[-1]
                note_charge(out, str(path), tag, el)  # a plug-in hybrid's battery charge at departure, if any
                if tag == "include" and el.attrib.get("href"):
                    inc = path.parent / el.attrib["href"]
                    if depth >= INCLUDE_DEPTH:
                        raise UserError(f"{path}: <include href={el.attrib['href']!r}> "
                                        f"nested more than {INCLUDE_DEPTH} deep (a cycle?)")
                    if not inc.is_file():
                        raise UserError(f"{path}: <include href={el.attrib['href']!r}>: "
                                        f"no such file {inc}")
                    _read_vtypes(inc, out, depth + 1)
                    el.clear()
                    continue
                if tag in VEHICLE_TAGS:
                    _vehicle_share(out, path, tag, el)
                    el.clear()
                    continue
                if tag in ("container", "containerFlow"):
                    out.containers += 1
                    box = el.attrib.get("type", "DEFAULT_CONTAINERTYPE")
                    out.container_of[el.attrib.get("id", "")] = box
                    out.container_types.add(box)
                if tag == "vTypeDistribution" and el.attrib.get("id"):
                    out.distributions.add(el.attrib["id"])
                if tag != "vType":
                    if tag != "param" and not tag.startswith(CF_CHILD):
                        el.clear()
                    continue
                vid = el.attrib.get("id")
                if vid is None:
                    continue
                params = {p.attrib.get("key"): p.attrib.get("value")
                          for p in el if p.tag.split("}")[-1] == "param"}
                where = f"{path}: vType '{vid}'"
                sumo_mass = _mass(where, "mass", el.attrib.get("mass"))
                if sumo_mass is None:
                    sumo_mass = _mass(where, "param vehicleMass", params.get("vehicleMass"))
                loading = _mass(where, "param loading", params.get("loading"), zero=True) or 0.0
                mass = _mass(where, "drvpw.mass", params.get("drvpw.mass"))
                said = "param drvpw.mass" if mass is not None else ("mass" if "mass" in el.attrib else "param vehicleMass") + (" + param loading" if loading else "")
                if mass is None and sumo_mass is not None:
                    mass = sumo_mass + loading
                group = next((g for g, vcs in {**NON_ROAD_CLASSES, **{c: {c} for c in ON_FOOT_MASS_MAX_KG}}.items() if el.attrib.get("vClass") in vcs), None)
                if mass is not None and mass > (cap := {**NON_ROAD_MASS_MAX_KG, **ON_FOOT_MASS_MAX_KG}.get(group, ROAD_MASS_MAX_KG)):
                    raise UserError(f"{where}: mass {mass:g} kg ({said}) is beyond any " + (f"{el.attrib['vClass']}'s (at most {cap:,.0f} kg"
                                    if group else f"road vehicle's (at most {cap:,.0f} kg: a road train's few hundred tonnes fit") + "; a typo?)")
                out[vid] = VTypeInfo(vid, mass, params.get("drvpw.equation") or None,
                                     str(path), el.attrib.get("vClass"), loading,
                                     el.attrib.get("emissionClass") or None,
                                     el.attrib.get("guiShape") or None,
                                     _length(el.attrib.get("length")),
                                     _capacity(el.attrib.get("personCapacity")),
                                     _cold_share(where, params.get("drvpw.cold_start")),
                                     {k: params[k] for k in SHUT_OFF_PARAMS if params.get(k) is not None},
                                     {k: params[k] for k in ENERGY_KEYS if params.get(k) is not None} or None,
                                     _mass(where, "mass", el.attrib.get("mass")),
                                     params.get("drvpw.mass") is not None,
                                     is_true(params.get("has.battery.device")),
                                     _driving(el), _action_step(el.attrib.get("actionStepLength")))
                el.clear()
    except ET.ParseError as e:
        raise UserError(f"{path}: not valid XML: {e}") from None
    except (EOFError, gzip.BadGzipFile, zlib.error) as e:  # a truncated or corrupt .gz
        raise UserError(f"{path}: not a readable gzip file (truncated or corrupt?): "
                        f"{e}") from None
    except OSError as e:
        raise UserError(f"{path}: cannot read: {e}") from None
