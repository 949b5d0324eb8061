"""Calibrated efficiency maps of a battery chain (issue #12 §1: η_t, η_r as small tables over
|P| and optionally speed), linear in their parameters.

The constant battery form of ``fit/chain.py`` is P_bat = x_t·max(P, 0) + η_r·P_rec + aux with
x_t = 1/η_t. Here x_t and η_r become piecewise-linear (hat-function) functions of |P| (and a
tensor product with hats over speed for ``"speed-power"``)::

    P_bat = Σ_k x_k·φ_k(|P|, v)·max(P, 0) + Σ_k r_k·ψ_k(|P|, v)·max(min(P, 0), −P_lim) + aux

so the losses L_t = (x_t(P) − 1)·P on traction and L_r = (1 − η_r(P))·|P_rec| on
recuperation are ≥ 0 exactly when x_k ≥ 1 and r_k ≤ 1 at every knot (bounds of
``lsq_linear``: η in [ETA_MIN, 1]). Knots: 0 and quantiles :data:`POWER_QUANTILES` of the
traction (braking) power of the fitted samples, speed knots at :data:`SPEED_QUANTILES`; hats
are held constant beyond the ends, as the evaluator's tables are (model/chain.Table).

The evaluator interpolates η linearly; η_r is fitted in that form, so its table (the knots)
is exact. The traction fit is linear in 1/η, so its table is written on the knots refined
:data:`REFINE` times with η = 1/x_t(P) at every point: the evaluator then equals the fitted
model to well under 0.1 % of the traction power (tests/test_chain_map.py).

Standard errors: of the knot values from the linear fit (lower bounds: samples are
autocorrelated), η_t's by the delta method.
"""

from __future__ import annotations

import math

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain import EnergyChain, Table

#: efficiency map kinds (the calibrate command's efficiency option)
KINDS = ("constant", "power", "speed-power")
#: quantiles of the traction (braking) power |P| used as knots, besides 0
POWER_QUANTILES = (0.25, 0.5, 0.75, 0.95)
#: quantiles of the moving samples' speed used as speed knots (``speed-power``)
SPEED_QUANTILES = (0.1, 0.5, 0.9)
#: sub-intervals per knot interval of the written traction table
REFINE = 8
#: η at a knot of mid power (not the first, not the last) below this is flagged implausible
ETA_IMPLAUSIBLE = 0.6
#: η_t at a knot of positive power at or above this is lossless: no motor and inverter is
#: (a BEV's battery → wheel 0.75–0.97, fit/chain_checks.reading's constant η_t); the traction
#: power there is more than the battery gave: a road load too high there, or the battery's
#: power under-read
ETA_LOSSLESS = 0.99


def hats(x: np.ndarray, knots: np.ndarray) -> np.ndarray:
    """Hat functions on ``knots`` at ``x`` (n × k), constant beyond the ends (rows sum to 1)."""
    x = np.clip(np.asarray(x, float), knots[0], knots[-1])
    out = np.zeros((x.size, knots.size))
    j = np.clip(np.searchsorted(knots, x, side="right") - 1, 0, knots.size - 2)
    t = (x - knots[j]) / (knots[j + 1] - knots[j])
    rows = np.arange(x.size)
    out[rows, j] = 1.0 - t
    out[rows, j + 1] += t
    return out


def _knots(a: np.ndarray, quantiles) -> np.ndarray:
    q = np.quantile(a, quantiles) if a.size else np.array([])
    k = np.unique(np.r_[0.0, q])
    k = k[np.r_[True, np.diff(k) > max(1.0, 1e-3 * k[-1])]] if k.size > 1 else k
    if k.size < 2:
        raise UserError("energy chain: too few distinct power values for an efficiency map "
                        "(use a constant efficiency)")
    return k


def _speed_knots(v: np.ndarray) -> np.ndarray:
    mv = v[v > 0.1]
    k = np.unique(np.round(np.quantile(mv, SPEED_QUANTILES), 3)) if mv.size > 20 else np.array([])
    if k.size < 2:
        raise UserError("energy chain: too few moving samples for a speed-power efficiency map")
    return k


class MapBasis:
    """The basis of one efficiency (traction or recuperation) over |P| [× v]."""

    def __init__(self, power_knots, speed_knots=None):
        self.power = np.asarray(power_knots, float)
        self.speed = None if speed_knots is None else np.asarray(speed_knots, float)

    @property
    def size(self) -> int:
        return self.power.size * (1 if self.speed is None else self.speed.size)

    def matrix(self, p, v) -> np.ndarray:
        """n × size weights; column index = i_speed·len(power) + j_power."""
        hp = hats(np.abs(p), self.power)
        if self.speed is None:
            return hp
        hv = hats(v, self.speed)
        return (hv[:, :, None] * hp[:, None, :]).reshape(hp.shape[0], -1)

    def grid(self, coef: np.ndarray) -> np.ndarray:
        return np.asarray(coef, float).reshape(-1 if self.speed is not None else 1, self.power.size)

    def table(self, values: np.ndarray) -> Table:
        vals = np.asarray(values, float)
        return Table(vals if self.speed is not None else vals.reshape(-1), self.speed,
                     self.power)


def traction_table(basis: MapBasis, x: np.ndarray) -> Table:
    """The η_t table written for fitted x = 1/η_t on the knots: the power axis refined
    :data:`REFINE` times, η = 1/x interpolated linearly in x (the fitted form)."""
    k = basis.power
    fine = np.unique(np.concatenate([np.linspace(a, b, REFINE + 1) for a, b in zip(k[:-1], k[1:])]))
    w = hats(fine, k)                                      # fine × knots
    xg = basis.grid(x)                                     # speeds × knots
    eta = np.clip(1.0 / (xg @ w.T), 0.0, 1.0)            # bounds hold up to rounding
    return Table(eta if basis.speed is not None else eta.reshape(-1), basis.speed, fine)


def fit_columns(kind: str, p, v, ok):
    """(traction basis, recuperation basis) for ``kind`` from the samples ``ok``."""
    if kind not in KINDS[1:]:
        raise UserError(f"energy chain: efficiency must be one of {', '.join(KINDS)}, got {kind!r}")
    pos, neg = p[ok & (p > 0)], -p[ok & (p < 0)]
    vk = _speed_knots(v[ok]) if kind == "speed-power" else None
    bt = MapBasis(_knots(pos, POWER_QUANTILES), vk)
    br = MapBasis(_knots(neg, POWER_QUANTILES), vk)
    return bt, br


def knot_parameters(name: str, basis: MapBasis, beta, se, active, traction: bool) -> dict:
    """Per-knot report: η with its standard error, the loss at the knot, and a reading."""
    out = {}
    pk = np.tile(basis.power, 1 if basis.speed is None else basis.speed.size)
    vk = (np.repeat(basis.speed, basis.power.size) if basis.speed is not None
          else np.full(pk.size, np.nan))
    for j in range(basis.size):
        b, s = float(beta[j]), float(se[j])
        eta, s_eta = (min(1.0 / b, 1.0), s / b ** 2) if traction else (min(b, 1.0), s)
        key = f"{name}[{pk[j] / 1000:.1f} kW" + ("]" if math.isnan(vk[j]) else f", {vk[j] * 3.6:.0f} km/h]")
        loss = pk[j] * (1.0 / eta - 1.0) if traction else pk[j] * (1.0 - eta)
        side = "battery → shaft on traction" if traction else "shaft → battery on braking"
        r = f"{side} {eta:.1%} at {pk[j] / 1000:.1f} kW (loss {loss:.0f} W)"
        mid = 0 < j % basis.power.size < basis.power.size - 1
        if eta < ETA_IMPLAUSIBLE and mid:
            r += f"; IMPLAUSIBLE: below {ETA_IMPLAUSIBLE:.0%} at mid power"
        if traction and eta >= ETA_LOSSLESS and pk[j] > 0:
            r += ("; IMPLAUSIBLE: lossless traction (no motor and inverter is: expected 0.75–0.97): the driving "
                  "power at this power is more than the battery gave — the road load too high there, or the "
                  "battery's power under-read")
        if not traction and eta >= ETA_LOSSLESS and pk[j] != 0:
            r += ("; IMPLAUSIBLE: lossless braking (no generator and inverter is): the battery took in more "
                  "than the braking power at this power gives — the braking power under-read, or losses "
                  "absorbed by other terms; booked in SUMO it would over-credit every braking")
        out[key] = {"value": eta, "std_err": None if math.isnan(s_eta) else s_eta,
                    "at_bound": bool(active[j] != 0), "power_w": float(pk[j]),
                    "speed_mps": None if math.isnan(vk[j]) else float(vk[j]),
                    "loss_w": float(loss), "reading": r}
    return out


def map_chain(kw: dict, bt: MapBasis, br: MapBasis, x_t, eta_r) -> EnergyChain:
    """An EnergyChain with the fitted tables (kw: the other constructor arguments)."""
    return EnergyChain(traction_efficiency=traction_table(bt, x_t),
                       recuperation_efficiency=br.table(np.clip(br.grid(eta_r), 0.0, 1.0)), **kw)


def fitted_power(bt: MapBasis, br: MapBasis, x_t, eta_r, p, v, limit=None) -> np.ndarray:
    """The fitted model's traction + recuperation power (no auxiliaries) [W]: the reference the
    written tables are checked against."""
    rec = np.minimum(p, 0.0) if limit is None else np.maximum(np.minimum(p, 0.0), -limit)
    return (bt.matrix(p, v) @ x_t) * np.maximum(p, 0.0) + (br.matrix(p, v) @ eta_r) * rec
