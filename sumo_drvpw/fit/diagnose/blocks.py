"""The per-block sufficient-statistics engine of the residual tracer (fits, held-out SSE)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.diagnose.candidates import Candidate
from sumo_drvpw.fit.diagnose.options import DiagnoseOptions
from sumo_drvpw.model.terms import Inputs, parse_term


@dataclass
class ModelColumn:
    """A column of the model: values on analysis samples, scale, per-trip or not."""

    cand: Candidate
    values: np.ndarray
    scale: float
    offset: int = 0          # first position in the full coefficient vector
    mass_terms: dict = field(default_factory=dict)  # per-trip mass: term → coefficient at build


def _block_sums(m: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Sum rows of ``m`` (n × …) within contiguous blocks starting at ``starts``."""
    return np.add.reduceat(m, starts, axis=0)


class BlockModel:
    """Model state and candidate scoring on per-block sufficient statistics.

    The analysis samples are cut into contiguous blocks within trips; every model column
    is kept scaled to unit RMS (``scaled(j)``), and for each block b the engine holds
    ``block_zz[b]`` = Z_bᵀZ_b, ``block_zy[b]`` = Z_bᵀy_b and ``block_yy[b]`` = y_bᵀy_b
    (y scaled by ``y_scale``). A fit on any set of folds is then a sum of these and one
    small solve; a candidate needs one pass over the samples for its cross products with
    the model columns (``cand_z``), itself (``cand_zz``) and y (``cand_zy``).
    """

    def __init__(self, x: Inputs, y: np.ndarray, dt: np.ndarray, t: np.ndarray,
                 trip_codes: np.ndarray, trip_names, signals: dict, opt: DiagnoseOptions):
        self.x, self.y, self.dt, self.opt = x, y, dt, opt
        self.n = len(y)
        self.trip = trip_codes
        self.trip_names = list(trip_names)
        self.n_trips = len(self.trip_names)
        self.signals = signals
        # blocks: contiguous runs of block_s seconds within a trip
        t0 = np.zeros(self.n)
        tstart = np.r_[True, trip_codes[1:] != trip_codes[:-1]]
        first = np.maximum.accumulate(np.where(tstart, np.arange(self.n), 0))
        t0 = t - t[first]
        bidx = np.floor(t0 / opt.block_s).astype(np.int64)
        newb = np.r_[True, (trip_codes[1:] != trip_codes[:-1]) | (bidx[1:] != bidx[:-1])]
        self.starts = np.flatnonzero(newb)
        self.n_blocks = len(self.starts)
        self.block_of = np.cumsum(newb) - 1
        self.block_trip = trip_codes[self.starts]
        self.block_n = np.diff(np.r_[self.starts, self.n])
        self._assign_folds(np.bincount(trip_codes, minlength=self.n_trips))
        # sums of raw products per block, scaled afterwards: the streamed model adds the
        # same block sums batch by batch, so both give the same numbers
        raw_yy = _block_sums(y * y, self.starts)
        self.y_scale = float(np.sqrt(raw_yy.sum() / self.n)) or 1.0
        self.ys = y / self.y_scale
        self.block_yy = raw_yy / (self.y_scale * self.y_scale)
        self.cols: list[ModelColumn] = []
        self._factor_cache: dict = {}
        self.cand_cache: dict = {}   # term → (cand_z list per model column, cand_zz, cand_zy)
        self.n_scored = 0

    def _assign_folds(self, sizes: np.ndarray) -> None:
        """Block folds (interleaved within each trip) and, with ≥ 3 trips, trip folds
        balanced by samples (``sizes``: analysis samples per trip code); needs
        ``block_trip``, ``n_blocks``, ``n_trips`` and ``opt``."""
        opt = self.opt
        # block folds: interleaved within each trip
        k_b = opt.folds
        rank = np.zeros(self.n_blocks, dtype=np.int64)
        bstart = np.r_[True, self.block_trip[1:] != self.block_trip[:-1]]
        firstb = np.maximum.accumulate(np.where(bstart, np.arange(self.n_blocks), 0))
        rank = np.arange(self.n_blocks) - firstb
        self.fold_blocks = (rank % k_b).astype(np.int64)
        if len(np.unique(self.fold_blocks)) < 2:  # every block in one fold: none to train on
            raise UserError(f"no trip's usable samples span more than one block of {opt.block_s:g} s "
                            f"({self.n_blocks} block(s) in all): too short to hold any part out (held-out "
                            "validation needs a trip of ≥ 2 blocks: a longer log, or a shorter block length)")
        n_trips_present = int((sizes > 0).sum())
        if opt.validation == "trip" and n_trips_present < 3:
            raise UserError(f"validation by trip needs ≥ 3 trips, the data hold {n_trips_present}")
        self.by_trip = opt.validation == "trip" or (opt.validation == "auto" and n_trips_present >= 3)
        if self.by_trip:
            k_t = min(opt.folds, n_trips_present)
            order = np.argsort(-sizes, kind="stable")
            load = np.zeros(k_t)
            tfold = np.zeros(self.n_trips, dtype=np.int64)
            for tr in order:
                if sizes[tr] == 0:
                    continue
                f = int(np.argmin(load))
                tfold[tr] = f
                load[f] += sizes[tr]
            self.fold_trips = tfold[self.block_trip]
            self.validation = (f"{k_t}-fold cross-validation over whole trips ({n_trips_present} trips, "
                               f"balanced by samples); per-trip effects (and every candidate once one is in the "
                               f"model) on {k_b}-fold interleaved contiguous {opt.block_s:g}-s blocks within trips; "
                               f"test unit: held-out {opt.block_s:g}-s block")
        else:
            self.fold_trips = None
            self.validation = (f"{k_b}-fold cross-validation over contiguous {opt.block_s:g}-s blocks within trips "
                               f"(block j of a trip in fold j mod {k_b}; {n_trips_present} trip(s)); "
                               f"test unit: held-out block")

    # ---- values
    def factor(self, f: str) -> np.ndarray:
        if f not in self._factor_cache:
            if f.startswith("[") and f.endswith("]^2"):
                s = self.signals[f[1:-3]]
                val = s * s
            elif f.startswith("["):
                val = self.signals[f[1:-1]]
            else:
                val = parse_term(f).evaluate(self.x)
            self._factor_cache[f] = np.asarray(val, dtype=float)
        return self._factor_cache[f]

    def values(self, cand: Candidate) -> np.ndarray:
        if cand.kind == "trip_offset":
            return np.ones(self.n)
        if cand.kind == "trip_mass":
            return self.mass_part()[0]
        if cand.kind in ("signal", "signal_sq") and "*v^" not in cand.term:
            return self.factor(cand.term)
        parts = cand.term.split("*", 1) if cand.kind != "speed" else [cand.term]
        val = self.factor(parts[0])
        for p in parts[1:]:
            val = val * self.factor(p)
        return val

    def mass_part(self):
        """Σ c·term over the model's dense terms that carry mass, with full-data coefficients."""
        beta = self.full_fit()["beta"] if self.cols else None
        out = np.zeros(self.n)
        terms = {}
        for c in self.cols:
            if c.cand.scatter or c.cand.kind != "declared":
                continue
            if parse_term(c.cand.term).mg_order >= 1:
                coef = float(beta[c.offset]) * self.y_scale / c.scale
                terms[c.cand.term] = coef
                out += coef * c.values
        return out, terms

    # ---- model
    def widths(self):
        return [self.n_trips if c.cand.scatter else 1 for c in self.cols]

    @property
    def n_coef(self):
        return int(sum(self.widths()))

    def coef_index(self) -> np.ndarray:
        """Full coefficient index of each compact column, per block (B × q)."""
        q = len(self.cols)
        out = np.empty((self.n_blocks, q), dtype=np.int64)
        for j, c in enumerate(self.cols):
            out[:, j] = c.offset + (self.block_trip if c.cand.scatter else 0)
        return out

    def add(self, cand: Candidate, values: np.ndarray | None = None, mass_terms=None) -> None:
        vals = self.values(cand) if values is None else values
        vv = _block_sums(vals * vals, self.starts)
        scale = float(np.sqrt(vv.sum() / self.n))
        if not scale > 0 or not np.isfinite(scale):
            raise UserError(f"term '{cand.term}' is zero or not finite on the analysis samples")
        col = ModelColumn(cand, vals, scale, offset=self.n_coef, mass_terms=dict(mass_terms or {}))
        # stats of the new column against existing ones and itself
        q = len(self.cols)
        new_cross = np.empty((self.n_blocks, q + 1))
        for j, c in enumerate(self.cols):
            new_cross[:, j] = _block_sums(vals * c.values, self.starts) / (scale * c.scale)
        new_cross[:, q] = vv / (scale * scale)
        hz_new = _block_sums(vals * self.y, self.starts) / (scale * self.y_scale)
        if q == 0:
            self.block_zz = new_cross[:, :, None].copy()
            self.block_zy = hz_new[:, None].copy()
        else:
            G = np.empty((self.n_blocks, q + 1, q + 1))
            G[:, :q, :q] = self.block_zz
            G[:, :q, q] = new_cross[:, :q]
            G[:, q, :q] = new_cross[:, :q]
            G[:, q, q] = new_cross[:, q]
            self.block_zz = G
            self.block_zy = np.column_stack([self.block_zy, hz_new])
        self.cols.append(col)
        self._full = None

    def drop_last(self) -> None:
        """Remove the last model column (a finding that did not replicate)."""
        self.cols.pop()
        q = len(self.cols)
        self.block_zz = self.block_zz[:, :q, :q].copy()
        self.block_zy = self.block_zy[:, :q].copy()
        self._full = None

    def replace_last(self, values: np.ndarray, mass_terms: dict) -> None:
        """Replace the values of the last model column (per-trip mass refinement)."""
        last = self.cols.pop()
        q = len(self.cols)
        self.block_zz = self.block_zz[:, :q, :q].copy()
        self.block_zy = self.block_zy[:, :q].copy()
        self.add(last.cand, values, mass_terms)

    def scaled(self, j):
        c = self.cols[j]
        return c.values / c.scale

    def fold_of(self, scatter_scoring: bool) -> np.ndarray:
        if self.fold_trips is None or scatter_scoring or any(c.cand.scatter for c in self.cols):
            return self.fold_blocks
        return self.fold_trips

    def _model_fold_stats(self, fold):
        K = int(fold.max()) + 1
        P = self.n_coef
        idx = self.coef_index()
        A = np.zeros((K, P, P))
        b = np.zeros((K, P))
        np.add.at(A, (fold[:, None, None], idx[:, :, None], idx[:, None, :]), self.block_zz)
        np.add.at(b, (fold[:, None], idx), self.block_zy)
        return A, b, idx

    @staticmethod
    def _solve(A, b):
        d = np.einsum("...ii->...i", A)
        lam = 1e-9 * np.maximum(d.mean(axis=-1, keepdims=True), 1e-300)
        A = A.copy()
        A[..., np.arange(A.shape[-1]), np.arange(A.shape[-1])] += lam
        try:
            return np.linalg.solve(A, b[..., None])[..., 0]
        except np.linalg.LinAlgError:
            return np.einsum("...ij,...j->...i", np.linalg.pinv(A), b)

    def heldout_model(self, fold):
        """Per-block held-out SSE (scaled units) of the current model, and per-block β."""
        A, b, idx = self._model_fold_stats(fold)
        At, bt = A.sum(0) - A, b.sum(0) - b
        beta = self._solve(At, bt)                      # K × P
        bz = np.take_along_axis(beta[fold], idx, axis=1)  # B × q
        sse = (self.block_yy - 2 * np.einsum("bq,bq->b", bz, self.block_zy)
               + np.einsum("bi,bij,bj->b", bz, self.block_zz, bz))
        return np.maximum(sse, 0.0), bz

    def prefetch(self, cands: list[Candidate]) -> None:
        """Gather the block statistics of many candidates at once (streamed model; here a no-op)."""

    def cand_stats(self, cands: list[Candidate], vals: np.ndarray | None = None):
        """Block stats of candidate columns: cand_z (B × m × q), cand_zz (B × m), cand_zy (B × m), scales."""
        m = len(cands)
        q = len(self.cols)
        cand_z = np.empty((self.n_blocks, m, q))
        cand_zz = np.empty((self.n_blocks, m))
        cand_zy = np.empty((self.n_blocks, m))
        scales = np.empty(m)
        need_vals = [cd for cd in cands]
        for i, cd in enumerate(need_vals):
            cached = self.cand_cache.get(cd.term) if cd.kind != "trip_mass" else None
            if cached is not None and cached[0].shape[1] == q:
                cand_z[:, i], cand_zz[:, i], cand_zy[:, i], scales[i] = cached
                continue
            v = self.values(cd) if vals is None else vals[:, i]
            vv = _block_sums(v * v, self.starts)
            s = float(np.sqrt(vv.sum() / self.n))
            if not (s > 0 and np.isfinite(s)):
                s = np.nan
                cand_z[:, i], cand_zz[:, i], cand_zy[:, i], scales[i] = 0.0, 0.0, 0.0, s
                continue
            q0 = 0
            if cached is not None and np.isfinite(cached[3]):
                q0 = cached[0].shape[1]
                cand_z[:, i, :q0] = cached[0]
            for j in range(q0, q):
                c = self.cols[j]
                cand_z[:, i, j] = _block_sums(v * c.values, self.starts) / (s * c.scale)
            if cached is not None:
                cand_zz[:, i], cand_zy[:, i] = cached[1], cached[2]
            else:
                cand_zz[:, i] = vv / (s * s)
                cand_zy[:, i] = _block_sums(v * self.y, self.starts) / (s * self.y_scale)
            scales[i] = s
            if cd.kind != "trip_mass":
                self.cand_cache[cd.term] = (cand_z[:, i].copy(), cand_zz[:, i].copy(), cand_zy[:, i].copy(), s)
        return cand_z, cand_zz, cand_zy, scales

    def score(self, cands: list[Candidate], scatter: bool, fold: np.ndarray):
        """Held-out per-block SSE of model + each candidate (B × m), valid mask (m)."""
        cand_z, cand_zz, cand_zy, scales = self.cand_stats(cands)
        m = len(cands)
        P = self.n_coef
        w = self.n_trips if scatter else 1
        D = P + w
        K = int(fold.max()) + 1
        Am, bm, idx = self._model_fold_stats(fold)
        A = np.zeros((K, m, D, D))
        b = np.zeros((K, m, D))
        A[:, :, :P, :P] = Am[:, None]
        b[:, :, :P] = bm[:, None]
        cpos = P + (self.block_trip if scatter else np.zeros(self.n_blocks, dtype=np.int64))
        fi = fold[:, None, None]
        mi = np.arange(m)[None, :, None]
        np.add.at(A, (fi, mi, idx[:, None, :], cpos[:, None, None]), cand_z)
        np.add.at(A, (fi, mi, cpos[:, None, None], idx[:, None, :]), cand_z)
        np.add.at(A, (fold[:, None], np.arange(m)[None, :], cpos[:, None], cpos[:, None]), cand_zz)
        np.add.at(b, (fold[:, None], np.arange(m)[None, :], cpos[:, None]), cand_zy)
        Atot, btot = A.sum(0), b.sum(0)
        # spanned check (full data): residual fraction of the candidate after the model
        valid = np.isfinite(scales)
        if P and not scatter:
            sol = self._solve(Atot[:, :P, :P], Atot[:, :P, P])
            resid = Atot[:, P, P] - np.einsum("mp,mp->m", sol, Atot[:, :P, P])
            valid &= resid > 1e-6 * np.maximum(Atot[:, P, P], 1e-300)
        beta = self._solve(Atot[None] - A, btot[None] - b)   # K × m × D
        bb = beta[fold]                                          # B × m × D
        bz = np.take_along_axis(bb, np.broadcast_to(idx[:, None, :], (self.n_blocks, m, idx.shape[1])), axis=2)
        bc = np.take_along_axis(bb, np.broadcast_to(cpos[:, None, None], (self.n_blocks, m, 1)), axis=2)[..., 0]
        sse = (self.block_yy[:, None] - 2 * (np.einsum("bmq,bq->bm", bz, self.block_zy) + bc * cand_zy)
               + np.einsum("bmi,bij,bmj->bm", bz, self.block_zz, bz)
               + 2 * bc * np.einsum("bmq,bmq->bm", bz, cand_z) + bc * bc * cand_zz)
        self.n_scored += int(valid.sum())
        return np.maximum(sse, 0.0), valid

    # ---- fits and predictions
    def full_fit(self) -> dict:
        """OLS on all analysis samples: β (scaled), standard errors (scaled), rss."""
        if getattr(self, "_full", None) is not None:
            return self._full
        P = self.n_coef
        idx = self.coef_index()
        A = np.zeros((P, P))
        b = np.zeros(P)
        np.add.at(A, (idx[:, :, None], idx[:, None, :]), self.block_zz)
        np.add.at(b, idx, self.block_zy)
        beta = self._solve(A, b)
        rss = max(float(self.block_yy.sum() - beta @ b), 0.0)
        dof = max(self.n - P, 1)
        try:
            inv = np.linalg.pinv(A)
            se = np.sqrt(np.maximum(np.diag(inv) * rss / dof, 0.0))
        except np.linalg.LinAlgError:
            se = np.full(P, np.nan)
        self._full = {"beta": beta, "se": se, "rss": rss}
        return self._full

    def heldout_pred(self, fold) -> np.ndarray:
        """Held-out prediction [W] of the current model for every analysis sample."""
        _, bz = self.heldout_model(fold)
        coef = bz[self.block_of]                     # n × q
        pred = np.zeros(self.n)
        for j in range(len(self.cols)):
            pred += coef[:, j] * self.scaled(j)
        return pred * self.y_scale

    def evaluate(self, fold) -> dict:
        """Held-out prediction of the current model and what is reported of it: ``pred``
        [W] per analysis sample, ``metrics`` (:func:`sumo_drvpw.fit.compare.metrics`),
        ``trip_sse`` per trip code [W²], ``trip_energy`` and ``trip_net_energy``."""
        from sumo_drvpw.fit.compare import metrics, trip_energy, trip_net_energy

        pred = self.heldout_pred(fold)
        trips = np.asarray(self.trip_names)[self.trip]
        return {"pred": pred, "metrics": metrics(pred, self.y),
                "trip_sse": np.bincount(self.trip, weights=(pred - self.y) ** 2, minlength=self.n_trips),
                "trip_energy": trip_energy(pred, self.y, self.dt, trips),
                "trip_net_energy": trip_net_energy(pred, self.y, self.dt, trips)}

    def energy_shares(self, centre_last: tuple[str, list[str]] | None = None) -> np.ndarray:
        """Traction energy share of each model column with the full-data fit: Σ P_j·Δt over
        samples with predicted power > 0, over the model's total traction energy [-].
        ``centre_last`` (signal factor, basis factors; ``candidates.signal_split``): the
        last column's share is taken with its signal centred at its mean."""
        powers = np.column_stack([self.column_power(j) for j in range(len(self.cols))])
        total = powers.sum(axis=1)
        wgt = np.where(total > 0, self.dt, 0.0)
        if centre_last is not None:
            sig, basis = centre_last
            base = np.ones(self.n)
            for f in basis:
                base = base * self.factor(f)
            j = len(self.cols) - 1
            # the column's power over its values, times the mean signal's part of them
            coef = float(self.full_fit()["beta"][self.cols[j].offset]) * self.y_scale / self.cols[j].scale
            powers[:, j] -= coef * float(np.mean(self.factor(sig))) * base
        e_tot = float(total @ wgt)
        return powers.T @ wgt / e_tot if e_tot > 0 else np.full(len(self.cols), np.nan)

    def trip_counts(self) -> np.ndarray:
        """Analysis samples per trip code."""
        return np.bincount(self.trip, minlength=self.n_trips)

    def mean_rho(self) -> float:
        """Mean air density over the analysis samples [kg/m³]."""
        return float(np.mean(self.x.rho))

    def column_power(self, j: int) -> np.ndarray:
        """Power [W] of model column j with the full-data fit."""
        f = self.full_fit()
        c = self.cols[j]
        if c.cand.scatter:
            coef = f["beta"][c.offset + self.trip]
        else:
            coef = f["beta"][c.offset]
        return coef * self.scaled(j) * self.y_scale

    def coefficients(self) -> tuple[dict, dict]:
        """Unscaled coefficients and standard errors: term → value (per-trip: trip → value)."""
        f = self.full_fit()
        co, se = {}, {}
        for c in self.cols:
            k = self.y_scale / c.scale
            if c.cand.scatter:
                sl = slice(c.offset, c.offset + self.n_trips)
                present = self.trip_counts() > 0
                co[c.cand.term] = {self.trip_names[i]: float(v) * k
                                   for i, v in enumerate(f["beta"][sl]) if present[i]}
                se[c.cand.term] = {self.trip_names[i]: float(v) * k
                                   for i, v in enumerate(f["se"][sl]) if present[i]}
            else:
                co[c.cand.term] = float(f["beta"][c.offset]) * k
                se[c.cand.term] = float(f["se"][c.offset]) * k
        return co, se

    # ---- duplicate candidates
    def _spanned_stats(self, cands, names, groups):
        """Sums over the analysis samples for :meth:`drop_spanned`: the Gram of the signals
        ``names``, of the model's scaled columns, and per group of candidates (key → (VᵀV,
        ZᵀV)) for groups whose column has no earlier twin."""
        q = len(self.cols)
        g = None
        if len(names) > 1:
            s = np.column_stack([np.asarray(self.signals[k], float) for k in names])
            g = s.T @ s
        zm = np.column_stack([self.scaled(j) for j in range(q)]) if q else np.zeros((self.n, 0))
        grams = {}
        for key, ks in groups.items():
            vals = np.column_stack([self.values(cands[k]) for k in ks])
            grams[key] = (vals.T @ vals, zm.T @ vals)
        return g, zm.T @ zm, grams

    def drop_spanned(self, cands: list[Candidate], tol: float = 1e-10) -> tuple[list, list[dict]]:
        """Drop candidates identical to, or numerically spanned by, earlier ones (issue #9 §1).

        In candidate order (the first wins): a column whose values are proportional to an
        earlier column's is dropped with all its forms; within the forms of one column (and
        among the speed functions) a candidate is dropped when, after projection on the
        current model's columns, it is left with a share < ``tol`` of its sum of squares
        (spanned by the model) or is proportional to an earlier candidate's remainder
        (1 − r² < ``tol``: adding either gives the same fit). Per-trip candidates are kept.
        Returns (kept candidates, dropped records ``{"term", "reason"}``).
        """
        dropped: list[dict] = []
        groups: dict[str, list[int]] = {}
        for k, c in enumerate(cands):
            if c.scatter:
                continue
            groups.setdefault(c.signals[0] if c.signals else "", []).append(k)
        names = list(self.signals)
        g, a, grams = self._spanned_stats(cands, names, groups)
        # 1. columns proportional to an earlier column (s × s Gram)
        twin: dict[str, str] = {}
        if len(names) > 1:
            d = np.sqrt(np.maximum(np.diag(g), 1e-300))
            cos = g / np.outer(d, d)
            for j in range(1, len(names)):
                for i in range(j):
                    if names[i] not in twin and 1.0 - cos[i, j] ** 2 < tol:
                        twin[names[j]] = names[i]
                        break
        # 2. within each column's forms and among the speed functions
        drop = {}
        q = len(self.cols)
        for key, ks in groups.items():
            if key in twin:
                for k in ks:
                    drop[k] = f"identical to the forms of column '{twin[key]}' (proportional values)"
                continue
            cc, cm = grams[key]
            sol = np.linalg.lstsq(a, cm, rcond=None)[0] if q else np.zeros((0, len(ks)))
            r = cc - cm.T @ sol                       # Gram of the remainders after the model
            kept: list[int] = []
            for jj, k in enumerate(ks):
                if not cc[jj, jj] > 0:
                    drop[k] = "zero on these data"
                    continue
                if r[jj, jj] < tol * cc[jj, jj]:
                    drop[k] = "spanned by the model's terms on these data"
                    continue
                hit = next((ii for ii in kept
                            if 1.0 - r[ii, jj] ** 2 / (r[ii, ii] * r[jj, jj]) < tol), None)
                if hit is not None:
                    drop[k] = f"identical to {cands[ks[hit]].term} (given the model's terms) on these data"
                    continue
                kept.append(jj)
        out = []
        for k, c in enumerate(cands):
            if k in drop:
                dropped.append({"term": c.term, "reason": drop[k]})
            else:
                out.append(c)
        return out, dropped
