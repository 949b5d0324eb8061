"""A battery chain's parameters held at given values (``fixed=``; ``calibrate --fix``).

Holding a parameter is physics, not fit: where the data cannot tell two parameters apart
(cruise only: the traction efficiency and the auxiliary draw are collinear), or where a
better source knows one (the dynamometer's efficiencies under a road calibration, a
logger's auxiliary draw), it is given and the rest fitted. The fixed columns' part of the
design is known, so it moves to the target: y − Σ x_j·c_j on the free columns. Both
engines factor the whole design [√w·X √w·y] into its triangle R (fit/chain.py; streamed,
fit/chain_stream.py), so the fixed part is taken off R itself: [R_free, R_y − R_fixed·c]
has the same Gram matrix as the reduced design, and its own triangle is solved as any
other (:func:`solve_fixed`). The same numbers in memory and streamed, whatever was fixed.
"""

from __future__ import annotations

import math

import numpy as np

from sumo_drvpw.errors import UserError

#: parameters of a battery chain that may be held (besides ``loads.<column>`` and, with an
#: HVAC, ``hvac.heating_w_per_k``, ``hvac.cooling_w_per_k``, ``hvac.warmup_j_per_k``)
BASE = ("traction_efficiency", "recuperation_efficiency", "aux_power_w", "recuperation_limit_w")
#: the efficiencies: (0, 1]; every other parameter is a power, a gain or a limit: ≥ 0 (the limit > 0)
EFFICIENCIES = ("traction_efficiency", "recuperation_efficiency")


def fixable(names) -> list[str]:
    """What may be held, given the fit's columns ``names`` (fit/chain.py battery_columns):
    its constant parameters and the recuperation limit."""
    return [n for n in names if "#" not in n] + ["recuperation_limit_w"]


def check_fixed(fixed: dict, names, where: str = "energy chain") -> dict:
    """``fixed`` (name → value) checked against the columns ``names``: a name the fit has,
    an efficiency in (0, 1], a power, gain or limit ≥ 0 (a limit > 0). Returns it as floats."""
    ok = fixable(names)
    out = {}
    for k, v in (fixed or {}).items():
        if k not in ok:
            raise UserError(f"{where}: cannot fix {k!r}: not among {', '.join(ok)}")
        try:
            x = float(v)
        except (TypeError, ValueError):
            x = math.nan
        if not math.isfinite(x):
            raise UserError(f"{where}: {k} = {v!r}: give a finite number")
        if k in EFFICIENCIES and not 0.0 < x <= 1.0:
            raise UserError(f"{where}: {k} = {v!r}: an efficiency lies in (0, 1]")
        if k == "recuperation_limit_w" and not x > 0:
            raise UserError(f"{where}: {k} = {v!r}: a recuperation limit is a braking power > 0 W")
        if x < 0:
            raise UserError(f"{where}: {k} = {v!r}: a power or gain is ≥ 0")
        out[k] = x
    return out


def coefficients(names, fixed: dict) -> dict:
    """Column index → the coefficient a fixed parameter sets (x_t = 1/η_t for the traction
    efficiency, else its value); the recuperation limit is no column."""
    return {j: (1.0 / fixed[n] if n == "traction_efficiency" else float(fixed[n]))
            for j, n in enumerate(names) if n in fixed}


def solve_fixed(r: np.ndarray, n: int, lb, ub, fx: dict):
    """Bounded least squares on the factor ``r`` of [√w·X √w·y] (fit/chain.py solve_factor)
    with the columns ``fx`` (index → coefficient) held. Returns the whole β (the held values
    in place), the RSS, the active bounds (0 where held) and the free columns' standard
    errors (NaN where held or at a bound)."""
    from sumo_drvpw.fit.chain import _covariance, solve_factor

    k = len(lb)
    if not fx:
        beta, rss, act, xs = solve_factor(r, n, lb, ub)
        return beta, rss, act, _covariance(xs, rss, act)
    free = [j for j in range(k) if j not in fx]
    held = np.array(sorted(fx))
    m = np.column_stack([r[:, free], r[:, k] - r[:, held] @ np.array([fx[j] for j in held])])
    rr = np.linalg.qr(m, mode="r")
    beta, active, se = np.empty(k), np.zeros(k, int), np.full(k, np.nan)
    beta[held] = [fx[j] for j in held]
    if free:
        b, rss, act, xs = solve_factor(rr, n, [lb[j] for j in free], [ub[j] for j in free])
        beta[free], active[free], se[free] = b, act, _covariance(xs, rss, act)
    else:  # everything held: the residual is the factor's last column
        rss = float(rr[:, -1] @ rr[:, -1])
    return beta, rss, active, se
