"""Roles of a drive log's extra columns: condition, load or response (drive-log spec, "Roles").

* ``condition`` — an exogenous circumstance of the drive (ambient temperature, season,
  weather, wipers, wind, passengers, tyre pressure, altitude, cabin set-point);
* ``load`` — an auxiliary power draw in W or convertible to W (heater, A/C, 12 V): additive;
* ``response`` — a consequence of the power demand or of the powertrain's control (pedal,
  throttle, torques and torque commands, currents, voltages, engine load and speed, fuel
  flow, state of charge, regenerative-brake torque, cumulative counters).

Roles travel with the log in the Parquet key-value metadata ``drive_log.roles`` (a JSON
object column → role), come from the mapping TOML (``role = "…"`` in a ``[columns."…"]``
entry), and each adapter declares its vendor's columns. A column without a declared role
gets one inferred from its name when the name says clearly what it is (:data:`NAME_RULES`,
reported as "inferred from the name"); otherwise its role is ``unknown`` and the residual
tracer screens it (constant, id-like, derived from the inputs, proxy of the target).
"""

from __future__ import annotations

import json
import re

from sumo_drvpw.errors import UserError

ROLES = ("condition", "load", "response")
UNKNOWN = "unknown"
#: Parquet key-value metadata key (drive-log spec).
META_KEY = "drive_log.roles"

#: (regular expression on the lower-case column name, role), first match wins. Only
#: names that leave no doubt: a torque, current or voltage is never an exogenous cause.
NAME_RULES: tuple[tuple[str, str], ...] = (
    (r"(^|_)(ambient|outside|outdoor|amb)(_|$)|(^|_)season|weather|(^|_)winter|(^|_)summer"
     r"|wiper|rain|passenger|occupan|tyre_press|tire_press|altitude|(^|_)set_?point"
     r"|(^|_)yaw_rate|curvature", "condition"),
    (r"(heater|heating|hvac|a_?c|aircon|aux|compressor|ptc)_?(power)?_(w|kw)$", "load"),
    (r"torque|(^|_)current|_a$|voltage|_v$|pedal|throttle|(^|_)soc|state_of_charge|(^|_)rpm"
     r"|_rpm$|engine_load|(^|_)load_pct|fuel|regen|(^|_)tot_|total_|cumul|odometer|counter"
     r"|energy_(wh|kwh|j)$|_(wh|kwh)$|gear|(^|_)maf|air_flow|lambda|equivalence_ratio|injector"
     r"|power_(w|kw)$", "response"),
)


def check_role(role: str, where: str) -> str:
    """``role`` if it is one of :data:`ROLES`; else a UserError naming ``where``."""
    if role not in ROLES:
        raise UserError(f"{where}: role must be one of {', '.join(ROLES)}, got {role!r}")
    return role


def infer_role(name: str) -> str:
    """Role suggested by a column's name (:data:`NAME_RULES`), or ``unknown``."""
    low = name.lower()
    for pattern, role in NAME_RULES:
        if re.search(pattern, low):
            return role
    return UNKNOWN


def from_metadata(metadata: dict) -> dict[str, str]:
    """Declared roles stored with a log (``DriveLog.metadata``; keys str or bytes)."""
    raw = metadata.get(META_KEY, metadata.get(META_KEY.encode(), None)) if metadata else None
    if raw is None:
        return {}
    if isinstance(raw, bytes):
        raw = raw.decode("utf-8")
    try:
        doc = json.loads(raw)
    except ValueError:
        raise UserError(f"metadata '{META_KEY}' is not JSON: {raw[:60]!r}") from None
    if not isinstance(doc, dict):
        raise UserError(f"metadata '{META_KEY}' must be a JSON object column → role")
    return {str(k): check_role(str(v), f"metadata '{META_KEY}', column '{k}'") for k, v in doc.items()}


def to_metadata(roles: dict[str, str]) -> dict[bytes, bytes]:
    """Parquet schema metadata entry for ``roles`` (column → role)."""
    for k, v in roles.items():
        check_role(v, f"role of column '{k}'")
    return {META_KEY.encode(): json.dumps(dict(sorted(roles.items()))).encode("utf-8")}


def resolve(columns, declared: dict[str, str] | None = None) -> dict[str, dict]:
    """Role of each column: ``{column: {"role", "source"}}`` with source ``declared``,
    ``inferred from the name`` or ``none``."""
    declared = declared or {}
    out = {}
    for c in columns:
        if c in declared:
            out[c] = {"role": declared[c], "source": "declared"}
        else:
            r = infer_role(c)
            out[c] = {"role": r, "source": "inferred from the name" if r != UNKNOWN else "none"}
    return out


def of_log(log) -> dict[str, dict]:
    """Roles of a :class:`~sumo_drvpw.data.log.DriveLog`'s extra columns (see :func:`resolve`)."""
    return resolve(log.extra_columns, from_metadata(getattr(log, "metadata", {}) or {}))
