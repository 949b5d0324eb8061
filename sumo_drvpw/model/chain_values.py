"""An energy chain's parameter values: efficiency tables over speed and |power|, and the
checked numbers of a ``[chain]`` table (:mod:`sumo_drvpw.model.chain` reads them)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import FUELS, STANDSTILL_MPS


@dataclass(eq=False)
class Table:
    """A small efficiency table over speed [m/s] and/or |power| [W], linearly interpolated."""

    values: np.ndarray
    speed_mps: np.ndarray | None = None
    power_w: np.ndarray | None = None

    def __call__(self, v, p) -> np.ndarray:
        """Interpolated value at speed ``v`` [m/s] and power ``p`` [W] (|p| is used)."""
        pts = []
        if self.speed_mps is not None:
            pts.append(np.clip(np.asarray(v, float), self.speed_mps[0], self.speed_mps[-1]))
        if self.power_w is not None:
            pts.append(np.clip(np.abs(np.asarray(p, float)), self.power_w[0], self.power_w[-1]))
        return self._interpolator()(np.stack(np.broadcast_arrays(*pts), axis=-1))

    def _interpolator(self):
        """The table's scipy interpolator, built once (a chain evaluates its tables every step of
        a run: building it cost about 6× its evaluation); built again if an axis or the values
        are replaced."""
        key = (id(self.values), id(self.speed_mps), id(self.power_w))
        cached = self.__dict__.get("_interp")
        if cached is None or cached[0] != key:
            from scipy.interpolate import RegularGridInterpolator

            axes = tuple(a for a in (self.speed_mps, self.power_w) if a is not None)
            cached = (key, RegularGridInterpolator(axes, self.values, method="linear"))
            self.__dict__["_interp"] = cached
        return cached[1]

    def __getstate__(self) -> dict:  # (pickled to a worker without its interpolator)
        return {k: x for k, x in self.__dict__.items() if k != "_interp"}

    def __eq__(self, other) -> bool:
        return isinstance(other, Table) and self.to_dict() == other.to_dict()

    def to_dict(self) -> dict:
        d = {}
        if self.speed_mps is not None:
            d["speed_mps"] = self.speed_mps.tolist()
        if self.power_w is not None:
            d["power_w"] = self.power_w.tolist()
        d["values"] = self.values.tolist()
        return d


Efficiency = float | Table


def _efficiency(val, key: str, where: str) -> Efficiency:
    if isinstance(val, dict):
        unknown = set(val) - {"speed_mps", "power_w", "values"}
        if unknown:
            raise UserError(f"{where} [chain.{key}]: unknown key(s) {sorted(unknown)} "
                            "(known: speed_mps, power_w, values)")
        axes = {}
        for ax in ("speed_mps", "power_w"):
            if ax in val:
                a = _numbers(val[ax], f"chain.{key}.{ax}", where)
                if a.ndim != 1 or a.size < 2 or not np.all(np.isfinite(a)) or np.any(np.diff(a) <= 0):
                    raise UserError(f"{where} [chain.{key}]: '{ax}' must be ≥ 2 strictly "
                                    f"increasing numbers, got {val[ax]!r}")
                axes[ax] = a
        if not axes or "values" not in val:
            raise UserError(f"{where} [chain.{key}]: a table needs 'values' and at least one "
                            "axis of speed_mps, power_w")
        vals = _numbers(val["values"], f"chain.{key}.values", where)
        shape = tuple(a.size for a in axes.values())
        if vals.shape != shape:
            raise UserError(f"{where} [chain.{key}]: 'values' has shape {vals.shape}, the axes "
                            f"need {shape}")
        bad = ~((vals > 0) & (vals <= 1))
        if bad.any():
            raise UserError(f"{where} [chain.{key}]: efficiencies must be in (0, 1], got "
                            f"{vals[bad].flat[0]!r}")
        return Table(vals, axes.get("speed_mps"), axes.get("power_w"))
    x = _number(val, key, where)
    if not 0 < x <= 1:
        raise UserError(f"{where} [chain]: '{key}' must be in (0, 1], got {val!r}")
    return x


def _numbers(val, key: str, where: str) -> np.ndarray:
    """A list (of lists) of numbers as an array; a UserError naming ``key`` for anything else
    (strings, tables, rows of different lengths)."""
    def ok(x):
        return (isinstance(x, (int, float)) and not isinstance(x, bool)) or (
            isinstance(x, list) and all(ok(y) for y in x))

    try:
        if not isinstance(val, list) or not ok(val):
            raise ValueError
        return np.asarray(val, float)
    except (ValueError, OverflowError):
        raise UserError(f"{where} [{key}]: must be a list of numbers (rows of one length), got {val!r}") from None


#: the largest magnitude a finite chain number may have: beyond any road vehicle's power [W],
#: energy per kelvin [J/K] or fuel per start [L] (a larger one printed litres in hundreds of digits)
CHAIN_NUMBER_MAX = 1e9


def _number(val, key: str, where: str, finite: bool = True) -> float:
    """A number (finite unless ``finite`` is False, and then within ±CHAIN_NUMBER_MAX; NaN never)."""
    if isinstance(val, bool) or not isinstance(val, (int, float)):
        raise UserError(f"{where} [chain]: '{key}' must be a number, got {val!r}")
    x = float(val)
    if np.isnan(x) or (finite and not np.isfinite(x)):
        raise UserError(f"{where} [chain]: '{key}' must be a finite number, got {val!r}")
    if np.isfinite(x) and abs(x) > CHAIN_NUMBER_MAX:
        raise UserError(f"{where} [chain]: '{key}' = {val!r} is beyond any road vehicle's "
                        f"(|x| ≤ {CHAIN_NUMBER_MAX:g})")
    return x


def _nonneg(val, key: str, where: str, inf: bool = False) -> float:
    """A number ≥ 0; +inf only where ``inf`` (a limit or threshold never reached)."""
    x = _number(val, key, where, finite=False)
    if not x >= 0 or (x == np.inf and not inf):
        raise UserError(f"{where} [chain]: '{key}' must be ≥ 0{'' if inf else ' and finite'}, "
                        f"got {val!r}")
    return x


def keyed_table(value, name: str, keys, where: str, what: str = "") -> dict:
    """An equation file's ``[name]`` table checked: a table (``what``: what it holds, said when it
    is not) of ``keys`` only; a UserError naming ``where`` and the table otherwise."""
    if not isinstance(value, dict):
        raise UserError(f"{where} [{name}]: must be a table{what}")
    bad = set(value) - set(keys)
    if bad:
        raise UserError(f"{where} [{name}]: unknown key(s) {sorted(bad)} (known: {', '.join(keys)})")
    return value


#: a provenance's keys read as lists (compare, run and export-vtype iterate them)
PROVENANCE_LISTS = ("logs", "trip_signatures", "warnings")


def provenance_table(value, where: str, table: str) -> dict:
    """A ``[provenance]`` (or ``[chain.provenance]``) table, its :data:`PROVENANCE_LISTS` as
    lists: a text alone is read as a list of one (it would be read character by character:
    ``logs = "a/b.csv"`` named the folders '/' and '.'), another value is a UserError naming
    ``where`` and the key. The rest is free-form."""
    if not isinstance(value, dict):
        raise UserError(f"{where}: '{table}' must be a table ([{table}]), got {value!r}")
    out = dict(value)
    for k in PROVENANCE_LISTS:
        if k in out and isinstance(out[k], str):
            out[k] = [out[k]]
        elif k in out and not isinstance(out[k], list):
            raise UserError(f"{where}: [{table}] {k} must be a list (one entry per "
                            f"{'file' if k == 'logs' else 'trip' if k == 'trip_signatures' else 'warning'}), "
                            f"got {out[k]!r}")
    return out


def corrected_fuel_power(fuel_power_w, battery_power_w, battery_to_fuel: float) -> np.ndarray:
    """Fuel power corrected for the hybrid battery's energy change (SAE J1711 §4 idea) [W].

    P_fuel,corr = P_fuel + k·P_bat: battery energy delivered (P_bat > 0, discharging) would
    otherwise have come from fuel at k fuel joules per battery joule; energy stored
    (P_bat < 0) was paid for with fuel. Summed over a trip this removes the bias of a
    state-of-charge swing.

    Parameters
    ----------
    fuel_power_w : measured fuel power (mass flow × LHV) [W]
    battery_power_w : HV battery power, positive when discharging [W]
    battery_to_fuel : k [-], fuel energy per unit of battery energy (≈ 1/η_marginal)
    """
    return np.asarray(fuel_power_w, float) + battery_to_fuel * np.asarray(battery_power_w, float)


def fuel_j_per_l(fuel: str) -> float:
    """A fuel's energy per litre at its lower heating value [J/L]: LHV [J/kg] · density [kg/L]
    (:data:`sumo_drvpw.model.constants.FUELS`), so litres = fuel energy [J] / this, as
    :meth:`EnergyChain.evaluate` turns fuel power into ``fuel_lps``.

    >>> round(fuel_j_per_l("gasoline") / 1e6, 2)   # 43.2 MJ/kg · 0.745 kg/L
    32.18
    """
    if fuel not in FUELS:
        raise UserError(f"fuel must be one of {', '.join(FUELS)}, got {fuel!r}")
    fp = FUELS[fuel]
    return fp["lhv_j_per_kg"] * fp["density_kg_per_l"]


#: the smallest rated engine output a fuel chain may declare [W]: below any engine's
ENGINE_MAX_MIN_W = 1000.0


def engine_keys(doc: dict, idle_w: float, pred: str, where: str) -> dict:
    """A fuel chain's optional engine keys, checked: ``moving_idle_fuel_power_w`` (the fuel at
    zero output while moving, ≥ the standing idle fuel ``idle_w``: a diesel's friction grows with
    engine speed) and ``engine_max_w`` (the engine's rated output, > 0) [W]; {} where neither."""
    kw = {}
    for k in ("moving_idle_fuel_power_w", "engine_max_w"):
        if k not in doc:
            continue
        if pred != "fuel":
            raise UserError(f"{where} [chain]: '{k}' is an engine's: only for predicts = \"fuel\", "
                            f"got predicts = {pred!r}")
        kw[k] = _nonneg(doc[k], k, where)
    if kw.get("moving_idle_fuel_power_w", np.inf) < idle_w:
        raise UserError(f"{where} [chain]: 'moving_idle_fuel_power_w' (fuel at zero output while moving) must be "
                        f"≥ idle_fuel_power_w = {idle_w:g} W (an engine turning faster has more friction), "
                        f"got {doc['moving_idle_fuel_power_w']!r}")
    if kw.get("engine_max_w", ENGINE_MAX_MIN_W) < ENGINE_MAX_MIN_W:  # (a moped's is some 2 kW: 300 is kW as W)
        raise UserError(f"{where} [chain]: 'engine_max_w' (the engine's rated output) must be ≥ {ENGINE_MAX_MIN_W:g} W "
                        f"(watts, not kW), got {doc['engine_max_w']!r}")
    return kw


def zero_output_fuel(idle_w: float, moving_w: float | None, v, standstill_mps: float):
    """The fuel power at zero engine output [W] per sample: the idle fuel standing (v below
    ``standstill_mps``), ``moving_w`` while moving where given (the friction at road engine speed)."""
    return idle_w if moving_w is None else np.where(np.asarray(v, float) < standstill_mps, idle_w, moving_w)


def engine_capped(eng_w, max_w: float | None) -> tuple:
    """(the engine output delivered, the demand above the rated output ``max_w`` that it cannot
    deliver) [W] per sample; no cap where ``max_w`` is None (the excess then None)."""
    if max_w is None:
        return eng_w, None
    return np.minimum(eng_w, max_w), np.maximum(eng_w - max_w, 0.0)


class Engine(NamedTuple):
    """A fuel chain's engine at each sample (:func:`engine_demand`) [W]."""

    delivered_w: np.ndarray      #: the output it delivers, min(E, P_max)
    beyond_w: np.ndarray | None  #: the demand above its rated output, max(E − P_max, 0); None without one
    at_rating: np.ndarray        #: where the demand reaches the rated output (E ≥ P_max; False without one)
    zero_output_w: np.ndarray | float  #: the fuel power at zero output (:func:`zero_output_fuel`)


def engine_demand(chain, p, v, signals=None, eta_t=None) -> Engine:
    """A fuel chain's engine, the one formula (the chain's evaluation, model/chain.py, and the
    chain trace's linearisation, fit/chain_linear.py, both read it): the output demand

        E = max(P, 0)/η_t(v, P) + P_aux                                  [W]

    (P: driving power, η_t: ``traction_efficiency``, P_aux: the chain's auxiliary draw —
    constant, loads, HVAC, :meth:`~sumo_drvpw.model.chain.EnergyChain.auxiliary`), capped at the
    rated output P_max (``engine_max_w``; the demand above it not delivered), and the fuel at zero
    output: the idle fuel standing, ``moving_idle_fuel_power_w`` while moving where declared.

    Parameters
    ----------
    chain : the fuel chain (:class:`~sumo_drvpw.model.chain.EnergyChain`)
    p, v : driving power [W], speed [m/s] per sample
    signals : column → array (the loads, the HVAC temperature)
    eta_t : η_t per sample where the caller has it (a table evaluated once), else evaluated here
    """
    if eta_t is None:
        eff = chain.traction_efficiency
        eta_t = eff(v, p) if isinstance(eff, Table) else eff
    eng = np.maximum(p, 0.0) / eta_t + chain.auxiliary(np.size(p), signals)
    delivered, beyond = engine_capped(eng, chain.engine_max_w)
    at = np.zeros(eng.shape, bool) if beyond is None else eng >= chain.engine_max_w
    return Engine(delivered, beyond, at,
                  zero_output_fuel(chain.idle_fuel_power_w, chain.moving_idle_fuel_power_w, v, STANDSTILL_MPS))
