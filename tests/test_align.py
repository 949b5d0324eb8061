"""Channels on their own clocks put onto the speed samples (sumo_drvpw/data/adapters/align.py):
a channel logged faster than the speed is averaged over each speed sample's interval, which
keeps its integral (the energy of a power, the charge of a current) whatever the clocks; a
power's two factors averaged together keep the mean power; a channel's pause stays missing.
The real-data check (a JLU road trip at 1-Hz speed) is in tests/test_mdf_import.py."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sumo_drvpw.data.adapters._common import new_report
from sumo_drvpw.data.adapters.align import (align_channels, faster, interp_onto, keep_power, onto, window_mean,
                                            windows)


def _clocks(seed, n_speed, fast_step):
    """Speed times: steps of 1–1.4 s (no gap); a fast channel's: steps of 0.5–1.5 × fast_step
    from before the first speed sample to after the last."""
    rng = np.random.default_rng(seed)
    ts = 3.0 + np.cumsum(np.r_[0.0, rng.uniform(1.0, 1.4, n_speed - 1)])
    tc = ts[0] - 0.5 + np.cumsum(rng.uniform(0.5, 1.5, int(2 * (ts[-1] - ts[0] + 1.0) / fast_step) + 10) * fast_step)
    return rng, ts, tc


def _integral(t0, t1, tc, xc):
    """∫ from t0 to t1 of the channel, linear between its samples (exact: on its own grid)."""
    g = np.union1d(tc[(tc > t0) & (tc < t1)], [t0, t1])
    return np.trapezoid(np.interp(g, tc, xc), g)


@settings(max_examples=60, deadline=None)
@given(st.integers(0, 10_000), st.integers(3, 60), st.floats(0.01, 0.3))
def test_the_mean_over_each_interval_keeps_the_integral(seed, n_speed, fast_step):
    rng, ts, tc = _clocks(seed, n_speed, fast_step)
    xc = rng.normal(100.0, 80.0, len(tc))
    assert faster(ts, tc)
    x, mean = onto(ts, tc, xc)
    assert mean and np.isfinite(x).all()
    a, b = windows(ts)
    # the interval is the drive log's time weight dt_s: half the way to each neighbour
    np.testing.assert_allclose(b - a, 0.5 * (np.r_[np.diff(ts), 0.0] + np.r_[0.0, np.diff(ts)]), rtol=1e-12)
    assert np.sum(x * (b - a)) == pytest.approx(_integral(ts[0], ts[-1], tc, xc), rel=1e-9, abs=1e-9)
    # each value is the mean over its own interval
    k = int(rng.integers(len(ts)))
    assert x[k] == pytest.approx(_integral(a[k], b[k], tc, xc) / (b[k] - a[k]), rel=1e-9, abs=1e-9)


def test_a_slower_channel_is_interpolated_and_a_faster_one_averaged():
    ts = np.arange(0.0, 20.0, 0.1)
    tc = np.arange(0.0, 20.0, 1.0)
    x, mean = onto(ts, tc, 2.0 * tc)
    assert not mean and not faster(ts, tc)
    np.testing.assert_allclose(x[ts <= 19.0], 2.0 * ts[ts <= 19.0], rtol=1e-12, atol=1e-12)
    # at exactly twice the rate: averaged; a linear channel's mean is its value at the interval's middle
    x, mean = onto(tc, ts[::5], 2.0 * ts[::5])
    a, b = windows(tc)
    assert mean
    np.testing.assert_allclose(x[:-1], (a + b)[:-1], rtol=1e-12)


def test_a_pause_in_a_fast_channel_stays_missing():
    ts = np.arange(0.0, 60.0, 1.0)
    tc = np.r_[np.arange(0.0, 20.0, 0.02), np.arange(30.0, 60.0, 0.02)]  # paused 20 … 30 s
    x = window_mean(ts, tc, np.ones(len(tc)))
    a, b = windows(ts)
    touches = (b > tc[tc < 20.0].max()) & (a < 30.0)
    assert np.isnan(x[touches]).all() and touches.sum() == 11       # 19.98 … 30.0: the samples at 20 … 30 s
    np.testing.assert_allclose(x[~touches], 1.0)


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 10_000), st.floats(0.0, 1.0))
def test_current_and_voltage_averaged_together_keep_the_mean_power(seed, resistance):
    """A pack V = V₀ − R·I with a current on its own 100-Hz clock and the voltage on a
    50-Hz clock: averaged apart, V̄·Ī exceeds the mean power by R·var(I) within each
    interval; kept, Σ V·I·dt is the integral of the power."""
    rng, ts, tc = _clocks(seed, 40, 0.01)
    i = np.clip(np.cumsum(rng.normal(0.0, 8.0, len(tc))), -200.0, 200.0)  # wandering through both signs [A]
    tv = tc[::2] + 0.003
    v = 360.0 - resistance * np.interp(tv, tc, i)
    out = {"battery_current_a": onto(ts, tc, i)[0], "battery_voltage_v": onto(ts, tv, v)[0]}
    apart = out["battery_current_a"] * out["battery_voltage_v"]
    kept = keep_power(ts, {"battery_current_a": (tc, i), "battery_voltage_v": (tv, v)}, out)
    assert kept == [("battery_current_a", "battery_voltage_v")]
    a, b = windows(ts)
    exact = _integral(ts[0], ts[-1], tc, i * interp_onto(tc, tv, v))
    power = out["battery_current_a"] * out["battery_voltage_v"]
    assert np.sum(power * (b - a)) == pytest.approx(exact, rel=1e-9, abs=1e-6)
    assert np.sum(apart * (b - a)) >= exact - 1e-6 * abs(exact) - 1e-6  # V̄·Ī ≥ mean V·I when V falls with I
    # the current stays a current: within the range of its samples in the whole span, up to the
    # difference between the voltage's mean on its own clock (the column it is divided by, so that
    # the columns' product is the mean power) and on the current's (seed 135, R = 1 Ω: 200.0021 A
    # where the current stood at its 200-A clip: 1e-5; it was asserted to 1e-9, a flaky failure)
    assert np.all(np.abs(out["battery_current_a"]) <= np.abs(i).max() * (1 + 1e-3))


def test_a_shaft_that_reverses_keeps_the_plain_mean_torque():
    """T·n averaged where the speed changes sign within an interval: a weighted mean by n
    would be unbounded there, so the plain mean stays; elsewhere the product is kept."""
    ts = np.arange(0.0, 20.0, 1.0)
    tc = np.arange(-0.5, 20.5, 0.01)
    n = 1000.0 * np.sin(2 * np.pi * tc / 7.3)  # crosses 0 inside some intervals
    torque = 50.0 + 40.0 * np.cos(2 * np.pi * tc / 3.1)
    out = {"motor_torque_nm": onto(ts, tc, torque)[0], "motor_speed_rpm": onto(ts, tc, n)[0]}
    plain = out["motor_torque_nm"].copy()
    keep_power(ts, {"motor_torque_nm": (tc, torque), "motor_speed_rpm": (tc, n)}, out)
    a, b = windows(ts)
    crossing = np.array([np.ptp(np.sign(n[(tc >= lo) & (tc <= hi)])) > 0 for lo, hi in zip(a, b)])
    assert crossing.any() and (~crossing).any()
    np.testing.assert_array_equal(out["motor_torque_nm"][crossing], plain[crossing])
    assert np.all((out["motor_torque_nm"] >= 10.0 - 1e-9) & (out["motor_torque_nm"] <= 90.0 + 1e-9))
    mean_power = np.array([_integral(lo, hi, tc, torque * n) / (hi - lo) for lo, hi in zip(a, b)])
    np.testing.assert_allclose((out["motor_torque_nm"] * out["motor_speed_rpm"])[~crossing],
                               mean_power[~crossing], rtol=1e-9)


def test_an_asynchronous_log_averages_a_channel_logged_faster_than_the_speed():
    """A CAN export: speed once a second on its own rows, the current and voltage ten times a
    second on theirs: both averaged, the power kept, and the import note says so."""
    t_speed = np.arange(0.0, 30.0, 1.0)
    t_fast = np.arange(0.05, 30.0, 0.1)
    i = 50.0 + 40.0 * np.sin(2 * np.pi * 3.7 * t_fast)  # a ripple the 1-Hz samples would alias
    rows = pd.DataFrame({"time_s": np.r_[t_speed, t_fast],
                         "speed_mps": np.r_[np.full(len(t_speed), 10.0), np.full(len(t_fast), np.nan)],
                         "battery_current_a": np.r_[np.full(len(t_speed), np.nan), i],
                         "battery_voltage_v": np.r_[np.full(len(t_speed), np.nan), 350.0 - 0.1 * i]})
    rows = rows.sort_values("time_s", kind="stable").reset_index(drop=True)
    rep = new_report("can.csv", "can", len(rows))
    out = align_channels(rows, rep)
    assert len(out) == len(t_speed)
    ts = out["time_s"].to_numpy()
    a, b = windows(ts)
    p = (out["battery_current_a"] * out["battery_voltage_v"]).to_numpy()
    ok = np.isfinite(p)
    assert ok[1:-1].all()
    exact = [_integral(lo, hi, t_fast, i * (350.0 - 0.1 * i)) / (hi - lo) for lo, hi in zip(a[ok], b[ok])]
    np.testing.assert_allclose(p[ok], exact, rtol=1e-9)
    # the current is its mean: the 3.7-Hz ripple of ±40 A is gone from it
    assert np.max(np.abs(out["battery_current_a"].to_numpy()[ok] - 50.0)) < 5.0
    note = " ".join(rep["notes"])
    assert "averaged over each speed sample's interval: battery_current_a, battery_voltage_v" in note
    assert "battery_current_a is its mean weighted by battery_voltage_v" in note
