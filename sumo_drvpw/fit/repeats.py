"""How low can a per-trip energy error go on a set of logs? The scatter between repeat trips.

Two trips on the same route, started within an hour of each other, share the car, the
driver, the season and the day's weather. Whatever their per-trip errors (predicted /
measured − 1, each trip held out) still differ by is trip-to-trip scatter that the logged
inputs do not carry — wind on a one-way leg, traffic the speed trace shows only in part,
tyre and drivetrain warm-up history. A model of the logged inputs cannot remove it; a
model of day-level conditions (temperature, season) cannot either, because the pair shares
them. With the pair differences d = e_a − e_b:

    σ̂ = sqrt(Σ d² / (2·n_pairs))

is the standard deviation of that scatter per trip (each trip's share of the difference,
assuming the two trips' scatter is independent and equal). Treated as normal with mean
zero, it sets what a model whose *only* error was this scatter would score on k held-out
trips: mean |e| ≈ σ̂·sqrt(2/π), the worst |e| of k at its median σ̂·Φ⁻¹(1 − (1 − 0.5^(1/k))/2),
and the probability that all k trips stay within a bound b, (2Φ(b/σ̂) − 1)^k.

This says how much of a held-out error is within reach of better modelling, not that the
remaining scatter is random: it is what these logs do not record.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

#: largest start-to-start gap of two trips counted as repeats [s]
MAX_GAP_S = 3600.0


def repeat_pairs(starts: dict, routes: dict, max_gap_s: float = MAX_GAP_S) -> list[tuple[str, str]]:
    """Consecutive trips on the same route whose starts lie at most ``max_gap_s`` apart.

    Parameters
    ----------
    starts : trip → start time (anything :func:`pandas.to_datetime` reads; missing → skipped)
    routes : trip → route name (missing or empty → skipped)

    Each trip pairs only with the next one on its route (a chain A–B, B–C for three in a
    row), so every difference uses new information.
    """
    rows = []
    for t, s in starts.items():
        r = routes.get(t)
        ts = pd.to_datetime(s, errors="coerce")
        if r is None or not str(r).strip() or str(r) == "nan" or pd.isna(ts):
            continue
        rows.append((str(r).strip(), ts, str(t)))
    rows.sort()
    out = []
    for (r1, s1, t1), (r2, s2, t2) in zip(rows, rows[1:]):
        if r1 == r2 and (s2 - s1).total_seconds() <= max_gap_s:
            out.append((t1, t2))
    return out


def repeat_scatter(errors: dict, pairs: list[tuple[str, str]], k: int = 10,
                   bounds: tuple[float, ...] = (0.03, 0.06)) -> dict:
    """The per-trip scatter σ̂ from repeat pairs and what it implies for ``k`` held-out trips.

    Parameters
    ----------
    errors : trip → held-out per-trip error (predicted/measured − 1); pairs with a missing or
        non-finite error are skipped
    pairs : from :func:`repeat_pairs`
    k : number of held-out trips the implications are stated for
    bounds : per-trip bounds b for P(all k within b)

    Returns ``{"pairs": [{"a", "b", "error_a", "error_b", "difference"}], "n_pairs", "sigma",
    "mean_abs_floor", "worst_of_k_median", "p_all_within": {b: p}, "k"}``; sigma NaN without
    a usable pair.
    """
    from scipy.stats import norm

    used = []
    for a, b in pairs:
        ea, eb = errors.get(a, math.nan), errors.get(b, math.nan)
        if math.isfinite(ea) and math.isfinite(eb):
            used.append({"a": a, "b": b, "error_a": float(ea), "error_b": float(eb),
                         "difference": float(ea - eb)})
    if not used:
        return {"pairs": [], "n_pairs": 0, "sigma": math.nan, "mean_abs_floor": math.nan,
                "worst_of_k_median": math.nan, "p_all_within": {b: math.nan for b in bounds}, "k": k}
    d = np.array([u["difference"] for u in used])
    sigma = float(np.sqrt(np.sum(d ** 2) / (2 * d.size)))
    worst = sigma * float(norm.ppf(1.0 - (1.0 - 0.5 ** (1.0 / k)) / 2.0))
    p = {b: float((2.0 * norm.cdf(b / sigma) - 1.0) ** k) if sigma > 0 else 1.0 for b in bounds}
    return {"pairs": used, "n_pairs": len(used), "sigma": sigma,
            "mean_abs_floor": sigma * math.sqrt(2.0 / math.pi), "worst_of_k_median": worst,
            "p_all_within": p, "k": k}
