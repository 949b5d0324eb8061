"""fit.repeats: the per-trip scatter that repeat trips (same route, within the hour) leave
between their held-out errors, and what it implies for k held-out trips."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sumo_drvpw.fit.repeats import repeat_pairs, repeat_scatter


def test_pairs_are_consecutive_trips_on_one_route_within_the_hour():
    starts = {"A": "2019-07-09 09:37:58", "B": "2019-07-09 09:49:09", "C": "2019-07-09 10:30:00",
              "D": "2019-07-09 17:48:14",              # same route, 7 h later: not a repeat
              "E": "2019-07-09 09:40:00",              # other route
              "F": None, "G": "2019-07-09 09:41:00"}  # no start; no route
    routes = {"A": "Munich East", "B": "Munich East", "C": "Munich East ", "D": "Munich East",
              "E": "FTMRoute", "F": "Munich East", "G": ""}
    assert repeat_pairs(starts, routes) == [("A", "B"), ("B", "C")]
    assert repeat_pairs(starts, routes, max_gap_s=15 * 60) == [("A", "B")]


def test_hand_values_for_two_pairs():
    # d = 0.04 and −0.02: σ̂ = sqrt((0.0016 + 0.0004) / 4) = sqrt(0.0005) = 0.022361
    r = repeat_scatter({"a": 0.05, "b": 0.01, "c": -0.03, "d": -0.01, "e": 0.2},
                       [("a", "b"), ("c", "d"), ("e", "missing")], k=10, bounds=(0.06,))
    assert r["n_pairs"] == 2
    assert r["sigma"] == pytest.approx(math.sqrt(0.0005), rel=1e-12)
    assert r["mean_abs_floor"] == pytest.approx(math.sqrt(0.0005) * math.sqrt(2 / math.pi), rel=1e-12)
    # P(|Z| ≤ 0.06/σ̂ = 2.683) = 0.99271 (normal table), to the 10th power 0.9295
    assert r["p_all_within"][0.06] == pytest.approx(0.9295, abs=2e-4)


def test_no_usable_pair_gives_nan_not_a_number_made_up():
    r = repeat_scatter({"a": math.nan, "b": 0.1}, [("a", "b")])
    assert r["n_pairs"] == 0 and math.isnan(r["sigma"]) and math.isnan(r["worst_of_k_median"])


def test_planted_scatter_is_recovered_and_shared_day_effects_cancel():
    """Per-trip error = a day effect shared by the pair (large, ±15 %) + independent scatter
    of σ = 4 %: σ̂ recovers 4 % within 5 %, untouched by the day effect; the implied mean |e|
    and the median worst of 10 agree with a direct simulation of that scatter."""
    rng = np.random.default_rng(7)
    n, sigma = 4000, 0.04
    day = rng.uniform(-0.15, 0.15, n)
    err, pairs = {}, []
    for i in range(n):
        err[f"{i}a"], err[f"{i}b"] = day[i] + rng.normal(0, sigma), day[i] + rng.normal(0, sigma)
        pairs.append((f"{i}a", f"{i}b"))
    r = repeat_scatter(err, pairs, k=10)
    assert r["sigma"] == pytest.approx(sigma, rel=0.05)
    z = rng.normal(0, sigma, (20000, 10))
    assert r["mean_abs_floor"] == pytest.approx(np.mean(np.abs(z)), rel=0.05)
    assert r["worst_of_k_median"] == pytest.approx(np.median(np.abs(z).max(axis=1)), rel=0.05)
    assert r["p_all_within"][0.06] == pytest.approx(np.mean(np.abs(z).max(axis=1) <= 0.06), abs=0.02)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)), min_size=1, max_size=30),
       st.floats(-0.3, 0.3))
def test_sigma_is_invariant_to_a_common_shift_and_swapping_the_pair(pairs_e, shift):
    err = {}
    for i, (a, b) in enumerate(pairs_e):
        err[f"{i}a"], err[f"{i}b"] = a, b
    pairs = [(f"{i}a", f"{i}b") for i in range(len(pairs_e))]
    r = repeat_scatter(err, pairs)
    shifted = repeat_scatter({k: v + shift for k, v in err.items()}, [(b, a) for a, b in pairs])
    assert shifted["sigma"] == pytest.approx(r["sigma"], rel=1e-9, abs=1e-12)
    bounds = list(r["p_all_within"].values())
    assert all(0.0 <= p <= 1.0 for p in bounds)
