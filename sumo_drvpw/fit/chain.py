"""Calibrate an energy chain (sumo_drvpw.model.chain) on top of a road-load equation.

Given the driving power P [W] of the road-load equation, the battery form is linear in its
parameters (model/chain.py)::

    P_bat = x_t·max(P, 0) + η_r·max(min(P, 0), −P_lim) + P_aux,0 + Σ g_k·L_k
            + h_heat·max(T_set − T, 0) + h_cool·max(T − T_set, 0),      x_t = 1/η_t

so for a fixed recuperation limit P_lim it is a bounded linear least-squares problem,
solved by ``scipy.optimize.lsq_linear`` (x_t ≥ 1, 0 < η_r ≤ 1, P_aux,0, g_k, h ≥ 0), each
sample weighted by its duration (√Δt on the rows), so irregular logs weigh time, not rows.
The limit is profiled over a grid of the observed braking powers and kept only when it
lowers the BIC (n·ln RSS + k·ln n). The fuel form is fitted the same way
(fit/chain_fuel.py).

Memory: the design is never built whole: [√Δt·X √Δt·y] is factored block by block into
its triangle R (TSQR: Demmel et al. 2012) and the bounded problem solved on R, which has
the whole design's normal equations and residuals (:func:`_solve`).

Uncertainty: the covariance of the linear fit on the free (inactive) parameters,
s²·(X_fᵀW X_f)⁻¹ with s² = RSS/(n − k_free); parameters at a bound get none. Samples of
a drive log are autocorrelated, so these are lower bounds: per-trip hold-out errors
(validation/chain.py) are the honest measure.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import lsq_linear

from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.chain_checks import _check_chain_inputs, reading
from sumo_drvpw.model.chain import EnergyChain, corrected_fuel_power

#: smallest efficiency the fit may return (the bound (0, 1] made closed) [-]
ETA_MIN = 1e-3
#: quantiles of the observed braking power |min(P, 0)| tried as recuperation limits
LIMIT_QUANTILES = (0.5, 0.7, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995)
#: samples per block of a fit's design (factored block by block, never built whole)
BLOCK_ROWS = 65_536


@dataclass
class ChainFit:
    """A calibrated chain with its parameters, uncertainties and readings."""

    chain: EnergyChain
    parameters: dict = field(default_factory=dict)
    n: int = 0
    r2: float = math.nan
    rmse_w: float = math.nan
    energy_ratio: float = math.nan
    profile: list = field(default_factory=list)
    #: samples left out because a declared load or the HVAC temperature is unknown (NaN) there
    unknown_input_samples: int = 0
    #: parameters read as implausible or not identified (fit/chain_checks.py)
    warnings: list = field(default_factory=list)
    #: a fuel chain's target at standstill (:func:`~sumo_drvpw.fit.chain_fuel.standing_sums`:
    #: standing s, with fuel flowing s, that fuel J), or None
    standing: object = None
    #: a fuel chain's line refitted on windowed means (fit/chain_windows.py ``windowed_lines``)
    windowed: list = field(default_factory=list)

    def summary(self) -> str:
        lines = [f"energy chain ({self.chain.predicts}): n={self.n}  R²={self.r2:.4f}  "
                 f"RMSE={self.rmse_w / 1000:.3f} kW  predicted/measured energy={self.energy_ratio:.4f}"]
        if self.unknown_input_samples:
            lines.append(f"  ({self.unknown_input_samples} samples left out of the fit: a declared load or "
                         "the HVAC temperature is unknown (NaN) there, so their battery power holds an "
                         "unknown load)")
        for k, p in self.parameters.items():
            se = p.get("std_err")
            se_s = ("fixed" if p.get("fixed") else "at bound" if p.get("at_bound")
                    else (f"± {se:.4g}" if se is not None else ""))
            lines.append(f"  {k:<28} {p['value']:>12.5g} {se_s:<14} {p.get('reading', '')}")
        from sumo_drvpw.fit.chain_checks import range_note

        note = range_note(self.chain.provenance)
        return "\n".join(lines + ([f"  {note}"] if note else []))


def _col(signals: dict, name: str, n: int, known: np.ndarray | None = None) -> np.ndarray:
    """Column ``name`` as floats, NaN read as 0; with ``known``, its NaN samples are
    cleared in that mask (an unknown load is not a zero load when fitting)."""
    if name not in signals:
        raise UserError(f"energy chain: the log has no column '{name}' (available: "
                        f"{', '.join(sorted(signals)) or 'none'})")
    x = np.broadcast_to(np.asarray(signals[name], float), (n,))
    if known is not None:
        known &= np.isfinite(x)
    return np.nan_to_num(x, nan=0.0)


def _solve(make, w: np.ndarray, ok: np.ndarray, lb, ub):
    """Bounded least squares of y on X over the samples ``ok``, each weighted by its
    duration ``w`` (√w on the rows): :func:`solve_factor` of :func:`factor_rows`.
    Returns (β, RSS, active mask, (R_x, samples))."""
    return solve_factor(*factor_rows(make, w, ok, len(lb)), lb, ub)


def factor_rows(make, w: np.ndarray, ok: np.ndarray, k: int) -> tuple[np.ndarray, int]:
    """The triangle R of [√w·X √w·y] over the samples ``ok`` and their number: ``make(sl)``
    gives (X, y) of the samples ``sl`` (a slice of ``BLOCK_ROWS``, all of its rows; ``ok``
    is applied here), factored block by block (TSQR: a factor of more rows stacks on it)."""
    r, n = np.zeros((0, k + 1)), 0
    for lo in range(0, len(ok), BLOCK_ROWS):
        sl = slice(lo, lo + BLOCK_ROWS)
        o = ok[sl]
        if not o.any():
            continue
        x, y = make(sl)
        sw = np.sqrt(w[sl][o])
        blk = np.empty((sw.size, k + 1))
        blk[:, :k] = x[o] * sw[:, None]
        blk[:, k] = np.broadcast_to(y, o.shape)[o] * sw
        r = np.linalg.qr(np.vstack([r, blk]), mode="r")
        n += sw.size
    return r, n


def solve_factor(r: np.ndarray, n: int, lb, ub):
    """Bounded least squares on the factor R = [[R_x, z], [0, ρ]] of [√w·X √w·y]: the
    same normal equations, RSS = ‖z − R_x β‖² + ρ², solved with BVLS, the columns scaled
    to unit norm for the solver. Returns (β, RSS, active mask, (R_x, samples))."""
    k = len(lb)
    rx, z = r[:k, :k], r[:k, k]
    rho2 = float(r[k, k]) ** 2 if r.shape[0] > k else 0.0
    scale = np.sqrt((rx ** 2).sum(axis=0))  # the column norms of √w·X
    scale[scale == 0] = 1.0
    res = lsq_linear(rx / scale, z, bounds=(np.asarray(lb) * scale, np.asarray(ub) * scale),
                     method="bvls", lsmr_tol="auto")
    # the solver's bounds hold on the scaled problem up to rounding: a parameter at its bound
    # (auxiliary power 0, η_r 1) may come back 1e-14 beyond it; the bounds are physics
    beta = np.clip(res.x / scale, lb, ub)
    e = z - rx @ beta
    return beta, float(e @ e) + rho2, res.active_mask, (rx, n)


def _held_rss(make, w: np.ndarray, ok: np.ndarray) -> float:
    """The weighted RSS of a fit with every column held (``make(sl)`` gives no free column
    and the target less the held part)."""
    r, _ = factor_rows(make, w, ok, 0)
    return float(r[:, 0] @ r[:, 0])


def _covariance(fac: tuple, rss: float, active: np.ndarray) -> np.ndarray:
    """Standard errors of the free parameters from the factor (R_x, samples) of :func:`_solve`."""
    rx, n = fac
    k = rx.shape[1]
    se = np.full(k, np.nan)
    free = np.flatnonzero(active == 0)
    dof = n - free.size
    if free.size and dof > 0:
        a = rx[:, free]
        try:
            cov = np.linalg.inv(a.T @ a) * rss / dof
            se[free] = np.sqrt(np.maximum(np.diag(cov), 0.0))
        except np.linalg.LinAlgError:
            pass
    return se


#: a residual sum of squares below this share of the target's (uncentred, weighted) sum of
#: squares is numerically zero: fits that reach it tie, and the BIC's penalty chooses
RSS_ZERO = 1e-12


def _bic(rss: float, n: int, k: int, yy: float = 0.0) -> float:
    """n·ln(RSS/n) + k·ln n, the RSS floored at :data:`RSS_ZERO`·``yy`` (Σw·y²): without
    noise, nested forms that both fit exactly would otherwise be told apart by rounding."""
    return n * math.log(max(rss, RSS_ZERO * yy, 1e-300) / n) + k * math.log(n)


def _stats(pred, y, w) -> tuple[float, float, float]:
    e = pred - y
    ybar = float(np.average(y, weights=w))
    sst = float(w @ (y - ybar) ** 2)
    r2 = 1.0 - float(w @ e ** 2) / sst if sst > 0 else math.nan
    rmse = math.sqrt(float(w @ e ** 2) / float(w.sum()))
    ey = float(w @ y)
    return r2, rmse, (float(w @ pred) / ey if ey != 0 else math.nan)


def battery_columns(p, y, w, sig: dict, loads=(), hvac=None, predicts="battery", warmup_rate=None,
                    mask=None):
    """The battery chain's design columns (the recuperation column None: it depends on the
    limit, :func:`battery_design`), names, bounds, the samples to fit on and how many were
    left out for an unknown (NaN) declared load or HVAC temperature."""
    n = p.size
    cols = [np.maximum(p, 0.0), None]
    names = ["traction_efficiency", "recuperation_efficiency"]
    lb, ub = [1.0, ETA_MIN], [1.0 / ETA_MIN, 1.0]
    known = np.ones(n, bool)  # declared loads and HVAC temperature known
    if predicts == "battery":
        cols.append(np.broadcast_to(1.0, (n,)))
        names.append("aux_power_w")
        lb.append(0.0)
        ub.append(np.inf)
        for c in loads:
            cols.append(_col(sig, c, n, known))
            names.append(f"loads.{c}")
            lb.append(0.0)
            ub.append(np.inf)
        if hvac:
            t = _col(sig, hvac.get("column", "ambient_c"), n, known)
            ts = float(hvac.get("setpoint_c", 20.0))
            cols += [np.maximum(ts - t, 0.0), np.maximum(t - ts, 0.0)]
            names += ["hvac.heating_w_per_k", "hvac.cooling_w_per_k"]
            lb += [0.0, 0.0]
            ub += [np.inf, np.inf]
            if warmup_rate is not None:
                cols.append(np.broadcast_to(np.asarray(warmup_rate, float), (n,)))
                names.append("hvac.warmup_j_per_k")
                lb.append(0.0)
                ub.append(np.inf)
    ok = np.isfinite(p) & np.isfinite(y) & np.isfinite(w)
    for c in cols:
        if c is not None:
            ok &= np.isfinite(c)
    if mask is not None:
        ok &= np.asarray(mask, bool)
    unknown = int((ok & ~known).sum())
    return cols, names, lb, ub, ok & known, unknown


def too_few_samples(n_ok: int, k: int, unknown: int, loads=(), hvac=None, where: str = "") -> UserError:
    """The error of a battery chain with fewer usable samples than its ``k`` parameters need,
    naming the declared loads' and HVAC temperature's columns where their unknown (NaN)
    values left ``unknown`` samples out (an all-NaN air temperature said only '0 usable')."""
    cols = [*loads, *([hvac.get("column", "ambient_c")] if hvac else [])]
    why = f": {unknown} left out where {' or '.join(cols)} is unknown (NaN)" if unknown and cols else ""
    return UserError(f"{where + ': ' if where else ''}energy chain: only {n_ok} usable samples for {k} parameters{why}")


def battery_design(cols: list, neg: np.ndarray, sl, lim) -> list:
    """The columns of :func:`battery_columns` on the samples ``sl``, the recuperation
    column max(min(P, 0), −P_lim) for the limit ``lim`` [W] (None: no limit)."""
    c = [None if col is None else col[sl] for col in cols]
    c[1] = neg[sl] if lim is None else np.maximum(neg[sl], -lim)
    return c


def calibrate_battery(p_drive_w, v_mps, meas_w, dt_s, signals: dict | None = None, *,
                      loads=(), hvac: dict | None = None, mask=None, limit="profile",
                      predicts: str = "battery", fixed: dict | None = None,
                      efficiency: str = "constant", warmup_rate=None, counter_view=None) -> ChainFit:
    """Calibrate a battery (or powertrain-output) chain on measured power.

    Parameters
    ----------
    p_drive_w : driving power of the road-load equation [W]
    v_mps : speed [m/s]
    meas_w : measured battery power V·I, positive when discharging [W]
    dt_s : sample durations [s] (weights)
    signals : column → array (loads, HVAC temperature)
    loads : logged load columns (gains fitted, ≥ 0)
    hvac : None or {"column", "setpoint_c"}: fit heating and cooling gains [W/K] ≥ 0
    mask : samples to fit on (default: all with finite values)
    limit : "profile" (profile a recuperation limit, kept if it lowers the BIC), None
        (no limit) or a number [W] (fixed)
    predicts : "battery" or "powertrain_output" (no auxiliary power)
    fixed : parameters held at given values (e.g. the dynamometer's efficiencies when a road
        calibration should find only what the road adds), name → value; reported as fixed
    efficiency : "constant", or "power" / "speed-power": η_t and η_r as tables over |P|
        (and speed), fitted on a hat-function basis (fit/chain_map.py)
    warmup_rate : with ``hvac``: per sample, the rate [K/s] at which a cold cabin's warm-up
        is spread over the trip's start (e.g. (T_set − T_cabin,0)⁺·e^(−t/τ)/τ); its
        coefficient is the chain's ``hvac.warmup_j_per_k`` [J/K] ≥ 0, booked in SUMO once
        per cold departure (:meth:`EnergyChain.cold_start`), not by :meth:`EnergyChain.evaluate`
    counter_view : the measured power is the BMS's energy counters' rate: their view of the
        log (:class:`~sumo_drvpw.data.counters.CounterView`), through which the design is
        seen as the counters book it (None: V·I)
    """
    p = np.asarray(p_drive_w, float)
    n = p.size
    y = np.asarray(meas_w, float)
    v = np.broadcast_to(np.asarray(v_mps, float), (n,))
    w = np.broadcast_to(np.asarray(dt_s, float), (n,)).astype(float)
    sig = signals or {}
    cols, names, lb, ub, ok, unknown = battery_columns(p, y, w, sig, loads, hvac, predicts, warmup_rate, mask)
    emap = None
    if efficiency != "constant":
        from sumo_drvpw.fit import chain_map

        bt, br = chain_map.fit_columns(efficiency, p, v, ok)
        emap = (bt, br)
        names = ([f"traction_efficiency#{j}" for j in range(bt.size)]
                 + [f"recuperation_efficiency#{j}" for j in range(br.size)] + names[2:])
        lb = [1.0] * bt.size + [ETA_MIN] * br.size + lb[2:]
        ub = [1.0 / ETA_MIN] * bt.size + [1.0] * br.size + ub[2:]
    if ok.sum() < len(names) + 2:
        raise too_few_samples(int(ok.sum()), len(names), unknown, loads, hvac)
    neg = np.minimum(p, 0.0)
    brake = -neg[ok & (neg < 0)]
    if limit == "profile":
        grid = [None] + (sorted({float(np.quantile(brake, q)) for q in LIMIT_QUANTILES})
                         if brake.size > 20 else [])
    elif limit is None:
        grid = [None]
    else:
        grid = [float(limit)]

    seen = {}

    def design(sl, lim):
        """The design's rows of the samples ``sl`` (the efficiency tables' hat weights too;
        through the counters' view when the target is theirs)."""
        if counter_view is not None:
            if lim not in seen:
                seen.clear()
                seen[lim] = counter_view(raw_design(slice(None), lim))
            return seen[lim][sl]
        return raw_design(sl, lim)

    def raw_design(sl, lim):
        c = battery_design(cols, neg, sl, lim)
        if emap is not None:
            c[0] = c[0][:, None] * emap[0].matrix(p[sl], v[sl])
            c[1] = c[1][:, None] * emap[1].matrix(p[sl], v[sl])
        return np.column_stack(c)

    from sumo_drvpw.fit.chain_fixed import check_fixed, coefficients

    fixed = check_fixed(fixed, names)  # (streamed, the held part is taken off the factor: chain_fixed.py)
    if "recuperation_limit_w" in fixed:  # held: not profiled
        grid = [fixed["recuperation_limit_w"]]
    fx = coefficients(names, fixed)
    free = [j for j in range(len(names)) if j not in fx]
    lb_f, ub_f = [lb[j] for j in free], [ub[j] for j in free]
    best, profile = None, []
    for lim in grid:
        def make(sl, lim=lim):
            x = design(sl, lim)
            off = sum(x[:, j] * val for j, val in fx.items()) if fx else 0.0
            return x[:, free], y[sl] - off

        b_free, rss, act_free, xs = _solve(make, w, ok, lb_f, ub_f) if free else (
            np.empty(0), _held_rss(make, w, ok), np.zeros(0, int), None)
        k = len(free) + (lim is not None)
        bic = _bic(rss, int(ok.sum()), k)
        profile.append({"recuperation_limit_w": lim, "rss": rss, "bic": bic})
        if best is None or bic < best[0]:
            best = (bic, lim, b_free, rss, act_free, xs)
    _, lim, b_free, rss, act_free, xs = best
    beta = np.empty(len(names))
    beta[free] = b_free
    se = np.full(len(names), np.nan)
    if free:
        se[free] = _covariance(xs, rss, act_free)
    active = np.zeros(len(names), int)
    active[free] = act_free
    for j, val in fx.items():
        beta[j] = val
    chain, params = battery_chain(names, beta, se, active, lim, hvac, predicts, fixed, fx, emap, efficiency)
    if counter_view is None:
        pred = chain.evaluate(p[ok], v[ok], signals={k: np.asarray(a)[ok] for k, a in sig.items()})["power_w"]
    else:  # as the fit saw it (and a streamed fit's sums do)
        pred = counter_view(chain.evaluate(p, v, signals=sig)["power_w"])[ok]
    r2, rmse, ratio = _stats(pred, y[ok], w[ok])
    chain.std_err = {k: p_["std_err"] for k, p_ in params.items() if p_["std_err"] is not None}
    chain.metrics = {"n": int(ok.sum()), "r2": r2, "rmse_w": rmse, "energy_ratio": ratio}
    return ChainFit(chain, params, int(ok.sum()), r2, rmse, ratio, profile, unknown)


def battery_chain(names, beta, se, active, lim, hvac, predicts="battery", fixed=None, fx=None, emap=None,
                  efficiency="constant"):
    """The battery chain and its parameters (value, std_err, at_bound, reading) from the
    fitted coefficients ``beta`` of the columns ``names`` (x_t = 1/η_t first), their
    standard errors and active bounds, and the recuperation limit ``lim`` (None: none)."""
    fixed, fx = fixed or {}, fx or {}
    params = {}
    kw = {"predicts": predicts, "loads": {}, "hvac": None}
    if emap is not None:
        from sumo_drvpw.fit import chain_map

        nt, nr = emap[0].size, emap[1].size
        params.update(chain_map.knot_parameters("traction_efficiency", emap[0], beta[:nt], se[:nt],
                                                active[:nt], True))
        params.update(chain_map.knot_parameters("recuperation_efficiency", emap[1], beta[nt:nt + nr],
                                                se[nt:nt + nr], active[nt:nt + nr], False))
    for j, name in enumerate(names):
        if "#" in name:
            continue
        val, s = float(beta[j]), float(se[j])
        if name in fixed:
            val = float(fixed[name])
        elif name == "traction_efficiency":  # fitted x_t = 1/η_t; delta method for se
            val, s = 1.0 / val, s / val ** 2
        params[name] = {"value": val, "std_err": None if math.isnan(s) else s,
                        "at_bound": bool(active[j] != 0)}
        if j in fx:
            params[name]["fixed"] = True
        if name.startswith("loads."):
            kw["loads"][name[6:]] = val
        elif name.startswith("hvac."):
            kw["hvac"] = kw["hvac"] or {"column": hvac.get("column", "ambient_c"),
                                        "setpoint_c": float(hvac.get("setpoint_c", 20.0))}
            kw["hvac"][name[5:]] = val
        else:
            kw[name] = val
    if lim is not None:
        kw["recuperation_limit_w"] = lim
        params["recuperation_limit_w"] = {"value": lim, "std_err": None, "at_bound": False,
                                          "how": "profiled (BIC) over quantiles of the braking power"}
        if "recuperation_limit_w" in fixed:
            params["recuperation_limit_w"].update(how="fixed: given, not profiled", fixed=True)
    for name, p_ in params.items():
        if "reading" not in p_:
            p_["reading"] = reading(name, p_["value"])
    if emap is not None:
        chain = chain_map.map_chain(kw, emap[0], emap[1], beta[:nt], beta[nt:nt + nr])
        chain.provenance = {"efficiency_map": efficiency,
                            "fitted_knots_power_w": {"traction": emap[0].power.tolist(),
                                                     "recuperation": emap[1].power.tolist()}}
    else:
        chain = EnergyChain(**kw)
    return chain, params


def _nan_none(x) -> float | None:
    x = float(x)
    return None if math.isnan(x) else x


def chain_target(m, chain: EnergyChain) -> np.ndarray:
    """The measured power a chain is compared with [W]: battery V·I, or SOC-corrected fuel
    power (:func:`sumo_drvpw.model.chain.corrected_fuel_power`) for a fuel chain."""
    if chain.predicts == "fuel" and m.battery_w is not None:
        return corrected_fuel_power(m.power_w, m.battery_w, chain.battery_fuel_factor)
    return m.power_w


def declared_fuel_cut(equation) -> float | None:
    """What a fuel chain's calibration keeps of the chain ``equation`` declares: its overrun
    fuel cut-off (``fuel_cut_below_w``, None: none declared). A declared braking energy given
    back (``recuperation_round_trip``, not fitted) or plug-in battery (``[chain.depleting]``) is
    refused, not dropped without a word."""
    ch = getattr(equation, "chain", None)
    if getattr(ch, "recuperation_round_trip", 0.0):
        raise UserError(f"{ch.where} [chain]: recuperation_round_trip (a hybrid's braking energy given back) is "
                        "declared, not fitted, and a fuel chain's calibration would drop it: calibrate on an "
                        "equation without it (the fitted marginal efficiency then holds the braking credit)")
    if getattr(ch, "depleting", None) is not None:
        raise UserError(f"{ch.where} [chain.depleting]: a plug-in hybrid's battery is declared, not fitted, and a fuel "
                        "chain's calibration would drop it: calibrate on an equation without it (on charge-sustaining "
                        "trips), then add it")
    return getattr(ch, "fuel_cut_below_w", None)


def calibrate_on(m, equation=None, *, loads=(), hvac=None, limit="profile", engine_off="profile",
                 mask=None, p_drive_w=None, fixed: dict | None = None,
                 efficiency: str = "constant", warmup_rate=None, rating: str = "declared",
                 window_s: float | None = None) -> ChainFit:
    """Calibrate the chain of ``m.target`` on a :class:`~sumo_drvpw.data.measured.Measured`;
    fit on ``m.usable`` (and ``mask``). A fuel chain's rated output (``engine_max_w``):
    ``rating`` "declared" keeps the one ``equation``'s chain declares (none without), "profile"
    profiles it (:func:`~sumo_drvpw.fit.chain_fuel.profile_cap`: kept only where its BIC beats
    the line without; refused where the chain declares one, which it would replace). A fuel chain
    with ``window_s`` [s] is fitted on means over windows of that many seconds within the trips
    (fit/chain_windows.py: a derived acceleration's noise out of the regressor).

    The chain's input is ``p_drive_w`` [W] when given, else ``equation``'s driving power.
    Give the *measured* driving power when the log has one (motor torque × speed, the
    power-split P_PTdrv): the chain's parameters then describe the powertrain alone. Fitted
    on a road-load equation's power instead, they also absorb that equation's errors, and
    noise in the input attenuates the fitted slopes (errors in variables): on the Prius
    Gen 2 this turns η_m ≈ 0.39 into an implausible 0.6 (docs/energy-chain.md).
    """
    if p_drive_w is None and equation is None:
        raise UserError("calibrate_on: give the chain's input, the measured driving power (p_drive_w=) "
                        "or a road-load equation (equation=)")
    p = equation.power(m.inputs) if p_drive_w is None else np.asarray(p_drive_w, float)
    dt = m.log.df["dt_s"].to_numpy(float)
    use = m.usable if mask is None else (m.usable & mask)
    sig = m.inputs.signals
    _check_chain_inputs(m, use, loads, p)
    from sumo_drvpw.fit.chain_checks import check_chain

    if window_s is not None and m.target != "fuel":
        raise UserError(f"energy chain: fitting on windowed means (window_s {window_s!r}) is the fuel target's "
                        f"only, got '{m.target}'")
    if rating != "declared" and m.target != "fuel":
        raise UserError(f"energy chain: a rated output ({rating!r}) is an engine's: the fuel target only, "
                        f"got '{m.target}'")
    if m.target == "fuel":
        if hvac:  # the fuel chain's calibration fits no HVAC power: not dropped without a word
            raise UserError(f"hvac {hvac.get('column')}: the HVAC power per kelvin is fitted for the battery "
                            "target only; a fuel chain books the climate's draw as auxiliary power "
                            "(or a logged load in W)")
        fuel = m.vehicle.powertrain.get("fuel", "gasoline") if m.vehicle is not None else "gasoline"
        from sumo_drvpw.fit.chain_fuel import calibrate_fuel, declared_engine, engine_off_for

        cut = declared_fuel_cut(equation)
        engine = declared_engine(equation)
        if rating == "profile":
            if engine["engine_max_w"] is not None:
                raise UserError(f"{equation.chain.where} [chain]: engine_max_w is declared; a profiled rated output "
                                "would replace it: keep the declared one, or calibrate on an equation without it")
            engine["engine_max_w"] = "profile"
        elif rating != "declared":
            raise UserError(f"energy chain: the rated output is 'declared' or 'profile', got {rating!r}")
        fit = calibrate_fuel(p, m.inputs.v, m.power_w, dt, m.battery_w, sig, loads=loads, mask=use,
                             engine_off=engine_off_for(m.vehicle, m.battery_w is not None, engine_off),
                             fuel=fuel, fuel_cut_below_w=cut, trip=m.inputs.trip, window_s=window_s, **engine)
    elif m.target != "battery":
        raise UserError(f"energy chain: calibrate needs the battery or fuel target, got '{m.target}'")
    else:
        fit = calibrate_battery(p, m.inputs.v, m.power_w, dt, sig, loads=loads, hvac=hvac,
                                mask=use, limit=limit, fixed=fixed, efficiency=efficiency,
                                warmup_rate=warmup_rate, counter_view=getattr(m, "counter_view", None))
    from sumo_drvpw.fit.chain_checks import hvac_trip_sums

    trips = (hvac_trip_sums(m.inputs.trip, sig.get(hvac.get("column", "ambient_c"), np.full(len(dt), np.nan)),
                            float(hvac.get("setpoint_c", 20.0)),
                            dt, use) if hvac and m.target == "battery" and m.inputs.trip is not None else None)
    check_chain(fit, m.vehicle, p, m.inputs.v, use, where=m.log.describe(),  # plausibility, fitted range
                counts=getattr(m, "counts", None), hvac_trips=trips, measured=p_drive_w is not None)
    return fit


def profile_recuperation_limit(p_wheel_w, p_recuperated_w, dt_s, mask=None,
                               quantiles=LIMIT_QUANTILES) -> dict:
    """Recuperation limit with friction-brake blending, from the wheel power a road-load
    equation predicts and the power the motor actually recuperated (motor torque × speed).

    When braking needs more than the machine takes back, the friction brakes take the rest:
    the motor sees max(P_wheel, −P_lim) for P_wheel < 0. The limit is profiled over
    quantiles of the braking power −min(P_wheel, 0) (and no limit), minimising the
    duration-weighted RSS of max(P_wheel, −P_lim) − P_recuperated on the braking samples,
    kept only when it lowers the BIC (n·ln(RSS/n) + k·ln n, k = 1 with a limit).

    Parameters
    ----------
    p_wheel_w : driving power of the road-load equation [W]
    p_recuperated_w : measured power at the machine, negative when recuperating [W]
    dt_s : sample durations [s] (weights)
    mask : samples to use (default all finite)

    Returns {"recuperation_limit_w": float or None, "profile": [{limit, rss, bic}],
    "n": braking samples}.
    """
    p = np.asarray(p_wheel_w, float)
    y = np.asarray(p_recuperated_w, float)
    w = np.broadcast_to(np.asarray(dt_s, float), p.shape)
    ok = np.isfinite(p) & np.isfinite(y) & np.isfinite(w) & (p < 0)
    if mask is not None:
        ok &= np.asarray(mask, bool)
    n = int(ok.sum())
    if n < 20:
        return {"recuperation_limit_w": None, "profile": [], "n": n}
    brake = -p[ok]
    grid = [None] + sorted({float(np.quantile(brake, q)) for q in quantiles})
    best, profile = None, []
    for lim in grid:
        pred = p[ok] if lim is None else np.maximum(p[ok], -lim)
        rss = float(w[ok] @ (pred - y[ok]) ** 2)
        bic = _bic(rss, n, int(lim is not None))
        profile.append({"recuperation_limit_w": lim, "rss": rss, "bic": bic})
        if best is None or bic < best[0]:
            best = (bic, lim)
    return {"recuperation_limit_w": best[1], "profile": profile, "n": n}
