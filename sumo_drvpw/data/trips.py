"""Per-trip helpers of the drive-log reader: integer trip codes (no Python string per row),
trip ids as arrays, the centred moving average that never crosses a trip, and the signals
derived within trips (time derivative, grade from elevation).

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


def run_median_step(t: np.ndarray, trip_codes: np.ndarray) -> np.ndarray:
    """Median interval between consecutive samples of each run of equal codes [s], per run
    (0, 1, … in order; NaN for a one-sample run): each trip's own sampling, whatever else
    the log holds."""
    start = trip_starts(trip_codes)
    run = np.cumsum(start) - 1
    out = np.full(int(run[-1]) + 1 if len(run) else 0, np.nan)
    within = ~start[1:]
    if within.any():
        med = pd.Series(np.diff(t)[within]).groupby(run[1:][within]).median()
        out[med.index.to_numpy()] = med.to_numpy()
    return out


def rolling_mean_by_run(x: np.ndarray, trip_codes: np.ndarray, window: np.ndarray) -> np.ndarray:
    """:func:`per_trip_rolling_mean` with each run of equal codes on its own width
    (``window[k]`` samples for run k in order)."""
    run = np.cumsum(trip_starts(trip_codes)) - 1
    w = np.asarray(window, np.int64)[run]
    widths = np.unique(w)
    if len(widths) == 1:
        return per_trip_rolling_mean(x, trip_codes, int(widths[0]))
    out = np.empty(len(x))
    for k in widths:
        m = w == k
        out[m] = per_trip_rolling_mean(x[m], run[m], int(k))
    return out


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


def derivative(y: np.ndarray, t: np.ndarray, trip_codes: np.ndarray, window_s, end_span_s=None) -> np.ndarray:
    """Smoothed time derivative within trips: central difference, then a centred mean.

    Parameters
    ----------
    y : signal [any unit]
    t : time [s], strictly increasing within a trip
    trip_codes : integer code per sample (samples of a trip, or of a stretch between two
        logging gaps, are contiguous; each run of equal codes is differentiated on its own)
    window_s : width of the moving average [s], one for all, or one per run (in order); in
        samples at each run's own median interval, so a trip's derivative does not depend on
        the trips read with it
    end_span_s : the least time a one-sided difference at a run's end spans [s], one for all
        or one per run (None or 0: one sample): a signal updated less often than it is logged
        (a speed held between updates, :func:`sumo_drvpw.data.plausible.update_interval`)
        changes by an update's Δy within one sample, so a one-sample difference at an end
        reads it over the row's interval (2·a for 2-Hz rows of a speed updated once a second)
        where the central differences inside read it over their two rows

    Returns dy/dt [unit/s]; one-sided differences at trip ends, 0 for one-sample trips.
    """
    n = len(y)
    d = np.zeros(n)
    if n < 2:
        return d
    start = trip_starts(trip_codes)
    end = np.r_[start[1:], True]
    # central differences by slices; one-sided ones only at trip ends (few samples)
    dy, dt = np.empty(n), np.empty(n)
    np.subtract(y[2:], y[:-2], out=dy[1:-1])
    np.subtract(t[2:], t[:-2], out=dt[1:-1])
    b = np.flatnonzero(start | end)
    lo = np.where(start[b], b, b - 1)
    hi = np.where(end[b], b, b + 1)
    if end_span_s is not None:
        lo, hi = _end_span(t, start, b, lo, hi, end_span_s)
    dy[b] = y[hi] - y[lo]
    dt[b] = t[hi] - t[lo]
    ok = dt > 0
    np.divide(dy, dt, out=d, where=ok)
    med = run_median_step(t, trip_codes)
    runs = np.flatnonzero(start)
    length = np.diff(np.r_[runs, n])
    win = np.broadcast_to(np.asarray(window_s, float), med.shape)
    width = np.where(med > 0, np.minimum(win / np.where(med > 0, med, 1.0), length), 1.0)
    # an odd width keeps the centred mean centred (an even one shifts by half a sample)
    return rolling_mean_by_run(d, trip_codes, np.maximum(np.round(width), 1).astype(np.int64) | 1)


def _end_span(t, start, b, lo, hi, span_s):
    """The one-sided differences' ends ``lo``, ``hi`` at the run ends ``b`` (in order) of
    :func:`derivative` widened to span at least ``span_s`` (per run) within the run."""
    run = np.cumsum(start) - 1
    span = np.broadcast_to(np.asarray(span_s, float), (int(run[-1]) + 1,))[run[b]]
    short = np.flatnonzero((span > 0) & (t[hi] - t[lo] < span * (1 - 1e-9)))
    if not len(short):
        return lo, hi
    lo, hi = lo.copy(), hi.copy()
    first = np.flatnonzero(start)
    last = np.r_[first[1:], len(t)] - 1
    for j in short:  # few: the ends of runs whose signal is held between updates
        r = run[b[j]]
        s, e = first[r], last[r]
        if lo[j] == b[j] and start[b[j]]:  # a run's first sample: forward to the first one span away
            hi[j] = min(s + int(np.searchsorted(t[s:e + 1], t[s] + span[j] * (1 - 1e-9), side="left")), e)
        if hi[j] == b[j] and b[j] == e:  # its last: back to the last one span before it
            lo[j] = max(s + int(np.searchsorted(t[s:e + 1], t[e] - span[j] * (1 - 1e-9), side="right")) - 1, s)
    return lo, hi


def grade_from_elevation(z: np.ndarray, dist: np.ndarray, trip_codes: np.ndarray,
                         window_m: float) -> np.ndarray:
    """Grade angle from elevation smoothed over distance, within trips.

    For each trip the elevation is interpolated onto a 1 m distance grid, averaged over
    ``window_m`` (centred), differentiated, and read back at each sample's distance.
    Coarse elevation (whole metres) then gives a grade resolution of about 1/window_m.

    Parameters
    ----------
    z : elevation [m]; dist : distance travelled since trip start [m]
    trip_codes : integer trip code per sample; window_m : smoothing distance [m]

    Returns θ [rad] = atan(dz/ds).
    """
    theta = np.zeros(len(z))
    starts = np.flatnonzero(trip_starts(trip_codes))
    bounds = np.r_[starts, len(z)]
    for a, b in zip(bounds[:-1], bounds[1:]):
        s, zz = dist[a:b], z[a:b]
        ok = np.isfinite(zz)
        if ok.sum() < 2 or s[-1] - s[0] < 2:
            continue
        su, first = np.unique(s[ok], return_index=True)
        zu = zz[ok][first]
        grid = np.arange(su[0], su[-1] + 1.0, 1.0)
        zg = np.interp(grid, su, zu)
        w = max(int(round(window_m)), 1)
        if w > 1 and len(zg) > w:
            kernel = np.ones(w) / w
            pad = np.pad(zg, (w // 2, w - 1 - w // 2), mode="edge")
            zg = np.convolve(pad, kernel, mode="valid")
        slope = np.gradient(zg, grid) if len(grid) > 1 else np.zeros_like(grid)
        theta[a:b] = np.arctan(np.interp(s, grid, slope))
    return theta


def trips_without(col: pd.Series, trip_codes: np.ndarray) -> np.ndarray:
    """Rows of the trips in which the column holds no value at all (in a folder of logs, the
    trips of a file without it), as a bool mask."""
    has = np.bincount(trip_codes, weights=col.notna().to_numpy(float)) > 0
    return ~has[trip_codes]


#: sample-index edges of the blocks whose mean speeds a trip's signature carries (fixed, so
#: a trip cut short by a row keeps the blocks it has whole)
SIGNATURE_EDGES = (0, 64, 256, 1024, 4096, 16384, 65536, 262144)
#: the speeds whose clear crossings are a trip's anchors (:func:`trip_anchors`): multiples of
#: this [m/s]
ANCHOR_LEVEL_MPS = 2.0
#: samples a crossing's speed stays on each side of its level, so a speed hovering at it
#: (noise, a steady cruise) gives none: each anchor is told by its own neighbourhood alone
ANCHOR_CLEAR = 8
#: samples from an anchor over which its mean speed (and battery power) is taken
ANCHOR_SPAN = 16
#: the most anchors an equation file keeps of a trip (evenly spread over it), and of all its
#: trips together: a calibration on thousands of trips keeps fewer of each (at least
#: KEPT_ANCHORS_MIN), so its file stays some 100 characters a trip, not 1.6 kB
KEPT_ANCHORS, KEPT_ANCHORS_TOTAL, KEPT_ANCHORS_MIN = 64, 6400, 8
#: anchors of a compared trip that must agree with a calibration trip's, at one offset, to
#: tell the trip a part of it: at least this many, and this share of the calibration trip's
#: kept anchors within the part
PART_MIN_ANCHORS, PART_SHARE = 3, 0.6


def trip_anchors(v: np.ndarray, p: np.ndarray | None = None) -> np.ndarray:
    """A trip's anchors: (sample index, mean speed [m/s], mean battery power [W] or NaN over
    the :data:`ANCHOR_SPAN` samples from it) at each sample where the speed crosses a multiple
    of :data:`ANCHOR_LEVEL_MPS` clearly (below it over the :data:`ANCHOR_CLEAR` samples
    before, at or above it over as many from the sample, or the other way round), as rows.

    Each anchor depends on the samples around it only, so a part of a trip (rows dropped at
    its start or end, a trip split in two files) has the anchors of the whole within it,
    their indices shifted by the rows dropped before it (:func:`same_trips`)."""
    n, c = len(v), ANCHOR_CLEAR
    if n < c + ANCHOR_SPAN + 1:
        return np.zeros((0, 3))
    from scipy.ndimage import maximum_filter1d, minimum_filter1d

    ok = np.isfinite(v)  # (a sample without a speed: no anchor across it)
    # the highest and lowest speed over the c samples from each index (origin: the window's start)
    hi = maximum_filter1d(np.where(ok, v, np.inf), c, origin=-(c // 2), mode="nearest")
    lo = minimum_filter1d(np.where(ok, v, -np.inf), c, origin=-(c // 2), mode="nearest")
    i = np.arange(c, n - ANCHOR_SPAN + 1)
    before_hi, before_lo, after_hi, after_lo = hi[i - c], lo[i - c], hi[i], lo[i]
    step = ANCHOR_LEVEL_MPS
    with np.errstate(invalid="ignore"):
        up = (np.floor(before_hi / step) + 1) * step <= after_lo
        down = (np.floor(before_lo / step) * step > after_hi) & (before_lo >= step)
    span = i[up | down][:, None] + np.arange(ANCHOR_SPAN)  # each crossing's samples from it
    x = v[span]
    span = span[x.max(axis=1) > x.min(axis=1)]  # (NaN or a span at one speed: it tells little)
    power = p[span].mean(axis=1) if p is not None else np.full(len(span), np.nan)
    return np.column_stack([span[:, 0], v[span].mean(axis=1), power])


def trip_signatures(df: pd.DataFrame) -> dict[str, list[float]]:
    """Trip → its signature [samples, duration s, mean speed, rms speed, then the mean speed
    over each whole block of samples between :data:`SIGNATURE_EDGES` (m/s), then the mean and
    rms of the product of ``battery_voltage_v`` and ``battery_current_a`` (W; 0 0 without
    them), then 3 and the trip's anchors (:func:`trip_anchors`: sample index, mean speed,
    mean power or 0, three numbers each)] in a read log ``df`` (``trip_id``, ``time_s``,
    ``speed_mps``): what tells the same trip read from another file — re-exported, in another
    format or unit, renamed, or among other trips — or a part of it (rows dropped at its start
    or end, a trip split in two files), so that ``compare`` can say an equation is compared on
    trips it was calibrated on (:func:`same_trips`); the battery's power tells two tests whose
    speed was logged alike (the shared JLU dynamometer's UDDS_01 and UDDS_02: the same speed
    samples, 1.29 and 1.22 kWh). Rounded to 7 significant digits (an equation file keeps them,
    with at most :data:`KEPT_ANCHORS` anchors, :func:`signature_texts`); a signature written
    before the anchors (4 numbers and the blocks, then the power's two if logged) is read as
    it was."""
    trip = df["trip_id"].astype(str).to_numpy()
    t, v = df["time_s"].to_numpy(float), df["speed_mps"].to_numpy(float)
    pw = (df["battery_voltage_v"].to_numpy(float) * df["battery_current_a"].to_numpy(float)
          if {"battery_voltage_v", "battery_current_a"} <= set(df.columns) else None)
    starts = np.flatnonzero(trip_starts(trip)) if len(trip) else np.zeros(0, np.int64)
    ends = np.r_[starts[1:], len(trip)]
    out: dict[str, list[float]] = {}
    for a, b in zip(starts, ends):  # (a trip's rows are contiguous in a read log)
        x = v[a:b]
        sig = [int(b - a), float(np.nanmax(t[a:b]) - np.nanmin(t[a:b])), float(np.nanmean(x)),
               float(np.sqrt(np.nanmean(x * x)))]
        sig += [float(np.nanmean(x[lo:hi])) for lo, hi in zip(SIGNATURE_EDGES, SIGNATURE_EDGES[1:])
                if hi + 2 <= len(x)]
        p = pw[a:b] if pw is not None and np.isfinite(pw[a:b]).any() else None
        sig += [float(np.nanmean(p)), float(np.sqrt(np.nanmean(p * p)))] if p is not None else [0.0, 0.0]
        anchors = trip_anchors(x, p)
        sig += [3.0] + np.nan_to_num(anchors, nan=0.0).ravel().tolist()
        out.setdefault(str(trip[a]), [int(sig[0])] + [float(f"{y:.7g}") for y in sig[1:]])
    return out


def signature_texts(sigs: dict[str, list[float]]) -> list[str]:
    """:func:`trip_signatures` as an equation's provenance keeps them: one line of numbers
    each, with at most :data:`KEPT_ANCHORS` of a trip's anchors (fewer when the trips are
    many: :data:`KEPT_ANCHORS_TOTAL`), evenly spread over it."""
    out = []
    most = max(KEPT_ANCHORS_MIN, min(KEPT_ANCHORS, KEPT_ANCHORS_TOTAL // max(len(sigs), 1)))
    for sig in sigs.values():
        sig = list(sig)
        head, anchors = _split(sig)
        if len(anchors) > most:
            keep = np.unique(np.round(np.linspace(0, len(anchors) - 1, most)).astype(int))
            sig = sig[:head] + [3.0] + anchors[keep].ravel().tolist()
        out.append(" ".join(f"{x:.7g}" for x in sig))
    return out


def _numbers(sig) -> list[float] | None:
    """A kept signature (a line of numbers, or a list) as numbers; None when it is not one
    (an equation file edited by hand: provenance informs, it does not refuse)."""
    try:
        out = [float(x) for x in (sig.split() if isinstance(sig, str) else sig)]
    except (TypeError, ValueError):
        return None
    return out if len(out) >= 4 else None


def _split(sig) -> tuple[int, np.ndarray]:
    """(the length of a signature's part before its anchors, its anchors as rows of three):
    a signature written before the anchors has none (4 numbers, the blocks, the power's two
    or none); one with anchors always has the power's two, then 3 and the anchors' numbers."""
    k = sum(hi + 2 <= sig[0] for hi in SIGNATURE_EDGES[1:])
    head = 6 + k
    rest = len(sig) - head - 1
    if rest < 0 or sig[head] != 3.0 or rest % 3:
        return min(len(sig), head), np.zeros((0, 3))
    return head, np.asarray(sig[head + 1:], float).reshape(-1, 3)


def _parts(sig) -> tuple[list, list, np.ndarray]:
    """(the blocks' mean speeds, [mean, rms battery power] or [], the anchors' rows) of a
    signature: as many blocks as its samples give (:func:`trip_signatures`), then the power,
    if any (0 0: none), then the anchors, if any."""
    k = sum(hi + 2 <= sig[0] for hi in SIGNATURE_EDGES[1:])
    power = list(sig[4 + k:6 + k])
    if len(power) == 2 and power[1] == 0.0:  # written without the battery
        power = []
    return list(sig[4:4 + k]), power, _split(sig)[1]


def same_trips(signatures, trips: dict[str, list[float]]) -> list[str]:
    """The trips of ``trips`` (trip → :func:`trip_signatures`) matching one of ``signatures``:
    the same samples re-read, or a part of them, not another drive of the same route or cycle.

    The same samples: allowed a few samples lost at the end (a file cut in its last row: 0.2 %
    or 2) and what they move the duration and the mean and rms speed, plus 0.01 % (or 1 mm/s)
    of rounding (speeds re-exported to 1 mm/s move them by 1e-5); the blocks' mean speeds,
    whole in both, within that rounding alone. A repeat drive of a dyno cycle differs by more
    (its driver's trace error, some 0.1–0.5 km/h rms). Where both carry the battery's power,
    its mean (either sign: a current logged the other way round) and rms agree as the speed's
    do, plus 1 W. A trip whose speed never changes (a parked session: all 0) matches none: its
    speed cannot tell it from another session of the same length.

    A part (:meth:`_AnchorIndex.part_of`): a trip no longer than a kept one whose anchors
    (:func:`trip_anchors`) are the kept trip's, shifted by the rows before it — rows dropped
    at the start, at the end, one file of a trip split in two. Signatures written before the
    anchors tell the same samples only."""
    refs = [r for r in map(_numbers, signatures) if r is not None]
    head = np.array([r[:4] for r in refs], float).reshape(-1, 4)  # (each ref compared at once)
    parts = [_parts(r) for r in refs]
    index = _AnchorIndex(head[:, 0], [a for _, _, a in parts])
    out = []
    for tid, sig in trips.items():
        n, dur, mv, rv = sig[:4]
        if not rv > abs(mv):  # rms = |mean|: one speed throughout
            continue
        dn = np.abs(head[:, 0] - n)
        lost = dn / max(n, 1)  # share of samples one of the two lacks
        near = ((dn <= max(2.0, 0.002 * n)) & (np.abs(head[:, 1] - dur) <= 1e-3 + 1e-6 * dur + 2.0 * lost * dur)
                & (np.abs(head[:, 2] - mv) <= 1e-3 + 1e-4 * abs(mv) + 3.0 * lost * rv)
                & (np.abs(head[:, 3] - rv) <= 1e-3 + 1e-4 * rv + 3.0 * lost * rv))
        blocks, power, anchors = _parts(sig)
        for j in np.flatnonzero(near):
            ref_blocks, ref_power, _ = parts[j]
            if (all(abs(p - q) <= 1e-3 + 1e-4 * abs(q) for p, q in zip(ref_blocks, blocks))
                    and (len(power) < 2 or len(ref_power) < 2 or (
                        abs(abs(ref_power[0]) - abs(power[0])) <= 1.0 + 1e-4 * abs(power[0]) + 3.0 * lost[j] * power[1]
                        and abs(ref_power[1] - power[1]) <= 1.0 + 1e-4 * power[1] + 3.0 * lost[j] * power[1]))):
                out.append(tid)
                break
        else:
            if index.part_of(int(n), anchors):
                out.append(tid)
    return out


class _AnchorIndex:
    """The kept trips' anchors sorted by their mean speed, for :meth:`part_of`: each compared
    trip's anchors are looked up among all kept trips' at once."""

    def __init__(self, samples, anchors: list[np.ndarray]):
        self.samples = np.asarray(samples, float)
        rows = [np.column_stack([np.full(len(a), j), a]) for j, a in enumerate(anchors) if len(a)]
        allrows = np.concatenate(rows) if rows else np.zeros((0, 4))
        allrows = allrows[np.argsort(allrows[:, 2], kind="stable")]
        self.ref, self.at, self.speed, self.power = (allrows[:, 0].astype(np.int64), allrows[:, 1],
                                                     allrows[:, 2], allrows[:, 3])
        self.own = [np.sort(a[:, 0]) if len(a) else np.zeros(0) for a in anchors]  # each trip's indices

    def part_of(self, n: int, anchors: np.ndarray) -> bool:
        """Whether a compared trip of ``n`` samples and these anchors is a part of a kept trip:
        at one offset s ≥ 0 with s + n at most the kept trip's samples (+ 2: a row cut), at
        least :data:`PART_MIN_ANCHORS` of its anchors and :data:`PART_SHARE` of the kept trip's
        within the part (those with a whole neighbourhood in it) are the compared trip's:
        the index shifted by s, the mean speed within 1 mm/s (+ 0.01 %), the battery power,
        where both have it, within 3 W (+ 0.01 %) in either sign."""
        if len(anchors) < PART_MIN_ANCHORS or not len(self.speed):
            return False
        tol = 1e-3 + 1e-4 * np.abs(anchors[:, 1])
        lo = np.searchsorted(self.speed, anchors[:, 1] - tol, side="left")
        hi = np.searchsorted(self.speed, anchors[:, 1] + tol, side="right")
        count = hi - lo
        if not count.sum():
            return False
        mine = np.repeat(np.arange(len(anchors)), count)  # every pair of agreeing speeds
        theirs = np.repeat(lo, count) + np.arange(len(mine)) - np.repeat(np.cumsum(count) - count, count)
        ref, shift = self.ref[theirs], self.at[theirs] - anchors[mine, 0]
        p, q = self.power[theirs], anchors[mine, 2]
        known = (p != 0) & (q != 0) & np.isfinite(p) & np.isfinite(q)
        ok = ((shift >= 0) & (shift + n <= self.samples[ref] + 2)
              & (~known | (np.abs(np.abs(p) - np.abs(q)) <= 3.0 + 1e-4 * np.abs(q))))
        if not ok.any():
            return False
        pairs, votes = np.unique(np.column_stack([ref[ok], shift[ok]]), axis=0, return_counts=True)
        for (j, s), k in zip(pairs[votes >= PART_MIN_ANCHORS], votes[votes >= PART_MIN_ANCHORS]):
            own = self.own[int(j)]  # the kept trip's anchors within the part, as the part has them
            within = (np.searchsorted(own, s + n - ANCHOR_SPAN, side="right")
                      - np.searchsorted(own, s + ANCHOR_CLEAR, side="left"))
            if k >= PART_SHARE * within:
                return True
        return False
