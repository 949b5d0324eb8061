"""The loop closed on an energy chain, streamed: :func:`trace_chain_stream` in bounded memory.

:func:`~sumo_drvpw.fit.chain_linear.trace_chain` for logs that do not fit in memory. The
search is the same code (:func:`sumo_drvpw.fit.chain_search.search`); what differs is where
its statistics come from:

1. **one read of the logs**, batch by batch of whole trips
   (:func:`~sumo_drvpw.fit.diagnose.source.read_batches`), into the arrays the trace needs
   per analysis sample — measured and declared target power, weight, time, trip, the
   model inputs and the signals the road load, the chain and its candidates read — kept as
   :class:`~sumo_drvpw.fit.diagnose.source.Batches` (in memory up to a budget, else in a
   temporary folder); on the way, which candidates are offered
   (:func:`~sumo_drvpw.fit.chain_effects.offer_stats`, merged over batches), the baseline's
   metrics and per-trip energies, what each trip lost to left-out samples;
2. **passes** over the prepared batches: each batch's candidate columns rebuilt on it
   (:func:`~sumo_drvpw.fit.chain_effects.candidates` with the decisions of all batches),
   reduced to per-block statistics (a block never crosses a trip, so a batch's blocks are
   the log's: :mod:`sumo_drvpw.fit.chain_blocks`) for each round's scoring, and to per-fold
   sums for the fits, the profiled parameters' refinement and each fold's closed equation;
   a last pass predicts each held-out sample with its fold's closed equation (exact chain).

The recuperation limits offered are the quantiles of the braking power on all analysis
samples, found exactly from its counts per bin and the distinct values of the bins that hold
the order statistics (fit/chain_stream.py's method), so findings and per-trip figures equal
the in-memory tracer's to rounding whatever the logs' length (tests/test_chain_trace_stream.py).
A target read from a BMS's energy counters (their view spans the log) is traced in memory
only; a trip id in two files is refused, as in memory.
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from sumo_drvpw.data.stream import plan
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.chain_blocks import Blocks, block_starts, block_stats, fit_from_sums, heldout_from_stats
from sumo_drvpw.fit.chain_effects import candidates, decide, merge_offer, offer_stats, refine
from sumo_drvpw.fit.chain_linear import (ChainTraceOptions, ChainTraceResult, _pick, chain_samples, stateful,
                                         check_chain_equation, predict)
from sumo_drvpw.fit.chain_search import close, fold_equations, report_doc, rms, search
from sumo_drvpw.fit.chain_stream import _keys, _merge_hist, quantile_bins, quantiles_of
from sumo_drvpw.fit.diagnose.source import CACHE_MB, INPUT_FIELDS, Batches, parquet_metadata, read_batches
from sumo_drvpw.fit.diagnose.stream_run import READ_ROWS
from sumo_drvpw.fit.diagnose.streamed import _MetricSums
from sumo_drvpw.fit.stream import _add_counts
from sumo_drvpw.fit.trip_energy import left_out_by_trip, trip_energy_doc, trip_net_energy, with_left_out
from sumo_drvpw.model.terms import Inputs


class _TripSums:
    """Per-trip net energies (measured, predicted) in order of first appearance: a trip's
    sums come whole from one batch, so they are the in-memory ones."""

    def __init__(self):
        self.e: dict = {}

    def add(self, pred, y, w, trips) -> None:
        for t, v in trip_net_energy(pred, y, w, trips)["trips"].items():
            self.e[t] = (v["measured_j"], v["predicted_j"])

    def doc(self) -> dict:
        return trip_energy_doc(list(self.e), [v[0] for v in self.e.values()], [v[1] for v in self.e.values()])


def _merge_unknown(a: dict, b: dict) -> dict:
    for col, d in b.items():
        if col in a:
            a[col]["samples"] += d["samples"]
            a[col]["trips"] = sorted(set(a[col]["trips"]) | set(d["trips"]))
        else:
            a[col] = dict(d)
    return a


def _inputs(d, trips: bool = False) -> Inputs:
    """A prepared batch's model inputs, with the signals it kept (and its trip ids, for a
    road load with ``trip=ID`` terms)."""
    keys = dict.fromkeys([*d, *getattr(d, "_files", ())])   # (a batch on disk: its files too)
    trip = np.asarray(d["names"], dtype=object)[np.asarray(d["tloc"])] if trips and "names" in keys else None
    return Inputs(*(np.asarray(d[f], float) for f in INPUT_FIELDS), {k[2:]: d[k] for k in keys if k.startswith("s:")},
                  trip)


def _reads_trips(equation) -> bool:
    """Whether a term of ``equation`` reads the trip ids (a ``trip=ID`` factor)."""
    from sumo_drvpw.model.terms import parse_term

    return any(f.startswith("trip=") for t in equation.terms for f in parse_term(t).factors)


class _Streamed:
    """The search's engine on prepared batches (:mod:`sumo_drvpw.fit.chain_search`)."""

    def __init__(self, batches, equation, opt, decided, bl: Blocks, starts: list, offs: list, sw, e_pred):
        self.batches, self.eq, self.opt, self.decided = batches, equation, opt, decided
        self.bl, self.starts, self.offs, self.sw, self.e_pred = bl, starts, offs, sw, e_pred
        self.passes = 0
        self.trips = _reads_trips(equation) or stateful(equation.chain)  # (a battery's state: per trip)

    def _batches(self):
        self.passes += 1
        for i, d in enumerate(self.batches):
            yield i, d

    def inputs(self, d) -> Inputs:
        return _inputs(d, self.trips)

    def context(self, d):
        """A batch's inputs, residual and candidates (with their columns on it)."""
        x = self.inputs(d)
        xe = x.with_mass(self.eq.mass_kg) if self.eq.mass_kg else x
        p = self.eq.power(xe)
        n = len(d["y"])
        cands = candidates(SimpleNamespace(inputs=x, dt=np.asarray(d["w"], float)), self.eq, p, np.arange(n),
                           self.opt, {}, self.decided)
        return {"x": x, "r": np.asarray(d["y"]) - np.asarray(d["pred0"]), "w": np.asarray(d["w"], float),
                "cands": {c.name: c for c in cands}, "n": n}

    @staticmethod
    def column(ctx, c, vi):
        """(free columns, fixed column) of variant ``vi`` of candidate ``c`` on a batch."""
        bc = ctx["cands"][c.name]
        if vi < c.grid:
            return bc.variants[vi][:2]
        return None, bc.profile[0](c.variants[vi][2])   # a refined parameter

    def cols(self, ctx, acc):
        n = ctx["n"]
        Z, fx = np.zeros((n, 0)), np.zeros(n)
        for c, vi in acc:
            z, f = self.column(ctx, c, vi)
            if z is not None:
                Z = np.column_stack([Z, z])
            if f is not None:
                fx = fx + f
        return Z, fx

    def _sample_fold(self, i, n):
        st = self.starts[i]
        return np.repeat(self.bl.fold[self.offs[i]:self.offs[i] + st.size], np.diff(np.r_[st, n]))

    def score(self, acc, pool):
        parts = [[] for _ in pool]
        for i, d in self._batches():
            ctx = self.context(d)
            Z, fx = self.cols(ctx, acc)
            rf = ctx["r"] - fx
            for j, c in enumerate(pool):
                if c is None:
                    tv, Zc = [rf], Z
                elif c.variants[0][0] is None:
                    tv, Zc = [rf - self.column(ctx, c, v)[1] for v in range(c.grid)], Z
                else:
                    tv, Zc = [rf], np.column_stack([Z, self.column(ctx, c, 0)[0]])
                parts[j].append([block_stats(ctx["w"], self.starts[i], Zc, t) for t in tv])
        out = []
        for p in parts:
            variants = [tuple(np.concatenate([b[v][k] for b in p]) for k in range(5)) for v in range(len(p[0]))]
            out.append(heldout_from_stats(self.bl, variants)[:2])
        return out

    def grams(self, make, fold) -> list:
        """Σ w·MᵀM, the sample count and Σ w of each matrix ``make(ctx)`` gives per batch, on
        all samples or on those outside ``fold``."""
        acc = None
        for i, d in self._batches():
            ctx = self.context(d)
            rows = slice(None) if fold is None else self._sample_fold(i, ctx["n"]) != fold
            w = ctx["w"][rows]
            part = [((M[rows] * w[:, None]).T @ M[rows], int(w.size), float(w.sum())) for M in make(ctx)]
            acc = part if acc is None else [(a[0] + b[0], a[1] + b[1], a[2] + b[2]) for a, b in zip(acc, part)]
        return acc

    @staticmethod
    def _fit(g):
        G, n, sw = g
        return fit_from_sums(G[:-1, :-1], G[:-1, -1], G[-1, -1], n, sw)

    def best_variant(self, acc, c, fold):
        if len(c.variants) == 1 and c.profile is None:
            return 0

        def mats(cols):
            def make(ctx):
                Z, fx = self.cols(ctx, acc)
                rf = ctx["r"] - fx
                return [np.column_stack([Z, rf - col(ctx)]) for col in cols]
            return make
        grid = [lambda ctx, v=v: self.column(ctx, c, v)[1] for v in range(c.grid)]
        scores = [self._fit(g)[2] for g in self.grams(mats(grid), fold)]
        at = lambda L: self._fit(self.grams(mats([lambda ctx: ctx["cands"][c.name].profile[0](L)]), fold)[0])[2]  # noqa: E731
        i, L = refine(c, scores, at)
        if L is None:
            return i
        c.variants.append((None, True, L))
        return len(c.variants) - 1

    def fit(self, acc, fold):
        def make(ctx):
            Z, fx = self.cols(ctx, acc)
            return [np.column_stack([Z, ctx["r"] - fx])]
        return self._fit(self.grams(make, fold)[0])[:2]

    def free_coef(self, acc, c, vi):
        def make(ctx):
            Z, fx = self.cols(ctx, acc)
            return [np.column_stack([Z, self.column(ctx, c, vi)[1], ctx["r"] - fx])]
        return float(self._fit(self.grams(make, None)[0])[0][-1])

    def contrib_j(self, c, vi, coef):
        total = 0.0
        for _, d in self._batches():
            ctx = self.context(d)
            z, f = self.column(ctx, c, vi)
            contrib = (z @ coef if z is not None else 0.0) + (0.0 if f is None else f)
            total += float(np.sum(ctx["w"] * contrib))
        return total

    def held_out(self, eqs):
        """Metrics and per-trip energies of each sample predicted by its fold's closed equation."""
        ms, ts = _MetricSums(), _TripSums()
        for i, d in self._batches():
            x = self.inputs(d)
            n = len(d["y"])
            sfold = self._sample_fold(i, n)
            held = np.full(n, np.nan)
            for k in np.unique(sfold):
                held[sfold == k] = predict(eqs[k], x, dt_s=np.asarray(d["w"], float) if stateful(eqs[k].chain)
                                           else None)[sfold == k]
            ms.add(held, np.asarray(d["y"]))
            ts.add(held, d["y"], d["w"], np.asarray(d["names"])[d["tloc"]])
        return ms, ts


def _keep_signals(m, equation, opt) -> list:
    """The signals the chain, its closed equation and its candidates may read: the road
    load's own too (``radial``'s yaw rate, ``[col]`` terms), or its driving power would
    differ from the one the batch was read with."""
    from sumo_drvpw.fit.chain_effects import _load_columns
    from sumo_drvpw.model.terms import parse_term

    ch = equation.chain
    road = {c for t in equation.terms for c in parse_term(t).columns}
    return sorted(set(ch.signals) | road | {ch.temperature_column, "ambient_c"} | set(_load_columns(m, ch, opt)))


def trace_chain_stream(paths, vehicle, equation, target: str, opt: ChainTraceOptions | None = None,
                       read_options=None, rows: int = READ_ROWS,
                       cache_mb: float = CACHE_MB, progress=None, bar=None) -> ChainTraceResult:
    """:func:`~sumo_drvpw.fit.chain_linear.trace_chain` on drive logs of any length (module
    docstring): ``paths`` files or folders, ``vehicle`` a name, file or Vehicle, ``equation``
    the declared equation whose chain predicts ``target`` (battery or fuel); ``rows``,
    ``cache_mb`` as :func:`~sumo_drvpw.fit.diagnose.stream_run.diagnose_stream`.

    Returns the :class:`ChainTraceResult` (no per-sample predictions: ``heldout_pred_w`` and
    ``mask`` are None; the per-trip energies carry what each trip lost to left-out samples);
    ``report["resources"]`` holds rows, passes and whether the batches were on disk;
    ``files`` and ``counts`` attributes: the logs read and the reader's counts."""
    from sumo_drvpw.data.measured import check_sign_sums, merge_sign_sums
    from sumo_drvpw.data.plausible import check_distinct_trips
    from sumo_drvpw.model.vehicles import load_vehicle

    opt = opt or ChainTraceOptions()
    opt.check()
    say = progress or (lambda s: None)
    check_chain_equation(equation, target)
    veh = load_vehicle(vehicle) if isinstance(vehicle, str) else vehicle
    check_distinct_trips(paths)  # (a trip's sums are taken whole from one batch)
    files = list(dict.fromkeys(p.path for p in plan(paths)))
    meta = parquet_metadata(paths)
    batches = Batches(cache_mb)
    stats, counts, left, unknown, names, hist = None, {}, {}, {}, set(), None
    sign = source = None  # the battery sign test's sums, tested on all batches as in memory
    base, before = _MetricSums(), _TripSums()
    n_rows = n = 0
    sw = e_pred = 0.0
    keep = None
    try:
        for m in read_batches(paths, veh, read_options, target, rows, sign_check=False):
            if bar:
                bar(len(m.power_w))
            if getattr(m, "counter_view", None) is not None:
                raise UserError(f"{m.log.describe()}: a battery target read from the BMS's energy counters is "
                                "traced in memory only (their view of the power spans the log)")
            m.log.metadata = meta  # (the columns' roles, as the whole log's reader has them)
            counts = _add_counts(counts, m.counts)
            sign, source = merge_sign_sums(sign, m.sign_test), source or m.source
            ok, p, y_all, pred0_all, dt_all = chain_samples(m, equation)
            trips_all = m.log.df["trip_id"].astype(str).to_numpy()
            left.update(left_out_by_trip(y_all, ok, dt_all, trips_all))
            idx = np.flatnonzero(ok)
            stats = merge_offer(stats, offer_stats(m, equation, p, idx, opt, braking=False))
            brake = -p[idx][p[idx] < 0]
            if brake.size:  # counted per bin: the limits' quantiles are found exactly (_brake_quantiles)
                hist = _merge_hist(hist, np.unique(_keys(brake), return_counts=True))
            n_rows += len(y_all)
            if not idx.size:
                continue
            keep = _keep_signals(m, equation, opt) if keep is None else keep
            tstr = trips_all[idx]
            bnames, tloc = np.unique(tstr, return_inverse=True)
            sig = {k: np.asarray(m.inputs.signals[k], float)[idx] for k in keep if k in m.inputs.signals}
            _merge_unknown(unknown, equation.chain.unknown_inputs(sig, idx.size, tstr))
            y, pred0, w = y_all[idx], pred0_all[idx], dt_all[idx]
            base.add(pred0, y)
            before.add(pred0, y, w, tstr)
            n += idx.size
            sw += float(w.sum())
            e_pred += float(np.sum(w * pred0))
            names.update(bnames.tolist())
            d = {"y": y, "pred0": pred0, "w": w, "t": m.log.df["time_s"].to_numpy(float)[idx],
                 "tloc": tloc.astype(np.int32), "names": [str(s) for s in bnames],
                 **{f: np.asarray(getattr(m.inputs, f), float)[idx] for f in INPUT_FIELDS},
                 **{"s:" + k: v for k, v in sig.items()}}
            del m
            batches.append(d)
        if target == "battery":
            check_sign_sums(files[0] if len(files) == 1 else f"{len(files)} files", source, sign)
        if n < 50:
            raise UserError(f"{', '.join(files)}: only {n} samples with finite measured {target} power, "
                            "driving power and chain prediction; need at least 50")
        if hist is not None and stats["brake_n"] > 50:
            stats["brake_quantiles"] = _brake_quantiles(batches, equation, hist)
        res = _trace(batches, equation, target, opt, stats, np.array(sorted(names)), sw, e_pred, files, say)
        res.report["baseline"] = {"metrics": _metric_doc(base, res.base_stats),
                                  "trip_net_energy": before.doc()}
        res.report["chain_unknown_inputs"] = dict(sorted(unknown.items()))
        for k in ("baseline", "final"):
            with_left_out(res.report[k]["trip_net_energy"], left, net=True)
        res.report["resources"] = {"rows": n_rows, "passes": res.passes, "batches_on_disk": batches.on_disk}
    finally:
        batches.close()
    res.files, res.counts = files, counts
    return res


def _brake_quantiles(batches, equation, hist) -> list:
    """``np.quantile`` of the braking powers of all analysis samples at the recuperation
    limits' quantiles (chain_effects.LIMIT_QUANTILES), exactly: from their counts per bin
    (``hist``) and the distinct values of the bins that hold the order statistics, gathered
    in one pass over the prepared batches (as fit/chain_stream.py does for calibrate)."""
    from sumo_drvpw.fit.chain_effects import LIMIT_QUANTILES

    bins = quantile_bins(hist, LIMIT_QUANTILES)[1]
    values = None
    for d in batches:
        x = _inputs(d, _reads_trips(equation))
        p = equation.power(x.with_mass(equation.mass_kg) if equation.mass_kg else x)
        brake = -p[p < 0]
        sel = brake[np.isin(_keys(brake), bins)]
        if sel.size:
            values = _merge_hist(values, np.unique(sel, return_counts=True))
    return quantiles_of(hist, values, LIMIT_QUANTILES)


def _metric_doc(ms: _MetricSums, stats, sw=None) -> dict:
    doc = _pick(ms.result())
    if sw is not None:
        doc["rmse_heldout_linear_w"] = float(np.sqrt(stats[0].sum() / sw))
    doc["block_energy_rms_j"] = rms(stats[1])
    return doc


def _trace(batches, equation, target, opt, stats, trip_names, sw, e_pred, files, say) -> ChainTraceResult:
    starts, btrip, offs, nb = [], [], [], 0
    for d in batches:
        g = np.searchsorted(trip_names, np.asarray(d["names"]))[d["tloc"]]
        st = block_starts(g, d["t"], opt.block_s)
        starts.append(st)
        btrip.append(g[st])
        offs.append(nb)
        nb += st.size
    bl = Blocks(None, None, None, None, opt, block_trip=np.concatenate(btrip))
    left_out: dict = {}
    decided = decide(stats, equation, opt, left_out)
    eng = _Streamed(batches, equation, opt, decided, bl, starts, offs, sw, e_pred)
    first = next(iter(batches))
    x = eng.inputs(first)
    cands = candidates(SimpleNamespace(inputs=x, dt=np.asarray(first["w"], float)), equation, equation.power(
        x.with_mass(equation.mass_kg) if equation.mass_kg else x), np.arange(len(first["y"])), opt, left_out, decided)
    for c in cands:  # the search's candidates: each variant's parameters, its columns rebuilt per batch
        c.variants = [(None if z is None else z.shape[1], None if f is None else True, par) for z, f, par in c.variants]
        c.profile = None if c.profile is None else (None, c.profile[1])
    n = sum(len(d["y"]) for d in batches)
    say(f"{n} samples, {len(trip_names)} trip(s), {bl.n_blocks} blocks; "
        f"{len(cands)} candidate effects; validation: {bl.how}")
    findings, rounds, rejected, accepted, base_stats, cur_stats = search(eng, equation, cands, opt, trip_names, say)
    closed = close(eng, equation, accepted, findings, target, files)
    ms, ts = eng.held_out(fold_equations(eng, equation, accepted))
    report = report_doc(target, equation, closed, bl, n, trip_names, {},
                        None, _metric_doc(ms, cur_stats, sw), None, ts.doc(), findings, rounds, rejected, cands)
    report["columns_left_out"] = left_out
    res = ChainTraceResult(report, closed, equation)
    res.base_stats, res.passes = base_stats, eng.passes
    return res
