"""The i3 trips without heater V·I (issue #12): what load they miss, and whether a logged
signal estimates it on held-out trips. Run inside :func:`sumo_drvpw.validation.chain_i3.i3_study`.

What is missing: the chain (constant η, logged loads at gain 1) calibrated on the trips with
heater V·I and fed each trip's *measured* motor power leaves, on a trip without V·I, only its
unknown heater load (and the chain's own ~1 % error); its deficit E_bat − prediction per trip
is the load's size. It is a bound, not an estimator: it reads the battery.

Candidate estimators of the heater's electrical power from signals the 16 trips do log (causes
or loads, not the battery's response): the CAN heater power and the controller's requested
heater power at gain 1 (both are W at the heater; scale and offset checked against V·I on the
34 trips), their minimum (two reports of one heater: it draws no more than requested, and a
CAN value held after the message stops is no draw), and an air-side heat balance
k·(T_heat exchanger − T_air)⁺ (k = ṁ_air·c_p of the fan's air flow, W/K, fitted on V·I).

Protocol (fixed before the held-out run): an estimator's parameters are fitted on the training
folds' trips with V·I only (target V·I); the estimator the training side would choose is the
one with the lowest heater-energy error in a trip-grouped 5-fold CV on the trips with V·I;
every candidate is judged on held-out trips without V·I by the battery energy per trip, in
the 2-fold and the 5-fold of the pipeline (each fold's chain and road load as in chain_i3).
The candidate list was drawn up after looking at the 16 trips' signals (held CAN values,
requests above the draw): a candidate that wins there is selected on those trips, not held out.
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.validation.chain_common import KWH, mean_abs, trip_rows

#: candidate heater estimators, in the report's order ("none": the pipeline as it is)
HEATER_ESTIMATORS = ("none", "can", "req", "min_can_req", "heat_balance")
#: a CAN heater value held unchanged at least this long [s] counts as a hold in the report
HOLD_S = 60.0


def heat_balance_k(hx_c, air_c, heater_w, mask) -> float:
    """k [W/K] of heater ≈ k·(T_hx − T_air)⁺, least squares through the origin on ``mask``
    (finite samples only): the air-side heat balance of the heater core at a fixed fan level,
    k = ṁ_air·c_p."""
    f = np.maximum(np.asarray(hx_c, float) - np.asarray(air_c, float), 0.0)
    y = np.asarray(heater_w, float)
    s = mask & np.isfinite(f) & np.isfinite(y)
    den = float(f[s] @ f[s])
    return float(f[s] @ y[s]) / den if den > 0 else 0.0


def heater_estimate(name: str, cols: dict, fit_mask) -> tuple[np.ndarray, dict]:
    """(heater power [W] per sample, fitted parameters) of estimator ``name`` from the logged
    columns ``cols`` (``can``, ``req``, ``hx``, ``air``, ``vi``); parameters are fitted on
    ``fit_mask`` (samples with the heater's V·I) against ``vi``."""
    can, req = np.nan_to_num(cols["can"]), np.nan_to_num(cols["req"])
    if name == "none":
        return np.zeros(can.size), {}
    if name == "can":
        return can, {}
    if name == "req":
        return req, {}
    if name == "min_can_req":
        return np.minimum(can, req), {}
    if name == "heat_balance":
        k = heat_balance_k(cols["hx"], cols["air"], cols["vi"], fit_mask)
        return k * np.nan_to_num(np.maximum(cols["hx"] - cols["air"], 0.0)), {"k_w_per_k": k}
    raise ValueError(f"unknown heater estimator {name!r}")


def hold_share(values, trips, dt, hold_s=HOLD_S) -> dict[str, float]:
    """Per trip: the share of its time a positive value is held unchanged ≥ ``hold_s``."""
    v = np.asarray(values, float)
    out = {}
    for t in dict.fromkeys(trips):
        m = np.flatnonzero(trips == t)
        a, d = v[m], dt[m]
        starts = np.flatnonzero(np.r_[True, a[1:] != a[:-1]])
        held = 0.0
        for s0, s1 in zip(starts, np.r_[starts[1:], a.size]):
            run = float(d[s0:s1].sum())
            if a[s0] > 0 and run >= hold_s:
                held += run
        out[str(t)] = held / float(d.sum()) if d.sum() > 0 else 0.0
    return out


def _energy_cv(cols, logged, trips, dt, ids, k=5) -> dict:
    """Per estimator: mean |Σ estimate·Δt − Σ V·I·Δt| [kWh] over the trips with V·I, each
    predicted with parameters fitted on the other logged trips (trip-grouped k-fold)."""
    lids = [t for t in ids if logged[trips == t].mean() > 0.5]
    out = {}
    for name in HEATER_ESTIMATORS:
        errs = []
        for j in range(k):
            held = lids[j::k]
            h, _ = heater_estimate(name, cols, logged & ~np.isin(trips, held))
            for t in held:
                s = trips == t
                errs.append(float((h[s] - cols["vi"][s]) @ dt[s]) / KWH)
        out[name] = {"mean_abs_kwh": float(np.mean(np.abs(errs))), "mean_kwh": float(np.mean(errs))}
    return out


def heater_study(df, x, mw, mb, grade_ok, logged, trips, dt, ids) -> dict:
    """The heater estimators on held-out trips without V·I (module docstring): 2-fold and
    trip-grouped 5-fold battery energy per trip, the chain alone and the pipeline."""
    from sumo_drvpw.fit.chain import calibrate_on
    from sumo_drvpw.validation.chain_i3 import (I3_KFOLD, I3_LOADS, I3_ROAD_TERMS, fit_road_load,
                                                fitted_recuperation_limit, with_recuperation_limit)

    cols = {"can": df["heater_power_w"].to_numpy(float), "req": df["heater_power_requested_w"].to_numpy(float),
            "hx": df["heat_exchanger_temperature_c"].to_numpy(float), "air": df["ambient_c"].to_numpy(float),
            "vi": df["heater_electric_w"].to_numpy(float)}
    flagged = {t: not bool(logged[trips == t].mean() > 0.5) for t in ids}
    sig = mb.inputs.signals
    gain1 = {f"loads.{c}": 1.0 for c in I3_LOADS}
    protocols = {"2-fold": [ids[0::2], ids[1::2]], f"{I3_KFOLD}-fold": [ids[j::I3_KFOLD] for j in range(I3_KFOLD)]}
    out = {"estimators": list(HEATER_ESTIMATORS), "protocols": {}}
    for proto, folds in protocols.items():
        pred = {(e, v): np.full(trips.size, np.nan) for e in HEATER_ESTIMATORS for v in ("pipeline", "chain_only")}
        params = {e: [] for e in HEATER_ESTIMATORS}
        for held in folds:
            test = np.isin(trips, held)
            train = ~test
            use = mw.usable & grade_ok & train
            eq, _, _ = fit_road_load(x, mw.power_w, use, I3_ROAD_TERMS, "i3_heater")
            p_eq = eq.power(x)
            fit = calibrate_on(mb, loads=list(I3_LOADS), mask=train & logged, p_drive_w=mw.power_w,
                               fixed=gain1, limit=None)
            ch = with_recuperation_limit(fit.chain, fitted_recuperation_limit(p_eq, mw.power_w, dt, use))
            for e in HEATER_ESTIMATORS:
                h, prm = heater_estimate(e, cols, train & logged)
                params[e].append(prm)
                s2 = dict(sig, heater_electric_w=np.where(logged, cols["vi"], h))
                pred[(e, "pipeline")][test] = ch.evaluate(p_eq, x.v, signals=s2)["power_w"][test]
                pred[(e, "chain_only")][test] = fit.chain.evaluate(mw.power_w, x.v, signals=s2)["power_w"][test]
        res = {}
        for (e, v), p in pred.items():
            rows = trip_rows(p, mb.power_w, dt, trips)
            res.setdefault(e, {"params": params[e]})[v] = {
                "mean_abs_error": mean_abs(rows),
                "mean_abs_error_flagged": mean_abs(rows, where=lambda r: flagged[r["trip"]]),
                "mean_abs_error_unflagged": mean_abs(rows, where=lambda r: not flagged[r["trip"]]),
                "errors": {r["trip"]: r["error"] for r in rows}}
            out["measured_kwh"] = {r["trip"]: r["measured_kwh"] for r in rows}
        # the bound: each trip without V·I given its own deficit (chain alone, measured motor
        # power) as heater energy — reads the battery, so no estimator can do better on average
        co, pipe = res["none"]["chain_only"]["errors"], res["none"]["pipeline"]["errors"]
        bound = {t: pipe[t] - min(co[t], 0.0) if flagged[t] else pipe[t] for t in ids}
        res["bound"] = {"mean_abs_error": float(np.mean(np.abs(list(bound.values())))),
                        "mean_abs_error_flagged": float(np.mean([abs(bound[t]) for t in ids if flagged[t]])),
                        "errors": bound}
        out["protocols"][proto] = res
    k5 = out["protocols"][f"{I3_KFOLD}-fold"]
    meas = out["measured_kwh"]
    co = k5["none"]["chain_only"]["errors"]
    out["deficit_kwh"] = {t: -co[t] * meas[t] for t in ids if flagged[t]}
    out["energy_cv"] = _energy_cv(cols, logged, trips, dt, ids)
    out["training_choice"] = min((e for e in HEATER_ESTIMATORS if e != "none"),
                                 key=lambda e: out["energy_cv"][e]["mean_abs_kwh"])
    per = {}
    for t in ids:
        s = trips == t
        per[t] = {k: float(np.nan_to_num(cols[k][s]) @ dt[s]) / KWH for k in ("can", "req", "vi")}
    out["trip_kwh"] = per
    # CAN and the request against V·I on the trips with it: scale, offset, holds
    s = logged & np.isfinite(cols["can"]) & np.isfinite(cols["req"])
    on = s & (cols["vi"] > 100.0)
    off = s & (cols["vi"] < 1.0)
    holds = hold_share(np.nan_to_num(cols["can"]), trips, dt)
    out["signals"] = {
        "can_over_vi_median": float(np.median(cols["can"][on] / cols["vi"][on])),
        "req_over_vi_median": float(np.median(cols["req"][on] / cols["vi"][on])),
        "can_while_off_mean_w": float(np.mean(cols["can"][off])),
        "req_while_off_mean_w": float(np.mean(cols["req"][off])),
        "can_hold_share_flagged": float(np.mean([holds[t] for t in ids if flagged[t]])),
        "can_hold_share_unflagged": float(np.mean([holds[t] for t in ids if not flagged[t]]))}
    return out
