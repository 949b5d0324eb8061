"""Validation of the energy chain (issue #12) on the shared real data: energy per held-out trip.

Run::

    .venv/bin/python -m sumo_drvpw.validation.chain [REPORT.md [DATA_FOLDER]]

writes the Markdown report and ``<out>.json`` beside it. Every number is computed by the run.

Studies (each trip's prediction comes from a chain calibrated without that trip):

* **BMW i3** (TUM, 50 trips): road load calibrated stepwise (Indt var. 1) on the motor's
  mechanical power, the battery chain on V·I with the heater and A/C as logged loads;
  2-fold: trips alternately in fold A/B, calibrate on one fold, predict the other. The
  chain is fitted on the measured motor power (so it describes the powertrain, not the
  road-load equation's errors) and predicts from the road-load equation's power.
  Logger dropouts (speed and accelerometer held or linearly filled for ≥ 5 s:
  :func:`sumo_drvpw.fit.input_checks.log_dropouts`, inputs only) are left out of every fit
  and of every per-trip energy, measured, predicted and SUMO's alike.
  The heater load is the heater's own electrical power V·I. Trips A03–A21 lack heater V
  and I: their heater load is unknown (0 in the fit) and they are *flagged*; their "Heating
  Power CAN" is no substitute — in summer trips it reads up to 5 kW on average, more than
  the battery energy not delivered to the motor (E_bat − E_motor), which no heater can.
  Beside the 2-fold, trip-grouped 5-fold CV (each trip predicted by a calibration on the
  other 40 trips: the 40/10 splits of docs/closing-the-loop.md; the headline, chosen before
  the run) with the chain's η constant, as tables over |P| (fit/chain_map.py), and chosen per
  fold by an inner trip-grouped 5-fold CV on the training trips only
  (:func:`select_efficiency`: tables only if they lower the inner error on every inner fold).
* **JLU BEV**: chain calibrated on all dynamometer tests on the published dyno road load
  (A, B, C at 1919 kg, ``jlu_bev.toml``); then the six road trips: *before* with the dyno
  chain (flat, and with grade from elevation), *after* closing the loop with the battery-target
  tracer of ``diagnose`` (:func:`sumo_drvpw.fit.chain_linear.close_loop_heldout`,
  leave-one-trip-out: what the road adds, searched on the other five trips); for contrast a
  fixed-structure closure — road load plus
  grade, the dyno's efficiencies kept (same powertrain), and what the road adds fitted on
  the other five road trips (leave-one-trip-out): auxiliary power and a recuperation limit
  (kept when it lowers the BIC). Sensitivity: no limit; every parameter refitted.
* **Prius Gen 2** (2 trips): road load calibrated on the power-split P_PTdrv of the other
  trip, the Willans fuel chain on its fuel flow against the measured P_PTdrv, with the HV
  battery's V·I as SOC correction; prediction from the road-load equation's power; fuel
  per trip in litres, measured raw and SOC-corrected. For contrast, the chain fitted on
  the road-load equation's power.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

from sumo_drvpw.model.chain import corrected_fuel_power

KWH = 3.6e6  # J per kWh


def _measured(data: Path, folder: str, fmt: str, vehicle: str, add=None):
    """(wheel-target Measured or None, log, vehicle) of a shared data set read in place."""
    from sumo_drvpw.data import adapters
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.model.vehicles import load_vehicle

    veh = load_vehicle(vehicle)
    df, _ = adapters.read(fmt, data / folder)
    if add is not None:
        df = add(df)
    return from_frame(df, veh, name=f"{folder}"), veh


def _trip_rows(pred_w, meas_w, dt, trips, scale=KWH, unit="kwh") -> list[dict]:
    """Net energy per trip, predicted vs measured: Σ P·Δt over finite samples."""
    ok = np.isfinite(pred_w) & np.isfinite(meas_w)
    rows = []
    for t in dict.fromkeys(trips):
        s = ok & (trips == t)
        em = float(meas_w[s] @ dt[s]) / scale
        ep = float(pred_w[s] @ dt[s]) / scale
        rows.append({"trip": str(t), f"measured_{unit}": em, f"predicted_{unit}": ep,
                     "error": ep / em - 1.0 if em != 0 else math.nan})
    return rows


def _mean_abs(rows, key="error", where=None) -> float:
    e = [abs(r[key]) for r in rows if math.isfinite(r[key]) and (where is None or where(r))]
    return float(np.mean(e)) if e else math.nan


def _params(fit) -> dict:
    return {k: {kk: p.get(kk) for kk in ("value", "std_err", "at_bound", "reading")}
            for k, p in fit.parameters.items()}


# ------------------------------------------------------------------ BMW i3

#: the i3's road-load terms: DrvPw on the corrected data plus the condition term the loop's
#: tracer found on every fold (docs/closing-the-loop.md): [ambient_c]·v², a speed-
#: proportional force that falls with temperature (tyres and bearings warm, winter tyres)
I3_ROAD_TERMS = ("acc", "grade", "aero", "roll", "[ambient_c]*v^2")
#: logged loads of the i3, measured at the battery: additive with gain 1 (physics)
I3_LOADS = ("heater_electric_w", "aircon_power_w")


def corrected_inputs(log, x):
    """A copy of ``x`` with the measurement-side corrections of the closed loop
    (docs/closing-the-loop.md): grade fused from the accelerometer (fast part) and the
    logged grade (slow part; :func:`sumo_drvpw.fit.diagnose.structural.fused_sin_grade`),
    ρ at the logged altitude (standard atmosphere) when pressure is not logged. Returns
    (inputs, finite-grade mask)."""
    import copy

    from sumo_drvpw.fit.diagnose.structural import (P0_KPA, accelerometer_sin_grade, fused_sin_grade,
                                                    pressure_at_altitude_kpa)

    df = log.df
    x = copy.copy(x)
    if "elevation_m" in df and "pressure_kpa" not in df:
        h = df["elevation_m"].to_numpy(float)
        x.rho = np.where(np.isfinite(h), x.rho * pressure_at_altitude_kpa(h) / P0_KPA, x.rho)
    codes = np.unique(np.asarray(df["trip_id"]).astype(str), return_inverse=True)[1]
    t = df["time_s"].to_numpy(float)
    dt = float(np.median(np.diff(t)[np.diff(codes) == 0]))
    if "imu_accel_mps2" in x.signals:
        s_acc = accelerometer_sin_grade(x.signals["imu_accel_mps2"], x.a, codes, dt)
        x.theta = np.arcsin(fused_sin_grade(s_acc, np.sin(x.theta), codes, dt))
    return x, np.isfinite(x.theta)


def _road_load(x, y, use, terms, name):
    """Least squares of ``terms``; refitted under fit.physical's constraints when implausible.
    Returns (Equation, free coefficients, constraint message or None)."""
    from sumo_drvpw.fit.ols import gram
    from sumo_drvpw.fit.physical import apply_physics, constrained_fit
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.terms import term_matrix

    use = use & np.all(np.isfinite(term_matrix(terms, x)), axis=1) & np.isfinite(y)
    free = constrained_fit(gram(x, np.where(use, y, 0.0), terms, use), {}).params
    eq, msg = apply_physics(Equation(name, dict(free)), x, y, use)
    return eq, dict(free), msg


def i3_study(data: Path) -> dict:
    """2-fold held-out battery energy per trip of the TUM BMW i3 (see module docstring)."""
    import copy

    from sumo_drvpw.data.measured import measure
    from sumo_drvpw.fit.chain import calibrate_on, profile_recuperation_limit
    from sumo_drvpw.fit.input_checks import dropout_report, log_dropouts

    def add(df):
        df = df.copy()
        df["heater_logged"] = (df["heater_voltage_v"].notna() & df["heater_current_a"].notna())
        df["heater_electric_w"] = (df["heater_voltage_v"] * df["heater_current_a"]).fillna(0.0)
        df["aircon_power_w"] = df["aircon_power_w"].fillna(0.0)
        return df

    log, veh = _measured(data, "bmw_i3_tum", "bmw-i3-tum", "bmw_i3", add)
    mw, mb = measure(log, veh), measure(log, veh, "battery")
    # logger dropouts (held or linearly filled speed and accelerometer, inputs only; the rule
    # of docs/closing-the-loop.md, fit.input_checks) are no measurement: out of every fit and
    # of the per-trip energies, measured and predicted alike, on every trip
    drop = log_dropouts(log)
    drop = np.zeros(len(log.df), bool) if drop is None else drop
    mw.usable, mb.usable = mw.usable & ~drop, mb.usable & ~drop
    mb.power_w = np.where(drop, np.nan, mb.power_w)
    x, grade_ok = corrected_inputs(log, mw.inputs)
    trips = np.asarray(log.df["trip_id"]).astype(str)
    dt = log.df["dt_s"].to_numpy(float)
    logged = log.df["heater_logged"].to_numpy(bool)
    sig = mb.inputs.signals
    ids = list(dict.fromkeys(sorted(trips)))
    folds = {"A": set(ids[0::2]), "B": set(ids[1::2])}
    loads = list(I3_LOADS)
    gain1 = {f"loads.{c}": 1.0 for c in loads}
    variants = ("pipeline", "no_limit", "no_ambient_term", "cold_form", "as_logged", "loads_free",
                "symmetric_efficiency", "chain_only", "efficiency_map", "chain_only_map")
    pred = {k: np.full(trips.size, np.nan) for k in variants}
    fits, sumo_params = {}, {}
    for name, fold in folds.items():
        train = np.isin(trips, sorted(fold))
        use = mw.usable & grade_ok & train
        eq, free, msg = _road_load(x, mw.power_w, use, I3_ROAD_TERMS, f"i3_fold{name}")
        eq4, _, _ = _road_load(x, mw.power_w, use, I3_ROAD_TERMS[:4], f"i3_fold{name}_no_ambient")
        eq_log, _, _ = _road_load(mw.inputs, mw.power_w, mw.usable & train, I3_ROAD_TERMS[:4],
                                  f"i3_fold{name}_as_logged")
        # the powertrain (motor shaft → battery) on the measured motor power, on trips whose
        # heater load is known; the logged loads enter with gain 1
        fit = calibrate_on(mb, loads=loads, mask=train & logged, p_drive_w=mw.power_w,
                           fixed=gain1, limit=None)
        fit_free = calibrate_on(mb, loads=loads, mask=train & logged, p_drive_w=mw.power_w, limit=None)
        # friction-brake blending: the limit beyond which the equation's braking power is not
        # recuperated, from the equation's power against the motor's
        p_eq = eq.power(x)
        lim = profile_recuperation_limit(p_eq, mw.power_w, dt, mask=use)
        chain = copy.deepcopy(fit.chain)
        chain.recuperation_limit_w = lim["recuperation_limit_w"]
        test = ~train

        def put(key, ch, p):
            pred[key][test] = ch.evaluate(p, x.v, signals=sig)["power_w"][test]

        put("pipeline", chain, p_eq)
        put("no_limit", fit.chain, p_eq)
        ch4 = copy.deepcopy(fit.chain)
        ch4.recuperation_limit_w = profile_recuperation_limit(eq4.power(x), mw.power_w, dt,
                                                              mask=use)["recuperation_limit_w"]
        put("no_ambient_term", ch4, eq4.power(x))
        # the temperature term in a form the SUMO plug-in evaluates (model/terms 'cold' =
        # 20 °C − T, 0 without a temperature): a drag ∝ v rising in the cold
        eqc, _, _ = _road_load(x, mw.power_w, use, I3_ROAD_TERMS[:4] + ("cold*v^2",), f"i3_fold{name}_cold")
        chc = copy.deepcopy(fit.chain)
        chc.recuperation_limit_w = profile_recuperation_limit(eqc.power(x), mw.power_w, dt,
                                                              mask=use)["recuperation_limit_w"]
        put("cold_form", chc, eqc.power(x))
        chl = copy.deepcopy(fit.chain)
        chl.recuperation_limit_w = profile_recuperation_limit(
            eq_log.power(mw.inputs), mw.power_w, dt, mask=mw.usable & train)["recuperation_limit_w"]
        pred["as_logged"][test] = chl.evaluate(eq_log.power(mw.inputs), x.v, signals=sig)["power_w"][test]
        chf = copy.deepcopy(fit_free.chain)
        chf.recuperation_limit_w = chain.recuperation_limit_w
        put("loads_free", chf, p_eq)
        fit_sym = calibrate_on(mb, loads=loads, mask=train & logged, p_drive_w=mw.power_w,
                               fixed=dict(gain1, recuperation_efficiency=fit.chain.traction_efficiency),
                               limit=None)
        chs = copy.deepcopy(fit_sym.chain)
        chs.recuperation_limit_w = chain.recuperation_limit_w
        put("symmetric_efficiency", chs, p_eq)
        put("chain_only", fit.chain, mw.power_w)
        # η_t, η_r as tables over |P| (fit/chain_map.py), same loads and limit
        fit_map = calibrate_on(mb, loads=loads, mask=train & logged, p_drive_w=mw.power_w,
                               fixed=gain1, limit=None, efficiency="power")
        chm = copy.deepcopy(fit_map.chain)
        chm.recuperation_limit_w = chain.recuperation_limit_w
        put("efficiency_map", chm, p_eq)
        put("chain_only_map", fit_map.chain, mw.power_w)
        params = _params(fit)
        params["recuperation_limit_w"] = {
            "value": lim["recuperation_limit_w"], "std_err": None, "at_bound": False,
            "reading": ("braking power of the road-load equation beyond "
                        f"{lim['recuperation_limit_w'] / 1000:.1f} kW goes to the friction brakes "
                        "(profiled by BIC on the motor's measured power)")
            if lim["recuperation_limit_w"] is not None else "no limit kept (BIC)"}
        eq.mass_kg = None
        fits[name] = {"trips": sorted(fold), "road_load": dict(eq.terms), "road_load_free": free,
                      "road_load_constrained": msg, "chain": params, "r2": fit.r2, "rmse_w": fit.rmse_w,
                      "road_load_cold_form": dict(eqc.terms),
                      "chain_loads_free": {k: p["value"] for k, p in fit_free.parameters.items()},
                      "chain_symmetric": {k: p["value"] for k, p in fit_sym.parameters.items()},
                      "chain_map": _params(fit_map),
                      "map_selection": select_efficiency(mb, mw, loads, gain1, trips, train & logged, dt)}
        sumo_params[name] = (eq, chain)
    rows = _trip_rows(pred["pipeline"], mb.power_w, dt, trips)
    for k in variants[1:]:
        for r, a in zip(rows, _trip_rows(pred[k], mb.power_w, dt, trips)):
            r[f"error_{k}"] = a["error"]
    season = dict(zip(trips, np.asarray(log.df["season"]).astype(str)))
    ok = np.isfinite(mb.power_w) & np.isfinite(mw.power_w)
    for r in rows:
        s = ok & (trips == r["trip"])
        gap = float((mb.power_w[s] - mw.power_w[s]) @ dt[s]) / KWH
        heat = float(log.df["heater_electric_w"].to_numpy(float)[s] @ dt[s]) / KWH
        can = float(np.nan_to_num(log.df["heater_power_w"].to_numpy(float)[s]) @ dt[s]) / KWH
        r.update(season=season[r["trip"]], heater_kwh=heat, heater_can_kwh=can,
                 battery_minus_motor_kwh=gap, flagged=not bool(logged[s].mean() > 0.5))
    # what the battery takes beyond the motor and the logged loads, by motor power (trips
    # with heater V·I): constant = auxiliary power; rising = losses; falling below the
    # auxiliary power while braking = the battery takes in more than the motor gives back
    load = sum(log.df[c].to_numpy(float) for c in I3_LOADS)
    gap_w = mb.power_w - load - mw.power_w
    s = logged & np.isfinite(gap_w) & np.isfinite(mw.power_w)
    edges = np.array([-40e3, -30e3, -20e3, -10e3, -2e3, 2e3, 10e3, 20e3, 30e3, 40e3, 60e3])
    k = np.digitize(mw.power_w[s], edges)
    bins = [{"from_w": float(edges[i - 1]), "to_w": float(edges[i]), "n": int((k == i).sum()),
             "motor_w": float(np.mean(mw.power_w[s][k == i])),
             "battery_minus_loads_minus_motor_w": float(np.mean(gap_w[s][k == i]))}
            for i in range(1, edges.size) if (k == i).sum() > 100]
    sumo = _i3_sumo(log, x, trips, rows, folds, sumo_params, veh, drop)
    out = {"rows": rows, "fits": fits, **sumo,
           "mean_error": float(np.nanmean([r["error"] for r in rows])),
           "mean_abs_error": _mean_abs(rows),
           "mean_abs_error_unflagged": _mean_abs(rows, where=lambda r: not r["flagged"]),
           "mean_abs_error_summer": _mean_abs(rows, where=lambda r: r["season"] == "summer"),
           "mean_abs_error_winter": _mean_abs(rows, where=lambda r: r["season"] == "winter"),
           "mean_error_summer": float(np.mean([r["error"] for r in rows if r["season"] == "summer"])),
           "mean_error_winter": float(np.mean([r["error"] for r in rows if r["season"] == "winter"])),
           "n_flagged": sum(r["flagged"] for r in rows), "road_terms": list(I3_ROAD_TERMS),
           "gap_by_motor_power": bins,
           "dropouts_s": dropout_report(drop, trips, dt)}
    for k in variants[1:]:
        out[f"mean_abs_error_{k}"] = _mean_abs(rows, f"error_{k}")
    out["kfold"] = _i3_kfold(x, mw, mb, grade_ok, logged, trips, dt, ids, loads, gain1, I3_KFOLD)
    return out


#: folds of the i3's trip-grouped cross-validation beside the 2-fold (each trip predicted by a
#: calibration on the other 40 trips: the 40/10 splits of docs/closing-the-loop.md)
I3_KFOLD = 5


def select_efficiency(mb, mw, loads, gain1, trips, train, dt, k=5) -> dict:
    """Training-side choice between a constant η and the |P| map: trip-grouped k-fold CV on
    the training trips only (chain fed the measured motor power, net battery energy per inner
    held-out trip). The map is chosen only when it lowers the inner mean |error| on every
    inner fold (consistently), never by the outer held-out result."""
    from sumo_drvpw.fit.chain import calibrate_on

    ids = sorted(set(trips[train]))
    per = []
    for j in range(k):
        inner = set(ids[j::k])
        fit_on = train & ~np.isin(trips, sorted(inner))
        test = np.isin(trips, sorted(inner)) & train
        errs = {}
        for kind in ("constant", "power"):
            ch = calibrate_on(mb, loads=loads, mask=fit_on, p_drive_w=mw.power_w, fixed=gain1,
                              limit=None, efficiency=kind).chain
            pred = ch.evaluate(mw.power_w, mw.inputs.v, signals=mb.inputs.signals)["power_w"]
            pred = np.where(test, pred, np.nan)
            errs[kind] = _mean_abs(_trip_rows(pred, np.where(test, mb.power_w, np.nan), dt, trips))
        per.append(errs)
    better = [e["power"] < e["constant"] for e in per]
    return {"inner_folds": per, "map_better_on": int(sum(better)), "k": k,
            "choice": "power" if all(better) else "constant"}


def _i3_kfold(x, mw, mb, grade_ok, logged, trips, dt, ids, loads, gain1, k) -> dict:
    """The pipeline (road load, chain with constant η or the |P| map, recuperation limit) in
    trip-grouped k-fold cross-validation: fold j = every k-th trip from the j-th."""
    import copy

    from sumo_drvpw.fit.chain import calibrate_on, profile_recuperation_limit

    keys = ("pipeline", "efficiency_map", "chain_only", "chain_only_map", "selected")
    pred = {kk: np.full(trips.size, np.nan) for kk in keys}
    sig = mb.inputs.signals
    choices = []
    for j in range(k):
        test = np.isin(trips, ids[j::k])
        train = ~test
        use = mw.usable & grade_ok & train
        eq, _, _ = _road_load(x, mw.power_w, use, I3_ROAD_TERMS, f"i3_kfold{j}")
        p_eq = eq.power(x)
        lim = profile_recuperation_limit(p_eq, mw.power_w, dt, mask=use)["recuperation_limit_w"]
        sel = select_efficiency(mb, mw, loads, gain1, trips, train & logged, dt)
        choices.append(sel)
        for kind, a, b in (("constant", "pipeline", "chain_only"), ("power", "efficiency_map", "chain_only_map")):
            fit = calibrate_on(mb, loads=loads, mask=train & logged, p_drive_w=mw.power_w, fixed=gain1,
                               limit=None, efficiency=kind)
            ch = copy.deepcopy(fit.chain)
            ch.recuperation_limit_w = lim
            pred[a][test] = ch.evaluate(p_eq, x.v, signals=sig)["power_w"][test]
            pred[b][test] = fit.chain.evaluate(mw.power_w, x.v, signals=sig)["power_w"][test]
            if kind == sel["choice"]:
                pred["selected"][test] = pred[a][test]
    rows = _trip_rows(pred["pipeline"], mb.power_w, dt, trips)
    for kk in keys[1:]:
        for r, a in zip(rows, _trip_rows(pred[kk], mb.power_w, dt, trips)):
            r[f"error_{kk}"] = a["error"]
    flagged = {t: not bool(logged[trips == t].mean() > 0.5) for t in ids}
    out = {"k": k, "rows": rows, "selection": choices, "mean_abs_error": _mean_abs(rows),
           "mean_abs_error_unflagged": _mean_abs(rows, where=lambda r: not flagged[r["trip"]]),
           "mean_abs_error_flagged": _mean_abs(rows, where=lambda r: flagged[r["trip"]])}
    for kk in keys[1:]:
        out[f"mean_abs_error_{kk}"] = _mean_abs(rows, f"error_{kk}")
        out[f"mean_abs_error_{kk}_unflagged"] = _mean_abs(rows, f"error_{kk}",
                                                          where=lambda r: not flagged[r["trip"]])
    return out


def _i3_sumo(log, x, trips, rows, folds, sumo_params, veh, drop) -> dict:
    """Each trip through SUMO's electric models, shipped and with the parameters of the
    fold that did not see the trip (chain_sumo.chain_vtype_params; the trip's mean logged
    heater and A/C power added to the constant intake, as a SUMO user who knows it would);
    the seconds of a logger dropout are booked neither by SUMO nor in the measured energy."""
    import tempfile

    from sumo_drvpw.validation.chain_sumo import ELECTRIC_MODELS, chain_vtype_params, sumo_battery_kwh

    df = log.df
    load = sum(df[c].to_numpy(float) for c in I3_LOADS)
    area = veh.body.get("frontal_area_m2")
    missing, vtypes = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for r in rows:
            s = trips == r["trip"]
            fold = next(k for k, f in folds.items() if r["trip"] not in f)  # the other fold's fit
            eq, chain = sumo_params[fold]
            p, miss = chain_vtype_params(eq, chain, float(np.mean(x.mass[s])), area,
                                         extra_aux_w=float(np.mean(load[s])), at_motor_shaft=True)
            missing[fold] = miss
            vtypes.setdefault(fold, p)
            sm = sumo_battery_kwh(df["time_s"].to_numpy()[s], x.v[s], x.theta[s], Path(tmp), p,
                                  drop=drop[s])
            for label, v in sm.items():
                r[f"{label}_kwh"] = v["kwh"]
                r[f"{label}_error"] = v["kwh"] / r["measured_kwh"] - 1.0
                r[f"{label}_nan_steps"] = v["nan_steps"]
    means = {}
    for label in ELECTRIC_MODELS:
        if not rows or f"{label}_error" not in rows[0]:
            continue
        ratio = lambda where: float(np.mean([1 + r[f"{label}_error"] for r in rows if where(r)]))  # noqa: E731
        means[label] = {"mean_ratio": ratio(lambda r: True),
                        "mean_ratio_summer": ratio(lambda r: r["season"] == "summer"),
                        "mean_ratio_winter": ratio(lambda r: r["season"] == "winter"),
                        "mean_abs_error": _mean_abs(rows, f"{label}_error"),
                        "nan_steps": int(sum(r[f"{label}_nan_steps"] for r in rows))}
    return {"sumo_models": means, "sumo_chain_vtypes": vtypes, "sumo_chain_missing": missing}


# ------------------------------------------------------------------ JLU BEV

def jlu_study(data: Path) -> dict:
    """Dyno-calibrated chain on the JLU road trips, before and after closing the loop."""
    from sumo_drvpw.data.measured import measure
    from sumo_drvpw.fit.chain import calibrate_on
    from sumo_drvpw.model.equations import Equation

    dlog, veh = _measured(data, "jlu_bev_dyno", "jlu-dyno", "jlu_bev")
    rl = {}
    from sumo_drvpw.fileio import read_toml

    rl = read_toml(veh.path, "vehicle file")["road_load"]
    terms = {"acc": 1.0, "v1": float(rl["a_n"]), "v2": float(rl["b_n_per_mps"]),
             "v3": float(rl["c_n_per_mps2"])}
    flat = Equation("jlu_dyno_roadload", dict(terms))
    graded = Equation("jlu_dyno_roadload_grade", dict(terms, grade=1.0))
    dy = measure(dlog, veh, "battery")
    dfit = calibrate_on(dy, flat)
    rlog, _ = _measured(data, "jlu_bev_road", "jlu-road", "jlu_bev")
    ro = measure(rlog, veh, "battery")
    trips = np.asarray(rlog.df["trip_id"]).astype(str)
    dt = rlog.df["dt_s"].to_numpy(float)

    def ev(chain, eq):
        return chain.evaluate(eq.power(ro.inputs), ro.inputs.v, signals=ro.inputs.signals)["power_w"]

    before = _trip_rows(ev(dfit.chain, flat), ro.power_w, dt, trips)
    before_g = _trip_rows(ev(dfit.chain, graded), ro.power_w, dt, trips)
    dyno_eta = {"traction_efficiency": dfit.chain.traction_efficiency,
                "recuperation_efficiency": dfit.chain.recuperation_efficiency}
    variants = {"after": (dyno_eta, "profile"), "after_no_limit": (dyno_eta, None),
                "after_all_refit": ({}, "profile")}
    preds = {k: np.full(trips.size, np.nan) for k in variants}
    loo = {}
    for t in dict.fromkeys(trips):
        train = trips != t
        for k, (fixed, lim) in variants.items():
            f = calibrate_on(ro, graded, mask=train, fixed=fixed, limit=lim)
            preds[k][~train] = ev(f.chain, graded)[~train]
            if k == "after":
                loo[t] = {n: p["value"] for n, p in f.parameters.items() if not p.get("fixed")}
    after_rows = _trip_rows(preds["after"], ro.power_w, dt, trips)
    # the loop closed by diagnose's battery-target tracer (fit.chain_linear): leave-one-trip-out,
    # the tracer searches what the road adds to the dyno chain on the other five trips
    from sumo_drvpw.fit.chain_linear import close_loop_heldout

    declared = Equation("jlu_dyno_chain", dict(terms))
    declared.chain = dfit.chain
    traced = close_loop_heldout(ro, declared)
    sens = {k: _trip_rows(preds[k], ro.power_w, dt, trips) for k in ("after_no_limit", "after_all_refit")}
    g = rlog.df.groupby("trip_id", sort=False)
    info = {str(k): {"ambient_c": float(v["ambient_c"].mean()), "duration_s": float(v["time_s"].max() - v["time_s"].min()),
                     "standstill_share": float((v["speed_mps"] < 0.1).mean()),
                     "net_elevation_m": float(v["elevation_m"].iloc[-1] - v["elevation_m"].iloc[0])}
            for k, v in g}
    st_road = ro.inputs.v < 0.1
    st_dyno = dy.inputs.v < 0.1
    return {"dyno_chain": _params(dfit), "dyno_r2": dfit.r2, "dyno_n": dfit.n,
            "road_load_terms": terms,
            "standstill_battery_w": {"dyno": float(np.nanmean(dy.power_w[st_dyno])),
                                     "road": float(np.nanmean(ro.power_w[st_road]))},
            "before": before, "before_grade": before_g, "after": after_rows, "loo_parameters": loo,
            "after_no_limit": sens["after_no_limit"], "after_all_refit": sens["after_all_refit"],
            "mean_abs_error_after_no_limit": _mean_abs(sens["after_no_limit"]),
            "mean_abs_error_after_all_refit": _mean_abs(sens["after_all_refit"]),
            "trip_info": info,
            "mean_abs_error_before": _mean_abs(before), "mean_abs_error_before_grade": _mean_abs(before_g),
            "mean_abs_error_after": _mean_abs(after_rows),
            "diagnose": {t: {k: r[k] for k in ("before", "after", "findings")} for t, r in traced["trips"].items()},
            "diagnose_found_on": traced["found_on"],
            "mean_abs_error_after_diagnose": traced["mean_abs_error_after"],
            "mean_abs_error_before_diagnose": traced["mean_abs_error_before"]}


# ------------------------------------------------------------------ Prius Gen 2

def prius2_study(data: Path) -> dict:
    """Fuel per held-out trip of the Prius Gen 2 (Willans chain, SOC-corrected)."""
    from sumo_drvpw.data.measured import measure
    from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
    from sumo_drvpw.fit.chain import calibrate_on
    from sumo_drvpw.model.constants import FUELS

    log, veh = _measured(data, "prius_gen2_torquepro", "torquepro-prius2", "prius2")
    mw, mf = measure(log, veh), measure(log, veh, "fuel")
    trips = np.asarray(log.df["trip_id"]).astype(str)
    dt = log.df["dt_s"].to_numpy(float)
    fp = FUELS["gasoline"]
    per_l = fp["lhv_j_per_kg"] * fp["density_kg_per_l"]  # J per litre
    rows, fits = [], {}
    for t in dict.fromkeys(trips):
        train = trips != t
        res = calibrate(mw.inputs, mw.power_w, CANDIDATES["indt-var-1"], mask=mw.usable & train,
                        reference_mass_kg=veh.mass_kg)
        eq = res.to_equation(f"prius2_without_{t}")
        fit = calibrate_on(mf, mask=train, p_drive_w=mw.power_w)
        out = fit.chain.evaluate(eq.power(mf.inputs), mf.inputs.v, dt_s=dt, signals=mf.inputs.signals)
        # for contrast: the chain fitted on the road-load equation's power (errors in variables)
        fit_eq = calibrate_on(mf, eq, mask=train)
        out_eq = fit_eq.chain.evaluate(eq.power(mf.inputs), mf.inputs.v, dt_s=dt, signals=mf.inputs.signals)
        k = fit.chain.battery_fuel_factor
        corr = corrected_fuel_power(mf.power_w, mf.battery_w, k)
        s = ~train & np.isfinite(out["power_w"]) & np.isfinite(corr)
        raw_l = float(np.nan_to_num(mf.power_w[s]) @ dt[s]) / per_l
        corr_l = float(corr[s] @ dt[s]) / per_l
        pred_l = float(out["fuel_l"][s].sum())
        pred_eq_l = float(out_eq["fuel_l"][s].sum())
        dist_km = float(mf.inputs.v[s] @ dt[s]) / 1000.0
        rows.append({"trip": t, "distance_km": dist_km, "measured_l": raw_l,
                     "battery_kwh": float(mf.battery_w[s] @ dt[s]) / KWH,
                     "measured_corrected_l": corr_l, "predicted_l": pred_l,
                     "predicted_co2_kg": float(out["co2_kg"][s].sum()),
                     "error": pred_l / corr_l - 1.0, "error_vs_raw": pred_l / raw_l - 1.0,
                     "error_chain_fitted_on_equation": pred_eq_l / corr_l - 1.0,
                     "measured_l_per_100km": 100.0 * raw_l / dist_km})
        fits[t] = {"road_load": dict(eq.terms), "chain": _params(fit), "r2": fit.r2,
                   "chain_fitted_on_equation": _params(fit_eq)}
        # SUMO's PHEMlight5 petrol class along the same trip (its grade as logged)
        import tempfile

        from sumo_drvpw.validation.chain_sumo import sumo_fuel_l

        s_all = trips == t
        with tempfile.TemporaryDirectory() as tmp:
            sm = sumo_fuel_l(log.df["time_s"].to_numpy()[s_all], mf.inputs.v[s_all],
                             np.nan_to_num(mf.inputs.theta[s_all]), Path(tmp), fp["density_kg_per_l"])
        for label, x in sm.items():
            rows[-1][f"{label}_l"] = x["l"]
            rows[-1][f"{label}_error"] = x["l"] / corr_l - 1.0
            rows[-1][f"{label}_error_vs_raw"] = x["l"] / raw_l - 1.0
            rows[-1][f"{label}_nan_steps"] = x["nan_steps"]
    return {"rows": rows, "fits": fits, "mean_abs_error": _mean_abs(rows),
            "mean_abs_error_chain_fitted_on_equation": _mean_abs(rows, "error_chain_fitted_on_equation")}


from sumo_drvpw.validation.chain_render import render  # noqa: E402  (the report of run())


STUDIES = {"bmw_i3": i3_study, "jlu": jlu_study, "prius2": prius2_study}
#: the data-set folders the studies read (for :func:`~sumo_drvpw.validation.data.resolve_data`)
FOLDERS = ("bmw_i3_tum", "jlu_bev_dyno", "jlu_bev_road", "prius_gen2_torquepro")


def run(data: Path, studies=None) -> dict:
    """Run the studies (default all) on the shared data folder; return their results."""
    t0 = time.perf_counter()
    res = {k: f(Path(data)) for k, f in STUDIES.items() if studies is None or k in studies}
    res["seconds"] = time.perf_counter() - t0
    return res


def main(argv=None) -> int:
    """``python -m sumo_drvpw.validation.chain [REPORT.md [DATA_FOLDER]]`` (positional only:
    library modules name no command-line options; defaults docs/energy-chain-validation.md
    and $SUMO_DRVPW_DATA or ../shared/data). Exit 2 with one line when the data are absent."""
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.fileio import plain, write_json, write_text
    from sumo_drvpw.validation.data import resolve_data

    args = list(sys.argv[1:] if argv is None else argv)
    out = Path(args[0] if args else "docs/energy-chain-validation.md")
    try:
        data = resolve_data(args[1] if len(args) > 1 else None, FOLDERS)
        res = run(data)
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    cmd = "python -m sumo_drvpw.validation.chain" + (f" {out}" if args else "")
    write_json(out.with_suffix(".json"), plain(res))
    write_text(out, render(res, cmd))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
