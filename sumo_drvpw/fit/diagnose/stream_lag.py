"""The streamed tracer's lag search (issue #14) in memory flat in rows.

The in-memory lag step (``search._timing_step``, :func:`structural.timing`) works on
per-block sums Z_bᵀy_ℓ and y_ℓᵀy_ℓ for every shift ℓ. Kept for all blocks and shifts
they grow with the rows (8 Hz, 60-s blocks, 4 declared terms, 27 shifts: 135 numbers,
≈ 1.1 KB per block, ≈ 180 MB at 100 M rows and as much again while a selection of them
is scaled). What the step reads of them is less:

* the lag chosen per fold (and on all data) compares *training* SSEs, i.e. sums over the
  blocks of a fold: per fold Σ Z_bᵀy_ℓ and Σ y_ℓᵀy_ℓ (K × q × L). They are gathered per
  trip (trip folds, and the per-trip lags of the report need them anyway) and per
  block fold (block j of a trip in fold j mod K) in the layout pass;
* the paired block test needs each held-out block's SSE at ℓ = 0 and at its fold's
  chosen lag only: one more pass gathers the per-block sums of those ≤ K + 1 shifts and
  keeps two per block (lag 0, the block's fold's lag).

So the lag search keeps O(trips × q × L + blocks × q) numbers, not O(blocks × q × L).
The results are the in-memory step's: the same sums, added in a different order (to
rounding).
"""

from __future__ import annotations

import math

import numpy as np

from sumo_drvpw.fit.diagnose.result import lag_decision, lag_finding, pick_metrics
from sumo_drvpw.fit.diagnose.structural import block_lag_sums, per_trip_lags_from_stats

#: rows of shifted powers held at once (whole trips)
CHUNK = 65_536


def _chunks(view, st):
    """(a, b, first trip index, last trip index + 1, trip starts, trip ends, block
    positions lo:hi in ``st``) of about ``CHUNK`` rows of whole trips of a view."""
    tc = view.trip
    tb = np.flatnonzero(np.r_[True, tc[1:] != tc[:-1]])
    te = np.r_[tb[1:], view.n]
    lo = 0
    while lo < len(tb):
        hi = lo + 1
        while hi < len(tb) and te[hi] - tb[lo] <= CHUNK:
            hi += 1
        a, b = int(tb[lo]), int(te[hi - 1])
        b0, b1 = np.searchsorted(st, [a, b])
        yield a, b, lo, hi, tb, te, int(b0), int(b1)
        lo = hi


def _shifted(view, a: int, b: int, lags: np.ndarray) -> np.ndarray:
    """Raw power of the rows a:b of a view's common samples read ℓ rows later (n × L)."""
    d = view.extra["batch"]
    rows = d["idx"][d["common"]][a:b]
    return d["yrow"][rows[:, None] + lags[None, :]]


class LagSums:
    """Raw sums of the lag search for the shifts ``lags`` (a hook of the timing model's
    layout pass, or a pass of its own): per trip (n, XᵀX, Xᵀy_ℓ, y_ℓᵀy_ℓ) and per block
    fold (rank of the block within its trip mod ``folds``) Σ Xᵀy_ℓ and Σ y_ℓᵀy_ℓ."""

    def __init__(self, lags: np.ndarray, folds: int):
        self.lags = np.asarray(lags, dtype=np.int64)
        self.folds = folds
        self.fzy = self.fyy = None
        self.trips: dict = {}
        self._last = (-1, -1)          # (trip code, rank) of the last block seen

    def _ranks(self, btrip: np.ndarray) -> np.ndarray:
        """Rank of each block within its trip, carried over from the previous call (as
        ``BlockModel._assign_folds`` over all blocks in order)."""
        n = len(btrip)
        start = np.r_[True, btrip[1:] != btrip[:-1]]
        first = np.maximum.accumulate(np.where(start, np.arange(n), 0))
        rank = np.arange(n) - first
        if n and btrip[0] == self._last[0]:
            rank[first == 0] += self._last[1] + 1
        if n:
            self._last = (int(btrip[-1]), int(rank[-1]))
        return rank

    def __call__(self, view, st) -> None:
        decl = view.decl
        tc = view.trip
        q, L = decl.shape[1], len(self.lags)
        if self.fzy is None:
            self.fzy, self.fyy = np.zeros((self.folds, q, L)), np.zeros((self.folds, L))
        for a, b, lo, hi, tb, te, b0, b1 in _chunks(view, st):
            x = [decl[a:b, j] for j in range(q)]
            ys = _shifted(view, a, b, self.lags)
            sb = st[b0:b1] - a
            zy, yy = block_lag_sums(x, ys, sb)                     # per block, this chunk only
            btrip = tc[st[b0:b1]]
            bf = self._ranks(btrip) % self.folds
            np.add.at(self.fzy, bf, zy)
            np.add.at(self.fyy, bf, yy)
            # per trip: the sums of its blocks (a block lies within one trip)
            first = np.flatnonzero(np.r_[True, btrip[1:] != btrip[:-1]])
            tzy, tyy = np.add.reduceat(zy, first, axis=0), np.add.reduceat(yy, first, axis=0)
            xm = np.column_stack(x)
            for i in range(lo, hi):
                r0, r1 = int(tb[i]) - a, int(te[i]) - a
                t = int(tc[tb[i]])
                s = (r1 - r0, xm[r0:r1].T @ xm[r0:r1], tzy[i - lo], tyy[i - lo])
                old = self.trips.get(t)        # a trip split over two batches: add its parts
                self.trips[t] = s if old is None else tuple(u + v for u, v in zip(old, s))

    def absorb(self, other: "LagSums") -> None:
        """Take in the sums of more shifts (gathered in another pass over the same views)."""
        lags = np.r_[self.lags, other.lags]
        order = np.argsort(lags, kind="stable")
        self.fzy = np.concatenate([self.fzy, other.fzy], axis=2)[:, :, order]
        self.fyy = np.concatenate([self.fyy, other.fyy], axis=1)[:, order]
        self.trips = {t: (n, a, np.concatenate([zy, other.trips[t][2]], axis=1)[:, order],
                          np.r_[yy, other.trips[t][3]][order]) for t, (n, a, zy, yy) in self.trips.items()}
        self.lags = lags[order]

    def fold_sums(self, tr0, lags):
        """Scaled per-fold sums (K × q × L, K × L) for the shifts ``lags`` on the folds of
        ``tr0.fold_of(False)`` (by trip when the model validates by trip)."""
        pos = np.searchsorted(self.lags, lags)
        fold = tr0.fold_of(False)
        k = int(fold.max()) + 1
        if fold is tr0.fold_blocks:
            zy, yy = self.fzy[:k][:, :, pos], self.fyy[:k][:, pos]
        else:
            tfold = np.zeros(tr0.n_trips, np.int64)
            tfold[tr0.block_trip] = fold
            zy = np.zeros((k,) + self.fzy.shape[1:2] + (len(pos),))
            yy = np.zeros((k, len(pos)))
            for t in sorted(self.trips):
                _, _, tzy, tyy = self.trips[t]
                zy[tfold[t]] += tzy[:, pos]
                yy[tfold[t]] += tyy[pos]
        s = np.array([c.scale for c in tr0.cols])
        return zy / (s[None, :, None] * tr0.y_scale), yy / (tr0.y_scale * tr0.y_scale)

    def trip_stats(self, lags) -> dict:
        pos = np.searchsorted(self.lags, lags)
        return {t: (n, a, zy[:, pos], yy[pos]) for t, (n, a, zy, yy) in self.trips.items()}


def _fold_fits(tr0, sums: LagSums, lags):
    """Per shift: the training fit of each fold (β, K × q), its training SSE and the
    all-data SSE (as ``structural.timing_from_blocks``)."""
    fold = tr0.fold_of(False)
    k = int(fold.max()) + 1
    fold_zz = np.zeros((k,) + tr0.block_zz.shape[1:])
    np.add.at(fold_zz, fold, tr0.block_zz)
    train_zz = fold_zz.sum(0)[None] - fold_zz
    fzy_all, fyy_all = sums.fold_sums(tr0, lags)
    betas, train, all_sse = {}, [], []
    for i, lag in enumerate(lags):
        fzy, fyy = fzy_all[:, :, i], fyy_all[:, i]
        tzy, tyy = fzy.sum(0)[None] - fzy, fyy.sum() - fyy
        beta = tr0._solve(train_zz, tzy)
        betas[lag] = beta
        train.append(tyy - np.einsum("kq,kq->k", beta, tzy))
        full = tr0._solve(fold_zz.sum(0), fzy.sum(0))
        all_sse.append(fyy.sum() - float(full @ fzy.sum(0)))
    return betas, np.array(train), all_sse


def _block_sse(tr0, betas: dict, fold_lag: list):
    """One pass: per-block held-out SSE at lag 0 and at the block's fold's lag."""
    fold = tr0.fold_of(False)
    use = np.array(sorted(set(fold_lag) | {0}), dtype=np.int64)
    col = np.searchsorted(use, fold_lag)          # per fold: its column in ``use``
    c0 = int(np.searchsorted(use, 0))
    q, nb = len(tr0.cols), tr0.n_blocks
    zy0, zyc, yy0, yyc = np.zeros((nb, q)), np.zeros((nb, q)), np.zeros(nb), np.zeros(nb)
    for view in tr0._views():
        st, off = view.extra["starts"], view.extra["off"]
        decl = view.decl
        for a, b, *_, b0, b1 in _chunks(view, st):
            zy, yy = block_lag_sums([decl[a:b, j] for j in range(q)], _shifted(view, a, b, use), st[b0:b1] - a)
            g = np.arange(off + b0, off + b1)
            cc = col[fold[g]]
            zy0[g], yy0[g] = zy[:, :, c0], yy[:, c0]
            zyc[g], yyc[g] = zy[np.arange(len(g)), :, cc], yy[np.arange(len(g)), cc]
    s = np.array([c.scale for c in tr0.cols]) * tr0.y_scale
    y2 = tr0.y_scale * tr0.y_scale
    zz = tr0.block_zz

    def sse(zy, yy, b):
        return np.maximum(yy / y2 - 2 * np.einsum("bq,bq->b", b, zy / s)
                          + np.einsum("bi,bij,bj->b", b, zz, b), 0.0)
    bc = np.stack([betas[fold_lag[f]][f] for f in range(len(fold_lag))])
    return sse(zy0, yy0, betas[0][fold]), sse(zyc, yyc, bc[fold])


def timing_streamed(tr0, sums: LagSums, lags, dt_s: float, paired_test, blocks: bool = True) -> dict:
    """:func:`structural.timing_from_blocks` from per-fold sums and one pass for the
    per-block SSEs (``blocks=False``: only the lag chosen on all data, no pass)."""
    lags = sorted(lags)
    betas, train, all_sse = _fold_fits(tr0, sums, lags)
    lag_all = lags[int(np.argmin(all_sse))]
    if not blocks:
        return {"lag_samples": int(lag_all)}
    best_fold = np.argmin(train, axis=0)
    fold_lag = [lags[i] for i in best_fold]
    sse0_b, chosen = _block_sse(tr0, betas, fold_lag)
    d = sse0_b - chosen
    sse0, sse1 = float(sse0_b.sum()), float(chosen.sum())
    gain = 1.0 - math.sqrt(sse1 / sse0) if sse0 > 0 else 0.0
    return {"lag_samples": int(lag_all), "lag_s": lag_all * dt_s,
            "fold_lags_s": [lag * dt_s for lag in fold_lag],
            "p_value": paired_test(d) if lag_all != 0 else 1.0, "rmse_gain": gain, "d": d,
            "rmse_by_lag_s": {f"{lag * dt_s:+.3g}": math.sqrt(max(s, 0.0) / tr0.n) * tr0.y_scale
                              for lag, s in zip(lags, all_sse)}}


def coarse_lags(lags, coarse: int) -> list:
    """The coarse grid of shifts (as ``search._timing_step``)."""
    big = int(lags[-1])
    step = max(1, math.ceil(big / coarse))
    return sorted(set(range(-big, big + 1, step)) | {0})


def timing_step(tr0, sums: LagSums, declared_model, opt, lags, dt_med, say, paired_test, coarse):
    """The lag step of the in-memory tracer (``search._timing_step``) on the streamed
    timing model ``tr0`` whose layout pass gathered ``sums`` for the coarse shifts.
    Returns (finding or None, note, model with the lag applied or None);
    ``declared_model(lag)`` builds the declared model with the power shifted by ``lag``."""
    big = int(lags[-1])
    step = max(1, math.ceil(big / coarse))
    tried = coarse_lags(lags, coarse)
    if step > 1:
        best = timing_streamed(tr0, sums, tried, dt_med, paired_test, blocks=False)["lag_samples"]
        fine = [k for k in range(best - step + 1, best + step) if -big <= k <= big and k not in tried]
        if fine:  # one more pass for the shifts around the best coarse one
            more = LagSums(np.array(sorted(fine), dtype=np.int64), sums.folds)
            for view in tr0._views():
                more(view, view.extra["starts"])
            sums.absorb(more)
        tried = sorted(set(tried) | set(fine))
    res = timing_streamed(tr0, sums, tried, dt_med, paired_test)
    note, accepted = lag_decision(res, per_trip_lags_from_stats(tr0, sums.trip_stats(tried), tried, dt_med),
                                  len(tried), opt, say)
    if not accepted:
        return None, note, None
    fold = tr0.fold_of(False)
    before = tr0.evaluate(fold)
    tr1 = declared_model(res["lag_samples"])
    after = tr1.evaluate(fold)
    finding = lag_finding(res, note["per_trip_lag_s"], pick_metrics(before["metrics"]),
                          pick_metrics(after["metrics"]))
    return finding, note, tr1
