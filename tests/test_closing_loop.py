"""Closing the loop on real data (issue #11): the temperature factor ``cold`` of the term
grammar, evaluated the same by the equation evaluator and the SUMO ledger's fast path."""

import numpy as np
import pytest

from sumo_drvpw.model.constants import G, T_REF_C
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.model.terms import Inputs, category_of, term_matrix
from sumo_drvpw.sim.ledger import LEDGER_CATEGORIES, EquationSet


def _inputs(n, amb=None, seed=0):
    rng = np.random.default_rng(seed)
    sig = {} if amb is None else {"ambient_c": np.asarray(amb, float)}
    return Inputs(rng.uniform(0, 35, n), rng.uniform(-2, 2, n), rng.uniform(-0.05, 0.05, n),
                  np.zeros(n), rng.uniform(1200, 1800, n), np.full(n, 1.2), sig)


def test_cold_is_reference_minus_ambient_and_zero_without_temperature():
    x = _inputs(3, [0.0, 20.0, np.nan])
    # hand: T_ref 20 °C − 0 °C = 20 K; at 20 °C 0 K; unknown temperature → reference (0 K)
    np.testing.assert_array_equal(term_matrix(["cold"], x)[:, 0], [20.0, 0.0, 0.0])
    assert T_REF_C == 20.0
    np.testing.assert_array_equal(term_matrix(["cold"], _inputs(4))[:, 0], np.zeros(4))
    assert category_of("roll*cold") == "roll" and category_of("cold*v^2") == "roll"


def test_roll_cold_is_the_iso_temperature_correction_of_c_r():
    # c_r(T) = c_r0·(1 + k·(T_ref − T)); c_r0 0.01, k 0.008/K (ISO 28580), at −5 °C: 1.2·c_r0
    n = 50
    x = _inputs(n, np.full(n, -5.0))
    eq = Equation("crT", {"roll": 0.01, "roll*cold": 0.01 * 0.008})
    want = 0.01 * 1.2 * x.mass * G * x.v * np.cos(x.theta)
    np.testing.assert_allclose(eq.power(x), want, rtol=1e-12)


@pytest.mark.parametrize("amb", [None, "field"])
def test_ledger_fast_path_books_the_cold_terms_as_the_evaluator(amb):
    n = 400
    rng = np.random.default_rng(3)
    x = _inputs(n, None if amb is None else rng.uniform(-10, 35, n), seed=4)
    eqs = [Equation("a", {"acc": 1.2, "grade": 1.05, "aero_rho": 0.58, "roll": 0.02,
                          "roll*cold": 3e-4}),
           Equation("b", {"acc": 1.0, "roll": 0.012, "cold*v^2": 0.17}, mass_kg=1500.0)]
    pc = EquationSet(eqs).category_powers(x)
    for e, eq in enumerate(eqs):
        cp = eq.category_powers(x)
        for k, cat in enumerate(LEDGER_CATEGORIES):
            np.testing.assert_allclose(pc[:, e, k], cp.get(cat, np.zeros(n)), rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(pc[:, e].sum(1), eq.power(x), rtol=1e-12, atol=1e-9)
    if amb is None:   # no temperature: the equation at the reference temperature
        ref = Equation("a0", {k: c for k, c in eqs[0].terms.items() if "cold" not in k})
        np.testing.assert_allclose(eqs[0].power(x), ref.power(x), rtol=1e-12)
