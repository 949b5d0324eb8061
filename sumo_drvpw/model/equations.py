"""Driving-power equations as data: named basis terms with coefficients (TOML).

File format (all tables but ``[equation]`` and one of ``[terms]``/``[beta]`` optional)::

    [equation]
    name = "drvpw_prius3"
    description = "..."
    source = "where the numbers come from"
    mass_kg = 1530.9          # optional: a fixed mass for this equation's m-terms [kg]
    reference_mass_kg = 1625  # needed with [beta]: the mass the β were fitted at [kg]
    vclasses = ["passenger"]  # SUMO vClasses it is made for (default: DEFAULT_VCLASSES)
    predicts = "wheel"        # what the terms give: "wheel" (road-load power at the
                              # wheels) or "powertrain_output" (incl. drivetrain losses)
    speed_range_mps = [0, 33] # optional validity range of the data behind it [m/s]
    accel_range_mps2 = [-3, 2]  # [m/s²]; calibrated equations record both

    [terms]       # coefficient per term of the basis (sumo_drvpw.model.terms); power = Σ c·term
    acc = 0.9994
    [beta]        # or: Table-3-style coefficients on mass-free bases, converted on load:
    acc = 1624    #   c = β / m_ref for m-terms, β / (m_ref·g) for m·g-terms
    [std_err]     # optional, same keys, same basis as the coefficients they go with
    [p_values]
    [provenance]  # free-form: log, vehicle, date, settings of a calibration
    [metrics]     # free-form fit statistics
    [chain]       # optional energy chain after the road-load terms (sumo_drvpw.model.chain)
    [measurement] # optional: corrections of the logs it was calibrated on (power lag, grade
                  # source, air density; sumo_drvpw.model.measurement), applied to every log it
                  # is later compared on; not used in SUMO, where inputs are clean

Built-in equations live in ``sumo_drvpw/model/builtin/equations/*.toml``; a name that is not a file
path is looked up there. A loaded equation's name must match ``NAME_PATTERN`` (it becomes
part of column names and XML attribute names).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from sumo_drvpw.model.constants import MASS_MAX_KG, G
from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import read_toml
from sumo_drvpw.model.terms import CATEGORIES, Inputs, parse_term, term_matrix

#: Names an equation file may give: a letter, then letters, digits, ``_ . -`` (≤ 64 chars),
#: so that names are safe in column names, file names and XML attribute names.
NAME_PATTERN = r"^[A-Za-z][A-Za-z0-9_.-]{0,63}$"
#: SUMO vClasses an equation is for when it does not say (``vclasses``): the car classes.
DEFAULT_VCLASSES = ("passenger", "private", "taxi", "hov", "vip", "evehicle", "authority")
#: What an equation's terms can predict (``predicts``).
PREDICTS = ("wheel", "powertrain_output")
#: SUMO's vehicle classes (sumo.dlr.de/docs/Definition_of_Vehicles,_Vehicle_Types,_and_Routes;
#: SUMO 1.28 accepts each), and its deprecated names with the class SUMO reads them as
SUMO_VCLASSES = ("ignoring", "private", "emergency", "authority", "army", "vip", "pedestrian",
                 "passenger", "hov", "taxi", "bus", "coach", "delivery", "truck", "trailer",
                 "motorcycle", "moped", "bicycle", "evehicle", "tram", "rail_urban", "rail",
                 "rail_electric", "rail_fast", "ship", "container", "cable_car", "subway",
                 "aircraft", "wheelchair", "scooter", "drone", "custom1", "custom2")
DEPRECATED_VCLASSES = {"public_emergency": "emergency", "public_authority": "authority",
                       "public_army": "army", "public_transport": "bus", "transport": "truck",
                       "lightrail": "tram", "cityrail": "rail_urban", "rail_slow": "rail"}
#: the keys of an equation file's ``[equation]`` table
EQUATION_KEYS = ("name", "description", "source", "mass_kg", "reference_mass_kg", "vclasses",
                 "predicts", "speed_range_mps", "accel_range_mps2")


def check_vclass(name, where: str, key: str) -> str:
    """``name`` if it is a SUMO vClass, else a UserError naming ``where``, ``key`` and it
    (a vehicle's class comes from SUMO, so any other name would never match one)."""
    if name in SUMO_VCLASSES:
        return name
    if name in DEPRECATED_VCLASSES:
        raise UserError(f"{where}: {key} names {name!r}, SUMO's deprecated name of vClass "
                        f"'{DEPRECATED_VCLASSES[name]}' (as which SUMO reports such vehicles): "
                        f"write '{DEPRECATED_VCLASSES[name]}'")
    import difflib

    close = difflib.get_close_matches(str(name), SUMO_VCLASSES, n=2)
    hint = f"did you mean {' or '.join(close)}? " if close else ""
    raise UserError(f"{where}: {key} names {name!r}, which is not a SUMO vClass ({hint}SUMO's "
                    f"{len(SUMO_VCLASSES)} vClasses include passenger, taxi, delivery, truck, "
                    "trailer, bus, coach, motorcycle, evehicle, custom1)")

#: built-in equations: package data (importlib.resources; a regular install unpacks them)
BUILTIN_DIR = Path(str(resources.files("sumo_drvpw.model") / "builtin" / "equations"))


@dataclass
class Equation:
    """A driving-power equation: P [W] = Σ_j c_j·term_j (seed paper Eq. 13/14 form).

    Parameters
    ----------
    name : identifier used in reports and outputs
    terms : term string → coefficient c_j [W per unit of the term; the term units are
        in :mod:`sumo_drvpw.model.terms`]
    mass_kg : fixed mass for the m-terms [kg], or None to use the vehicle's/sample's mass

    Example
    -------
    >>> import numpy as np
    >>> from sumo_drvpw.model.terms import Inputs
    >>> eq = Equation(name="car", terms={"acc": 1.05, "aero": 0.35, "roll": 0.009})
    >>> one = np.ones(1)
    >>> x = Inputs(v=20 * one, a=0 * one, theta=0 * one, wind=0 * one, mass=1500 * one,
    ...            rho=1.2041 * one)
    >>> round(float(eq.power(x)[0]))   # 0.35·20³ + 0.009·1500·9.81·20 [W]
    5449
    """

    name: str
    terms: dict[str, float]
    mass_kg: float | None = None
    description: str = ""
    source: str = ""
    std_err: dict[str, float] = field(default_factory=dict)
    p_values: dict[str, float] = field(default_factory=dict)
    provenance: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    path: str | None = None
    #: optional :class:`sumo_drvpw.model.chain.EnergyChain` (``[chain]``): battery or fuel
    chain: object | None = None
    #: SUMO vClasses the equation is made for (``equation.vclasses``)
    vclasses: tuple[str, ...] = DEFAULT_VCLASSES
    #: what the terms give: "wheel" or "powertrain_output" (``equation.predicts``)
    terms_predict: str = "wheel"
    #: validity range of the data behind the equation: speed [m/s], acceleration [m/s²]
    speed_range_mps: tuple[float, float] | None = None
    accel_range_mps2: tuple[float, float] | None = None
    #: corrections of the calibration logs (``[measurement]``,
    #: :class:`sumo_drvpw.model.measurement.Measurement`), None when none was declared
    measurement: object | None = None
    #: the mass the coefficients were fitted at [kg] (``equation.reference_mass_kg``: that of a
    #: ``[beta]`` equation, a published fit's test mass), None when not given
    reference_mass_kg: float | None = None

    @property
    def predicts(self) -> str:
        """What the equation file predicts: what its terms give (``wheel`` or
        ``powertrain_output``) without a chain, else the chain's target."""
        return self.terms_predict if self.chain is None else self.chain.predicts

    def validity(self) -> tuple:
        """(speed [m/s], acceleration [m/s²], driving power [W]) ranges of the data behind
        the equation, each (min, max) or None: its own speed and acceleration ranges, and
        what its energy chain was fitted on (``[chain.provenance]`` ``speed_range_mps``,
        ``power_range_w``; fit/chain_checks.py), the speed range the narrower of the two."""
        prov = getattr(self.chain, "provenance", None) or {}
        got = {}
        for key in ("speed_range_mps", "power_range_w"):
            r = prov.get(key)
            if r is None:
                continue
            try:
                lo, hi = (float(x) for x in r)
            except (TypeError, ValueError):
                lo = hi = math.nan
            if not (math.isfinite(lo) and math.isfinite(hi) and lo <= hi):
                raise UserError(f"equation '{self.name}' ({self.path or 'built in'}): [chain.provenance] {key} "
                                f"must be [min, max], got {r!r}")
            got[key] = (lo, hi)
        v, c = self.speed_range_mps, got.get("speed_range_mps")
        if v is not None and c is not None:
            v = (max(v[0], c[0]), min(v[1], c[1]))
        return (v if v is not None else c), self.accel_range_mps2, got.get("power_range_w")

    def __post_init__(self):
        if not self.terms:
            raise UserError(f"equation '{self.name}' has no terms")
        for t in self.terms:
            parse_term(t)

    @property
    def term_names(self) -> list[str]:
        """The term strings, in the equation's order."""
        return list(self.terms)

    @property
    def coefficients(self) -> np.ndarray:
        """Coefficients c_j [W per unit of term j], in the order of :attr:`term_names`."""
        return np.array([self.terms[t] for t in self.terms], dtype=float)

    @property
    def categories(self) -> list[str]:
        """Reporting category (acc, grade, aero, roll, other) of each term, in order."""
        return [parse_term(t).category for t in self.terms]

    @property
    def signals(self) -> set[str]:
        """Log columns the equation needs beyond the standard inputs."""
        return {s for t in self.terms for s in parse_term(t).signals}

    def term_powers(self, x: Inputs) -> np.ndarray:
        """Power of each term [W], shape (n samples, k terms)."""
        return term_matrix(self.term_names, x.with_mass(self.mass_kg)) * self.coefficients

    def power(self, x: Inputs) -> np.ndarray:
        """Total driving power [W] per sample."""
        return self.term_powers(x).sum(axis=1)

    def category_powers(self, x: Inputs) -> dict[str, np.ndarray]:
        """Power [W] per reporting category (acc, grade, aero, roll, and other if used)."""
        tp = self.term_powers(x)
        out = {c: np.zeros(len(x)) for c in CATEGORIES}
        for j, c in enumerate(self.categories):
            out[c] = out.get(c, np.zeros(len(x))) + tp[:, j]
        return out

    def beta(self, reference_mass_kg: float) -> dict[str, float]:
        """Coefficients on mass-free bases (Table-3 style) at a reference mass [kg]."""
        return coefficients_to_beta(self.terms, self.mass_kg or reference_mass_kg)

    def to_dict(self) -> dict:
        """The TOML document of this equation."""
        eq = {"name": self.name}
        if self.description:
            eq["description"] = self.description
        if self.source:
            eq["source"] = self.source
        if self.mass_kg is not None:
            eq["mass_kg"] = float(self.mass_kg)
        if self.reference_mass_kg is not None:
            eq["reference_mass_kg"] = float(self.reference_mass_kg)
        if tuple(self.vclasses) != DEFAULT_VCLASSES:
            eq["vclasses"] = list(self.vclasses)
        if self.terms_predict != "wheel":
            eq["predicts"] = self.terms_predict
        for key in ("speed_range_mps", "accel_range_mps2"):
            r = getattr(self, key)
            if r is not None:
                eq[key] = [float(r[0]), float(r[1])]
        doc = {"equation": eq, "terms": {k: float(v) for k, v in self.terms.items()}}
        for key in ("std_err", "p_values", "provenance", "metrics"):
            val = getattr(self, key)
            if val:
                doc[key] = val
        if self.chain is not None:
            doc["chain"] = self.chain.to_dict()
        if self.measurement is not None:
            doc["measurement"] = self.measurement.to_dict()
        return doc


def beta_to_coefficients(beta: dict[str, float], reference_mass_kg: float) -> dict[str, float]:
    """Convert coefficients on mass-free bases to this basis (Table 3 → Eq. 14 form).

    Table 3 of the seed paper fits β on v·a, v·sin θ, v(v − v_w)², v·cos θ… at the test
    mass. Our ``acc`` = m·v·a, so c_acc = β_acc/m; ``grade``/``roll``/``roll_v2`` carry
    m·g, so c = β/(m·g); terms without m are unchanged.

    Parameters
    ----------
    beta : term → β on the mass-free basis
    reference_mass_kg : mass at which β were fitted [kg]
    """
    return {t: float(b) / _mass_scale(t, reference_mass_kg) for t, b in beta.items()}


def coefficients_to_beta(terms: dict[str, float], reference_mass_kg: float) -> dict[str, float]:
    """Inverse of :func:`beta_to_coefficients`: β = c·m for m-terms, c·m·g for m·g-terms.

    Parameters
    ----------
    terms : term → coefficient in this basis [W per unit of the term]
    reference_mass_kg : mass to express β at [kg]
    """
    return {t: float(c) * _mass_scale(t, reference_mass_kg) for t, c in terms.items()}


def _mass_scale(term: str, mass_kg: float) -> float:
    """The factor a term carries beyond its mass-free form: 1, m, or m·g."""
    order = parse_term(term).mg_order
    return 1.0 if order == 0 else mass_kg * (G if order == 2 else 1.0)


def builtin_names() -> list[str]:
    """Names of the built-in equations (package data ``model/builtin/equations/``), sorted."""
    return sorted(p.stem for p in BUILTIN_DIR.glob("*.toml"))


#: |coefficient| above this is not a physical coefficient in any term basis (masses are in
#: the basis; β on mass-free bases stay below 1e5 even for 40 t trucks)
COEF_MAX = 1.0e6
#: plausible vehicle mass for equation.mass_kg and reference_mass_kg [kg]
MASS_RANGE_KG = (1.0, MASS_MAX_KG)


def _floats(table: dict, where: str) -> dict[str, float]:
    if not isinstance(table, dict):
        raise UserError(f"{where}: must be a table of term = number, got {table!r}")
    out = {}
    for k, v in table.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise UserError(f"{where}: value of '{k}' must be a number, got {v!r}")
        if not math.isfinite(v):
            raise UserError(f"{where}: value of '{k}' must be a finite number, got {v!r}")
        if abs(v) > COEF_MAX:
            raise UserError(f"{where}: value of '{k}' is {v:g}, beyond ±{COEF_MAX:g}: not a "
                            "coefficient of this term basis")
        out[str(k)] = float(v)
    return out


def _mass(meta: dict, key: str, where: str, table: str = "equation") -> float | None:
    """<table>.<key> as a plausible mass [kg], or None when absent."""
    v = meta.get(key)
    if v is None:
        return None
    lo, hi = MASS_RANGE_KG
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not (lo <= v <= hi):
        raise UserError(f"{where}: {table}.{key} must be a vehicle mass in [{lo:g}, {hi:g}] kg, "
                        f"got {v!r}")
    return float(v)


def check_equation(eq: Equation, where: str) -> None:
    """UserError for an :class:`Equation` built in code whose values no equation file may
    have: a coefficient that is no finite number (NaN books NaN energy, a string is read as
    a number), a mass outside :data:`MASS_RANGE_KG`, a vClass SUMO does not know (it would
    book no vehicle, silently) — as :func:`equation_from_dict` checks a file's."""
    what = f"{where}: equation '{eq.name}'"
    _floats(dict(eq.terms), f"{what} terms")
    _mass({"mass_kg": eq.mass_kg}, "mass_kg", what)
    if isinstance(eq.vclasses, str) or not all(isinstance(v, str) for v in eq.vclasses):
        raise UserError(f"{what}: vclasses must be a list of SUMO vClass names, e.g. (\"passenger\",), "
                        f"got {eq.vclasses!r}")
    for v in eq.vclasses:
        check_vclass(v, what, "vclasses")
    ch = eq.chain
    if ch is not None and ch.predicts == "fuel":
        ch.require_complete()  # (read from a file without its engine's keys)
        if not 0.0 < float(ch.marginal_efficiency) < 1.0:  # an EnergyChain's default, no engine's
            raise UserError(f"{what}: its fuel chain's marginal_efficiency is {ch.marginal_efficiency!r}: no "
                            "engine turns all its fuel into work (the EnergyChain default, 1, describes none); "
                            "give the engine's fuel, marginal_efficiency, idle_fuel_power_w and engine_off_below_w")


def equation_from_dict(doc: dict, where: str = "<equation>") -> Equation:
    """Build an :class:`Equation` from a parsed TOML document; errors name ``where``."""
    known = {"equation", "terms", "beta", "std_err", "p_values", "provenance", "metrics", "paper",
             "chain", "measurement"}
    unknown = set(doc) - known
    if unknown:
        raise UserError(f"{where}: unknown table(s) {sorted(unknown)} (known: {sorted(known)})")
    meta = doc.get("equation")
    if not isinstance(meta, dict) or "name" not in meta:
        raise UserError(f"{where}: missing [equation] table with a 'name'")
    bad = [k for k in meta if k not in EQUATION_KEYS]
    if bad:
        raise UserError(f"{where} [equation]: unknown key {bad[0]!r} "
                        f"(known: {', '.join(EQUATION_KEYS)})")
    for key in ("name", "description", "source"):
        if key in meta and not isinstance(meta[key], str):
            raise UserError(f"{where}: equation.{key} must be a string, got {meta[key]!r}")
    ref = _mass(meta, "reference_mass_kg", where)
    _mass(meta, "mass_kg", where)
    if "beta" in doc and "terms" in doc:
        raise UserError(f"{where}: give either [terms] or [beta], not both")
    if "beta" in doc:
        if ref is None:
            raise UserError(f"{where}: [beta] needs equation.reference_mass_kg")
        terms = beta_to_coefficients(_floats(doc["beta"], f"{where} [beta]"), float(ref))
        std = doc.get("std_err", {})
        std = beta_to_coefficients(_floats(std, f"{where} [std_err]"), float(ref)) if std else {}
    elif "terms" in doc:
        terms = _floats(doc["terms"], f"{where} [terms]")
        std = _floats(doc.get("std_err", {}), f"{where} [std_err]")
    else:
        raise UserError(f"{where}: missing [terms] (or [beta]) table")
    for table, vals in (("std_err", std), ("p_values", doc.get("p_values", {}))):
        stray = [k for k in vals if k not in terms]
        if stray:  # a standard error of no coefficient: a misspelt term name
            raise UserError(f"{where}: [{table}] '{stray[0]}' is not among the terms "
                            f"({', '.join(terms)})")
    neg = [k for k, v in std.items() if v < 0]
    if neg:
        raise UserError(f"{where}: [std_err] '{neg[0]}' is {std[neg[0]]:g}; a standard error is >= 0")
    mass = meta.get("mass_kg")
    name = str(meta["name"])
    if not re.match(NAME_PATTERN, name):
        raise UserError(f"{where}: equation.name {name!r} is not allowed: use a letter, then "
                        "letters, digits, '_', '.', '-' (at most 64 characters)")
    vcl = meta.get("vclasses", list(DEFAULT_VCLASSES))
    if isinstance(vcl, str):  # one class; each name is checked below, so "a, b" is refused
        vcl = [vcl]
    if not isinstance(vcl, list) or not all(isinstance(v, str) and v for v in vcl):
        raise UserError(f"{where}: equation.vclasses must be a list of SUMO vClass names, "
                        f"e.g. [\"passenger\"], got {vcl!r}")
    for v in vcl:
        check_vclass(v, where, "equation.vclasses")
    pred = meta.get("predicts", "wheel")
    if pred not in PREDICTS:
        raise UserError(f"{where}: equation.predicts must be one of {', '.join(PREDICTS)}, "
                        f"got {pred!r}")
    ranges = {}
    for key in ("speed_range_mps", "accel_range_mps2"):
        r = meta.get(key)
        if r is None:
            continue
        if (not isinstance(r, list) or len(r) != 2 or not all(
                isinstance(x, (int, float)) and not isinstance(x, bool) for x in r)
                or not r[0] < r[1]):
            raise UserError(f"{where}: equation.{key} must be [low, high] numbers with "
                            f"low < high, got {r!r}")
        ranges[key] = (float(r[0]), float(r[1]))
    chain = None
    if "chain" in doc:
        from sumo_drvpw.model.chain_toml import chain_from_dict

        chain = chain_from_dict(doc["chain"], where)
    measurement = None
    if "measurement" in doc:
        from sumo_drvpw.model.measurement import measurement_from_dict

        measurement = measurement_from_dict(doc["measurement"], where)
    from sumo_drvpw.model.chain_values import provenance_table

    for k in ("provenance", "metrics"):
        if not isinstance(doc.get(k, {}), dict):
            raise UserError(f"{where}: '{k}' must be a table ([{k}]), got {doc[k]!r}")
    prov = provenance_table(doc.get("provenance", {}), where, "provenance")
    _mass(doc.get("metrics", {}), "reference_mass_kg", where, "metrics")  # a run holds the equation to it
    try:
        return Equation(
            name=name, terms=terms, vclasses=tuple(vcl), terms_predict=pred, **ranges,
            mass_kg=None if mass is None else float(mass), reference_mass_kg=None if ref is None else float(ref),
            description=str(meta.get("description", "")), source=str(meta.get("source", "")),
            std_err=std, p_values=_floats(doc.get("p_values", {}), f"{where} [p_values]"),
            provenance=prov, metrics=dict(doc.get("metrics", {})),
            path=None if where.startswith("<") else where, chain=chain, measurement=measurement)
    except UserError as e:
        raise UserError(f"{where}: {e}") from None


def load_equation(spec: str | Path) -> Equation:
    """Load an equation by built-in name or from a TOML file path."""
    p = Path(spec)
    if p.suffix == ".toml" or p.exists():
        return equation_from_dict(read_toml(p, "equation file"), str(p))
    builtin = BUILTIN_DIR / f"{spec}.toml"
    if builtin.is_file():
        eq = equation_from_dict(read_toml(builtin, "equation file"), str(builtin))
        return eq
    named = [k for k in SPEC_EQUATIONS if str(spec).startswith(k[:-4]) and str(spec).endswith("spec")]
    raise UserError(f"unknown equation '{spec}': not a file and not a built-in "
                    f"(built-ins: {', '.join(builtin_names())}; from the vehicle's specs: {', '.join(SPEC_EQUATIONS)}"
                    + (f" — a report's '{spec}' is {named[0]} for that vehicle" if named else "") + ")")


def save_equation(eq: Equation, path: str | Path) -> None:
    """Write an equation as TOML atomically. The logs its provenance (and its chain's)
    names are written relative to the file's folder, so they name the same files from
    any working folder and after the folder is moved whole (absolute where no relative
    path exists: another drive)."""
    import os

    import tomli_w

    from sumo_drvpw.fileio import plain, write_text

    folder = Path(os.path.abspath(path)).parent  # (symbolic links kept: the path as the user has it)

    def rel(x) -> str:
        try:
            return Path(os.path.relpath(os.path.abspath(x), folder)).as_posix()
        except ValueError:
            return os.path.abspath(x)

    d = eq.to_dict()
    for holder in (d, d.get("chain")):
        prov = holder.get("provenance") if isinstance(holder, dict) else None
        if isinstance(prov, dict) and prov.get("logs"):
            holder["provenance"] = {**prov, "logs": [rel(x) for x in prov["logs"]]}
    write_text(path, tomli_w.dumps(plain(d, toml=True)))


def vsp_from_specs(vehicle) -> Equation:
    """VSP with a vehicle's physical specs (seed paper Eq. 1), as an equation.

    P = m·v·[a(1 + ε_i) + g·sin θ + g·C_r] + ½·ρ·C_d·A·v(v − v_w)²: in this basis
    acc = 1 + ε_i, grade = 1, m_v1 = g·C_r (VSP has no cos θ), aero_rho = C_d·A.

    Parameters
    ----------
    vehicle : :class:`sumo_drvpw.model.vehicles.Vehicle` with [body] drag_coefficient,
        frontal_area_m2, rolling_coefficient and optional rotating_mass_factor
    """
    cd = vehicle.need("body", "drag_coefficient")
    area = vehicle.need("body", "frontal_area_m2")
    cr = vehicle.need("body", "rolling_coefficient")
    eps = float(vehicle.body.get("rotating_mass_factor", 0.1))
    return Equation(name=f"vsp_{vehicle.name}spec",
                    terms={"acc": 1.0 + eps, "grade": 1.0, "m_v1": G * cr, "aero_rho": cd * area},
                    description=f"VSP with the physical specs of {vehicle.name} (seed paper Eq. 1)",
                    source=f"vehicle file {vehicle.path}", reference_mass_kg=_spec_mass(vehicle))


def _spec_mass(vehicle) -> float | None:
    """The mass a vehicle's specs describe it at [kg] (its drag, rolling resistance and
    published A, B, C are that vehicle's): the equation's ``reference_mass_kg``."""
    m = getattr(vehicle, "mass_kg", None)
    return float(m) if m else None


#: the [road_load] keys of A, B, C, each under either name (the second: the Prius files')
ROAD_LOAD_KEYS = (("a_n", "f0_N"), ("b_n_per_mps", "f1_N_per_mps"), ("c_n_per_mps2", "f2_N_per_mps2"))


def roadload_from_specs(vehicle) -> Equation:
    """The vehicle's published road load as an equation: F = A + B·v + C·v² (coast-down or
    chassis-dynamometer target coefficients) plus the inertial force m·a and the grade
    force m·g·sin θ.

    P = m·v·a + m·g·v·sin θ + A·v + B·v² + C·v³: in this basis acc = 1, grade = 1, v1 = A,
    v2 = B, v3 = C. A, B, C are measured on a flat road (or a dynamometer, whose log has no
    grade: the term is 0 there); on a road the potential energy is exact physics, as in
    ``vsp_spec`` and the EPA built-ins — without it a chain calibrated on a hilly road log
    booked the descents' recuperation to nothing (a LeafSpy log in Wales: η_r 0.001 at its
    bound, 0.47 with it). No rotating mass beyond what the test mass carries.

    Parameters
    ----------
    vehicle : :class:`sumo_drvpw.model.vehicles.Vehicle` with [road_load] a_n, b_n_per_mps,
        c_n_per_mps2 (or as the built-in Prius files write them: f0_N, f1_N_per_mps,
        f2_N_per_mps2)
    """
    rl = vehicle.road_load
    got = [next((k for k in keys if k in rl), None) for keys in ROAD_LOAD_KEYS]
    if None in got:
        raise UserError(f"vehicle '{vehicle.name}' ({vehicle.path}): [road_load] lacks "
                        + ", ".join(" or ".join(repr(k) for k in keys)
                                    for keys, k in zip(ROAD_LOAD_KEYS, got) if k is None)
                        + " (the published A [N], B [N/(m/s)], C [N/(m/s)²])")
    a, b, c = (vehicle.need("road_load", k) for k in got)
    return Equation(name=f"roadload_{vehicle.name}",
                    terms={"acc": 1.0, "grade": 1.0, "v1": a, "v2": b, "v3": c},
                    description=f"published road load of {vehicle.name} (A + B·v + C·v², plus m·a and m·g·sin θ)",
                    source=f"vehicle file {vehicle.path} [road_load]", reference_mass_kg=_spec_mass(vehicle))


#: equations built from the vehicle file instead of read from one: name → builder
SPEC_EQUATIONS = {"vsp_spec": vsp_from_specs, "roadload_spec": roadload_from_specs}
