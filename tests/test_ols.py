"""The one OLS path (sumo_drvpw.fit.ols) against statsmodels, the reference implementation."""

from __future__ import annotations


import numpy as np
import pytest
import statsmodels.api as sm
from hypothesis import given, settings
from hypothesis import strategies as st

from sumo_drvpw.fit.ols import dense_gram, ols


def _design(seed: int, n: int = 400):
    rng = np.random.default_rng(seed)
    v = rng.uniform(1.0, 35.0, n)
    a = rng.normal(0.0, 0.6, n)
    X = np.column_stack([v, v ** 2, v ** 3, 1500.0 * v * a, np.ones(n)])
    y = X @ np.array([180.0, 2.0, 0.4, 1.08, 600.0]) + rng.normal(0.0, 300.0, n)
    return X, y


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 2 ** 31 - 1))
def test_ols_matches_statsmodels(seed):
    """β, se, t, p and RSS as statsmodels.OLS (no constant added) reports them, on a
    badly scaled design (v … v³ in W, a column of ones)."""
    X, y = _design(seed)
    fit = ols(X, y, names=("v1", "v2", "v3", "acc", "one"))
    ref = sm.OLS(y, X, hasconst=False).fit()
    np.testing.assert_allclose(fit.beta, ref.params, rtol=1e-7)
    np.testing.assert_allclose(fit.se, ref.bse, rtol=1e-7)
    np.testing.assert_allclose(fit.t, ref.tvalues, rtol=1e-7)
    np.testing.assert_allclose(fit.p, ref.pvalues, rtol=1e-6, atol=1e-300)
    assert fit.rss == pytest.approx(ref.ssr, rel=1e-8)
    assert fit.dof == ref.df_resid and fit.n == len(y)
    assert list(fit.params) == ["v1", "v2", "v3", "acc", "one"]


def test_exact_data_give_exact_coefficients_and_zero_error():
    v = np.linspace(1.0, 30.0, 50)
    fit = ols(np.column_stack([v, v ** 3]), 150.0 * v + 0.3 * v ** 3)
    assert fit.params == pytest.approx({"x0": 150.0, "x1": 0.3}, rel=1e-9)
    assert fit.rss == pytest.approx(0.0, abs=1e-6 * float((150.0 * v) @ (150.0 * v)))


def test_one_column_vector_design():
    x = np.arange(1.0, 11.0)
    assert ols(x, 2.5 * x).beta[0] == pytest.approx(2.5)


def test_collinear_or_too_few_samples_raise():
    v = np.linspace(1.0, 30.0, 50)
    with pytest.raises(ValueError, match="collinear"):
        ols(np.column_stack([v, 2.0 * v]), v)
    with pytest.raises(ValueError, match="n = 2"):
        ols(np.column_stack([v[:2], v[:2] ** 2]), v[:2])
    with pytest.raises(ValueError, match="names"):
        dense_gram(np.column_stack([v, v]), v, names=("a",))


def test_gram_of_dense_design_equals_term_gram():
    """The dense and the chunked term path accumulate the same statistics."""
    from sumo_drvpw.fit.ols import gram
    from sumo_drvpw.model.terms import Inputs, term_matrix

    rng = np.random.default_rng(3)
    n = 1000
    z = np.zeros(n)
    x = Inputs(v=rng.uniform(0, 30, n), a=rng.normal(0, 1, n), theta=z, wind=z,
               mass=np.full(n, 1400.0), rho=np.full(n, 1.2))
    y = rng.normal(0, 1000, n)
    names = ("acc", "aero", "roll")
    g1 = gram(x, y, names, chunk=137)
    g2 = dense_gram(term_matrix(names, x), y, names)
    np.testing.assert_allclose(g1.xtx, g2.xtx, rtol=1e-12)
    np.testing.assert_allclose(g1.xty, g2.xty, rtol=1e-12)
    assert g1.n == g2.n == n and g1.yty == pytest.approx(g2.yty, rel=1e-12)
