"""One equation's sums of a streamed comparison (fit/stream_compare.py), merged across batches,
and what `compare` reports read from them as :mod:`sumo_drvpw.fit.compare` computes it in
memory: metrics, speed bins, the ≥ 80 km/h summary (exact counts, means and RMSE;
percentiles from the reservoir sample), the error–term correlations and the chain inputs
unknown on some samples."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.ols import Gram
from sumo_drvpw.fit.stream import Moments


@dataclass
class _EqStats:
    """Per-equation sums of a comparison over the samples with a finite prediction."""

    cats: list
    mom: dict            # subset → Moments of [meas, pred] (all, light, heavy)
    sse: dict            # subset → Σe²
    se: dict             # subset → Σe
    sae: float           # Σ|e|
    ecat: Moments        # [e, category powers]
    cmin: np.ndarray
    cmax: np.ndarray
    eref: Moments | None  # [e, reference category powers]
    rmin: np.ndarray | None
    rmax: np.ndarray | None
    energy: np.ndarray   # Σ P_cat·Δt over samples with positive total
    hs: np.ndarray       # n, Σe, Σe² at ≥ 80 km/h, then below
    bins: np.ndarray     # (3, nbins): n, Σe, Σe² per 10 km/h speed bin
    trip_e: dict         # trip → (E⁺meas, E⁺pred, E_net meas, E_net pred)
    ptrac: float = 0.0   # Σ max(P̂, 0)·Δt of the compared target (its chain's for battery, fuel)
    unknown: dict = None  # chain input → [samples, read_as, [trip ids of each batch]]

    def merge(self, b: "_EqStats") -> "_EqStats":
        if self.cats != b.cats:
            raise UserError(f"compare: the categories of an equation differ between batches "
                            f"({self.cats} and {b.cats})")
        nb = max(self.bins.shape[1], b.bins.shape[1])
        bins = np.zeros((3, nb))
        bins[:, :self.bins.shape[1]] += self.bins
        bins[:, :b.bins.shape[1]] += b.bins
        return _EqStats(
            self.cats, {k: self.mom[k].merge(b.mom[k]) for k in self.mom},
            {k: self.sse[k] + b.sse[k] for k in self.sse}, {k: self.se[k] + b.se[k] for k in self.se},
            self.sae + b.sae, self.ecat.merge(b.ecat),
            np.minimum(self.cmin, b.cmin), np.maximum(self.cmax, b.cmax),
            None if self.eref is None else self.eref.merge(b.eref),
            None if self.rmin is None else np.minimum(self.rmin, b.rmin),
            None if self.rmax is None else np.maximum(self.rmax, b.rmax),
            self.energy + b.energy, self.hs + b.hs, bins, {**self.trip_e, **b.trip_e},
            self.ptrac + b.ptrac, _merge_unknown(self.unknown, b.unknown))


def _merge_unknown(a: dict | None, b: dict | None) -> dict | None:
    """Chain inputs unknown in two sets of batches: samples add, trips are kept per batch."""
    if not a or not b:
        return a or b
    out = {c: [u[0], u[1], list(u[2])] for c, u in a.items()}
    for c, u in b.items():
        if c in out:
            out[c][0] += u[0]
            out[c][2] += u[2]
        else:
            out[c] = [u[0], u[1], list(u[2])]
    return out


def _unknown_doc(unknown: dict | None) -> dict:
    """:meth:`sumo_drvpw.model.chain.EnergyChain.unknown_inputs` from the merged sums
    (trips as ``np.unique`` of all batches' gives them, as strings)."""
    out = {}
    for c in sorted(unknown or {}):
        samples, read_as, trips = unknown[c]
        out[c] = {"samples": int(samples), "read_as": read_as,
                  "trips": [str(t) for t in np.unique(np.concatenate(trips))]}
    return out



def _mean_rmse(n, s1, s2) -> tuple[float, float]:
    return (s1 / n, math.sqrt(s2 / n)) if n else (math.nan, math.nan)


def _speed_bins(s: _EqStats, e_sample, v_sample) -> list[dict]:
    """:func:`sumo_drvpw.fit.compare.speed_bins` with exact n, mean and RMSE per bin and
    percentiles from the reservoir sample."""
    from sumo_drvpw.fit.compare import SPEED_BIN_MPS, _error_summary
    from sumo_drvpw.model.constants import KMH

    b = np.floor(np.maximum(v_sample, 0.0) / SPEED_BIN_MPS + 1e-9).astype(np.int64)
    out = []
    for k in range(s.bins.shape[1]):  # a handful of bins, not samples
        lo, hi = k * SPEED_BIN_MPS, (k + 1) * SPEED_BIN_MPS
        row = {"lo_kmh": lo / KMH, "hi_kmh": hi / KMH, "lo_mps": lo, "hi_mps": hi}
        row.update(_error_summary(e_sample[b == k]))
        n = int(s.bins[0, k])
        row["n"] = n
        row["mean_w"], row["rmse_w"] = _mean_rmse(n, s.bins[1, k], s.bins[2, k])
        out.append(row)
    return out


def _high_speed(s: _EqStats, e_sample, v_sample) -> dict:
    """:func:`sumo_drvpw.fit.compare.high_speed_summary`: counts, means and RMSE exact,
    percentiles from the reservoir sample."""
    from sumo_drvpw.fit.compare import high_speed_summary

    out = high_speed_summary(e_sample, v_sample)
    n_hi, s1, s2, n_lo, b1, b2 = s.hs
    n = n_hi + n_lo
    out["fraction"] = n_hi / n if n else math.nan
    out["n"] = int(n_hi)
    out["mean_w"], out["rmse_w"] = _mean_rmse(n_hi, s1, s2)
    out["mean_below_w"], out["rmse_below_w"] = _mean_rmse(n_lo, b1, b2)
    return out


def _metrics(s: _EqStats) -> dict:
    """:func:`sumo_drvpw.fit.compare.metrics` from sums (same keys and conventions)."""
    from sumo_drvpw.fit.compare import MIN_SAMPLES

    def r2(k):
        m = s.mom[k]
        sst = float(m.m2[0, 0])
        return 1.0 - s.sse[k] / sst if m.n >= MIN_SAMPLES and sst > 0.0 else math.nan

    def r2c(k):
        m = s.mom[k]
        den = float(m.m2[0, 0]) * float(m.m2[1, 1])
        return float(m.m2[0, 1]) ** 2 / den if m.n >= MIN_SAMPLES and den > 0.0 else math.nan

    def mr(k):
        return _mean_rmse(s.mom[k].n, s.se[k], s.sse[k])

    n = s.mom["all"].n
    return {"n": n, "r2": r2("all"), "r2_light": r2("light"), "r2_heavy": r2("heavy"),
            "rmse_w": mr("all")[1], "mae_w": s.sae / n if n else math.nan, "bias_w": mr("all")[0],
            "n_light": s.mom["light"].n, "n_heavy": s.mom["heavy"].n,
            "rmse_light_w": mr("light")[1], "rmse_heavy_w": mr("heavy")[1],
            "bias_light_w": mr("light")[0], "bias_heavy_w": mr("heavy")[0],
            "r2_corr": r2c("all"), "r2_corr_light": r2c("light"), "r2_corr_heavy": r2c("heavy")}


def _corr(mom: Moments, cats: list, cmin: np.ndarray, cmax: np.ndarray) -> dict:
    """:func:`sumo_drvpw.fit.compare.error_term_correlation` from the co-moments of
    [error, category powers] (same conventions)."""
    from sumo_drvpw.fit.compare import MIN_SAMPLES

    n = mom.n
    see = float(mom.m2[0, 0])
    out, names, idx = {}, [], []
    for i, c in enumerate(cats):
        spp = float(mom.m2[i + 1, i + 1])
        r = slope = math.nan
        big = max(1.0, abs(float(cmin[i])), abs(float(cmax[i]))) if n else 1.0
        if n >= MIN_SAMPLES and spp > 0.0 and float(cmax[i] - cmin[i]) > 1e-9 * big:
            sep = float(mom.m2[0, i + 1])
            slope = sep / spp
            r = sep / math.sqrt(spp * see) if see > 0.0 else math.nan
            names.append(c)
            idx.append(i + 1)
        out[c] = {"r": r, "slope": slope, "partial_slope": math.nan}
    if names and n > len(names) + 1:
        fit = Gram(mom.m2[np.ix_(idx, idx)], mom.m2[idx, 0], see, n, tuple(names)).fit(
            list(range(len(names))))
        if fit is not None:  # collinear category powers: no partial slope (NaN)
            for c, v in zip(names, fit["beta"]):
                out[c]["partial_slope"] = float(v)
    return out

