"""Forward–backward stepwise multiple regression (OLS, no intercept) → a DrvPw equation.

The seed paper calibrates DrvPw by stepwise multiple regression over candidate terms
(Indt var. 1: acc, grade, aero, roll; Indt var. 2: all eight), then a final multiple
regression of the selected terms.

Selection works on the sufficient statistics XᵀX, Xᵀy, yᵀy of all candidates, computed
in chunks (:mod:`sumo_drvpw.fit.ols`, the one OLS path), so a step costs O(k³) instead of
a pass over the samples; the statistics of a subset are exactly what
``statsmodels.OLS(y, X_S).fit()`` reports (a test checks this). The final model is fitted
by statsmodels on the selected columns.
"""

from __future__ import annotations

import datetime as _dt
from dataclasses import dataclass, field

import numpy as np

from sumo_drvpw.model.equations import Equation, coefficients_to_beta
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.ols import CHUNK, Gram, gram
from sumo_drvpw.model.terms import Inputs, parse_term, term_matrix

__all__ = ["CANDIDATES", "CHUNK", "Gram", "gram", "drop_spanned", "stepwise", "calibrate",
           "CalibrationResult", "resolve_candidates"]

#: The seed paper's candidate sets (Table 3).
CANDIDATES = {
    "indt-var-1": ("acc", "grade", "aero", "roll"),
    "indt-var-2": ("acc", "grade", "aero", "roll_v2", "roll", "v3", "v2", "v1"),
}
#: A candidate whose column keeps less than this share of its sum of squares after
#: projection on the columns kept before it is numerically spanned by them (|r| > 1 − 5e-11
#: for a pair): dropped before selection, so no tie is ever broken by rounding.
SPAN_TOL = 1e-10
#: |t| values within this relative distance count as a tie, broken by candidate order.
TIE_RTOL = 1e-9


def drop_spanned(g: Gram, tol: float = SPAN_TOL) -> tuple[list[int], list[dict]]:
    """Deterministic collinearity screen of the candidates, in candidate order.

    For candidate j, the share of its sum of squares left after projection on the columns
    kept so far is 1 − R²_j = (x_jᵀx_j − x_jᵀX_K (X_KᵀX_K)⁻¹ X_Kᵀx_j) / x_jᵀx_j (from the
    Gram matrix, no pass over the samples). Below ``tol`` the column is dropped: the first
    of identical columns in candidate order wins. Returns (kept indices, dropped records
    ``{"term", "reason", "spanned_by"}``).
    """
    kept: list[int] = []
    dropped: list[dict] = []
    for j, name in enumerate(g.names):
        d = g.xtx[j, j]
        if not d > 0:
            dropped.append({"term": name, "reason": "zero on these data", "spanned_by": []})
            continue
        if kept:
            a = g.xtx[np.ix_(kept, kept)]
            b = g.xtx[kept, j]
            sc = np.sqrt(np.diag(a))
            coef = np.linalg.lstsq(a / np.outer(sc, sc), b / sc, rcond=None)[0] / sc
            left = (d - coef @ b) / d
            if left < tol:
                parts = [(g.names[k], c) for k, c in zip(kept, coef)
                         if abs(c) * np.sqrt(g.xtx[k, k]) > 1e-6 * np.sqrt(d)]
                names = [n for n, _ in parts]
                one = len(parts) == 1 and abs(parts[0][1] - 1) < 1e-6
                reason = (f"identical to {names[0]}" if one else
                          f"spanned by {', '.join(names)}") + " on these data"
                dropped.append({"term": name, "reason": reason, "spanned_by": names})
                continue
        kept.append(j)
    return kept, dropped


def stepwise(g: Gram, p_enter: float = 0.10, p_remove: float = 0.15, max_steps: int = 100):
    """Forward–backward stepwise selection on sufficient statistics.

    Candidates that are identical to, or numerically spanned by, candidates before them
    are dropped first (:func:`drop_spanned`; listed in the trace with action ``drop``).
    Each round adds the candidate with the largest |t| (the smallest p-value) if its
    p-value is below ``p_enter``, then removes, one at a time, the selected term with the
    largest p-value while it is above ``p_remove``. Stops when nothing enters. |t| values
    equal within ``TIE_RTOL`` are a tie, broken by candidate order. Returns (selected
    names, trace list).
    """
    if p_enter > p_remove:
        raise UserError(f"p_enter ({p_enter}) must not exceed p_remove ({p_remove}), "
                        "or selection can cycle")
    kept, dropped = drop_spanned(g)
    trace = [{"step": i + 1, "action": "drop", "term": d["term"], "reason": d["reason"]}
             for i, d in enumerate(dropped)]
    sel: list[int] = []
    for _ in range(max_steps):
        # rank by |t| (same order as p at equal dof, but no underflow to p = 0 ties)
        best, best_t, best_p = None, -1.0, 1.0
        for j in kept:
            if j in sel:
                continue
            f = g.fit(sel + [j])
            if f is None:
                continue
            t = abs(float(f["t"][-1]))
            if t > best_t * (1.0 + TIE_RTOL):
                best, best_t, best_p = j, t, float(f["p"][-1])
        if best is None or best_p >= p_enter:
            break
        sel.append(best)
        trace.append({"step": len(trace) + 1, "action": "enter", "term": g.names[best],
                      "t_value": best_t, "p_value": best_p})
        while len(sel) > 1:
            f = g.fit(sel)
            at = np.abs(f["t"])
            # the smallest |t|; among ties the latest in candidate order leaves
            worst = min((i for i in range(len(sel)) if at[i] <= at.min() * (1.0 + TIE_RTOL)),
                        key=lambda i: -sel[i])
            if f["p"][worst] <= p_remove:
                break
            trace.append({"step": len(trace) + 1, "action": "remove", "term": g.names[sel[worst]],
                          "p_value": float(f["p"][worst])})
            sel.pop(worst)
    return [g.names[j] for j in sel], trace


def select_terms(g: Gram, p_enter: float, p_remove: float) -> tuple[list[str], list[dict], list[dict]]:
    """Stepwise selection on the sufficient statistics ``g`` of the usable samples, with the
    checks every calibration path shares: (selected terms, trace, dropped candidates
    ``{"term", "reason"}``); UserError when a candidate is not finite or nothing enters."""
    cands = g.names
    if g.n <= len(cands):
        raise UserError(f"too few usable samples ({g.n}) to calibrate {len(cands)} candidate terms")
    if not np.all(np.isfinite(g.xtx)):
        bad = [cands[j] for j in range(len(cands)) if not np.isfinite(g.xtx[j, j])]
        raise UserError(f"candidate term(s) {bad} are not finite on the usable samples")
    sel, trace = stepwise(g, p_enter, p_remove)
    if not sel:
        raise UserError("no candidate term entered the model at p-to-enter "
                        f"{p_enter}: the measured power is not explained by {list(cands)}")
    dropped = [{"term": t["term"], "reason": t["reason"]} for t in trace if t["action"] == "drop"]
    return sel, trace, dropped


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
    #: candidates dropped before selection: [{"term", "reason", "spanned_by"}]
    dropped: list = field(default_factory=list)
    #: range of the samples used [m/s], [m/s²]: the equation's validity range
    speed_range_mps: tuple[float, float] | None = None
    accel_range_mps2: tuple[float, float] | None = None

    @property
    def implausible(self) -> dict[str, str]:
        """Coefficients of this free fit that read implausibly as physics (term → why:
        :func:`sumo_drvpw.fit.physical.physical_reading`, the aero term at sea-level air);
        {} when all read plausibly. ``sumo-drvpw calibrate`` then writes the physically
        constrained refit (:func:`sumo_drvpw.fit.physical.physical_calibration` in Python)."""
        from sumo_drvpw.fit.physical import physical_reading

        return {t: r["note"] for t, r in physical_reading(self.params).items() if r["plausible"] is False}

    def to_equation(self, name: str, provenance: dict | None = None) -> Equation:
        """The equation of this free fit, for ``compare`` and the SUMO loop; check
        :attr:`implausible` first (a lag or a smoothed grade absorbed into a coefficient
        is wrong in SUMO, where inputs are clean)."""
        prov = {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                "method": "forward-backward stepwise OLS without intercept, final fit statsmodels OLS",
                "settings": self.settings, "selection_trace": self.trace, "sample_counts": self.counts,
                "dropped_candidates": self.dropped}
        prov.update(provenance or {})
        metrics = {"n": self.n, "r2": self.r2, "r2_uncentered": self.r2_uncentered}
        if self.reference_mass_kg:
            metrics["reference_mass_kg"] = self.reference_mass_kg
            metrics["beta_mass_free"] = coefficients_to_beta(self.params, self.reference_mass_kg)
        return Equation(name=name, terms=dict(self.params), std_err=dict(self.std_err),
                        p_values=dict(self.p_values), provenance=prov, metrics=metrics,
                        description="DrvPw calibrated by sumo-drvpw stepwise regression",
                        speed_range_mps=self.speed_range_mps,
                        accel_range_mps2=self.accel_range_mps2)

    def summary(self, physics: bool = True) -> str:
        """A plain-text table: n, R², and per term the coefficient [W per unit of the
        term], its standard error and p-value; then the dropped candidates and (``physics``)
        the coefficients that read implausibly (:attr:`implausible`)."""
        lines = [f"n = {self.n}, R² = {self.r2:.4f}", f"{'term':<12}{'coefficient':>14}{'std err':>12}{'p':>10}"]
        for t in self.terms:
            lines.append(f"{t:<12}{self.params[t]:>14.6g}{self.std_err[t]:>12.3g}{self.p_values[t]:>10.2g}")
        for d in self.dropped:
            lines.append(f"`{d['term']}` dropped: {d['reason']}")
        bad = self.implausible if physics else {}
        if bad:
            lines.append("implausible as physics: " + "; ".join(f"{t} ({why})" for t, why in bad.items()))
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
    p_enter, p_remove : p-value thresholds of forward–backward selection [-]
    counts : sample counts of the log, carried into the provenance
    reference_mass_kg : mass the coefficients refer to [kg]; adds the mass-free β to the
        equation's metrics

    The model is P = Σ_j c_j·term_j (no intercept), the terms of paper Table 3 (Indt var.
    1: acc, grade, aero, roll), selected forward–backward as in the paper's §3.

    Example
    -------
    >>> import numpy as np
    >>> from sumo_drvpw.model.terms import Inputs
    >>> from sumo_drvpw.fit.calibrate import calibrate
    >>> rng = np.random.default_rng(0)
    >>> n = 5000
    >>> v, a, zero = rng.uniform(1, 30, n), rng.normal(0, 0.5, n), np.zeros(n)
    >>> x = Inputs(v=v, a=a, theta=zero, wind=zero, mass=np.full(n, 1500.0),
    ...            rho=np.full(n, 1.2041))
    >>> y = 1.05 * 1500 * v * a + 0.35 * v**3 + 0.009 * 1500 * 9.81 * v
    >>> res = calibrate(x, y + rng.normal(0, 200, n), ("acc", "aero", "roll"))
    >>> res.terms, round(res.params["aero"], 2)
    (['acc', 'aero', 'roll'], 0.35)
    >>> res.implausible                  # {} here: every coefficient reads as physics
    {}
    >>> eq = res.to_equation("my_car")   # ready for compare() and the SUMO loop

    Where ``res.implausible`` names coefficients, use
    :func:`sumo_drvpw.fit.physical.physical_calibration` (the refit under physical
    constraints that ``sumo-drvpw calibrate`` writes). ``x``, ``y`` and ``mask`` must have
    one value per sample (a UserError otherwise).
    """
    import statsmodels.api as sm

    candidates = tuple(dict.fromkeys(candidates))
    for t in candidates:
        parse_term(t)
    y = np.asarray(y, float)
    n_x = len(np.asarray(x.v))
    if y.shape != (n_x,) or (mask is not None and np.shape(mask) != (n_x,)):
        raise UserError(f"calibrate: the inputs have {n_x} samples, the measured power "
                        f"{y.shape[0] if y.ndim else 0}" + ("" if mask is None else f", the mask {np.shape(mask)[0] if np.ndim(mask) else 0}")
                        + ": give one value per sample")
    use = np.isfinite(y) if mask is None else (np.asarray(mask, bool) & np.isfinite(y))
    # rows whose candidate terms are not finite (NaN signals) are left out as well
    for t in candidates:
        for s in parse_term(t).signals:
            if s in x.signals:
                use &= np.isfinite(np.asarray(x.signals[s], float))
    counts = dict(counts or {})
    counts["excluded_nonfinite_power"] = int((~np.isfinite(y)).sum())
    n_use = int(use.sum())
    if n_use and not np.any(y[use] != 0.0):
        raise UserError(f"calibrate: the measured power is 0 on all {n_use} usable samples: nothing to fit")
    g = gram(x, y, candidates, use)
    sel, trace, dropped = select_terms(g, p_enter, p_remove)
    xs, ys = _design(sel, x, y, use)
    # hasconst=False: no intercept by design; it also skips statsmodels' constant detection,
    # which costs three extra SVDs of the design matrix
    res = sm.OLS(ys, xs, hasconst=False).fit()
    # named exog, so summary() and params read as terms; the results keep their data
    # (summary(), aic, bic, condition_number work); the pseudo-inverse (n × k) is not
    # needed once the covariance is computed
    res.model.data.xnames = list(sel)
    res.model.__dict__.pop("pinv_wexog", None)
    sse = float(res.ssr)
    sst = float(((ys - ys.mean()) ** 2).sum())
    r2 = 1.0 - sse / sst if sst > 0 else float("nan")
    counts["used"] = n_use
    return CalibrationResult(
        terms=list(sel), params=dict(zip(sel, map(float, res.params))),
        std_err=dict(zip(sel, map(float, res.bse))), p_values=dict(zip(sel, map(float, res.pvalues))),
        r2=r2, r2_uncentered=float(res.rsquared), n=n_use, counts=counts, trace=trace,
        settings={"candidates": list(candidates), "p_enter": p_enter, "p_remove": p_remove},
        reference_mass_kg=reference_mass_kg, results=res, dropped=dropped,
        speed_range_mps=_range(x.v, use), accel_range_mps2=_range(x.a, use))


def _range(values, use) -> tuple[float, float]:
    """(min, max) of ``values`` over the used samples."""
    v = np.asarray(values, float)[use]
    return float(np.nanmin(v)), float(np.nanmax(v))


def resolve_candidates(spec: str) -> tuple[str, ...]:
    """Candidate terms from a set name (indt-var-1, indt-var-2), a TOML file, or a comma list."""
    if spec in CANDIDATES:
        return CANDIDATES[spec]
    if not spec.strip(" ,"):
        raise UserError(f"candidates {spec!r}: give a set ({', '.join(CANDIDATES)}), a TOML file "
                        "or a comma list of terms")
    from pathlib import Path

    p = Path(spec)
    if is_candidate_file(spec):
        import tomllib

        if not p.is_file():
            raise UserError(f"candidate file not found: {p}")
        try:
            doc = tomllib.loads(p.read_text(encoding="utf-8"))
        except tomllib.TOMLDecodeError as e:
            raise UserError(f"candidate file {p}: invalid TOML: {e}") from None
        from sumo_drvpw.fileio import check_toml_integers

        check_toml_integers(doc, f"candidate file {p}")
        terms = doc.get("candidates", {}).get("terms") if isinstance(doc.get("candidates"), dict) else doc.get("terms")
        if not isinstance(terms, list) or not terms:
            raise UserError(f"candidate file {p}: needs `terms = [\"acc\", ...]` (top level or in [candidates])")
        for t in terms:
            try:
                parse_term(str(t))
            except UserError as e:
                raise UserError(f"candidate file {p}: {e}") from None
        unknown = sorted(set(doc) - {"terms", "candidates", "constraints", "name", "description"})
        if unknown:  # (p_enter = 0.5 here set nothing, silently)
            raise UserError(f"candidate file {p}: unknown key {unknown[0]!r} (known: terms or [candidates] terms, "
                            "[constraints], name, description)")
        cons = doc.get("constraints")
        stray = sorted(set(cons) - set(map(str, terms))) if isinstance(cons, dict) else []
        if stray:
            raise UserError(f"candidate file {p}: constraints.{stray[0]} constrains no term of its terms "
                            f"({', '.join(map(str, terms))})")
        return tuple(map(str, terms))
    terms = tuple(s.strip() for s in spec.split(",") if s.strip())
    try:
        for t in terms:
            parse_term(t)
    except UserError as e:
        raise UserError(f"candidate terms '{spec}': {e} (or use indt-var-1, indt-var-2, a TOML file)") from None
    return terms


def is_candidate_file(spec) -> bool:
    """Whether a candidates option names a file (a .toml name, or any file that exists): its
    terms and its [constraints] are read from it, whatever its name."""
    from pathlib import Path

    return str(spec) not in CANDIDATES and (Path(str(spec)).suffix == ".toml" or Path(str(spec)).exists())
