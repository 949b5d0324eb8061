"""A scenario file's values checked as they are read: numbers, SUMO times, tables, flags,
shares, choices, lists and paths, each refused in one line naming the file and key
(:mod:`sumo_drvpw.sim.scenario` reads the file with them)."""

from __future__ import annotations

import math

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.equations import Equation


WIND_MAX_MPS = 100.0  # a scenario's strongest steady wind [m/s] (beyond the strongest gusts measured)


def _num(v, where: str, key: str, positive: bool = False, most: float = math.inf) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise UserError(f"{where}: '{key}' must be a number, got {v!r}")
    if (positive and v <= 0) or v > most:
        raise UserError(f"{where}: '{key}' must be > 0{f' and at most {most:g}' * (most < math.inf)}, got {v!r}")
    return float(v)


def sumo_seconds(text: str) -> float | None:
    """A time as SUMO writes and reads one, in seconds: "3600", "12.5", or clock time
    "h:m:s" / "d:h:m:s" ("7:00:00" = 25200; what --human-readable-time writes; sumolib's
    parseTime); None when it is neither."""
    from sumolib.miscutils import parseTime
    try:  # SUMO reads "h:m:s" and "d:h:m:s", nothing with fewer or more fields
        t = parseTime(text.strip()) if text.count(":") in (0, 2, 3) else None
    except (ValueError, IndexError):
        return None
    return t if t is None or math.isfinite(t) else None


def sumo_time(v, where: str, key: str, positive: bool = False) -> float:
    """A SUMO time value [s]: a number, or a string as SUMO reads one (:func:`sumo_seconds`)."""
    if isinstance(v, str):
        t = sumo_seconds(v)
        if t is None:
            raise UserError(f"{where}: '{key}' must be a time in seconds or h:m:s (SUMO's "
                            f"format), got {v!r}")
        v = t
    return _num(v, where, key, positive)


def _check_table(val, allowed: set[str], where: str, name: str) -> None:
    """``val`` must be a table whose keys are all in ``allowed``; errors name the key."""
    if not isinstance(val, dict):
        raise UserError(f"{where}: '{name}' must be a table")
    for k in val:
        if k not in allowed:
            raise UserError(f"{where}: unknown key '{name}.{k}' "
                            f"(known: {', '.join(sorted(allowed))})")


def _bool(v, where: str, key: str) -> bool:
    if not isinstance(v, bool):
        raise UserError(f"{where}: '{key}' must be true or false, got {v!r}")
    return v


def _share(v, where: str, key: str) -> float:
    """true / false, or a share in [0, 1] (a fraction of the vehicles)."""
    if isinstance(v, bool):
        return 1.0 if v else 0.0
    if not isinstance(v, (int, float)) or not 0.0 <= v <= 1.0:
        raise UserError(f"{where}: '{key}' must be true, false or a share from 0 to 1, got {v!r}")
    return float(v)


#: the air a road vehicle drives in (a value outside is a typo or a unit slip, e.g. Fahrenheit or
#: Pa): temperature [°C] as the chains' set-points allow, density [kg/m³] from a 5000-m pass
#: in summer to −50 °C at sea level, pressure [kPa] from 5000 m to the highest sea-level record
AIR_RANGES = {"temperature_c": (-60.0, 60.0), "density_kgm3": (0.6, 1.6), "pressure_kpa": (50.0, 110.0)}


def _in_range(x: float, lo_hi: tuple[float, float], where: str, key: str) -> None:
    if not lo_hi[0] <= x <= lo_hi[1]:
        raise UserError(f"{where}: '{key}' = {x:g} is not the air a vehicle drives in "
                        f"({lo_hi[0]:g} … {lo_hi[1]:g})")


def _choice(v, allowed: tuple[str, ...], where: str, key: str) -> str:
    if v not in allowed:
        raise UserError(f"{where}: '{key}' must be one of {', '.join(allowed)}, got {v!r}")
    return str(v)


def _strlist(v, where: str, key: str, example: str = '["..."]') -> list[str]:
    """A TOML array of strings (a bare string is refused: "a b" or "a,b" would be one item;
    ``equations`` may also hold Equation objects)."""
    kinds = (str, Equation) if key == "equations" else str
    if not isinstance(v, (list, tuple)) or not all(isinstance(x, kinds) for x in v):
        raise UserError(f"{where}: '{key}' must be a list of strings, e.g. {example}, got {v!r}")
    return list(v)


def _strmap(v, where: str, key: str, builtin=()) -> dict[str, str]:
    """A TOML table of name = road class (a non-empty string); a class that is one of
    ``builtin`` but for case or surrounding spaces ('Rail', 'city '), which would split that
    class in two, is refused."""
    if not isinstance(v, dict):
        raise UserError(f"{where}: '{key}' must be a table of name = road class, e.g. "
                        f'{{ "highway.primary" = "arterial" }}, got {v!r}')
    for k, c in v.items():
        if not isinstance(c, str) or not c.strip():
            raise UserError(f"{where}: '{key}.{k}' must be a road class name (a string), got {c!r}")
        same = next((b for b in builtin if b == c.strip().lower() and b != c), None)
        if same is None and c != c.strip():
            raise UserError(f"{where}: '{key}.{k}' {c!r} has spaces around the road class name, and would "
                            f"book apart from '{c.strip()}': write '{c.strip()}'")
        if same is not None:
            raise UserError(f"{where}: '{key}.{k}' {c!r} is the road class '{same}' but for case or spaces, "
                            f"and would book apart from it: write '{same}' (or a name of its own)")
    return {str(k): c for k, c in v.items()}


def _path(v, where: str, key: str) -> str:
    if not isinstance(v, str) or not v.strip():
        raise UserError(f"{where}: '{key}' must be a file path (a string), got {v!r}")
    return v


def tiny_mass(vt: str, vclass: str | None, mass, said: str) -> None:
    """A written mass below 1 % of its vClass's SUMO default refused (a 6-kg truck: tonnes):
    a vType's (:mod:`sumo_drvpw.sim.resolver`) and a told copy's (``[vtypes."<type>@<id>"]``);
    not of a vClass SUMO gives no mass of its own (:data:`NO_CLASS_MASS`: a 2-kg drone)."""
    from sumo_drvpw.sim.vtypes import SUMO_VCLASS_MASS_KG, SUMO_VEH_MASS_KG

    if vclass in NO_CLASS_MASS:
        return
    usual = SUMO_VCLASS_MASS_KG.get(vclass, SUMO_VEH_MASS_KG)
    if mass is not None and mass < 0.01 * usual:
        raise UserError(f"vType '{vt}': mass {mass:g} kg ({said}) is below 1 % of a {vclass or 'vehicle'}'s "
                        f"({usual:,.0f} kg, SUMO's default): tonnes, not kg? (a typo?)")


#: vClasses SUMO gives no mass of their own (``vehicletype.getMass``: the generic 1,500 kg, SUMO
#: 1.28): no class's usual mass to read a tonne against — a 5-kg parcel (a container of vClass
#: container), a 2-kg drone are written in kg
NO_CLASS_MASS = frozenset({"container", "drone", "aircraft", "cable_car", "custom1", "custom2"})


def written_mass(info, rider: bool = False) -> str:
    """Which of a vType's keys (:class:`~sumo_drvpw.sim.vtypes.VTypeInfo` ``info``) wrote its mass,
    and where: param drvpw.mass, else the mass attribute, else param vehicleMass (plus param
    loading, which a ``rider``'s mass — what SUMO adds to its vehicle — leaves out)."""
    key = ("param drvpw.mass" if info.drvpw_mass and not rider else "mass" if info.mass_attr_kg is not None
           else "param vehicleMass")
    return f"its {key}{' + param loading' if info.loading_kg and key != 'param drvpw.mass' and not rider else ''} in {info.source}"


def tiny_file_masses(files, told: dict) -> None:
    """The masses SUMO gives the vTypes of the route files ``files`` (``mass``, else param
    ``vehicleMass``; :func:`~sumo_drvpw.sim.vtypes.read_vtypes`) whose vClass is written checked as
    a booked vehicle's is (:func:`tiny_mass`), unless a ``drvpw.mass`` or the scenario's
    ``[vtypes.<id>] mass_kg`` (``told``: its vtype_data) gives the vehicle's: a rider — a person,
    a container — adds that mass to its vehicle, and no scenario key tells it (a container of
    vClass truck written 2 for 2 t rode as 2 kg). Not a vClass of :data:`NO_CLASS_MASS`."""
    from sumo_drvpw.sim.vtypes import sumo_type_mass

    for vt, info in files.items():
        if info.vclass and info.vclass not in NO_CLASS_MASS and not info.drvpw_mass \
                and (told.get(vt) or {}).get("mass_kg") is None:
            tiny_mass(vt, info.vclass, sumo_type_mass(files, vt), written_mass(info, rider=True))


def outputs_onto_inputs(args: list[str], inputs: list, where: str) -> None:
    """An output of SUMO's command line ``args`` (``--<key>-output F``, ``--log F`` …, a scenario's
    ``sumo.options``: an absolute path is kept where it is) naming a file the run reads — the
    scenario, its config, network, route or additional files (``inputs``) — refused naming the
    option: SUMO would write over it as it starts (a route file then fails half-read)."""
    from pathlib import Path

    from sumo_drvpw.sim.sumo_outputs import is_output_option

    ins = {Path(f).resolve() for f in inputs}
    for key, val in zip(args, args[1:]):
        if str(key).startswith("--") and is_output_option(str(key)[2:]):
            for f in (x.strip() for x in str(val).split(",")):
                if f and Path(f).is_absolute() and Path(f).resolve() in ins:
                    raise UserError(f"{where}: sumo.options: {key} {f}: a file the run reads (an input is never "
                                    "written); give the output another name, or a relative one (into OUT/sumo/)")
