"""A steady wind estimated from drive logs that carry the heading (a diagnosis, not a term).

The aero power at air speed v − w (w the tailwind along travel) is c·X_aero·(1 − w/v)²,
≈ c·X_aero − 2·c·X_aero·w/v for w ≪ v. A wind blowing from φ at W m/s meets a car heading
h head-on at W·cos(h − φ) = W_N·cos h + W_E·sin h, so the road load plus a steady wind is
linear in the equation's coefficients and in c·W_N, c·W_E with the two regressors
2·X_aero/v·cos h and 2·X_aero/v·sin h. Fitted together over trips driven in different
directions, they separate the car's drag (c) from the day's wind (W_N, W_E): on a single
straight trip they cannot (cos h is then a constant and the wind is the drag).

The result belongs in the logs (the import command's wind option: the canonical
``wind_mps``), never in an equation: SUMO's air is still unless a scenario says otherwise.
"""

from __future__ import annotations

import math

import numpy as np

from sumo_drvpw.fit.ols import ols
from sumo_drvpw.model.terms import parse_term, term_matrix

#: below this speed [m/s] samples do not inform the wind (X_aero/v is tiny, the heading noisy)
MIN_SPEED_MPS = 5.0


def estimate_wind(x, y, mask, heading_deg, terms, fixed: dict | None = None) -> dict:
    """Least squares of the power ``y`` on the equation's ``terms`` (``fixed``: term →
    value kept) plus a steady wind, over the samples of ``mask`` moving faster than
    MIN_SPEED_MPS with a finite heading.

    Returns {"speed_mps", "from_deg", "north_mps", "east_mps" (head-wind components: a
    car heading north meets ``north_mps`` head-on), "terms" (coefficients with the wind),
    "terms_still_air" (the same fit without it), "samples", "heading_spread"} — the
    spread is 1 − |mean unit heading vector| weighted by v³ (0: one straight line, where
    the wind is not separable from the drag). Needs one aero term in ``terms``.
    """
    terms = list(dict.fromkeys(terms))
    aero = [t for t in terms if parse_term(t).category == "aero"]
    if len(aero) != 1:
        raise ValueError(f"estimate_wind needs one aero term, got {aero}")
    fixed = {t: float(v) for t, v in (fixed or {}).items() if t in terms}
    X = term_matrix(terms, x)
    v = np.asarray(x.v, float)
    h = np.radians(np.asarray(heading_deg, float))
    use = (np.asarray(mask, bool) & np.all(np.isfinite(X), axis=1) & np.isfinite(y)
           & np.isfinite(h) & (v >= MIN_SPEED_MPS))
    j = terms.index(aero[0])
    r = 2.0 * X[use, j] / v[use]
    W = np.column_stack([r * np.cos(h[use]), r * np.sin(h[use])])
    free = [t for t in terms if t not in fixed]
    yy = y[use] - sum(X[use, terms.index(t)] * c for t, c in fixed.items())
    A = X[use][:, [terms.index(t) for t in free]]

    b_still = ols(A, yy).beta
    b = ols(np.column_stack([A, W]), yy).beta
    coef = dict(fixed, **{t: float(c) for t, c in zip(free, b[:len(free)])})
    c_aero = coef[aero[0]]
    north, east = (float(b[len(free)]) / c_aero, float(b[len(free) + 1]) / c_aero) if c_aero > 0 \
        else (math.nan, math.nan)
    w3 = v[use] ** 3
    spread = 1.0 - float(np.hypot(np.sum(w3 * np.cos(h[use])), np.sum(w3 * np.sin(h[use]))) / np.sum(w3))
    return {"speed_mps": float(math.hypot(north, east)),
            "from_deg": float(math.degrees(math.atan2(east, north)) % 360.0),
            "north_mps": north, "east_mps": east, "terms": coef,
            "terms_still_air": dict(fixed, **{t: float(c) for t, c in zip(free, b_still)}),
            "samples": int(use.sum()), "heading_spread": spread}
