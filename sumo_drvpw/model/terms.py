"""The term basis: every equation is a sum of coefficient × basis term.

One basis serves calibration, comparison, the SUMO loop and the residual tracer. A term
is written as a product of factors joined by ``*``:

=================  ==================================  ==========  =========
factor             value                                unit        category
=================  ==================================  ==========  =========
``acc``            m·v·a                                W           acc
``acc_pos``        m·v·max(a, 0): inertial power while      W           acc
                   speeding up only
``grade``          m·g·v·sin θ                          W           grade
``aero``           v·(v − v_w)·|v − v_w|                m³/s³       aero
``aero_rho``       ½·ρ·v·(v − v_w)·|v − v_w|            W/m²        aero
``roll``           m·g·v·cos θ                          W           roll
``roll_v2``        m·g·v²·cos θ                         W·m/s       roll
``m_v1``           m·v                                  kg·m/s      roll
``m_v3``           m·v³                                 kg·m³/s³    aero
``v1``/``v2``/``v3``  v, v², v³                         (m/s)^k     roll/roll/aero
``one``            1                                    –           other
``cold``           T_ref − T_ambient (T_ref 20 °C; 0 when  K           other
                   the ambient temperature is unknown)
``moving``         1 while the vehicle moves (v ≥ 0.1 m/s),  –           other
                   0 while it stands
``radial``         m·v·|ω|: the centripetal force in curves N           roll
                   (ω the yaw rate; 0 when it is unknown)
``v^k``            v to an integer power k (0…4)        (m/s)^k     v^3 aero, v^0 other, else roll
``[col]``          the log column ``col`` (``[col]^2`` squared)     other
``trip=ID``        1 on samples of trip ID, else 0      –           other
=================  ==================================  ==========  =========

The category of a product is that of its first physics factor (``acc``…``m_v3``,
``v1``…``v3``, ``v^k``), else ``other``. Power [W] = coefficient × term value.

Notes
-----
The basis carries the vehicle mass where physics puts it, so one equation serves
vehicles of different mass (Pitanuwat et al., Part I, Eq. 14 restates Table 3 this way).
``aero`` is the seed paper's v(v − v_wind)² (Table 3's β_aero multiplies it), signed
so that a tailwind faster than the car pushes it; ``aero_rho`` includes ½ρ, so its
coefficient is C_d·A [m²] and air density enters. ``m_v1``/``m_v3`` carry VSP LDV 1999's
mass-specific rolling and drag terms (Jiménez-Palacios 1999, Eq. 2 of the seed paper),
which have no cos θ.

``cold`` reads the ambient temperature [°C] from the signal ``ambient_c`` (a log's column;
in SUMO the scenario's air temperature when the loop passes it) and is 0 without it, so an
equation with ``roll*cold`` evaluates at the reference temperature where none is known.
``acc`` + ``acc_pos`` give the inertial power different coefficients while the car
speeds up (c_acc + c_acc_pos) and slows down (c_acc): the drivetrain delivers kinetic
energy at 1/η and returns it at η, so at the motor shaft (c_acc + c_acc_pos)/c_acc ≈ 1/η².

``v^0`` and ``moving`` split a constant power in two: ``v^0`` draws all the time (the
auxiliaries a car draws standing too: 12 V net, control, pumps), ``moving`` only while the
vehicle moves (powertrain losses that do not scale with the load: inverter switching,
magnetising, coolant pumps running with the drive). On a dynamometer the car hardly
stands, so only a road log separates them.

``radial`` reads the yaw rate ω [rad/s] from the signal ``yaw_rate_rps`` (a log's column; in
SUMO the change of the vehicle's angle over the step, which the loop passes when an
equation has the factor) and is 0 without it. m·v·|ω| = m·v²/r is the centripetal force
the tyres carry in a curve of radius r; a tyre carries it at a slip angle, which costs a
drag. ``radial*v1`` (μ·m·v²·|ω|, μ dimensionless: the share of the centripetal force that
acts as drag) is that loss as a power. ``radial`` alone, with a coefficient in m/s, is the
form of SUMO's Energy model, which books radialDragCoefficient × the centripetal force as
energy per step, i.e. a power coefficient of radialDragCoefficient/Δt
(:mod:`sumo_drvpw.model.energy_params`). Booked under ``roll``: both are tyre losses.

``roll*cold`` gives the temperature dependence of the rolling resistance,
c_r(T) = c_r0·(1 + k·(T_ref − T)) with k ≈ 0.6–1 %/K for passenger-car tyres (ISO 28580
temperature correction; Ejsmont et al. 2017): the ``roll`` coefficient is c_r0 and the
``roll*cold`` coefficient c_r0·k.

References
----------
Pitanuwat, S. et al., "Development of Hybrid-Vehicle Energy-Consumption Model for
Transportation Applications — Part I", Eq. 1, 2, 13, 14 and Table 3.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Callable, Mapping

import numpy as np

from sumo_drvpw.model.constants import G, STANDSTILL_MPS, T_REF_C
from sumo_drvpw.errors import UserError

#: The four physical categories the product reports, in display order.
CATEGORIES = ("acc", "grade", "aero", "roll")


@dataclass
class Inputs:
    """Per-sample inputs of the term basis; all arrays have one value per sample (SI).

    Parameters
    ----------
    v : speed over ground [m/s]
    a : longitudinal acceleration dv/dt [m/s²]
    theta : road grade angle, uphill positive [rad]
    wind : wind along the direction of travel, tailwind positive [m/s]
    mass : vehicle mass [kg]
    rho : air density [kg/m³]
    signals : extra columns by name (any unit), for ``[col]`` factors
    trip : trip id per sample, for ``trip=ID`` factors
    v_acc : speed the ``acc`` factor multiplies a by [m/s]; None: ``v``. The SUMO loop
        passes the step's mean speed (v_t + v_t−1)/2, so that m·v_acc·a·Δt is exactly
        the kinetic-energy change ½m(v_t² − v_t−1²) of the step at any step length;
        drive logs leave it None (acc = m·v·a).
    """

    v: np.ndarray
    a: np.ndarray
    theta: np.ndarray
    wind: np.ndarray
    mass: np.ndarray
    rho: np.ndarray
    signals: Mapping[str, np.ndarray] = field(default_factory=dict)
    trip: np.ndarray | None = None
    v_acc: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.v)

    def with_mass(self, mass_kg: float | None) -> "Inputs":
        """A copy whose mass is fixed to ``mass_kg`` [kg] (None: unchanged)."""
        if mass_kg is None:
            return self
        return Inputs(self.v, self.a, self.theta, self.wind,
                      np.full_like(self.v, float(mass_kg), dtype=float), self.rho,
                      self.signals, self.trip, self.v_acc)

    def take(self, idx) -> "Inputs":
        """The samples selected by a boolean mask or an index array."""
        return Inputs(self.v[idx], self.a[idx], self.theta[idx], self.wind[idx],
                      self.mass[idx], self.rho[idx],
                      {k: np.asarray(s)[idx] for k, s in self.signals.items()},
                      None if self.trip is None else np.asarray(self.trip)[idx],
                      None if self.v_acc is None else np.asarray(self.v_acc)[idx])


def _airspeed_term(x: Inputs) -> np.ndarray:
    u = x.v - x.wind
    return x.v * u * np.abs(u)


def _radial(x: Inputs) -> np.ndarray:
    """m·v·|ω| [N] with the yaw rate ω [rad/s] from the signal ``yaw_rate_rps``; 0 without
    it, and where it is not finite."""
    w = x.signals.get("yaw_rate_rps") if x.signals else None
    if w is None:
        return np.zeros_like(np.asarray(x.v, dtype=float))
    w = np.abs(np.asarray(w, dtype=float))
    return x.mass * x.v * np.where(np.isfinite(w), w, 0.0)


def _cold(x: Inputs) -> np.ndarray:
    """T_ref − T_ambient [K] from the signal ``ambient_c`` [°C]; 0 (reference) without it,
    and where the temperature is not finite."""
    t = x.signals.get("ambient_c") if x.signals else None
    if t is None:
        return np.zeros_like(np.asarray(x.v, dtype=float))
    d = T_REF_C - np.asarray(t, dtype=float)
    return np.where(np.isfinite(d), d, 0.0)


#: Physics factors: name → (function of Inputs, category, power of m·g in it for Table-3
#: conversion: 0 none, 1 mass only, 2 mass and g).
PRIMITIVES: dict[str, tuple[Callable[[Inputs], np.ndarray], str, int]] = {
    "acc": (lambda x: x.mass * (x.v if x.v_acc is None else x.v_acc) * x.a, "acc", 1),
    "acc_pos": (lambda x: x.mass * (x.v if x.v_acc is None else x.v_acc) * np.maximum(x.a, 0.0), "acc", 1),
    "grade": (lambda x: x.mass * G * x.v * np.sin(x.theta), "grade", 2),
    "aero": (_airspeed_term, "aero", 0),
    "aero_rho": (lambda x: 0.5 * x.rho * _airspeed_term(x), "aero", 0),
    "roll": (lambda x: x.mass * G * x.v * np.cos(x.theta), "roll", 2),
    "roll_v2": (lambda x: x.mass * G * x.v ** 2 * np.cos(x.theta), "roll", 2),
    "m_v1": (lambda x: x.mass * x.v, "roll", 1),
    "m_v3": (lambda x: x.mass * x.v ** 3, "aero", 1),
    "v1": (lambda x: x.v.astype(float, copy=True), "roll", 0),
    "v2": (lambda x: x.v ** 2, "roll", 0),
    "v3": (lambda x: x.v ** 3, "aero", 0),
    "one": (lambda x: np.ones_like(x.v, dtype=float), "other", 0),
    "cold": (lambda x: _cold(x), "other", 0),
    "moving": (lambda x: (np.asarray(x.v, float) >= STANDSTILL_MPS).astype(float), "other", 0),
    "radial": (_radial, "roll", 1),
}
#: signals a physics factor reads when the data have them (0 without): factor → signal
OPTIONAL_SIGNALS = {"cold": "ambient_c", "radial": "yaw_rate_rps"}

_VPOW = re.compile(r"^v\^([0-4])$")
_COL = re.compile(r"^\[([^\[\]]+)\](?:\^2)?$")
_TRIP = re.compile(r"^trip=(.+)$")


@dataclass(frozen=True)
class Term:
    """A parsed term: a product of factors, with its category and mass/g order."""

    text: str
    factors: tuple[str, ...]
    category: str
    mg_order: int  # 0: no m, 1: m, 2: m·g (for converting mass-free β)

    @property
    def signals(self) -> tuple[str, ...]:
        """The log columns this term reads."""
        out = []
        for f in self.factors:
            m = _COL.match(f)
            if m:
                out.append(m.group(1))
        return tuple(out)

    @property
    def columns(self) -> tuple[str, ...]:
        """Every log column the term's value depends on: its ``[col]`` signals, and
        ``ambient_c`` for the ``cold`` factor, ``yaw_rate_rps`` for ``radial`` (each 0
        without it, so not required as a signal is; a reader that selects columns must
        still read it)."""
        extra = tuple(OPTIONAL_SIGNALS[f] for f in self.factors if f in OPTIONAL_SIGNALS)
        return self.signals + tuple(c for c in extra if c not in self.signals)

    def evaluate(self, x: Inputs) -> np.ndarray:
        """Value of the term for every sample (unit: see the module table)."""
        val = None
        for f in self.factors:
            fv = _factor_value(f, x)
            val = fv if val is None else val * fv
        return np.asarray(val, dtype=float)


#: signals of diagnose's measurement-side findings (fit/diagnose/structural.py): what the
#: logs measured wrongly, corrected in the data — not terms an equation evaluates
MEASUREMENT_FINDINGS = {"grade_accelerometer": "the grade measured by the accelerometer instead of the "
                                               "logged elevation's",
                        "air_density_altitude": "the air density at the logged altitude"}


def measurement_finding(term: str, signal: str) -> str | None:
    """Why ``term`` cannot be evaluated when its ``signal`` is one of diagnose's
    measurement-side findings (None otherwise): the traced equation says what the logs
    lack; the equation to use is recalibrated on logs read with the correction."""
    what = MEASUREMENT_FINDINGS.get(signal)
    if what is None:
        return None
    return (f"term '{term}' is a measurement-side finding of diagnose ({what}): it says what the "
            "logs measured wrongly and is corrected in the data, not evaluated — recalibrate the "
            "equation on the logs read with that correction (the calibrate command diagnose printed; "
            "the equation then keeps it in its [measurement]) and use that one")


def _factor_value(f: str, x: Inputs) -> np.ndarray:
    if f in PRIMITIVES:
        return PRIMITIVES[f][0](x)
    m = _VPOW.match(f)
    if m:
        return x.v.astype(float) ** int(m.group(1))
    m = _COL.match(f)
    if m:
        name = m.group(1)
        if name not in x.signals:
            raise UserError(measurement_finding(f, name) or (
                f"term factor '{f}' needs the signal '{name}', which the data "
                f"do not have (available: {', '.join(sorted(x.signals)) or 'none'})"))
        s = np.asarray(x.signals[name], dtype=float)
        return s * s if f.endswith("^2") else s
    m = _TRIP.match(f)
    if m:
        if x.trip is None:
            raise UserError(f"term factor '{f}' needs trip ids, which the data do not have")
        return (np.asarray(x.trip).astype(str) == m.group(1)).astype(float)
    raise UserError(f"unknown term factor '{f}' (known: {', '.join(PRIMITIVES)}, v^k, [column], "
                    "[column]^2, trip=ID)")


@lru_cache(maxsize=4096)
def parse_term(text: str) -> Term:
    """Parse a term string such as ``acc``, ``[heater_w]*v^0`` or ``[ambient_c]*aero``."""
    factors = tuple(p.strip() for p in str(text).split("*"))
    if not factors or any(not p for p in factors):
        raise UserError(f"empty factor in term '{text}'")
    category, mg = "other", 0
    for f in factors:
        if f in PRIMITIVES:
            fn, cat, order = PRIMITIVES[f]
            if category == "other" and cat != "other":
                category = cat
            mg = max(mg, order)
            continue
        m = _VPOW.match(f)
        if m:
            if category == "other" and m.group(1) != "0":  # v^0: a constant power, as ``one``
                category = "aero" if m.group(1) == "3" else "roll"
            continue
        if _COL.match(f) or _TRIP.match(f):
            continue
        _factor_value(f, Inputs(*(np.zeros(0),) * 6))  # raises a UserError naming the factor
    return Term(str(text), factors, category, mg)


def term_matrix(terms: list[str] | tuple[str, ...], x: Inputs) -> np.ndarray:
    """Matrix (n samples × k terms) of term values, column order as given.

    Parameters
    ----------
    terms : term strings (grammar and unit of each factor: module table)
    x : the inputs, SI (v [m/s], a [m/s²], θ [rad], wind [m/s], m [kg], ρ [kg/m³])

    Column j holds term_j per sample in the unit of the module table (e.g. ``acc`` = m·v·a
    [W], ``aero`` = v·(v − v_w)·|v − v_w| [m³/s³]); power = coefficient × column.
    """
    out = np.empty((len(x), len(terms)), dtype=float)
    for j, t in enumerate(terms):
        out[:, j] = parse_term(t).evaluate(x)
    return out


def category_of(term: str) -> str:
    """The reporting category of a term: acc, grade, aero, roll or other."""
    return parse_term(term).category
