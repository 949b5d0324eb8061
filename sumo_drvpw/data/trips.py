"""Per-trip helpers of the drive-log reader: integer trip codes (no Python string per row),
trip ids as arrays, and the centred moving average that never crosses a trip.

Samples of a trip are contiguous (the reader checks it); a categorical ``trip_id`` (the
streamed reader's dictionary-encoded ids) is used through its integer codes.
"""

from __future__ import annotations

import numpy as np
import pandas as pd


def trip_starts(trip: np.ndarray) -> np.ndarray:
    """True where a new run of equal trip codes begins (row 0 included)."""
    return np.r_[True, trip[1:] != trip[:-1]]


def trip_codes_of(trip: pd.Series) -> np.ndarray:
    """Integer code per sample, equal for equal trip ids (a categorical column's own codes,
    else ``pd.factorize``): comparisons of neighbours without Python strings."""
    if isinstance(trip.dtype, pd.CategoricalDtype):
        return trip.cat.codes.to_numpy()
    return pd.factorize(trip)[0]


def per_trip_rolling_mean(x: np.ndarray, trip_codes: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average of width ``window`` samples that never crosses trips.

    Same as pandas ``rolling(window, center=True, min_periods=1).mean()`` per trip (NaN
    skipped), vectorized: window sums from per-trip cumulative sums (each trip's sums start
    at its first sample, so a trip's values do not depend on the trips read with it)."""
    if window <= 1:
        return x
    if window % 2 == 0:  # an even centred window: pandas' own alignment
        s = pd.Series(x)
        return s.groupby(trip_codes, sort=False).transform(
            lambda g: g.rolling(window, center=True, min_periods=1).mean()).to_numpy()
    n = len(x)
    start = trip_starts(trip_codes)
    first = np.flatnonzero(start)
    if len(first) <= 2000:  # trip by trip: each trip's arrays stay in cache
        out = np.empty(n)
        for a, b in zip(first, np.r_[first[1:], n]):
            out[a:b] = _rolling_mean_one(x[a:b], window)
        return out
    run = np.cumsum(start) - 1
    last = np.r_[first[1:], n] - 1
    i = np.arange(n)
    h = window // 2
    lo = np.maximum(i - h, first[run])
    hi = np.minimum(i + h, last[run])
    ok = np.isfinite(x)
    cs = pd.Series(np.where(ok, x, 0.0)).groupby(run, sort=False).cumsum().to_numpy()
    cnt = np.r_[0, np.cumsum(ok)]
    below = np.where(lo > first[run], cs[np.maximum(lo - 1, 0)], 0.0)
    c = cnt[hi + 1] - cnt[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(c > 0, (cs[hi] - below) / np.maximum(c, 1), np.nan)


def _rolling_mean_one(x: np.ndarray, window: int) -> np.ndarray:
    """Centred mean of odd width ``window`` over one trip, NaN skipped (min_periods=1)."""
    n, h = len(x), window // 2
    ok = np.isfinite(x)
    cs = np.zeros(n + 1)
    np.cumsum(np.where(ok, x, 0.0), out=cs[1:])
    cnt = np.zeros(n + 1, np.int64)
    np.cumsum(ok, out=cnt[1:])
    i = np.arange(n)
    lo = np.maximum(i - h, 0)
    hi = np.minimum(i + h + 1, n)
    c = cnt[hi] - cnt[lo]
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(c > 0, (cs[hi] - cs[lo]) / np.maximum(c, 1), np.nan)


def trip_array(trip: pd.Series) -> np.ndarray:
    """Trip ids as an object array; a categorical's rows point at its categories' strings
    (one string per trip, not one per row)."""
    if isinstance(trip.dtype, pd.CategoricalDtype):
        cats = np.asarray(trip.cat.categories, dtype=object)
        codes = trip.cat.codes.to_numpy()
        return np.append(cats, np.nan)[codes] if (codes < 0).any() else cats[codes]
    return trip.to_numpy()
