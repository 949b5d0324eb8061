"""A mapped column's name against its unit (``import columns``, data/adapters/columns.py): names
end in the SI unit their value is converted to (the drive-log spec's ``speed_mps``, ``power_w``…,
and every extra column alike: ``heater_w``, ``coolant_c``); the mapping's ``unit`` says what the
file holds. A name whose suffix spells another unit is refused, saying what to write (``name =
"speed_mps"`` with ``unit = "km/h"``), naming the mapping file and key; a suffix whose '/' a name
cannot hold is read as one ('speed_km_h', 'maf_g_s'); a name that leaves its unit unsaid gets a
note."""

from __future__ import annotations

import math

from sumo_drvpw.errors import UserError
from sumo_drvpw.data.adapters._common import CANONICAL, DEG_MIN, DIMENSIONS, UNITS, lookup_unit

SUFFIX_DIM = {v: k for k, v in DIMENSIONS.items() if v}


def _entry(p, key, name, unit, scale) -> dict:
    """Conversion of one mapped column: (kind, factor, offset) checked against the name's suffix."""
    if name == "trip_id":
        return {"name": name, "kind": "text", "factor": 1.0, "offset": 0.0}
    if name == "time_s" and unit.strip().lower() == "datetime":
        return {"name": name, "kind": "datetime", "factor": 1.0, "offset": 0.0}
    u = lookup_unit(unit)
    if u is None:
        raise UserError(f"{p}: {key}.unit '{unit}' is not a known unit (e.g. km/h, mph, m/s, ft, "
                        "°F, K, rpm, kW, lbf, …)")
    dim, f, o = u
    if unit.strip().lower() == "text":
        return {"name": name, "kind": "text", "factor": 1.0, "offset": 0.0}
    suffix = _suffix(name)
    said = (lookup_unit(suffix) or ("dimensionless",))[0] if len(suffix) > 1 and suffix not in LOOSE_SUFFIXES else None
    if dim == "angle" and suffix == "deg":
        f = f * 180.0 / math.pi
    elif suffix in SUFFIX_DIM and suffix not in LOOSE_SUFFIXES and dim != "dimensionless" and SUFFIX_DIM[suffix] != dim:
        if name in CANONICAL:  # (the drive-log spec's column: its unit is wrong, not its name)
            raise UserError(f"{p}: {key}: unit '{unit}' is {_a(dim)}, but '{name}' holds {_a(SUFFIX_DIM[suffix])}: "
                            f"write unit = one of {_spellings(SUFFIX_DIM[suffix])}")
        raise UserError(f"{p}: {key}: unit '{unit}' is {_a(dim)}, but name '{name}' ends in "
                        f"'_{suffix}' ({SUFFIX_DIM[suffix].replace('_', ' ')}): write name = \"{name[:-len(suffix)]}{DIMENSIONS[dim]}\" "
                        f"with unit = \"{unit}\" (names end in the SI unit the value is converted to)")
    elif said not in (None, "dimensionless", dim) and dim != "dimensionless":
        # ('heater_kw' from km/h, 'speed_km_h' from kW: the name says one quantity, the unit another)
        stem = name[:-len(suffix)]
        raise UserError(f"{p}: {key}: unit '{unit}' is {_a(dim)}, but name '{name}' ends in '_{suffix}', "
                        f"{_a(said)} unit: {_a(said)} in {suffix.replace('_', '/')} is written name = \"{stem}{DIMENSIONS[said]}\" "
                        f"with unit = \"{suffix.replace('_', '/')}\", {_a(dim)} in {unit} name = \"{stem}{DIMENSIONS[dim]}\"")
    elif name in CANONICAL and dim == "dimensionless" and suffix in SUFFIX_DIM:
        raise UserError(f"{p}: {key}: '{name}' needs a {SUFFIX_DIM[suffix]} unit, got '{unit}': "
                        f"write unit = one of {_spellings(SUFFIX_DIM[suffix])}")
    elif suffix and dim != "dimensionless" and suffix != DIMENSIONS[dim] and (lookup_unit(suffix) or ("",))[0] == dim \
            and not _si_spelling(suffix):
        # ('gps_speed_kmh' with unit km/h: written in m/s under a name that says km/h; 'coolant_celsius'
        # names the °C it holds by another spelling)
        raise UserError(f"{p}: {key}.name '{name}' ends in '_{suffix}', but the {dim.replace('_', ' ')} is written in "
                        f"'{DIMENSIONS[dim]}' (names end in their SI unit, the value converted to it): write "
                        f"name = \"{name[:-len(suffix)]}{DIMENSIONS[dim]}\" with unit = \"{unit}\"")
    # ("deg min", "34 11.28809": an angle checked as "deg" is above, its text read by cells.degrees_minutes)
    return {"name": name, "kind": "number", "factor": f * scale, "offset": o * scale,
            **({"deg_min": True} if unit.strip().lower() in DEG_MIN else {})}


#: one-part name suffixes that spell a unit but in a column's name often say something else: 'speed_ms'
#: (m/s more often than milliseconds), 'speed_min' (a minimum), 'altitude_gps' (from the GPS, not g/s)
LOOSE_SUFFIXES = frozenset({"ms", "us", "min", "gps"})


def _suffix(name: str) -> str:
    """A mapped name's unit suffix as written: its last two '_' parts where they spell a unit whose
    '/' a name cannot hold ('speed_km_h', 'maf_g_s', 'density_kg_m3': lookup_unit reads them),
    else its last part ('' for a name without '_')."""
    parts = name.split("_")
    two = "_".join(parts[-2:])
    if len(parts) > 2 and all(parts[-2:]) and (lookup_unit(two) or ("dimensionless",))[0] != "dimensionless":
        return two
    return parts[-1] if len(parts) > 1 else ""


def _a(dim: str) -> str:
    """'a speed', 'an angle' (a dimension's name with its article)."""
    return ("an " if dim[:1] in "aeiou" else "a ") + dim.replace("_", " ")


def _spellings(dim: str, n: int = 4) -> str:
    """The first ``n`` unit spellings of dimension ``dim`` (the unit table's order), quoted."""
    seen = []
    for k, (d, f, o) in UNITS.items():
        if d == dim and (f, o) not in [x[1] for x in seen]:
            seen.append((k, (f, o)))
    return ", ".join(f'"{k}"' for k, _ in seen[:n])


def _si_spelling(word: str) -> bool:
    """``word`` spells a dimension's SI unit ('celsius', 'percent', 'sec', 'volt': the value
    written under a name ending in it is in the unit it says)."""
    u = lookup_unit(word)
    return u is not None and u[0] != "dimensionless" and u[1:] == (1.0, 0.0)


def _name_note(key: str, name: str, unit: str | None) -> str | None:
    """What a mapped number's name leaves unsaid: a quantity written in its SI unit under a name
    without it ('gps_speed' from km/h: in m/s, and not read as a GPS speed, which only a
    ``gps_speed…_mps`` column is), or None."""
    dim = (lookup_unit(unit) or ("dimensionless",))[0] if unit is not None else "dimensionless"
    suffix = _suffix(name)
    gps = name.startswith("gps_speed") and not name.endswith("_mps")
    if dim == "speed" and "gps" in name.split("_") and not name.startswith("gps_speed"):  # ('speed_gps')
        return (f"{key}.name '{name}' is not read as a GPS speed (only a gps_speed…_mps column is, in m/s): "
                f"name it 'gps_speed_mps' (with its unit) to have it read as one")
    if gps and dim == "speed" and suffix != "mps" and _si_spelling(suffix) and lookup_unit(suffix)[0] == "speed":
        return (f"{key}.name '{name}' is not read as a GPS speed (only a gps_speed…_mps column is): "
                f"name it '{name[:-len(suffix)]}mps'")  # ('gps_speed_m_s')
    if (dim == "dimensionless" and not gps) or suffix == DIMENSIONS.get(dim) or (dim == "angle" and suffix == "deg") \
            or (dim != "dimensionless" and not gps and _si_spelling(suffix) and lookup_unit(suffix)[0] == dim):
        return None
    if dim == "dimensionless":  # ('gps_speed_kmh' without a unit: kept as it is, in no speed the log reads)
        stem = name[:-len(suffix) - 1] if suffix and lookup_unit(suffix) else name
        return (f"{key}.name '{name}' is not read as a GPS speed (only a gps_speed…_mps column is, in m/s): give "
                f"its unit and name it '{stem}_mps'")
    return (f"{key}.name '{name}' has no unit suffix: written in '{DIMENSIONS[dim]}' from '{unit}'; "
            + ("not read as a GPS speed (only gps_speed…_mps is); " if gps else "") + f"name it '{name}_{DIMENSIONS[dim]}' to say so")
