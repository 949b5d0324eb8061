"""Forward–backward stepwise multiple regression (OLS, no intercept) → a DrvPw equation.

The seed paper calibrates DrvPw by stepwise multiple regression over candidate terms
(Indt var. 1: acc, grade, aero, roll; Indt var. 2: all eight), then a final multiple
regression of the selected terms.

Selection works on the sufficient statistics XᵀX, Xᵀy, yᵀy of all candidates, computed
in chunks, so a step costs O(k³) instead of a pass over the samples: for a subset S the
OLS estimate is β = (X_SᵀX_S)⁻¹X_Sᵀy, RSS = yᵀy − βᵀX_Sᵀy, s² = RSS/(n − |S|),
se = √(s²·diag((X_SᵀX_S)⁻¹)), and the p-value is two-sided Student-t with n − |S| dof —
exactly what ``statsmodels.OLS(y, X_S).fit()`` reports (a test checks this). The final
model is fitted by statsmodels on the selected columns.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from .equations import Equation, coefficients_to_beta
from .errors import UserError
from .terms import Inputs, parse_term, term_matrix

#: The seed paper's candidate sets (Table 3).
CANDIDATES = {
    "indt-var-1": ("acc", "grade", "aero", "roll"),
    "indt-var-2": ("acc", "grade", "aero", "roll_v2", "roll", "v3", "v2", "v1"),
}
CHUNK = 1_000_000


@dataclass
class Gram:
    """Sufficient statistics of a no-intercept regression of y on X."""

    xtx: np.ndarray
    xty: np.ndarray
    yty: float
    n: int
    names: tuple[str, ...]

    def fit(self, idx: list[int]) -> dict | None:
        """OLS on the columns ``idx``: β, se, p, rss; None if the columns are collinear."""
        k = len(idx)
        if k == 0:
            return {"beta": np.zeros(0), "se": np.zeros(0), "t": np.zeros(0), "p": np.zeros(0),
                    "rss": self.yty}
        a = self.xtx[np.ix_(idx, idx)]
        d = np.sqrt(np.diag(a))
        if np.any(d == 0):
            return None
        scaled = a / np.outer(d, d)
        if np.linalg.cond(scaled) > 1e12:
            return None
        inv = np.linalg.inv(scaled) / np.outer(d, d)
        beta = inv @ self.xty[idx]
        rss = max(self.yty - beta @ self.xty[idx], 0.0)
        dof = self.n - k
        if dof <= 0:
            return None
        s2 = rss / dof
        se = np.sqrt(np.maximum(np.diag(inv) * s2, 0.0))
        with np.errstate(divide="ignore", invalid="ignore"):
            tval = np.where(se > 0, beta / se, np.inf)
        p = 2.0 * stats.t.sf(np.abs(tval), dof)
        return {"beta": beta, "se": se, "t": tval, "p": p, "rss": rss}


def gram(x: Inputs, y: np.ndarray, names, mask: np.ndarray | None = None, chunk: int = CHUNK) -> Gram:
    """Accumulate XᵀX, Xᵀy, yᵀy over samples (chunked: memory O(chunk·k))."""
    names = tuple(names)
    k = len(names)
    xtx, xty, yty, n = np.zeros((k, k)), np.zeros(k), 0.0, 0
    for lo in range(0, len(y), chunk):
        sl = slice(lo, min(lo + chunk, len(y)))
        xs = term_matrix(names, x.take(sl))
        ys = np.asarray(y[sl], float)
        if mask is not None:
            keep = mask[sl]
            xs, ys = xs[keep], ys[keep]
        xtx += xs.T @ xs
        xty += xs.T @ ys
        yty += float(ys @ ys)
        n += len(ys)
    return Gram(xtx, xty, yty, n, names)


def stepwise(g: Gram, p_enter: float = 0.10, p_remove: float = 0.15, max_steps: int = 100):
    """Forward–backward stepwise selection on sufficient statistics.

    Each round adds the candidate with the smallest p-value if it is below ``p_enter``,
    then removes, one at a time, the selected term with the largest p-value while it is
    above ``p_remove``. Stops when nothing enters. Returns (selected names, trace list).
    """
    if p_enter > p_remove:
        raise UserError(f"--p-enter ({p_enter}) must not exceed --p-remove ({p_remove}), "
                        "or selection can cycle")
    sel: list[int] = []
    trace = []
    for _ in range(max_steps):
        # rank by |t| (same order as p at equal dof, but no underflow to p = 0 ties)
        best, best_t, best_p = None, -1.0, 1.0
        for j in range(len(g.names)):
            if j in sel:
                continue
            f = g.fit(sel + [j])
            if f is None:
                continue
            if abs(f["t"][-1]) > best_t:
                best, best_t, best_p = j, abs(float(f["t"][-1])), float(f["p"][-1])
        if best is None or best_p >= p_enter:
            break
        sel.append(best)
        trace.append({"step": len(trace) + 1, "action": "enter", "term": g.names[best],
                      "t_value": best_t, "p_value": best_p})
        while len(sel) > 1:
            f = g.fit(sel)
            worst = int(np.argmin(np.abs(f["t"])))
            if f["p"][worst] <= p_remove:
                break
            trace.append({"step": len(trace) + 1, "action": "remove", "term": g.names[sel[worst]],
                          "p_value": float(f["p"][worst])})
            sel.pop(worst)
    return [g.names[j] for j in sel], trace


@dataclass
class CalibrationResult:
    """Outcome of a calibration: the fitted terms and their statistics (statsmodels)."""

    terms: list[str]
    params: dict[str, float]
    std_err: dict[str, float]
    p_values: dict[str, float]
    r2: float
    r2_uncentered: float
    n: int
    counts: dict
    trace: list[dict]
    settings: dict
    reference_mass_kg: float | None = None
    results: object = field(default=None, repr=False)

    def to_equation(self, name: str, provenance: dict | None = None) -> Equation:
        """The calibrated equation, ready for ``compare`` and the SUMO loop."""
        prov = {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                "method": "forward-backward stepwise OLS without intercept, final fit statsmodels OLS",
                "settings": self.settings, "selection_trace": self.trace, "sample_counts": self.counts}
        prov.update(provenance or {})
        metrics = {"n": self.n, "r2": self.r2, "r2_uncentered": self.r2_uncentered}
        if self.reference_mass_kg:
            metrics["reference_mass_kg"] = self.reference_mass_kg
            metrics["beta_mass_free"] = coefficients_to_beta(self.params, self.reference_mass_kg)
        return Equation(name=name, terms=dict(self.params), std_err=dict(self.std_err),
                        p_values=dict(self.p_values), provenance=prov, metrics=metrics,
                        description="DrvPw calibrated by sumo-drvpw stepwise regression")

    def summary(self) -> str:
        lines = [f"n = {self.n}, R² = {self.r2:.4f}", f"{'term':<12}{'coefficient':>14}{'std err':>12}{'p':>10}"]
        for t in self.terms:
            lines.append(f"{t:<12}{self.params[t]:>14.6g}{self.std_err[t]:>12.3g}{self.p_values[t]:>10.2g}")
        return "\n".join(lines)


def _design(terms, x: Inputs, y: np.ndarray, use: np.ndarray, chunk: int = CHUNK):
    """Design matrix and target of the used samples, filled chunk by chunk (no full-size
    temporaries, no copy of the inputs)."""
    idx = None if use.all() else np.flatnonzero(use)
    n = len(y) if idx is None else len(idx)
    xs = np.empty((n, len(terms)))
    for lo in range(0, n, chunk):
        hi = min(lo + chunk, n)
        sel = slice(lo, hi) if idx is None else idx[lo:hi]
        xs[lo:hi] = term_matrix(terms, x.take(sel))
    return xs, (y if idx is None else y[idx])


def calibrate(x: Inputs, y: np.ndarray, candidates, mask: np.ndarray | None = None,
              p_enter: float = 0.10, p_remove: float = 0.15, counts: dict | None = None,
              reference_mass_kg: float | None = None) -> CalibrationResult:
    """Select terms stepwise and fit the final OLS (statsmodels, no intercept).

    Parameters
    ----------
    x : term-basis inputs; y : measured driving power [W]
    candidates : term strings to choose from
    mask : samples to use (True = use); NaN rows in y or X are left out too
    p_enter, p_remove : p-value thresholds of forward–backward selection
    """
    import statsmodels.api as sm

    candidates = tuple(dict.fromkeys(candidates))
    for t in candidates:
        parse_term(t)
    y = np.asarray(y, float)
    use = np.isfinite(y) if mask is None else (np.asarray(mask, bool) & np.isfinite(y))
    # rows whose candidate terms are not finite (NaN signals) are left out as well
    for t in candidates:
        for s in parse_term(t).signals:
            if s in x.signals:
                use &= np.isfinite(np.asarray(x.signals[s], float))
    counts = dict(counts or {})
    counts["excluded_nonfinite_power"] = int((~np.isfinite(y)).sum())
    n_use = int(use.sum())
    if n_use <= len(candidates):
        raise UserError(f"too few usable samples ({n_use}) to calibrate {len(candidates)} candidate terms")
    g = gram(x, y, candidates, use)
    if not np.all(np.isfinite(g.xtx)):
        bad = [candidates[j] for j in range(len(candidates)) if not np.isfinite(g.xtx[j, j])]
        raise UserError(f"candidate term(s) {bad} are not finite on the usable samples")
    sel, trace = stepwise(g, p_enter, p_remove)
    if not sel:
        raise UserError("no candidate term entered the model at p-to-enter "
                        f"{p_enter}: the measured power is not explained by {list(candidates)}")
    xs, ys = _design(sel, x, y, use)
    # hasconst=False: no intercept by design; it also skips statsmodels' constant detection,
    # which costs three extra SVDs of the design matrix
    res = sm.OLS(ys, xs, hasconst=False).fit()
    del xs
    sse = float(res.ssr)
    _ = (res.bse, res.pvalues, res.tvalues, res.rsquared)  # cached before the data go
    # the results keep the design matrix and its pseudo-inverse (2 × n × k floats) alive;
    # drop the sample-length arrays so a CalibrationResult stays small
    res.remove_data()
    sst = float(((ys - ys.mean()) ** 2).sum())
    r2 = 1.0 - sse / sst if sst > 0 else float("nan")
    counts["used"] = n_use
    return CalibrationResult(
        terms=list(sel), params=dict(zip(sel, map(float, res.params))),
        std_err=dict(zip(sel, map(float, res.bse))), p_values=dict(zip(sel, map(float, res.pvalues))),
        r2=r2, r2_uncentered=float(res.rsquared), n=n_use, counts=counts, trace=trace,
        settings={"candidates": list(candidates), "p_enter": p_enter, "p_remove": p_remove},
        reference_mass_kg=reference_mass_kg, results=res)


def resolve_candidates(spec: str) -> tuple[str, ...]:
    """Candidate terms from a set name (indt-var-1, indt-var-2), a TOML file, or a comma list."""
    if spec in CANDIDATES:
        return CANDIDATES[spec]
    from pathlib import Path

    p = Path(spec)
    if p.suffix == ".toml" or p.exists():
        import tomllib

        if not p.is_file():
            raise UserError(f"--candidates: file not found: {p}")
        try:
            doc = tomllib.loads(p.read_text(encoding="utf-8"))
        except tomllib.TOMLDecodeError as e:
            raise UserError(f"--candidates {p}: invalid TOML: {e}") from None
        terms = doc.get("candidates", {}).get("terms") if isinstance(doc.get("candidates"), dict) else doc.get("terms")
        if not isinstance(terms, list) or not terms:
            raise UserError(f"--candidates {p}: needs `terms = [\"acc\", ...]` (top level or in [candidates])")
        for t in terms:
            try:
                parse_term(str(t))
            except UserError as e:
                raise UserError(f"--candidates {p}: {e}") from None
        return tuple(map(str, terms))
    if "," in spec or spec:
        terms = tuple(s.strip() for s in spec.split(",") if s.strip())
        try:
            for t in terms:
                parse_term(t)
        except UserError as e:
            raise UserError(f"--candidates '{spec}': {e} (or use indt-var-1, indt-var-2, a TOML file)") from None
        return terms
    raise UserError("--candidates is empty")
