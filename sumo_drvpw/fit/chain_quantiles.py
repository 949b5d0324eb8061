"""Exact quantiles of the braking powers in bounded memory (issue #14), for the streamed
chain fits (fit/chain_stream.py, fit/chain_trace_stream.py).

A pass counts the values per bin of their leading 24 bits (sign, exponent and 12 bits of
the mantissa: bins 1/4096 of their value wide, :func:`_keys`), a second keeps the distinct
values (with their counts) of the (at most 16) bins that hold the order statistics
``np.quantile`` interpolates (:func:`quantile_bins`), and :func:`quantiles_of` reads the
same floats as ``np.quantile`` from them (:func:`quantile_of_order`).
"""

from __future__ import annotations

import math

import numpy as np

#: the braking powers' bins: their float64 bits shifted right by this (12 mantissa bits kept)
KEY_SHIFT = 40


def quantile_of_order(order, n: int, q: float) -> float:
    """``np.quantile(a, q)`` (method 'linear') of n values from ``order(i)``, the i-th
    smallest: the same index, weight and interpolation as numpy's, so the same float."""
    vi = (n - 1) * q
    lo = math.floor(vi)
    if vi >= n - 1:
        a = b = order(n - 1)
    else:
        a, b = order(lo), order(lo + 1)
    g = vi - lo
    d = b - a
    return b - d * (1 - g) if g >= 0.5 else a + d * g


def quantile_bins(hist, quantiles) -> tuple[list, tuple]:
    """(the ranks of the order statistics ``np.quantile`` reads at ``quantiles`` among the
    values counted in ``hist`` (bin keys of :func:`_keys`, counts), the bins that hold them)."""
    n = int(hist[1].sum())
    ranks = set()
    for q in quantiles:
        vi = (n - 1) * q
        lo = math.floor(vi)
        ranks |= {n - 1} if vi >= n - 1 else {lo, lo + 1}
    cum = np.cumsum(hist[1])
    bins = {int(hist[0][np.searchsorted(cum, r, side="right")]) for r in ranks}
    return sorted(ranks), tuple(sorted(bins))


def quantiles_of(hist, values, quantiles) -> list:
    """``np.quantile`` (the same floats) at each of ``quantiles`` of the positive values
    counted in ``hist`` (:func:`quantile_bins`), from ``values``: the sorted distinct values
    of the bins that hold the order statistics, with their counts."""
    n = int(hist[1].sum())
    keys, counts = hist
    before = dict(zip(keys.tolist(), (np.cumsum(counts) - counts).tolist()))
    vals, vcum = values[0], np.cumsum(values[1])  # sorted distinct values
    vkeys = _keys(vals)

    def order(i):
        b = int(keys[np.searchsorted(np.cumsum(counts), i, side="right")])
        lo = int(np.searchsorted(vkeys, b))  # the bin's first value; i - before[b]: rank within it
        base = int(vcum[lo - 1]) if lo else 0
        return float(vals[lo + np.searchsorted(vcum[lo:] - base, i - before[b], side="right")])

    return [quantile_of_order(order, n, q) for q in quantiles]


def _keys(x: np.ndarray) -> np.ndarray:
    """Bin of each positive float (monotone in the value)."""
    return np.ascontiguousarray(x, np.float64).view(np.int64) >> KEY_SHIFT


def _merge_hist(a, b):
    if a is None:
        return b
    k, inv = np.unique(np.concatenate([a[0], b[0]]), return_inverse=True)
    return k, np.bincount(inv, np.concatenate([a[1], b[1]]), len(k)).astype(np.int64)

