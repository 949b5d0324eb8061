"""Where a fuel chain's windows (fit/chain_windows.py) split, and how often they are found.

The windowed Willans line (``calibrate --fit-window``) and the ATTENUATED check's refits on 10-, 30-
and 60-s windows average the driving power over runs of one trip's samples that never straddle one
of the line's kinks; these tests plant an engine, fit it on windowed means and compare with the
planted truth, or count the work the splits take."""

from __future__ import annotations

import numpy as np

import sumo_drvpw.fit.chain_windows as cw
from sumo_drvpw.fit.chain_fuel import calibrate_fuel, fuel_grid


def _trips(rng, n_trips: int):
    """Per trip a 1-Hz speed [m/s]: accelerate, cruise, brake to a stop, stand."""
    return [np.concatenate([np.arange(0.0, top, rng.uniform(0.25, 0.5)), np.full(int(rng.uniform(60, 300)), top),
                            np.arange(top, 0.0, -rng.uniform(0.6, 1.2)), np.zeros(60)])
            for top in rng.uniform(10.0, 27.0, n_trips)]


def test_the_splits_are_found_once_for_every_window_length(monkeypatch):
    """The ATTENUATED check refits on three window lengths, in memory (``windowed_lines``) and
    streamed (``window_designs``): each trip's runs (smoothed power sign, engine state, standing)
    are found once and chopped per length, not smoothed again for every length (before: three
    passes over every trip in each). The windows are those found one length at a time."""
    rng = np.random.default_rng(2)
    trips = _trips(rng, 8)
    v = np.concatenate(trips)
    trip = np.concatenate([np.full(t.size, k) for k, t in enumerate(trips)])
    p = 30_000.0 * np.concatenate([np.gradient(t) for t in trips]) * v + 1800.0 * v + 4.0 * v ** 3
    fuel = 20_000.0 + np.maximum(p, 0.0) / 0.4
    ok = rng.random(v.size) > 0.02
    calls = []
    real = cw._trip_cuts
    monkeypatch.setattr(cw, "_trip_cuts", lambda *a, **k: calls.append(1) or real(*a, **k))
    fit = calibrate_fuel(p, v, fuel, 1.0, trip=trip, mask=ok, engine_off=-np.inf, engine_on_above_mps=None)
    assert [r["window_s"] for r in fit.windowed] == list(cw.DILUTION_WINDOWS_S)
    assert len(calls) == len(trips)  # (before: 3 × 8)
    calls.clear()
    designs = list(cw.window_designs(fuel_grid(-np.inf, None), p, v, fuel, 1.0, None, {}, (), ok, trip))
    assert len(calls) == len(trips) and {k[1] for k, *_ in designs} == set(cw.DILUTION_WINDOWS_S)
    monkeypatch.setattr(cw, "_trip_cuts", real)
    runs = cw.trip_runs(p, v, fuel, 1.0, ok, trip)
    for ws in cw.DILUTION_WINDOWS_S:
        alone = cw.window_ids(p, v, fuel, 1.0, ok, trip, ws)
        assert np.array_equal(alone, cw.chop(runs, ws))
        assert alone.max() + 1 == np.unique(alone[ok]).size  # numbered 0, 1, … without gaps
