"""The chain tracer's held-out blocks: layout, folds, per-block statistics and the held-out step.

Shared by the in-memory tracer (:func:`sumo_drvpw.fit.chain_linear.trace_chain`, all
samples at once) and the streamed one (:mod:`sumo_drvpw.fit.chain_trace_stream`, batches
of whole trips): blocks never cross a trip, so a batch's blocks and their statistics are
the whole log's, and everything the search reads — each block's weighted ZᵀZ, Zᵀt, tᵀt
and energies, the folds' sums of them — is the same computed either way.
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.errors import UserError


def block_starts(trip, t, block_s: float) -> np.ndarray:
    """First sample of each block: ``block_s`` seconds from its trip's first sample
    (``trip``: integer code per sample, trips contiguous; ``t`` [s])."""
    trip = np.asarray(trip)
    codes, first = np.unique(trip, return_index=True)
    t0 = np.asarray(t)[first][np.searchsorted(codes, trip)]
    key = trip.astype(np.int64) * 10**7 + np.floor((np.asarray(t) - t0) / block_s).astype(np.int64)
    return np.r_[0, np.flatnonzero(np.diff(key) != 0) + 1]


def assign_folds(block_trip: np.ndarray, opt) -> tuple[np.ndarray, str]:
    """Fold of each block and how they were made (``opt``: validation, folds, block_s):
    whole trips with ≥ 3 (leave-one-trip-out up to 10, else ``folds`` groups, trips in the
    order of their codes), else blocks interleaved within trips."""
    present = np.unique(block_trip)
    n_trips = int(block_trip.max()) + 1
    if opt.validation == "trip" and present.size < 3:
        raise UserError(f"diagnose option validation 'trip' needs ≥ 3 trips, got {present.size}")
    if present.size >= 3 and opt.validation != "blocks":
        k = present.size if present.size <= 10 else opt.folds
        fmap = np.zeros(n_trips, np.int64)
        fmap[present] = np.arange(present.size) % k
        return fmap[block_trip], (f"{'leave-one-trip-out' if k == present.size else f'{k}-fold over whole trips'} "
                                  f"({present.size} trips)")
    j = np.zeros(block_trip.size, np.int64)
    for tr in present:  # block number within its trip
        b = np.flatnonzero(block_trip == tr)
        j[b] = np.arange(b.size)
    return j % opt.folds, f"{opt.folds}-fold interleaved {opt.block_s:g}-s blocks within trips"


def block_stats(w, starts, Z, t):
    """Per-block weighted ZᵀZ (B×q×q), Zᵀt (B×q), tᵀt (B), Σ w·Z (B×q) and Σ w·t (B)."""
    sums = lambda x: np.add.reduceat(x, starts, axis=0)  # noqa: E731
    nb, q = starts.size, Z.shape[1]
    zz = np.empty((nb, q, q))
    for i in range(q):  # column pairs: memory O(n), not O(n·q²)
        wz = w * Z[:, i]
        for j in range(i, q):
            zz[:, i, j] = zz[:, j, i] = sums(wz * Z[:, j])
    return zz, sums(w[:, None] * Z * t[:, None]), sums(w * t * t), sums(w[:, None] * Z), sums(w * t)


class Blocks:
    """The held-out blocks of the samples (``trip`` codes, ``t`` [s], weights ``w`` [s]) and
    their folds; ``block_trip`` given instead of samples for the streamed tracer, whose
    blocks come batch by batch."""

    def __init__(self, r, w, trip, t, opt, block_trip=None):
        self.r, self.w, self.block_s = r, w, opt.block_s
        if block_trip is None:
            self.starts = block_starts(trip, t, opt.block_s)
            block_trip = np.asarray(trip)[self.starts]
        self.block_trip = block_trip
        self.n_blocks = block_trip.size
        self.fold, self.how = assign_folds(block_trip, opt)
        self.K = int(self.fold.max()) + 1

    def sample_fold(self, n):
        return np.repeat(self.fold, np.diff(np.r_[self.starts, n]))

    def stats(self, Z, t):
        """Per-block statistics of the samples (:func:`block_stats`)."""
        return block_stats(self.w, self.starts, Z, t)

    def fold_sums(self, a):
        """Per-fold sums (K × …) of per-block values."""
        out = np.zeros((self.K,) + a.shape[1:])
        np.add.at(out, self.fold, a)
        return out

    def fold_beta(self, zz, zt):
        """OLS coefficients fitted without each fold (K×q)."""
        q = zz.shape[1]
        if q == 0:
            return np.zeros((self.K, 0))
        A, b = self.fold_sums(zz), self.fold_sums(zt)
        At, bt = A.sum(0) - A, b.sum(0) - b
        At = At + 1e-12 * np.eye(q) * np.maximum(np.einsum("kii->k", At), 1e-300)[:, None, None]
        return np.linalg.solve(At, bt[..., None])[..., 0]

    @staticmethod
    def sse(zz, zt, tt, beta):
        """SSE of every block under coefficients ``beta`` (B×q, one row per block)."""
        return tt - 2 * np.einsum("bq,bq->b", beta, zt) + np.einsum("bi,bij,bj->b", beta, zz, beta)


def heldout_from_stats(bl: Blocks, variants):
    """Held-out block SSE and block energy error, the profiled variant chosen per fold on
    its training blocks. ``variants``: per variant of a fixed column the :func:`block_stats`
    of (Z, t). Returns (per-block SSE [W²·s], per-block energy error [J], per-fold variant
    index, per-fold β)."""
    best = None
    for vi, (zz, zt, tt, ez, et) in enumerate(variants):
        beta = bl.fold_beta(zz, zt)                       # K × q
        all_sse = np.stack([bl.sse(zz, zt, tt, np.broadcast_to(beta[k], (bl.n_blocks, beta.shape[1])))
                            for k in range(bl.K)])        # K × B
        train = np.array([all_sse[k][bl.fold != k].sum() for k in range(bl.K)])
        held = all_sse[bl.fold, np.arange(bl.n_blocks)]
        e = et - np.einsum("bq,bq->b", ez, beta[bl.fold])
        if best is None:
            best = [train, held.copy(), e.copy(), np.zeros(bl.K, int), beta.copy()]
        else:
            better = train < best[0]
            best[0][better] = train[better]
            sel = better[bl.fold]
            best[1][sel] = held[sel]
            best[2][sel] = e[sel]
            best[3][better] = vi
            best[4][better] = beta[better]
    return np.maximum(best[1], 0.0), best[2], best[3], best[4]


def heldout(bl: Blocks, Z, t_variants):
    """:func:`heldout_from_stats` of t ~ Z on the samples, one target per variant."""
    return heldout_from_stats(bl, [bl.stats(Z, t) for t in t_variants])


def full_fit(w, Z, t):
    """Weighted OLS on all samples: (β, standard errors, weighted RSS)."""
    q = Z.shape[1]
    if q == 0:
        return np.zeros(0), np.zeros(0), float(np.sum(w * t * t))
    sw = np.sqrt(w)
    beta, *_ = np.linalg.lstsq(Z * sw[:, None], t * sw, rcond=None)
    res = t - Z @ beta
    rss = float(np.sum(w * res * res))
    dof = max(len(t) - q, 1)
    A = (Z * w[:, None]).T @ Z
    se = np.sqrt(np.maximum(np.diag(np.linalg.pinv(A)) * rss / dof * len(t) / max(w.sum(), 1e-300), 0.0))
    return beta, se, rss


def fit_from_sums(zz, zt, tt, n: int, sw: float):
    """:func:`full_fit` from the weighted sums ZᵀWZ (q×q), ZᵀWt (q), tᵀWt of ``n`` samples of
    total weight ``sw``: the columns scaled to unit norm before solving (the normal
    equations' conditioning is then the columns' collinearity only)."""
    q = zt.size
    if q == 0:
        return np.zeros(0), np.zeros(0), float(tt)
    s = np.sqrt(np.maximum(np.diag(zz), 1e-300))
    A = zz / np.outer(s, s)
    b = zt / s
    u = np.linalg.lstsq(A, b, rcond=None)[0]
    beta = u / s
    rss = float(max(tt - 2 * beta @ zt + beta @ zz @ beta, 0.0))
    dof = max(n - q, 1)
    se = np.sqrt(np.maximum(np.diag(np.linalg.pinv(zz)) * rss / dof * n / max(sw, 1e-300), 0.0))
    return beta, se, rss
