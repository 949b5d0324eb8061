"""An equation's ``[chain]`` table read into an :class:`~sumo_drvpw.model.chain.EnergyChain`:
its keys, each value checked as it is read (errors name the file and key), its sub-tables
(loads, HVAC, efficiency tables, a motor, a plug-in hybrid's depleting battery). The table
back from a chain: :meth:`EnergyChain.to_dict` (model/chain.py)."""

from __future__ import annotations

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain import FUEL_REQUIRED, EnergyChain
from sumo_drvpw.model.chain_buffer import usable_window
from sumo_drvpw.model.chain_plugin import depleting_from_dict
from sumo_drvpw.model.chain_values import (Table, _efficiency, _nonneg, _number, engine_keys, keyed_table,
                                          provenance_table)
from sumo_drvpw.model.constants import FUELS

PREDICTS = ("wheel", "powertrain_output", "battery", "fuel")
#: keys of the [chain] table, besides sub-tables loads, hvac and efficiency tables
KEYS = ("predicts", "traction_efficiency", "recuperation_efficiency", "recuperation_limit_w",
        "recuperation_by_decel_mps2", "aux_power_w", "standstill_aux_w", "loads", "hvac", "idle_fuel_power_w", "marginal_efficiency",
        "engine_off_below_w", "engine_on_above_mps", "fuel_cut_below_w", "charge_sustaining", "recuperation_round_trip",
        "battery_usable_j", "depleting", "fuel", "battery_to_fuel", "moving_idle_fuel_power_w", "engine_max_w",
        "cold_start_fuel_l", "cold_start_fuel_l_per_k", "cold_start_ref_c", "running_fuel_per_k",
        "motor", "std_err", "reading", "provenance", "metrics")
#: the largest plausible warm-running fuel increase per kelvin (5 %/K: +150 % at −6.7 °C
#: against the FTP's 23.9 °C, far beyond the ≈ 9 % certification pairs show)
RUNNING_FUEL_PER_K_MAX = 0.05
HVAC_KEYS = ("column", "setpoint_c", "heating_w_per_k", "cooling_w_per_k", "warmup_j_per_k")


def chain_from_dict(doc: dict, where: str = "<equation>") -> EnergyChain:
    """Build an :class:`EnergyChain` from a parsed ``[chain]`` table; errors name ``where``."""
    if not isinstance(doc, dict):
        raise UserError(f"{where}: [chain] must be a table")
    unknown = set(doc) - set(KEYS)
    if unknown:
        raise UserError(f"{where} [chain]: unknown key(s) {sorted(unknown)} (known: {', '.join(KEYS)})")
    pred = doc.get("predicts", "battery")
    if pred not in PREDICTS:
        raise UserError(f"{where} [chain]: predicts must be one of {', '.join(PREDICTS)}, got {pred!r}")
    kw: dict = {"predicts": pred}
    for k in ("traction_efficiency", "recuperation_efficiency"):
        if k in doc:
            kw[k] = _efficiency(doc[k], k, where)
    if "marginal_efficiency" in doc:
        kw["marginal_efficiency"] = _efficiency(doc["marginal_efficiency"], "marginal_efficiency", where)
        if isinstance(kw["marginal_efficiency"], Table):
            raise UserError(f"{where} [chain]: marginal_efficiency must be a number")
    if "standstill_aux_w" in doc:
        kw["standstill_aux_w"] = _number(doc["standstill_aux_w"], "standstill_aux_w", where)
        if kw["standstill_aux_w"] + _number(doc.get("aux_power_w", 0.0), "aux_power_w", where) < 0:
            raise UserError(f"{where} [chain]: aux_power_w + standstill_aux_w (auxiliary power while standing) "
                            f"must be ≥ 0, got standstill_aux_w = {doc['standstill_aux_w']!r}")
    if "engine_off_below_w" in doc:  # any number: -inf keeps a conventional engine running
        kw["engine_off_below_w"] = _number(doc["engine_off_below_w"], "engine_off_below_w", where, finite=False)
        if np.isnan(kw["engine_off_below_w"]) or kw["engine_off_below_w"] == np.inf:
            raise UserError(f"{where} [chain]: 'engine_off_below_w' must be a number below +inf "
                            f"(-inf: the engine never stops), got {doc['engine_off_below_w']!r}")
    if "charge_sustaining" in doc:
        if not isinstance(doc["charge_sustaining"], bool) or pred != "fuel":
            raise UserError(f"{where} [chain]: 'charge_sustaining' must be true or false, for predicts = "
                            f"\"fuel\" only, got {doc['charge_sustaining']!r} (predicts = {pred!r})")
        kw["charge_sustaining"] = doc["charge_sustaining"]
    if "recuperation_round_trip" in doc:
        kw["recuperation_round_trip"] = _nonneg(doc["recuperation_round_trip"], "recuperation_round_trip", where)
        if kw["recuperation_round_trip"] > 1.0 or not kw.get("charge_sustaining"):
            raise UserError(f"{where} [chain]: 'recuperation_round_trip' is the share of a charge-sustaining "
                            "hybrid's braking energy its battery gives back: in [0, 1], with predicts = \"fuel\" "
                            f"and charge_sustaining = true, got {doc['recuperation_round_trip']!r}")
    if "battery_usable_j" in doc:
        kw["battery_usable_j"] = usable_window(doc, kw.get("recuperation_round_trip"), where)
    if "fuel_cut_below_w" in doc:
        kw["fuel_cut_below_w"] = _number(doc["fuel_cut_below_w"], "fuel_cut_below_w", where)
        if pred != "fuel":
            raise UserError(f"{where} [chain]: 'fuel_cut_below_w' cuts an engine's fuel: only for "
                            f"predicts = \"fuel\", got predicts = {pred!r}")
    for k in ("recuperation_limit_w", "recuperation_by_decel_mps2", "aux_power_w", "idle_fuel_power_w",
              "engine_on_above_mps", "battery_to_fuel", "cold_start_fuel_l", "cold_start_fuel_l_per_k"):
        if k in doc:
            kw[k] = _nonneg(doc[k], k, where, inf=k in ("recuperation_limit_w", "engine_on_above_mps"))
    kw.update(engine_keys(doc, kw.get("idle_fuel_power_w", 0.0), pred, where))
    if "cold_start_ref_c" in doc:
        kw["cold_start_ref_c"] = _number(doc["cold_start_ref_c"], "cold_start_ref_c", where)
        if not -60.0 <= kw["cold_start_ref_c"] <= 60.0:
            raise UserError(f"{where} [chain]: 'cold_start_ref_c' must be an air temperature in "
                            f"-60 … 60 °C, got {doc['cold_start_ref_c']!r}")
    if "running_fuel_per_k" in doc:
        kw["running_fuel_per_k"] = _nonneg(doc["running_fuel_per_k"], "running_fuel_per_k", where)
        if kw["running_fuel_per_k"] > RUNNING_FUEL_PER_K_MAX:
            raise UserError(f"{where} [chain]: 'running_fuel_per_k' is a share of the fuel per kelvin, "
                            f"at most {RUNNING_FUEL_PER_K_MAX} (5 %/K), got {doc['running_fuel_per_k']!r}")
    for k in ("cold_start_fuel_l", "cold_start_fuel_l_per_k", "running_fuel_per_k"):
        if kw.get(k) and pred != "fuel":
            raise UserError(f"{where} [chain]: '{k}' is fuel in the cold: only for "
                            f"predicts = \"fuel\", got predicts = {pred!r}")
    loads = doc.get("loads", {})
    if not isinstance(loads, dict):
        raise UserError(f"{where} [chain.loads]: must be a table column → gain")
    kw["loads"] = {str(c): _nonneg(g, f"loads.{c}", where) for c, g in loads.items()}
    if "hvac" in doc:
        h = keyed_table(doc["hvac"], "chain.hvac", HVAC_KEYS, where)
        if not isinstance(h.get("column", "ambient_c"), str) or not str(h.get("column", "ambient_c")).strip():
            raise UserError(f"{where} [chain.hvac]: 'column' must be a log column name (a string), "
                            f"got {h['column']!r}")
        hv = {"column": str(h.get("column", "ambient_c")),
              "setpoint_c": _number(h.get("setpoint_c", 20.0), "hvac.setpoint_c", where)}
        if not -60.0 <= hv["setpoint_c"] <= 60.0:
            raise UserError(f"{where} [chain.hvac]: 'setpoint_c' must be a cabin temperature in -60 … 60 °C, "
                            f"got {h['setpoint_c']!r}")
        for k in ("heating_w_per_k", "cooling_w_per_k"):
            hv[k] = _nonneg(h.get(k, 0.0), f"hvac.{k}", where)
        if "warmup_j_per_k" in h:
            if pred != "battery":
                raise UserError(f"{where} [chain.hvac]: 'warmup_j_per_k' is the battery energy of a "
                                f"cabin's warm-up: only for predicts = \"battery\", got predicts = {pred!r}")
            hv["warmup_j_per_k"] = _nonneg(h["warmup_j_per_k"], "hvac.warmup_j_per_k", where)
        kw["hvac"] = hv
    if "fuel" in doc:
        if not isinstance(doc["fuel"], str) or doc["fuel"] not in FUELS:
            raise UserError(f"{where} [chain]: fuel must be one of {', '.join(FUELS)}, got {doc['fuel']!r}")
        kw["fuel"] = doc["fuel"]
    if "motor" in doc:  # SUMO's MMPEVEM motor: its constantPowerIntake is the chain's aux_power_w
        from sumo_drvpw.model.mmpevem import motor_from_dict
        kw["motor"] = motor_from_dict(doc, where)
        kw.setdefault("aux_power_w", kw["motor"].aux_power_w)
    for k in ("std_err", "reading", "provenance", "metrics"):
        if k in doc:
            if k == "provenance":
                kw[k] = provenance_table(doc[k], f"{where} [chain]", "chain.provenance")
                continue
            if not isinstance(doc[k], dict):
                raise UserError(f"{where} [chain]: '{k}' must be a table ([chain.{k}]), got {doc[k]!r}")
            kw[k] = dict(doc[k])
    if "depleting" in doc:  # (after the chain's own keys, which it inherits: their errors name [chain])
        kw["depleting"] = depleting_from_dict(doc, where)
    # a fuel chain without its engine's keys declares what a calibration keeps (its fuel cut-off)
    # and predicts nothing: :meth:`EnergyChain.require_complete` where it is used
    kw["missing"] = tuple(k for k in FUEL_REQUIRED if k not in doc) if pred == "fuel" else ()
    kw["where"] = where
    return EnergyChain(**kw)
