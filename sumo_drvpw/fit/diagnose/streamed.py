"""The residual tracer's block model on streamed samples: statistics from passes over batches.

:class:`StreamModel` is :class:`~sumo_drvpw.fit.diagnose.blocks.BlockModel` without
per-sample arrays: the per-block sufficient statistics (ZᵀZ, Zᵀy, yᵀy per block, the
candidates' cross products) and everything reported of a held-out prediction (metrics,
per-trip SSE and energies, energy shares) are sums over samples, gathered in passes over
the prepared batches of :mod:`sumo_drvpw.fit.diagnose.source`. The search, the test and
the fits are the in-memory model's own code on these statistics.

Memory: the batches (in memory up to a budget, else on disk) plus O(blocks × columns²)
per-block statistics — blocks of ``block_s`` seconds, so 1/480 of the rows at 8 Hz and
60-s blocks — plus one batch's arrays in a pass.
"""

from __future__ import annotations

import math

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.diagnose.blocks import BlockModel, ModelColumn
from sumo_drvpw.fit.diagnose.candidates import Candidate
from sumo_drvpw.fit.diagnose.options import DiagnoseOptions
from sumo_drvpw.fit.diagnose.source import View, cand_values, first_appearance

#: bytes of candidate block statistics kept between rounds (beyond: recomputed per round)
CACHE_BYTES = 400e6
#: measured power at and above which a sample is "heavy" (as fit.compare)
from sumo_drvpw.fit.compare import HEAVY_LOAD_W, MIN_SAMPLES  # noqa: E402


def _rs(m, starts):
    return np.add.reduceat(m, starts, axis=0)


class _Moments:
    """Count, mean and centred sum of squares, merged batch by batch (Chan et al. 1979)."""

    def __init__(self):
        self.n, self.mean, self.m2 = 0, 0.0, 0.0

    def add(self, x: np.ndarray) -> None:
        nb = len(x)
        if nb == 0:
            return
        mb = float(x.mean())
        m2b = float(((x - mb) ** 2).sum())
        n = self.n + nb
        d = mb - self.mean
        self.m2 += m2b + d * d * self.n * nb / n
        self.mean += d * nb / n
        self.n = n


class _MetricSums:
    """What :func:`sumo_drvpw.fit.compare.metrics` reports, from sums over batches."""

    def __init__(self):
        self.parts = {k: {"n": 0, "se": 0.0, "sa": 0.0, "s": 0.0, "meas": _Moments()}
                      for k in ("all", "light", "heavy")}

    def add(self, pred, meas):
        ok = np.isfinite(pred) & np.isfinite(meas)
        pred, meas = pred[ok], meas[ok]
        err = pred - meas
        heavy = meas >= HEAVY_LOAD_W
        for k, sel in (("all", slice(None)), ("light", ~heavy), ("heavy", heavy)):
            e, p = err[sel], self.parts[k]
            p["n"] += len(e)
            p["se"] += float(e @ e)
            p["sa"] += float(np.abs(e).sum())
            p["s"] += float(e.sum())
            p["meas"].add(meas[sel])

    def result(self) -> dict:
        def r2(p):
            if p["n"] < MIN_SAMPLES or not p["meas"].m2 > 0:
                return math.nan
            return 1.0 - p["se"] / p["meas"].m2

        a = self.parts["all"]
        n = a["n"]
        return {"n": n, "r2": r2(a), "r2_light": r2(self.parts["light"]), "r2_heavy": r2(self.parts["heavy"]),
                "rmse_w": math.sqrt(a["se"] / n) if n else math.nan,
                "mae_w": a["sa"] / n if n else math.nan, "bias_w": a["s"] / n if n else math.nan}


def _trip_energy_doc(names, e_meas, e_pred) -> dict:
    """The document of :func:`sumo_drvpw.fit.compare.trip_energy` from per-trip sums."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        err = np.where(e_meas != 0.0, e_pred / e_meas - 1.0, np.nan)
    trips = {str(t): {"measured_j": float(em), "predicted_j": float(ep), "error": float(er)}
             for t, em, ep, er in zip(names, e_meas, e_pred, err)}
    fin = np.abs(err[np.isfinite(err)])
    return {"mean_abs_error": float(fin.mean()) if fin.size else math.nan,
            "max_abs_error": float(fin.max()) if fin.size else math.nan, "trips": trips}


class StreamModel(BlockModel):
    """A :class:`BlockModel` whose samples are the views of ``prep`` (see module docstring).

    Parameters
    ----------
    prep : :class:`sumo_drvpw.fit.diagnose.stream_run.Prepared` (batches, declared terms,
        signals, trip names)
    opt : :class:`DiagnoseOptions`
    common : analysis samples restricted to those whose power is finite at every shift
        of the lag search (as the in-memory lag step)
    lag : shift of the measured power [samples] (0: none)
    columns : model columns added in the layout pass (:meth:`add_all`)
    hook : called as hook(view, block starts) for every view of the layout pass
    """

    def __init__(self, prep, opt: DiagnoseOptions, common: bool = False, lag: int = 0,
                 columns: list[Candidate] = (), hook=None):
        self.prep, self.opt, self.common, self.lag = prep, opt, common, lag
        columns = list(columns)
        sums = []      # per view: the sums of add_all for ``columns``, gathered in the layout pass
        self.declared = list(prep.declared)
        self.trip_names = list(prep.trip_names)
        self.n_trips = len(self.trip_names)
        self.signals = {k: None for k in prep.signal_names}
        self.x = None
        self.cols: list[ModelColumn] = []
        self._factor_cache, self.cand_cache = {}, {}
        self.n_scored = 0
        self.passes = 0
        starts, offs, btrip, byy, sizes = [], [], [], [], np.zeros(self.n_trips, np.int64)
        nb = 0
        n, rho, th_min, th_max, first = 0, 0.0, math.inf, -math.inf, []
        for view in self._views(blocks=False):
            tc, t = view.trip, view.t
            nv = view.n
            if nv == 0:
                starts.append(np.zeros(0, np.int64))
                offs.append(nb)
                continue
            tstart = np.r_[True, tc[1:] != tc[:-1]]
            firsti = np.maximum.accumulate(np.where(tstart, np.arange(nv), 0))
            bidx = np.floor((t - t[firsti]) / opt.block_s).astype(np.int64)
            newb = np.r_[True, (tc[1:] != tc[:-1]) | (bidx[1:] != bidx[:-1])]
            st = np.flatnonzero(newb)
            offs.append(nb)
            starts.append(st)
            nb += len(st)
            btrip.append(tc[st])
            byy.append(_rs(view.y * view.y, st))
            sizes += np.bincount(tc, minlength=self.n_trips)
            n += nv
            rho += float(view.x.rho.sum())
            th_min, th_max = min(th_min, float(view.x.theta.min())), max(th_max, float(view.x.theta.max()))
            first.extend(tc[np.r_[True, tc[1:] != tc[:-1]]].tolist())
            if columns:
                sums.append(self._column_sums(view, st, columns))
            if hook is not None:
                hook(view, st)
        self.n = n
        self._starts, self._offs = starts, offs
        self.block_trip = np.concatenate(btrip) if btrip else np.zeros(0, np.int64)
        self.n_blocks = len(self.block_trip)
        self._sizes = sizes
        self.trip_order = first_appearance(first)
        self._rho_mean = rho / n if n else math.nan
        self.theta_ptp = th_max - th_min if n else 0.0
        if n == 0:
            return
        self._assign_folds(sizes)
        raw_yy = np.concatenate(byy)
        self.y_scale = float(np.sqrt(raw_yy.sum() / n)) or 1.0
        self.block_yy = raw_yy / (self.y_scale * self.y_scale)
        if columns:
            self._add_from_sums(columns, *(np.concatenate([s[k] for s in sums]) for k in range(4)))

    # ---- passes
    def _views(self, blocks: bool = True):
        self.passes += 1
        for i, view in enumerate(self.prep.views(self.common, self.lag)):
            if blocks:
                st = self._starts[i]
                if len(st) == 0:
                    continue
                view.extra["starts"] = st
                view.extra["off"] = self._offs[i]
            yield view

    def _raw(self, view: View) -> list:
        """Raw values of the model columns on a view (one array per column)."""
        return [cand_values(view, c.cand, self.declared, c.mass_terms) for c in self.cols]

    def _zmat(self, view: View) -> np.ndarray:
        """Scaled model columns on a view (n × q), as ``BlockModel.scaled``."""
        if not self.cols:
            return np.zeros((view.n, 0))
        return np.column_stack([r / c.scale for r, c in zip(self._raw(view), self.cols)])

    def _block_cross(self, specs, q0s=None):
        """Per-block raw sums of candidate values v: (Σv², [Σv·x_j for j ≥ q0], Σv·y), with
        x_j the model columns' raw values — the in-memory model's sums, block by block."""
        q = len(self.cols)
        m = len(specs)
        q0s = q0s or [0] * m
        vv = np.zeros((self.n_blocks, m))
        vy = np.zeros((self.n_blocks, m))
        vz = [np.zeros((self.n_blocks, q - q0)) for q0 in q0s]
        for view in self._views():
            st, off = view.extra["starts"], view.extra["off"]
            sl = slice(off, off + len(st))
            raw = self._raw(view)
            for i, (cand, mt) in enumerate(specs):
                v = cand_values(view, cand, self.declared, mt)
                vv[sl, i] = _rs(v * v, st)
                vy[sl, i] = _rs(v * view.y, st)
                for j in range(q0s[i], q):
                    vz[i][sl, j - q0s[i]] = _rs(v * raw[j], st)
        return vv, vz, vy

    def _scales(self, q0: int = 0) -> np.ndarray:
        return np.array([c.scale for c in self.cols[q0:]])

    # ---- model
    def mass_part(self):
        """(None, term → coefficient): the per-trip mass composite, by its coefficients."""
        beta = self.full_fit()["beta"] if self.cols else None
        terms = {}
        for c in self.cols:
            if c.cand.scatter or c.cand.kind != "declared":
                continue
            from sumo_drvpw.model.terms import parse_term

            if parse_term(c.cand.term).mg_order >= 1:
                terms[c.cand.term] = float(beta[c.offset]) * self.y_scale / c.scale
        return None, terms

    def add(self, cand: Candidate, values=None, mass_terms=None) -> None:
        if cand.kind == "trip_mass" and mass_terms is None:
            mass_terms = self.mass_part()[1]
        vv, vz, vy = self._block_cross([(cand, mass_terms)])
        scale = float(np.sqrt(vv.sum() / self.n))
        if not scale > 0 or not np.isfinite(scale):
            raise UserError(f"term '{cand.term}' is zero or not finite on the analysis samples")
        self._append(cand, scale, mass_terms, vv[:, 0] / (scale * scale), vz[0] / (scale * self._scales()),
                     vy[:, 0] / (scale * self.y_scale))

    def _column_sums(self, view, st, cands):
        """Block sums of one view for :meth:`add_all`: Σv², Σv·y, Σv·x_j (model columns),
        Σv_i·v_j (j < i) of the raw values v of ``cands``."""
        m, q0 = len(cands), len(self.cols)
        nb = len(st)
        vv, vy = np.zeros((nb, m)), np.zeros((nb, m))
        old, new = np.zeros((nb, m, q0)), np.zeros((nb, m, m))
        raw = self._raw(view)
        vals = [cand_values(view, c, self.declared) for c in cands]
        for i, v in enumerate(vals):
            vv[:, i] = _rs(v * v, st)
            vy[:, i] = _rs(v * view.y, st)
            for j in range(q0):
                old[:, i, j] = _rs(v * raw[j], st)
            for j in range(i):
                new[:, i, j] = _rs(v * vals[j], st)
        return vv, vy, old, new

    def add_all(self, cands: list[Candidate]) -> None:
        """:meth:`add` each of ``cands`` in order, all in one pass (the same sums: the
        products x_i·x_j of the raw values per block, scaled afterwards)."""
        if not cands:
            return
        sums = [self._column_sums(view, view.extra["starts"], cands) for view in self._views()]
        self._add_from_sums(cands, *(np.concatenate([s[k] for s in sums]) for k in range(4)))

    def _add_from_sums(self, cands, vv, vy, old, new) -> None:
        for i, cand in enumerate(cands):
            scale = float(np.sqrt(vv[:, i].sum() / self.n))
            if not scale > 0 or not np.isfinite(scale):
                raise UserError(f"term '{cand.term}' is zero or not finite on the analysis samples")
            raw_cross = np.concatenate([old[:, i, :], new[:, i, :i]], axis=1)
            self._append(cand, scale, None, vv[:, i] / (scale * scale),
                         raw_cross / (scale * self._scales()), vy[:, i] / (scale * self.y_scale))

    def _append(self, cand, scale, mass_terms, zz_new, cross, hz_new) -> None:
        col = ModelColumn(cand, None, scale, offset=self.n_coef, mass_terms=dict(mass_terms or {}))
        q = len(self.cols)
        if q == 0:
            self.block_zz = zz_new[:, None, None].copy()
            self.block_zy = hz_new[:, None].copy()
        else:
            G = np.empty((self.n_blocks, q + 1, q + 1))
            G[:, :q, :q] = self.block_zz
            G[:, :q, q] = cross
            G[:, q, :q] = cross
            G[:, q, q] = zz_new
            self.block_zz = G
            self.block_zy = np.column_stack([self.block_zy, hz_new])
        self.cols.append(col)
        self._full = None

    def prefetch(self, cands: list[Candidate]) -> None:
        """Block statistics of many candidates in one pass (as far as the cache allows)."""
        q = len(self.cols)
        todo = [c for c in cands if c.kind != "trip_mass"
                and not (c.term in self.cand_cache and self.cand_cache[c.term][0].shape[1] == q)]
        per = self.n_blocks * (q + 2) * 8
        room = max(int(CACHE_BYTES // max(per, 1)) - len(self.cand_cache), 0)
        todo = todo[:room]
        if todo:
            self._fill(todo)

    def _fill(self, cands):
        q = len(self.cols)
        q0s = []
        for c in cands:
            cached = self.cand_cache.get(c.term)
            q0s.append(cached[0].shape[1] if cached is not None and np.isfinite(cached[3]) else 0)
        vv, vz, vy = self._block_cross([(c, None) for c in cands], q0s)
        for i, c in enumerate(cands):
            cached = self.cand_cache.get(c.term) if q0s[i] else None
            if cached is not None:
                s = cached[3]
                cz = np.concatenate([cached[0], vz[i] / (s * self._scales(q0s[i]))], axis=1)
                self.cand_cache[c.term] = (cz, cached[1], cached[2], s)
                continue
            s = float(np.sqrt(vv[:, i].sum() / self.n))
            if not (s > 0 and np.isfinite(s)):
                self.cand_cache[c.term] = (np.zeros((self.n_blocks, q)), np.zeros(self.n_blocks),
                                           np.zeros(self.n_blocks), np.nan)
                continue
            self.cand_cache[c.term] = (vz[i] / (s * self._scales()), vv[:, i] / (s * s), vy[:, i] / (s * self.y_scale), s)

    def cand_stats(self, cands: list[Candidate], vals=None):
        m, q = len(cands), len(self.cols)
        cand_z = np.empty((self.n_blocks, m, q))
        cand_zz = np.empty((self.n_blocks, m))
        cand_zy = np.empty((self.n_blocks, m))
        scales = np.empty(m)
        missing = [c for c in cands if c.kind != "trip_mass"
                   and not (c.term in self.cand_cache and self.cand_cache[c.term][0].shape[1] == q)]
        if missing:
            self._fill(missing)
        for i, cd in enumerate(cands):
            if cd.kind == "trip_mass":
                mt = self.mass_part()[1]
                vv, vz, vy = self._block_cross([(cd, mt)])
                s = float(np.sqrt(vv.sum() / self.n))
                if not (s > 0 and np.isfinite(s)):
                    cand_z[:, i], cand_zz[:, i], cand_zy[:, i], scales[i] = 0.0, 0.0, 0.0, np.nan
                    continue
                cand_z[:, i], cand_zz[:, i], cand_zy[:, i], scales[i] = (
                    vz[0] / (s * self._scales()), vv[:, 0] / (s * s), vy[:, 0] / (s * self.y_scale), s)
                continue
            cz, czz, czy, s = self.cand_cache[cd.term]
            if np.isfinite(s):
                cand_z[:, i], cand_zz[:, i], cand_zy[:, i] = cz, czz, czy
            else:
                cand_z[:, i], cand_zz[:, i], cand_zy[:, i] = 0.0, 0.0, 0.0
            scales[i] = s
        # keep the cache within its budget
        size = sum(v[0].nbytes + 16 * self.n_blocks for v in self.cand_cache.values())
        if size > CACHE_BYTES:
            for c in cands:
                self.cand_cache.pop(c.term, None)
        return cand_z, cand_zz, cand_zy, scales

    def _spanned_stats(self, cands, names, groups):
        q = len(self.cols)
        g = np.zeros((len(names), len(names))) if len(names) > 1 else None
        a = np.zeros((q, q))
        grams = {key: (np.zeros((len(ks), len(ks))), np.zeros((q, len(ks)))) for key, ks in groups.items()}
        for view in self._views():
            if g is not None:
                s = np.column_stack([np.asarray(view.signals[k], float) for k in names])
                g += s.T @ s
            z = self._zmat(view)
            a += z.T @ z
            for key, ks in groups.items():
                vals = np.column_stack([cand_values(view, cands[k], self.declared) for k in ks])
                cc, cm = grams[key]
                cc += vals.T @ vals
                cm += z.T @ vals
        return g, a, grams

    # ---- what is reported
    def _coef_per_sample(self, bz, view):
        blk = view.extra["off"] + np.repeat(np.arange(len(view.extra["starts"])),
                                            np.diff(np.r_[view.extra["starts"], view.n]))
        return bz[blk]

    def evaluate(self, fold) -> dict:
        _, bz = self.heldout_model(fold)
        ms = _MetricSums()
        k = self.n_trips
        sse, em, ep, nm, npred = (np.zeros(k) for _ in range(5))
        for view in self._views():
            z = self._zmat(view)
            coef = self._coef_per_sample(bz, view)
            pred = np.zeros(view.n)
            for j in range(z.shape[1]):
                pred += coef[:, j] * z[:, j]
            pred = pred * self.y_scale
            y, dt, tc = view.y, view.dt, view.trip
            ms.add(pred, y)
            sse += np.bincount(tc, weights=(pred - y) ** 2, minlength=k)
            ok = np.isfinite(pred) & np.isfinite(y)
            ep += np.bincount(tc, weights=np.where(ok & (pred > 0), pred, 0.0) * dt, minlength=k)
            em += np.bincount(tc, weights=np.where(ok & (y > 0), y, 0.0) * dt, minlength=k)
            npred += np.bincount(tc, weights=np.where(ok, pred, 0.0) * dt, minlength=k)
            nm += np.bincount(tc, weights=np.where(ok, y, 0.0) * dt, minlength=k)
        order = np.asarray(self.trip_order, dtype=np.int64)
        names = [self.trip_names[i] for i in order]
        return {"pred": None, "metrics": ms.result(), "trip_sse": sse,
                "trip_energy": _trip_energy_doc(names, em[order], ep[order]),
                "trip_net_energy": _trip_energy_doc(names, nm[order], npred[order])}

    def energy_shares(self) -> np.ndarray:
        beta = self.full_fit()["beta"]
        q = len(self.cols)
        acc, e_tot = np.zeros(q), 0.0
        for view in self._views():
            z = self._zmat(view)
            powers = np.empty((view.n, q))
            for j, c in enumerate(self.cols):
                coef = beta[c.offset + view.trip] if c.cand.scatter else beta[c.offset]
                powers[:, j] = coef * z[:, j] * self.y_scale
            total = powers.sum(axis=1)
            wgt = np.where(total > 0, view.dt, 0.0)
            acc += powers.T @ wgt
            e_tot += float(total @ wgt)
        return acc / e_tot if e_tot > 0 else np.full(q, np.nan)

    def trip_counts(self) -> np.ndarray:
        return self._sizes

    def mean_rho(self) -> float:
        return self._rho_mean

    def values(self, cand):  # pragma: no cover - the streamed model has no per-sample arrays
        raise NotImplementedError("the streamed block model keeps no per-sample values")

    def heldout_pred(self, fold):  # pragma: no cover
        raise NotImplementedError("the streamed block model keeps no per-sample predictions")
