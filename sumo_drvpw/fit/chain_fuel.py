"""Calibrate a fuel chain (model/chain.py) on top of a road-load equation: a Willans line
with engine-off, SOC-corrected with k = 1/η_m, linear in its parameters::

    P_fuel = a·on + b·(paid·max(P, 0) − P_bat) + c·cs + Σ c_k·paid·L_k,
    b = 1/η_m, a = P_idle,fuel, c = P_aux/η_m,

solved as the battery form is (fit/chain.py: bounded least squares on the factored design,
each sample weighted by its duration), with the engine-off threshold P_off (``on`` = P >
P_off) and the speed above which the engine always runs profiled over grids by BIC.

An engine that stops is fitted in the charge-sustaining form (``paid`` = 1, ``cs`` = 1;
model/chain.py): the target, fuel + P_bat/η_m, holds the battery's energy at the margin,
also where the engine is off and the battery drives, so only the idle fuel stops with
the engine, and the auxiliary draw the battery carries while it is off is a parameter of
its own. (The plain form, ``paid`` = ``on`` and no ``c``, would call that driving free:
it is the per-sample fuel flow, not the fuel a trip costs.) An engine that never stops
(P_off = −inf) has one form, its auxiliary draw in the idle fuel.

An engine the log shows idling at stops (fuel flowing on most of the standing time:
:func:`idles_at_stops`) is fitted as one that runs at standstill: every threshold P_off ≥ 0
stops the engine where the car stands (P = 0), which the log says it does not. Found on
Argonne's D3 dynamometer tests of a 2018 Toyota Camry (docs/d3-camry.md): without this
rule one fold read the conventional car as an engine that stops at P ≤ 0 with a 1.8 kW
auxiliary draw paid at the margin — a charge-sustaining hybrid's form taking up the
higher fuel of an engine in gear than at idle.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from sumo_drvpw.fit.chain import (ETA_MIN, ChainFit, _bic, _col, _covariance, _nan_none, _solve,
                                  _stats)
from sumo_drvpw.fit.chain_checks import reading
from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain import EnergyChain, Table, corrected_fuel_power
from sumo_drvpw.model.constants import STANDSTILL_MPS

#: engine-off thresholds tried for the fuel chain [W]
ENGINE_OFF_GRID_W = (-np.inf, 0.0, 1000.0, 2000.0, 3000.0, 4000.0, 5000.0, 6000.0, 8000.0, 10000.0, 12000.0, 15000.0)
#: the engine-off thresholds tried for a car without a traction battery [W]: an engine that
#: never stops, or one that stops only where no driving power is asked (at rest with
#: stop-start, on overrun); above 0 W nothing but a battery could drive the car
CONVENTIONAL_OFF_GRID_W = (-np.inf, 0.0)
#: speeds above which the engine always runs, tried for the fuel chain [m/s] (None: no such speed)
ENGINE_ON_SPEED_GRID_MPS = (None, 4.0, 6.0, 8.0, 10.0, 12.0, 14.0, 17.0, 20.0)
#: a fuel chain's engine on/off is identified at city speeds only when at least this share
#: of the calibration time lies below CITY_SPEED_MPS (50 km/h, the urban limit)
CITY_SPEED_MPS = 50.0 / 3.6
CITY_SHARE_MIN = 0.1
#: an engine burning fuel on at least this share of the standing time idles at stops
IDLES_AT_STOPS_SHARE = 0.5
#: burning fuel: a fuel power above this [W] (0.06 L/h of petrol; an engine that is off
#: reads 0, a small engine idling 0.3 L/h or more)
FUEL_FLOWING_W = 500.0
#: the standing time [s] below which a log does not tell whether its engine idles at stops
IDLING_MIN_STANDING_S = 30.0
#: the largest auxiliary draw a car's engine plausibly carries [W] (12 V net and the A/C
#: compressor at full load together; a fuel chain's reading flags more)
CAR_AUX_MAX_W = 3000.0


def fuel_grid(engine_off="profile", engine_on_above_mps="profile", fuel_cut_below_w=None,
              charge_sustaining: bool = True) -> list:
    """The fuel chains tried, one per engine-off threshold and engine-on speed (templates:
    their engine state only); an engine that never stops (off = −inf) is on at any speed:
    one fit, no speed threshold, and sustains no charge (``charge_sustaining`` applies to
    the thresholds it can stop at)."""
    grid = {"profile": ENGINE_OFF_GRID_W, "conventional": CONVENTIONAL_OFF_GRID_W}.get(
        engine_off, None) if isinstance(engine_off, str) else None
    grid = grid or (float(engine_off),)
    vgrid = (ENGINE_ON_SPEED_GRID_MPS if engine_on_above_mps == "profile" else (engine_on_above_mps,))
    return [EnergyChain(predicts="fuel", engine_off_below_w=off, engine_on_above_mps=von,
                        fuel_cut_below_w=fuel_cut_below_w, charge_sustaining=charge_sustaining and off > -np.inf)
            for off in grid for von in (vgrid if off > -np.inf else (None,))]


def engine_off_for(vehicle, battery_logged: bool, engine_off="profile"):
    """The engine-off thresholds to profile: "conventional" (:data:`CONVENTIONAL_OFF_GRID_W`)
    where ``engine_off`` is "profile" and the vehicle file declares no traction battery (its
    powertrain type 'direct', no [battery] table) and no battery power is logged; else
    ``engine_off`` as given."""
    if (isinstance(engine_off, str) and engine_off == "profile" and vehicle is not None
            and not battery_logged and vehicle.powertrain_type == "direct" and not vehicle.battery):
        return "conventional"
    return engine_off


def note_conventional(params: dict) -> None:
    """The engine-off reading of a fit made for a car without a traction battery."""
    params["engine_off_below_w"]["reading"] += (
        "; a car without a traction battery (the vehicle file declares none: powertrain type 'direct', "
        "no [battery]; no battery power logged): only an engine that never stops or one that stops "
        "where no driving power is asked (at rest, on overrun) was tried — a hybrid's engine-off "
        "threshold is profiled when its vehicle file declares its battery, or declared")
    params["engine_off_below_w"]["how"] = "profiled among 'never' and 0 W (no traction battery)"


def standing_sums(v, fuel_w, dt_s, ok) -> np.ndarray:
    """[standing time, of it with fuel flowing [s], the fuel energy flowing then [J]] on the
    samples ``ok`` (standing: v < STANDSTILL_MPS; flowing: fuel power above
    :data:`FUEL_FLOWING_W`): sums, so batches add."""
    stand = ok & (v < STANDSTILL_MPS)
    flow = stand & (fuel_w > FUEL_FLOWING_W)
    return np.array([float(dt_s[stand].sum()), float(dt_s[flow].sum()), float(dt_s[flow] @ fuel_w[flow])])


def idles_at_stops(sums) -> bool:
    """Whether :func:`standing_sums` show an engine idling at stops (enough standing time,
    fuel flowing on most of it)."""
    return bool(sums[0] >= IDLING_MIN_STANDING_S and sums[1] >= IDLES_AT_STOPS_SHARE * sums[0])


def note_idling(params: dict, sums) -> None:
    """The engine-off reading of a fit made with the engine running at standstill."""
    params["engine_off_below_w"]["reading"] += (
        f"; the log shows it idling at stops (fuel flowing on {sums[1] / sums[0]:.0%} of {sums[0]:.0f} s "
        "standing), so only an engine that runs at standstill was fitted")
    params["engine_off_below_w"]["how"] = "fixed: the engine idles at stops in the log"


def note_declared(params: dict) -> None:
    """The engine-off threshold of a fit made with the one the user declared."""
    params["engine_off_below_w"]["how"] = "declared"
    params["engine_off_below_w"]["reading"] += "; declared, not profiled"


def fuel_names(tmpl: EnergyChain, loads) -> list[str]:
    """The parameters of ``tmpl``'s Willans line: the idle fuel, 1/η_m, for a
    charge-sustaining template the auxiliary power (paid also while the engine is off: the
    battery carries it and the engine puts it back; with the engine off only while on, it is
    the idle fuel's), and the load gains."""
    return (["idle_fuel_power_w", "marginal_efficiency"] + ["aux_power_w"] * tmpl.charge_sustaining
            + [f"loads.{c}" for c in loads] + ["moving_idle_fuel_power_w"] * (tmpl.moving_idle_fuel_power_w is not None))


def fuel_bounds(names) -> tuple[list, list]:
    """Bounds of :func:`fuel_names`'s parameters: 1/η_m in [1, 1/ETA_MIN], the rest ≥ 0."""
    return [0.0, 1.0] + [0.0] * (len(names) - 2), [np.inf, 1.0 / ETA_MIN] + [np.inf] * (len(names) - 2)


def fuel_design(tmpl: EnergyChain, p, v, pb, lcols) -> np.ndarray:
    """The Willans line's design [on, paid·max(P, 0) − P_bat, (1), paid·L_k] of the engine
    state of ``tmpl`` (:func:`fuel_names`): paid = on, or everywhere for a charge-sustaining
    template (model/chain.py), which has the auxiliary power's column of ones. A rated output
    (``engine_max_w``) caps what the engine delivers, the driving power and the logged loads
    together (:func:`capped_drive`)."""
    paid = tmpl.paid(p, v).astype(float)
    aux = [np.ones(p.shape)] if tmpl.charge_sustaining else []
    on = tmpl.engine_on(p, v).astype(float)
    drive = capped_drive(p, tmpl.engine_max_w, lcols)
    return np.column_stack([on, paid * drive - pb] + aux + [paid * c for c in lcols]
                           + moving_columns(tmpl, on, v))


def capped_drive(p, cap_w, lcols=()) -> np.ndarray:
    """The driving power the engine delivers [W]: max(P, 0), at most the rated output ``cap_w``
    [W] (None: no cap) less the logged loads ``lcols`` [W, at the engine output] — the chain caps
    its engine demand max(P, 0) + P_aux + Σ g_k·L_k (model/chain_values.py ``engine_demand``), so
    with g_k = 1, a load logged in watts at the engine, max(P, 0) + Σ L_k ≤ ``cap_w`` and the loads'
    columns carry the rest. Without loads: min(max(P, 0), ``cap_w``)."""
    if cap_w is None:
        return np.maximum(p, 0.0)
    if not len(lcols):
        return np.clip(p, 0.0, cap_w)
    return np.clip(p, 0.0, np.maximum(cap_w - np.sum(lcols, axis=0), 0.0))


def fuel_chain(loads, beta, se, active, off, engine_on_above_mps, low: float, fuel="gasoline",
               fuel_cut_below_w=None, charge_sustaining: bool = False, battery: bool = True):
    """The fuel chain and its parameters from the fitted [a, b = 1/η_m, (c = P_aux/η_m for a
    ``charge_sustaining`` one), c_k] (:func:`fuel_names`), their standard errors and active
    bounds, the engine-off threshold and engine-on speed, the share ``low`` of the
    calibration time below city speed, and whether the log had the hybrid battery's power
    (``battery``)."""
    b = float(beta[1])
    eta = 1.0 / b
    params = {"idle_fuel_power_w": {"value": float(beta[0]), "std_err": _nan_none(se[0]),
                                    "at_bound": bool(active[0] != 0)},
              "marginal_efficiency": {"value": eta, "std_err": _nan_none(se[1] / b ** 2),
                                      "at_bound": bool(active[1] != 0)}}
    gains, k0 = {}, 2 + charge_sustaining  # the columns of fuel_names
    if charge_sustaining:  # c = P_aux/η_m
        params["aux_power_w"] = {"value": float(beta[2]) * eta, "std_err": _nan_none(se[2] * eta),
                                 "at_bound": bool(active[2] != 0)}
    for j, c in enumerate(loads):  # c_k = g_k/η_m → g_k = c_k·η_m
        gains[c] = float(beta[k0 + j]) * eta
        params[f"loads.{c}"] = {"value": gains[c], "std_err": _nan_none(se[k0 + j] * eta),
                                "at_bound": bool(active[k0 + j] != 0)}
    params["engine_off_below_w"] = {"value": off, "std_err": None, "at_bound": False,
                                    "how": "profiled (BIC) over a grid"}
    if engine_on_above_mps is not None:
        params["engine_on_above_mps"] = {"value": engine_on_above_mps, "std_err": None,
                                         "at_bound": False, "how": "profiled (BIC) over a grid"}
    for name, p_ in params.items():
        p_["reading"] = reading(name, p_["value"], fuel)
    if charge_sustaining:
        aux = params["aux_power_w"]["value"]
        params["aux_power_w"]["reading"] = (
            f"auxiliary draw {aux:.0f} W at the engine output (12 V net, pumps, A/C): the battery carries it "
            "while the engine is off and the engine puts it back, so it costs fuel at the margin also standing"
            + (f"; IMPLAUSIBLE for a car (12 V and A/C together up to about {CAR_AUX_MAX_W / 1000:.0f} kW): "
               "the line takes up what the driving power misses" if aux > CAR_AUX_MAX_W else ""))
    if charge_sustaining and off > 0:
        params["engine_off_below_w"]["reading"] += (
            "; charge-sustaining: below it the battery drives and the engine puts that energy back "
            "later, so all driving power costs fuel at the margin and only the idle fuel stops")
        if not battery:
            params["engine_off_below_w"]["reading"] += (
                "; the battery's share is NOT IDENTIFIED: the log has no hybrid-battery power "
                "(battery_voltage_v, battery_current_a), so the fit sees no fuel below the threshold and "
                "the recharging only as heavier fuel with the engine on, which the idle fuel and the "
                "auxiliary draw take up")
    if low < CITY_SHARE_MIN:  # the engine's on/off at city speeds is not in the data
        params["engine_off_below_w"]["reading"] += (
            f"; NOT IDENTIFIED at city speeds: {low:.0%} of the calibration time is below "
            f"{CITY_SPEED_MPS * 3.6:.0f} km/h, so where a SUMO study drives slower the engine's "
            "on/off is extrapolated (a hybrid that runs electric at low power there would use less fuel "
            "than this chain books)")
    chain = EnergyChain(predicts="fuel", idle_fuel_power_w=float(beta[0]), marginal_efficiency=eta,
                        engine_off_below_w=off, engine_on_above_mps=engine_on_above_mps,
                        fuel_cut_below_w=fuel_cut_below_w, loads=gains, fuel=fuel,
                        charge_sustaining=charge_sustaining,
                        aux_power_w=params["aux_power_w"]["value"] if charge_sustaining else 0.0)
    return chain, params


def calibrate_fuel(p_drive_w, v_mps, fuel_w, dt_s, battery_w=None, signals: dict | None = None, *,
                   loads=(), mask=None, engine_off="profile", fuel: str = "gasoline",
                   engine_on_above_mps="profile", fuel_cut_below_w: float | None = None,
                   charge_sustaining: bool = True, moving_idle: bool = False, engine_max_w=None,
                   trip=None, window_s: float | None = None, check_windows: bool = True) -> ChainFit:
    """Calibrate a Willans-line fuel chain with engine-off and battery (SOC) correction.

    Parameters
    ----------
    p_drive_w : driving power of the road-load equation [W]
    v_mps : speed [m/s]
    fuel_w : measured fuel power ṁ·LHV [W]
    dt_s : sample durations [s]
    battery_w : hybrid battery power V·I, positive when discharging [W], or None
    loads : logged load columns (gains ≥ 0, at the engine output)
    engine_off : "profile" (grid :data:`ENGINE_OFF_GRID_W`, by RSS) or a number [W]
    fuel : key of :data:`sumo_drvpw.model.constants.FUELS`
    engine_on_above_mps : speed above which the engine always runs [m/s]: "profile" (grid
        :data:`ENGINE_ON_SPEED_GRID_MPS` jointly with the threshold, by BIC), None or a number
    fuel_cut_below_w : a declared overrun fuel cut-off (model/chain.py), kept: those samples
        are unfuelled in the fit and the chain keeps it; None: none
    charge_sustaining : fit and return the charge-sustaining form for an engine that stops
        (default: the SOC-corrected target is that form's; an engine that never stops has
        one form); False: the plain form, the driving below P_off unfuelled
    moving_idle : fit a moving zero-output fuel ≥ the idle fuel (model/chain.py
        ``moving_idle_fuel_power_w``: an engine's friction at road speed, not its idle's)
    engine_max_w : the engine's rated output [W] (model/chain.py): None (no cap), a number
        (declared, kept: the fit books the demand above it at it) or "profile" (:func:`profile_cap`)
    trip : trip id per sample (None: one trip): windows never cross trips
    window_s : fit on means over windows of this many seconds (fit/chain_windows.py: the noise of a
        derived acceleration out of the regressor); None: on the samples
    check_windows : refit the per-sample line on windowed means
        (:data:`~sumo_drvpw.fit.chain_windows.DILUTION_WINDOWS_S`) into ``ChainFit.windowed``, which
        the plausibility check reads (fit/chain_checks.py ``dilution_note``)
    """
    p = np.asarray(p_drive_w, float)
    n = p.size
    y = np.asarray(fuel_w, float)
    v = np.broadcast_to(np.asarray(v_mps, float), (n,))
    w = np.broadcast_to(np.asarray(dt_s, float), (n,)).astype(float)
    pb = np.zeros(n) if battery_w is None else np.nan_to_num(np.asarray(battery_w, float))
    sig = signals or {}
    lcols = [_col(sig, c, n) for c in loads]
    ok = np.isfinite(p) & np.isfinite(y) & np.isfinite(w)
    if mask is not None:
        ok &= np.asarray(mask, bool)
    kw = {"loads": loads, "engine_off": engine_off, "fuel": fuel, "engine_on_above_mps": engine_on_above_mps,
          "fuel_cut_below_w": fuel_cut_below_w, "charge_sustaining": charge_sustaining, "moving_idle": moving_idle}
    if window_s is not None:
        from sumo_drvpw.fit.chain_windows import calibrate_windowed

        return calibrate_windowed(calibrate_fuel, p, v, y, w, battery_w, {c: sig[c] for c in loads}, ok, trip,
                                  window_s, engine_max_w=engine_max_w, **kw)
    best, profile = None, []
    profiled = isinstance(engine_off, str) and engine_off in ("profile", "conventional")
    conventional = profiled and engine_off == "conventional"
    yy = float(w[ok] @ y[ok] ** 2)
    idling = profiled and idles_at_stops(stand := standing_sums(v, y, w, ok))
    if idling:
        engine_off = -np.inf  # it runs where the car stands: no threshold P_off ≥ 0 fits that
    # (no traction battery: nothing carries the car's loads while its engine is off)
    for tmpl in fuel_grid(engine_off, engine_on_above_mps, fuel_cut_below_w, charge_sustaining and not conventional):
        tmpl.moving_idle_fuel_power_w = 0.0 if moving_idle else None
        tmpl.engine_max_w = None if engine_max_w in (None, "profile") else float(engine_max_w)
        def make(sl, tmpl=tmpl):
            return fuel_design(tmpl, p[sl], v[sl], pb[sl], [c[sl] for c in lcols]), y[sl]

        names = fuel_names(tmpl, loads)
        beta, rss, active, xs = _solve(make, w, ok, *fuel_bounds(names))
        off, von = tmpl.engine_off_below_w, tmpl.engine_on_above_mps
        bic = _bic(rss, int(ok.sum()), len(names) + 1 + (von is not None), yy)
        profile.append({"engine_off_below_w": off, "engine_on_above_mps": von, "rss": rss, "bic": bic})
        if best is None or bic < best[0]:
            best = (bic, tmpl, beta, active, xs, rss)
    _, tmpl, beta, active, xs, rss = best
    capped = profile_cap(lambda c: _solve(lambda sl: (fuel_design(dataclasses.replace(tmpl, engine_max_w=c), p[sl], v[sl], pb[sl],
                                                                   [c_[sl] for c_ in lcols]), y[sl]), w, ok,
                                          *fuel_bounds(fuel_names(tmpl, loads))),
                         p, ok, rss, int(ok.sum()), len(fuel_names(tmpl, loads)) + 1, yy) if engine_max_w == "profile" else None
    if capped:
        tmpl = dataclasses.replace(tmpl, engine_max_w=float(capped[0]))
        beta, rss, active, xs = capped[1]
    off, engine_on_above_mps = tmpl.engine_off_below_w, tmpl.engine_on_above_mps
    low = float(w[ok & (v < CITY_SPEED_MPS)].sum() / max(w[ok].sum(), 1e-12))
    chain, params = fuel_chain(loads, beta, _covariance(xs, rss, active), active, off, engine_on_above_mps,
                               low, fuel, fuel_cut_below_w, tmpl.charge_sustaining, battery_w is not None)
    if moving_idle:
        set_moving(chain, params, beta, _covariance(xs, rss, active), active, fuel)
    set_rating(chain, params, tmpl.engine_max_w, "profiled (RSS, kept by BIC)" if capped else "declared")
    fit_standing = stand if profiled else standing_sums(v, y, w, ok)
    if idling:
        note_idling(params, stand)
    elif conventional:
        note_conventional(params)
    if not profiled:
        note_declared(params)
    pred = chain.evaluate(p[ok], v[ok], signals={k: np.asarray(a)[ok] for k, a in sig.items()})["power_w"]
    target = corrected_fuel_power(y, pb, chain.battery_fuel_factor)[ok]
    r2, rmse, ratio = _stats(pred, target, w[ok])
    chain.std_err = {k: p_["std_err"] for k, p_ in params.items() if p_["std_err"] is not None}
    chain.metrics = {"n": int(ok.sum()), "r2": r2, "rmse_w": rmse, "energy_ratio": ratio,
                     "target": fuel_target_text(battery_w is not None)}
    fit = ChainFit(chain, params, int(ok.sum()), r2, rmse, ratio, profile, standing=fit_standing)
    if check_windows:  # the same engine state and form on windowed means (regression dilution)
        from sumo_drvpw.fit.chain_windows import windowed_lines

        kw.update(engine_off=off, engine_on_above_mps=engine_on_above_mps, charge_sustaining=tmpl.charge_sustaining)
        fit.windowed = windowed_lines(lambda *a: calibrate_fuel(*a, engine_max_w=tmpl.engine_max_w, check_windows=False,
                                                                **kw), p, v, y, w, battery_w,
                                      {c: sig[c] for c in loads}, ok, trip, cap_w=tmpl.engine_max_w)
    return fit


def fuel_target_text(battery: bool) -> str:
    """What a fuel chain was fitted to (its ``metrics["target"]``)."""
    return "fuel power + battery power / η_m (SOC-corrected)" if battery else "fuel power"


def moving_columns(tmpl: EnergyChain, on, v) -> list:
    """The design column of the moving zero-output fuel's excess over the idle fuel (engine on and
    moving, v ≥ STANDSTILL_MPS; its coefficient ≥ 0 keeps the moving fuel ≥ the idle fuel) where
    ``tmpl`` fits one (its ``moving_idle_fuel_power_w`` not None), else none."""
    return [] if tmpl.moving_idle_fuel_power_w is None else [on * (np.asarray(v, float) >= STANDSTILL_MPS)]


def set_moving(chain: EnergyChain, params: dict, beta, se, active, fuel: str) -> None:
    """The moving zero-output fuel (the last of :func:`fuel_names`) into ``chain`` and ``params``."""
    value = chain.idle_fuel_power_w + float(beta[-1])
    chain.moving_idle_fuel_power_w = value
    params["moving_idle_fuel_power_w"] = {
        "value": value, "std_err": _nan_none(se[-1]), "at_bound": bool(active[-1] != 0),
        "reading": (f"fuel at zero output while moving {value / 1000:.1f} kW, {float(beta[-1]) / 1000:.1f} kW above "
                    "the idle fuel (friction at road engine speed; std_err of that excess)")}


def set_rating(chain: EnergyChain, params: dict, cap: float | None, how: str) -> None:
    """The engine's rated output into ``chain`` and ``params`` from ``cap`` [W], the driving power
    at which the design (:func:`fuel_design`) caps the line (None: none), with ``how`` it was found
    (declared, profiled). The chain caps its engine demand max(P, 0) + P_aux (model/chain_values.py
    ``engine_demand``; η_t 1): its rating is ``cap`` + the fitted constant auxiliary power (a
    charge-sustaining fit's ``aux_power_w``; 0 where the auxiliaries are in the idle fuel), so the
    written chain books what the fit fitted."""
    if cap is None:
        return
    chain.engine_max_w = cap + chain.aux_power_w
    params["engine_max_w"] = {"value": chain.engine_max_w, "std_err": None, "at_bound": False, "how": how,
                              "reading": f"the engine's rated output {chain.engine_max_w / 1000:.0f} kW"}


def profile_cap(solve, p, ok, rss0: float, n: int, k: int, yy: float):
    """The engine's rated output profiled on the fit's RSS (``solve(cap)`` → (β, RSS, active, xs)):
    a coarse grid over the driving power's upper half, refined by bounded Brent search; kept
    (returned with its fit) only where its BIC beats the fit without a cap (RSS ``rss0``), else None."""
    from scipy.optimize import minimize_scalar

    pos = p[ok & (p > 0)]
    if pos.size < 10:
        return None
    grid = np.quantile(pos, np.linspace(0.5, 0.999, 25))
    rss = [solve(c)[1] for c in grid]
    j = int(np.argmin(rss))
    lo, hi = grid[max(j - 1, 0)], grid[min(j + 1, grid.size - 1)]
    cap = minimize_scalar(lambda c: solve(c)[1], bounds=(lo, hi), method="bounded",
                          options={"xatol": 1e-4 * hi}).x if hi > lo else grid[j]
    fit = solve(cap)
    return (cap, fit) if _bic(fit[1], n, k + 1, yy) < _bic(rss0, n, k, yy) else None


def declared_engine(equation) -> dict:
    """What a fuel chain's calibration does with the heavy-engine keys the chain of ``equation``
    declares (model/chain.py), as :func:`calibrate_fuel`'s keywords (and the streamed
    calibration's, fit/chain_stream.py ``ChainSpec``): a moving zero-output fuel
    (``moving_idle_fuel_power_w``) is fitted (≥ the idle fuel), a rated output (``engine_max_w``)
    kept, at the wheels: the driving power P at which P/η_t(P) + P_aux reaches P_max in the declared
    chain ((P_max − P_aux)·η_t for a constant η_t), the fitted chain's η_t being 1. UserError where
    there is no such one power: η_t a table over speed, or P_aux ≥ P_max."""
    ch = getattr(equation, "chain", None)
    kw = {"moving_idle": getattr(ch, "moving_idle_fuel_power_w", None) is not None,
          "engine_max_w": getattr(ch, "engine_max_w", None)}
    if kw["engine_max_w"] is None:
        return kw
    # the fitted chain has η_t 1 and its auxiliaries in the idle fuel: the rating at the wheels,
    # where P/η_t + P_aux reaches it
    left = kw["engine_max_w"] - ch.aux_power_w
    if left <= 0:
        raise UserError(f"{ch.where} [chain]: aux_power_w {ch.aux_power_w:g} W is not below engine_max_w "
                        f"{kw['engine_max_w']:g} W: the engine's rated output would drive nothing")
    eff = ch.traction_efficiency
    if not isinstance(eff, Table):
        kw["engine_max_w"] = left * eff
    elif eff.speed_mps is not None:
        raise UserError(f"{ch.where} [chain]: engine_max_w beside a traction_efficiency table over speed: the "
                        "driving power at which the engine reaches its rating differs with the speed, and the "
                        "calibrated chain (η_t 1) caps one driving power; calibrate on an equation whose "
                        "traction_efficiency is a number or a table over power only")
    else:  # P/η_t(P) rises from 0 to ≥ left on [0, left] (η_t ≤ 1)
        from scipy.optimize import brentq

        kw["engine_max_w"] = float(brentq(lambda p: p / float(np.ravel(eff(0.0, p))[0]) - left, 0.0, left, xtol=1e-6))
    return kw
