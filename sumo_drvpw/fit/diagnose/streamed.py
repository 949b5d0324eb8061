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
from sumo_drvpw.fit.diagnose.source import View, cand_values, factor, first_appearance

#: bytes of candidate block statistics kept between rounds (beyond: recomputed per round)
CACHE_BYTES = 400e6
#: measured power at and above which a sample is "heavy" (as fit.compare)
from sumo_drvpw.fit.compare import HEAVY_LOAD_W, MIN_SAMPLES  # noqa: E402
from sumo_drvpw.fit.trip_energy import trip_energy_doc  # noqa: E402


def _rs(m, starts):
    return np.add.reduceat(m, starts, axis=0)


def _concat_parts(sums: list) -> list:
    """The per-view tuples of block sums joined component by component; each view's part
    is let go once joined (``sums`` is emptied: not a second copy of all blocks at once)."""
    parts = [list(p) for p in sums]
    sums.clear()
    out = []
    for k in range(len(parts[0]) if parts else 0):
        out.append(np.concatenate([p[k] for p in parts]))
        for p in parts:
            p[k] = None
    return out


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
    columns : model columns added in the layout pass
    hook : called as hook(view, block starts) for every view of the layout pass
    defer : the layout pass is run by the caller (``layout_step`` per view of
        ``prep.views(common, lag)``, then ``layout_end``), e.g. for two models in one pass
    """

    def __init__(self, prep, opt: DiagnoseOptions, common: bool = False, lag: int = 0,
                 columns: list[Candidate] = (), hook=None, defer: bool = False):
        self.prep, self.opt, self.common, self.lag = prep, opt, common, lag
        columns = list(columns)
        self.declared = list(prep.declared)
        self.trip_names = list(prep.trip_names)
        self.n_trips = len(self.trip_names)
        self.signals = {k: None for k in prep.signal_names}
        self.x = None
        self.cols: list[ModelColumn] = []
        self._factor_cache, self.cand_cache = {}, {}
        self.n_scored = 0
        self.passes = 0
        self._version = 0
        self._lay = {"starts": [], "offs": [], "btrip": [], "byy": [], "sums": [], "first": [],
                     "sizes": np.zeros(self.n_trips, np.int64), "nb": 0, "n": 0, "rho": 0.0,
                     "th": [math.inf, -math.inf], "columns": columns, "hook": hook}
        if not defer:
            self.passes += 1
            for view in prep.views(common, lag):
                self.layout_step(view)
            self.layout_end()

    def layout_step(self, view) -> None:
        """The layout pass, one view: blocks, their yᵀy, trip sizes (and the columns' sums)."""
        L, opt = self._lay, self.opt
        tc, t = view.trip, view.t
        nv = view.n
        if nv == 0:
            L["starts"].append(np.zeros(0, np.int64))
            L["offs"].append(L["nb"])
            return
        tstart = np.r_[True, tc[1:] != tc[:-1]]
        firsti = np.maximum.accumulate(np.where(tstart, np.arange(nv), 0))
        bidx = np.floor((t - t[firsti]) / opt.block_s).astype(np.int64)
        newb = np.r_[True, (tc[1:] != tc[:-1]) | (bidx[1:] != bidx[:-1])]
        st = np.flatnonzero(newb)
        L["offs"].append(L["nb"])
        L["starts"].append(st)
        L["nb"] += len(st)
        L["btrip"].append(tc[st])
        L["byy"].append(_rs(view.y * view.y, st))
        L["sizes"] += np.bincount(tc, minlength=self.n_trips)
        L["n"] += nv
        L["rho"] += float(view.x.rho.sum())
        L["th"] = [min(L["th"][0], float(view.x.theta.min())), max(L["th"][1], float(view.x.theta.max()))]
        L["first"].extend(tc[tstart].tolist())
        if L["columns"]:
            L["sums"].append(self._column_sums(view, st, L["columns"]))
        if L["hook"] is not None:
            L["hook"](view, st)

    def layout_end(self) -> None:
        L = self._lay
        n = L["n"]
        self.n = n
        self._starts, self._offs = L["starts"], L["offs"]
        self.block_trip = np.concatenate(L["btrip"]) if L["btrip"] else np.zeros(0, np.int64)
        self.n_blocks = len(self.block_trip)
        self._sizes = L["sizes"]
        self.trip_order = first_appearance(L["first"])
        self._rho_mean = L["rho"] / n if n else math.nan
        self.theta_ptp = L["th"][1] - L["th"][0] if n else 0.0
        columns, sums = L["columns"], L["sums"]
        del self._lay
        if n == 0:
            return
        self._assign_folds(self._sizes)
        raw_yy = np.concatenate(L["byy"])
        self.y_scale = float(np.sqrt(raw_yy.sum() / n)) or 1.0
        self.block_yy = raw_yy / (self.y_scale * self.y_scale)
        if columns:
            self._add_from_sums(columns, *_concat_parts(sums))

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
        """Raw values of the model columns on a view (one array per column; computed once
        per view and model state, as several tasks of one pass ask for them)."""
        key = ("raw", self._version)
        if key not in view.extra:
            view.extra[key] = [cand_values(view, c.cand, self.declared, c.mass_terms) for c in self.cols]
        return view.extra[key]

    def _zmat(self, view: View) -> np.ndarray:
        """Scaled model columns on a view (n × q), as ``BlockModel.scaled``."""
        if not self.cols:
            return np.zeros((view.n, 0))
        return np.column_stack([r / c.scale for r, c in zip(self._raw(view), self.cols)])

    def _block_cross(self, specs, q0s=None):
        """Per-block raw sums of candidate values v: (Σv², [Σv·x_j for j ≥ q0], Σv·y), with
        x_j the model columns' raw values — the in-memory model's sums, block by block."""
        task = _Cross(self, specs, q0s)
        self._gather([task])
        return task.result()

    def _gather(self, tasks) -> None:
        """One pass over the views feeding every task (``step(view)``)."""
        for view in self._views():
            for t in tasks:
                t.step(view)

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
        """Block sums of one view for the layout pass: Σv², Σv·y, Σv·x_j (model columns),
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
        self._version += 1

    def prefetch(self, cands: list[Candidate]) -> None:
        """Block statistics of many candidates in one pass (as far as the cache allows)."""
        todo = self._prefetch_todo(cands)
        if todo:
            self._fill(todo)

    def _fill_plan(self, cands) -> list:
        q0s = []
        for c in cands:
            cached = self.cand_cache.get(c.term)
            q0s.append(cached[0].shape[1] if cached is not None and np.isfinite(cached[3]) else 0)
        return q0s

    def _fill(self, cands):
        q0s = self._fill_plan(cands)
        self._fill_store(cands, q0s, *self._block_cross([(c, None) for c in cands], q0s))

    def _fill_store(self, cands, q0s, vv, vz, vy) -> None:
        q = len(self.cols)
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
            self.cand_cache[c.term] = (vz[i] / (s * self._scales()), vv[:, i] / (s * s),
                                       vy[:, i] / (s * self.y_scale), s)

    def _prefetch_todo(self, cands) -> list:
        q = len(self.cols)
        todo = [c for c in cands if c.kind != "trip_mass" and not c.scatter
                and not (c.term in self.cand_cache and self.cand_cache[c.term][0].shape[1] == q)]
        per = self.n_blocks * (q + 2) * 8
        room = max(int(CACHE_BYTES // max(per, 1)) - len(self.cand_cache), 0)
        return todo[:room]

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
        """The sums of :meth:`BlockModel.drop_spanned`; in the same pass the block statistics
        of the candidates (:meth:`prefetch`) and the current model's held-out evaluation on
        its own folds (:meth:`evaluate`), which the search asks for next."""
        span = _Spanned(self, cands, names, groups)
        todo = self._prefetch_todo(cands)
        q0s = self._fill_plan(todo)
        cross = _Cross(self, [(c, None) for c in todo], q0s)
        fold = self.fold_of(False)
        ev = _Eval(self, fold)
        self._gather([span, cross, ev] if todo else [span, ev])
        if todo:
            self._fill_store(todo, q0s, *cross.result())
        self._ev_cache = (self._key(fold), ev.result())
        return span.result()

    def _key(self, fold):
        return (self._version, fold.tobytes())

    def drop_last(self) -> None:
        super().drop_last()
        self._version += 1

    # ---- what is reported
    def _coef_per_sample(self, bz, view):
        blk = view.extra["off"] + np.repeat(np.arange(len(view.extra["starts"])),
                                            np.diff(np.r_[view.extra["starts"], view.n]))
        return bz[blk]

    def evaluate(self, fold) -> dict:
        cached = getattr(self, "_ev_cache", None)
        if cached is not None and cached[0] == self._key(fold):
            return cached[1]
        task = _Eval(self, fold)
        self._gather([task])
        return task.result()

    def energy_shares(self, centre_last: tuple[str, list[str]] | None = None) -> np.ndarray:
        beta = self.full_fit()["beta"]
        q = len(self.cols)
        mean_sig = 0.0
        if centre_last is not None:  # the signal's mean over the analysis samples: one pass more
            tot, n = 0.0, 0
            for view in self._views():
                tot += float(np.sum(factor(view, centre_last[0], self.declared)))
                n += view.n
            mean_sig = tot / max(n, 1)
        acc, e_tot = np.zeros(q), 0.0
        for view in self._views():
            z = self._zmat(view)
            powers = np.empty((view.n, q))
            for j, c in enumerate(self.cols):
                coef = beta[c.offset + view.trip] if c.cand.scatter else beta[c.offset]
                powers[:, j] = coef * z[:, j] * self.y_scale
            total = powers.sum(axis=1)
            wgt = np.where(total > 0, view.dt, 0.0)
            if centre_last is not None:
                base = np.ones(view.n)
                for f in centre_last[1]:
                    base = base * factor(view, f, self.declared)
                c = self.cols[-1]
                powers[:, -1] -= beta[c.offset] * self.y_scale / c.scale * mean_sig * base
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


class _Cross:
    """Pass task: per-block raw sums of candidate values (see ``StreamModel._block_cross``)."""

    def __init__(self, tr: StreamModel, specs, q0s=None):
        self.tr, self.specs = tr, specs
        q, m = len(tr.cols), len(specs)
        self.q0s = q0s or [0] * m
        self.vv = np.zeros((tr.n_blocks, m))
        self.vy = np.zeros((tr.n_blocks, m))
        self.vz = [np.zeros((tr.n_blocks, q - q0)) for q0 in self.q0s]

    def step(self, view) -> None:
        tr = self.tr
        q = len(tr.cols)
        st, off = view.extra["starts"], view.extra["off"]
        sl = slice(off, off + len(st))
        raw = tr._raw(view)
        for i, (cand, mt) in enumerate(self.specs):
            v = cand_values(view, cand, tr.declared, mt)
            self.vv[sl, i] = _rs(v * v, st)
            self.vy[sl, i] = _rs(v * view.y, st)
            for j in range(self.q0s[i], q):
                self.vz[i][sl, j - self.q0s[i]] = _rs(v * raw[j], st)

    def result(self):
        return self.vv, self.vz, self.vy


class _Spanned:
    """Pass task: the sums of ``BlockModel.drop_spanned``."""

    def __init__(self, tr: StreamModel, cands, names, groups):
        q = len(tr.cols)
        self.tr, self.cands, self.names, self.groups = tr, cands, names, groups
        self.g = np.zeros((len(names), len(names))) if len(names) > 1 else None
        self.a = np.zeros((q, q))
        self.grams = {key: (np.zeros((len(ks), len(ks))), np.zeros((q, len(ks)))) for key, ks in groups.items()}

    def step(self, view) -> None:
        tr = self.tr
        if self.g is not None:
            s = np.column_stack([np.asarray(view.signals[k], float) for k in self.names])
            self.g += s.T @ s
        z = tr._zmat(view)
        self.a += z.T @ z
        for key, ks in self.groups.items():
            vals = np.column_stack([cand_values(view, self.cands[k], tr.declared) for k in ks])
            cc, cm = self.grams[key]
            cc += vals.T @ vals
            cm += z.T @ vals

    def result(self):
        return self.g, self.a, self.grams


class _Eval:
    """Pass task: the held-out evaluation of ``StreamModel.evaluate``."""

    def __init__(self, tr: StreamModel, fold):
        self.tr = tr
        _, self.bz = tr.heldout_model(fold)
        self.ms = _MetricSums()
        k = tr.n_trips
        self.sse, self.em, self.ep, self.nm, self.npred = (np.zeros(k) for _ in range(5))

    def step(self, view) -> None:
        tr, k = self.tr, self.tr.n_trips
        z = tr._zmat(view)
        coef = tr._coef_per_sample(self.bz, view)
        pred = np.zeros(view.n)
        for j in range(z.shape[1]):
            pred += coef[:, j] * z[:, j]
        pred = pred * tr.y_scale
        y, dt, tc = view.y, view.dt, view.trip
        self.ms.add(pred, y)
        self.sse += np.bincount(tc, weights=(pred - y) ** 2, minlength=k)
        ok = np.isfinite(pred) & np.isfinite(y)
        self.ep += np.bincount(tc, weights=np.where(ok & (pred > 0), pred, 0.0) * dt, minlength=k)
        self.em += np.bincount(tc, weights=np.where(ok & (y > 0), y, 0.0) * dt, minlength=k)
        self.npred += np.bincount(tc, weights=np.where(ok, pred, 0.0) * dt, minlength=k)
        self.nm += np.bincount(tc, weights=np.where(ok, y, 0.0) * dt, minlength=k)

    def result(self) -> dict:
        tr = self.tr
        order = np.asarray(tr.trip_order, dtype=np.int64)
        names = [tr.trip_names[i] for i in order]
        return {"pred": None, "metrics": self.ms.result(), "trip_sse": self.sse,
                "trip_energy": trip_energy_doc(names, self.em[order], self.ep[order]),
                "trip_net_energy": trip_energy_doc(names, self.nm[order], self.npred[order])}
