"""Vehicle files (TOML): mass, body, powertrain gearing and inertias, battery convention.

Schema (every number may have a public source under ``[sources]`` with the same dotted key)::

    [vehicle]
    name = "prius3"
    description = "..."
    mass_kg = 1625                 # test mass [kg]

    [body]                         # optional: physical road-load specs
    drag_coefficient = 0.25        # C_d [-]
    frontal_area_m2 = 2.23         # A [m²]
    rolling_coefficient = 0.008    # C_r [-]
    rotating_mass_factor = 0.1     # ε_i [-]

    [powertrain]
    type = "power_split"           # power_split | single_motor | battery | direct
    sun_teeth = 30                 # power_split
    ring_teeth = 78
    mg2_reduction = 2.636          # MG2 → ring shaft (1.0 when there is none) [-], > 1
    counter_ratio = 1.0            # ring shaft → counter shaft [-], > 1 slows the wheel
    final_drive = 3.267            # counter shaft → wheels [-]
    gear_ratio = 9.665             # single_motor: motor → wheels [-]
    wheel_radius_m = 0.3127        # dynamic tyre radius [m]
    displacement_l = 1.8           # combustion engine's displacement [L] (scales the fuel
                                   # chain's idle-fuel check, fit/chain_checks.py)
    fuel = "gasoline"              # gasoline | diesel: the fuel target's and chain's fuel
                                   # (a car of type direct without [battery]: no traction
                                   # battery, fit/chain_fuel.engine_off_for)

    [powertrain.inertia_kgm2]      # power_split: ice, carrier, mg1, sun, ring, mg2, wheels
    ice = 0.18

    [battery]
    current_positive = "discharge" # or "charge": sign of battery_current_a when discharging

    [sources]
    "vehicle.mass_kg" = "Pitanuwat et al. Part I, Sec. 2"

Ratios are written the conventional way (> 1 means the wheel turns slower); the seed
paper writes G_r, G_c, G_f as their inverses (< 1).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import read_toml
from sumo_drvpw.model.constants import FUELS, MASS_MAX_KG

#: built-in vehicles: package data (importlib.resources; a regular install unpacks them)
VEHICLE_DIR = Path(str(resources.files("sumo_drvpw.model") / "builtin" / "vehicles"))
POWERTRAIN_TYPES = ("power_split", "single_motor", "battery", "direct")
INERTIA_KEYS = ("ice", "carrier", "mg1", "sun", "ring", "mg2", "wheels")


@dataclass
class Vehicle:
    """A vehicle as data. Lengths [m], masses [kg], inertias [kg·m²], ratios [-]."""

    name: str
    mass_kg: float
    description: str = ""
    body: dict = field(default_factory=dict)
    powertrain: dict = field(default_factory=dict)
    battery: dict = field(default_factory=dict)
    sources: dict = field(default_factory=dict)
    path: str | None = None
    #: published road-load coefficients F = A + B·v + C·v² (coast-down or dynamometer target):
    #: a_n [N], b_n_per_mps [N/(m/s)], c_n_per_mps2 [N/(m/s)²]; empty when not published
    road_load: dict = field(default_factory=dict)

    @property
    def powertrain_type(self) -> str:
        """How measured power is computed (:mod:`sumo_drvpw.data.powertrain`): power_split,
        single_motor, battery or direct (the default)."""
        return self.powertrain.get("type", "direct")

    def need(self, table: str, key: str) -> float:
        """A required number from [table], or a UserError naming file and key."""
        t = getattr(self, table)
        if key not in t:
            raise UserError(f"vehicle '{self.name}' ({self.path}): [{table}] lacks '{key}'")
        return float(t[key])

    def inertia(self, key: str) -> float:
        """Rotational inertia [kg·m²] of a powertrain element (0 if not given)."""
        return float(self.powertrain.get("inertia_kgm2", {}).get(key, 0.0))


#: Physical ranges of vehicle-file numbers, "table.key" → (low, high) with low < value ≤ high
#: (zero or negative is refused wherever physics forbids it). Units as in the key names.
NUMBER_RANGES = {
    "vehicle.mass_kg": (0.0, MASS_MAX_KG),
    "body.drag_coefficient": (0.0, 3.0),
    "body.frontal_area_m2": (0.0, 30.0),
    "body.rolling_coefficient": (0.0, 0.1),
    "body.rotating_mass_factor": (-1e-12, 1.0),  # ε_i ≥ 0
    "powertrain.sun_teeth": (0.0, 500.0),
    "powertrain.ring_teeth": (0.0, 500.0),
    "powertrain.mg2_reduction": (0.0, 50.0),
    "powertrain.counter_ratio": (0.0, 50.0),
    "powertrain.final_drive": (0.0, 50.0),
    "powertrain.gear_ratio": (0.0, 50.0),
    "powertrain.wheel_radius_m": (0.05, 2.0),
    "powertrain.displacement_l": (0.0, 30.0),
    "road_load.a_n": (-1e-12, 1.0e5),            # A, B, C ≥ 0
    "road_load.b_n_per_mps": (-1e-12, 1.0e4),
    "road_load.c_n_per_mps2": (-1e-12, 1.0e3),
    "road_load.f0_N": (-1e-12, 1.0e5),           # the same, as the EPA's lists name them
    "road_load.f1_N_per_mps": (-1.0e4, 1.0e4),   # (B may be below 0 in the EPA's lists)
    "road_load.f2_N_per_mps2": (-1e-12, 1.0e3),
}
#: rotational inertias [kg·m²]: 0 ≤ J ≤ this
INERTIA_MAX_KGM2 = 1.0e3


#: the vehicle file's keys that hold a word, "table.key" → the words allowed (the
#: powertrain's inertias are a table of their own, INERTIA_KEYS)
TEXT_KEYS = {"powertrain.type": POWERTRAIN_TYPES, "powertrain.fuel": tuple(FUELS),
             "powertrain.inertia_kgm2": None}


def check_numbers(doc: dict, p) -> None:
    """Every number in [vehicle], [body], [powertrain] finite; known keys in physical range.

    Raises UserError naming the file, the key and the value.
    """
    import math

    def num(v):
        return isinstance(v, (int, float)) and not isinstance(v, bool)

    for table in ("vehicle", "body", "powertrain", "road_load"):
        t = doc.get(table, {})
        if not isinstance(t, dict):
            raise UserError(f"{p}: [{table}] must be a table")
        for k, v in t.items():
            key = f"{table}.{k}"
            if table in ("body", "powertrain") and key not in NUMBER_RANGES and key not in TEXT_KEYS:
                # a misspelt key would go unread
                known = ", ".join(n.split(".", 1)[1] for n in (*NUMBER_RANGES, *TEXT_KEYS) if n.startswith(f"{table}."))
                raise UserError(f"{p}: unknown key {key!r} (known: {known})")
            if TEXT_KEYS.get(key) is not None and v not in TEXT_KEYS[key]:
                raise UserError(f"{p}: {key} = {v!r}: must be one of {', '.join(TEXT_KEYS[key])}")
            if isinstance(v, dict) and key in NUMBER_RANGES:
                raise UserError(f"{p}: {key} = {v!r}: must be a number")
            if isinstance(v, dict):
                for k2, v2 in v.items():
                    if k == "inertia_kgm2" and k2 not in INERTIA_KEYS:
                        raise UserError(f"{p}: unknown key '{key}.{k2}' (known: {', '.join(INERTIA_KEYS)})")
                    if not num(v2) or not math.isfinite(v2) or (
                            k == "inertia_kgm2" and not 0 <= v2 <= INERTIA_MAX_KGM2):
                        raise UserError(f"{p}: {key}.{k2} = {v2!r}: "
                                        + (f"an inertia is a number in [0, {INERTIA_MAX_KGM2:g}] kg·m²"
                                           if k == "inertia_kgm2" else "must be a finite number"))
                continue
            if key in NUMBER_RANGES:
                lo, hi = NUMBER_RANGES[key]
                if not num(v) or not math.isfinite(v) or not lo < v <= hi:
                    span = (f"({lo:g}, {hi:g}]" if lo >= 0 or lo < -1e-9 else f"[0, {hi:g}]")
                    raise UserError(f"{p}: {key} = {v!r}: must be a number in {span}")
            elif num(v) and not math.isfinite(v):
                raise UserError(f"{p}: {key} = {v!r}: must be a finite number")


def vehicle_names() -> list[str]:
    """Names of the built-in vehicles (package data ``model/builtin/vehicles/``), sorted."""
    return sorted(p.stem for p in VEHICLE_DIR.glob("*.toml"))


def load_vehicle(spec: str | Path) -> Vehicle:
    """Load a vehicle by name (``sumo_drvpw/model/builtin/vehicles/NAME.toml``) or from a TOML path."""
    p = Path(spec)
    if not (p.suffix == ".toml" or p.exists()):
        p = VEHICLE_DIR / f"{spec}.toml"
        if not p.is_file():
            raise UserError(f"unknown vehicle '{spec}': not a file and not one of "
                            f"{', '.join(vehicle_names())}")
    doc = read_toml(p, "vehicle file")
    meta = doc.get("vehicle", {})
    if "mass_kg" not in meta:
        raise UserError(f"{p}: [vehicle] lacks 'mass_kg'")
    check_numbers(doc, p)
    v = Vehicle(name=str(meta.get("name", p.stem)), mass_kg=float(meta["mass_kg"]),
                description=str(meta.get("description", "")), body=doc.get("body", {}),
                powertrain=doc.get("powertrain", {}), battery=doc.get("battery", {}),
                sources=doc.get("sources", {}), path=str(p), road_load=doc.get("road_load", {}))
    return v  # (powertrain.type checked with the file's words: check_numbers, TEXT_KEYS)
