"""The battery chain's one optional parameter chosen by BIC (fit/chain.py): the recuperation
limit, profiled over quantiles of the braking power and kept only where n·ln(RSS/n) + k·ln n
falls. Does a long log with small noise and nothing planted keep a spurious limit for a tiny
fit gain (the question of issue #12's calibration gaps: the BIC has no floor on the gain)?

It does not, and no floor is needed: a limit is no free column but a clip of the braking
power, so where the recuperation is linear a limit at any profiled quantile (≤ the 99.5 %
quantile: some braking always lies beyond it) books that braking wrong and raises the RSS —
by orders of magnitude over the noise, not by chance (measured on 10⁴ … 3·10⁶ samples, noise
0, 1 and 50 W: never kept, every limit's RSS above the fit without). A planted limit is found."""

from __future__ import annotations

import numpy as np
import pytest

from sumo_drvpw.fit.chain import calibrate_battery

N = 300_000


def _log(noise_w: float, limit_w: float | None = None, seed: int = 1):
    """Driving power and speed of ``N`` samples and the battery power of a chain with η_t 0.9,
    η_r 0.7, 400 W auxiliary (recuperation clipped at ``limit_w`` where given), ``noise_w`` W noise."""
    rng = np.random.default_rng(seed)
    p = rng.normal(5e3, 20e3, N)
    v = np.abs(rng.normal(12.0, 6.0, N))
    neg = np.minimum(p, 0.0) if limit_w is None else np.maximum(np.minimum(p, 0.0), -limit_w)
    y = np.maximum(p, 0.0) / 0.9 + 0.7 * neg + 400.0 + noise_w * rng.standard_normal(N)
    return p, v, y


@pytest.mark.parametrize("noise_w", [0.0, 1.0, 20.0])
def test_a_long_log_with_nothing_planted_keeps_no_recuperation_limit(noise_w):
    p, v, y = _log(noise_w)
    fit = calibrate_battery(p, v, y, 1.0)
    assert fit.chain.recuperation_limit_w is None and "recuperation_limit_w" not in fit.parameters
    free, *limited = fit.profile
    assert free["recuperation_limit_w"] is None and len(limited) == 8  # every quantile was tried
    # each limit raises the RSS, by far more than the noise could lower it (not a near tie)
    floor = max(noise_w, 1e-3) ** 2 * N
    assert all(r["rss"] > free["rss"] + 100 * floor for r in limited)
    assert fit.chain.recuperation_efficiency == pytest.approx(0.7, rel=1e-3)


def test_a_planted_recuperation_limit_is_kept():
    """The control: the same log with its recuperation clipped at 25 kW keeps a limit, at the
    profiled quantile nearest the planted one."""
    p, v, y = _log(20.0, limit_w=25e3)
    fit = calibrate_battery(p, v, y, 1.0)
    lim = fit.chain.recuperation_limit_w
    brake = -np.minimum(p, 0.0)
    grid = [float(np.quantile(brake[brake > 0], q)) for q in (0.5, 0.7, 0.8, 0.9, 0.95, 0.98, 0.99, 0.995)]
    assert lim == min(grid, key=lambda g: abs(g - 25e3))
