"""The one least-squares path: OLS without intercept on sufficient statistics.

Every regression of the package goes through here (besides the tracer's
block-statistics solver in ``fit/diagnose``): stepwise selection in
:mod:`sumo_drvpw.fit.calibrate` (then ``statsmodels.OLS`` for the final, reported fit),
the error decomposition of :mod:`sumo_drvpw.fit.compare`, and the dense fits of the
validation studies.

For a design X (n × k, no intercept added: a column of ones is a term like any other) and
target y, the sufficient statistics are XᵀX, Xᵀy, yᵀy and n. For a subset S of columns

    β = (X_SᵀX_S)⁻¹X_Sᵀy,  RSS = yᵀy − βᵀX_Sᵀy,  s² = RSS/(n − |S|),
    se = √(s²·diag((X_SᵀX_S)⁻¹)),  t = β/se,  p = 2·(1 − F_t(|t|; n − |S|))

(Student-t, two-sided), exactly what ``statsmodels.OLS(y, X_S).fit()`` reports (a test in
tests/test_calibrate.py checks this). The inverse is taken on the Gram matrix scaled to
unit diagonal (a correlation matrix), so columns of very different magnitude (v and v³ in
W) do not cost precision; a scaled condition number above ``MAX_CONDITION`` counts as
collinear.

Example
-------
>>> import numpy as np
>>> from sumo_drvpw.fit.ols import ols
>>> v = np.linspace(1.0, 30.0, 200)
>>> fit = ols(np.column_stack([v, v**3]), 150.0 * v + 0.3 * v**3, names=("v1", "v3"))
>>> {k: round(b, 6) for k, b in fit.params.items()}
{'v1': 150.0, 'v3': 0.3}
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

from sumo_drvpw.model.terms import Inputs, term_matrix

#: Samples per chunk when accumulating the statistics of a term design (memory O(chunk·k)).
CHUNK = 1_000_000
#: Condition number of the unit-diagonal Gram matrix above which columns count as collinear.
MAX_CONDITION = 1e12


@dataclass
class Gram:
    """Sufficient statistics of a no-intercept regression of y on X.

    Attributes
    ----------
    xtx : XᵀX (k × k); xty : Xᵀy (k); yty : yᵀy; n : samples; names : column names
    """

    xtx: np.ndarray
    xty: np.ndarray
    yty: float
    n: int
    names: tuple[str, ...]

    def fit(self, idx: list[int]) -> dict | None:
        """OLS on the columns ``idx`` (module docstring): dict of ``beta``, ``se``, ``t``,
        ``p`` (arrays in the order of ``idx``) and ``rss``; None if the columns are
        collinear (a zero column or scaled condition number > ``MAX_CONDITION``) or leave
        no degree of freedom."""
        k = len(idx)
        if k == 0:
            return {"beta": np.zeros(0), "se": np.zeros(0), "t": np.zeros(0), "p": np.zeros(0),
                    "rss": self.yty}
        a = self.xtx[np.ix_(idx, idx)]
        d = np.sqrt(np.diag(a))
        if np.any(d == 0):
            return None
        scaled = a / np.outer(d, d)
        if np.linalg.cond(scaled) > MAX_CONDITION:
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
    """Accumulate XᵀX, Xᵀy, yᵀy of the term columns ``names`` over the samples.

    Parameters
    ----------
    x : term-basis inputs (:class:`sumo_drvpw.model.terms.Inputs`)
    y : target per sample [W]
    names : term strings, one column each (``term_matrix``)
    mask : samples to use (True = use); all when None
    chunk : samples per pass [-]; memory is O(chunk·k), never O(n·k)
    """
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


def dense_gram(X, y, names=None) -> Gram:
    """Sufficient statistics of a dense design ``X`` (n × k) and target ``y`` (n)."""
    X = np.asarray(X, float)
    if X.ndim == 1:
        X = X[:, None]
    y = np.asarray(y, float)
    names = tuple(names) if names is not None else tuple(f"x{j}" for j in range(X.shape[1]))
    if len(names) != X.shape[1] or len(y) != X.shape[0]:
        raise ValueError(f"ols: X is {X.shape[0]} × {X.shape[1]}, y has {len(y)} samples, "
                         f"{len(names)} names")
    return Gram(X.T @ X, X.T @ y, float(y @ y), len(y), names)


@dataclass
class OLSFit:
    """Result of :func:`ols`: coefficients and their statistics, in column order.

    Attributes
    ----------
    names : column names; beta, se, t, p : arrays per column (units of y per unit of
    the column, same, –, –); rss : residual sum of squares [y²]; n : samples;
    dof : n − k
    """

    names: tuple[str, ...]
    beta: np.ndarray
    se: np.ndarray
    t: np.ndarray
    p: np.ndarray
    rss: float
    n: int
    dof: int

    @property
    def params(self) -> dict[str, float]:
        """Coefficient per column name."""
        return dict(zip(self.names, map(float, self.beta)))

    @property
    def std_err(self) -> dict[str, float]:
        """Standard error per column name."""
        return dict(zip(self.names, map(float, self.se)))


def ols(X, y, names=None) -> OLSFit:
    """OLS of y on the columns of X without an added intercept (module docstring).

    Parameters
    ----------
    X : design (n × k, or n for one column); y : target (n); names : k column names
        (default x0, x1, …)

    Raises ``ValueError`` when the columns are collinear or leave no degree of freedom:
    a caller that hands its own design here knows its columns.
    """
    g = dense_gram(X, y, names)
    k = len(g.names)
    f = g.fit(list(range(k)))
    if f is None:
        raise ValueError(f"ols: columns {list(g.names)} are collinear or n = {g.n} ≤ k = {k}")
    return OLSFit(g.names, f["beta"], f["se"], f["t"], f["p"], float(f["rss"]), g.n, g.n - k)
