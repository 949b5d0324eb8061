"""The statistics of `compare`, accumulated batch by batch (issue #14).

Per equation: co-moments (Chan et al. 1979) of measured, predicted and category powers on
all / light / heavy samples, Σ|e|, Σe², energies, per-trip energies, speed-bin and
≥ 80 km/h sums, min/max of each category power, and a bounded reservoir sample (bottom-k
of a deterministic random key per sample) for the percentiles and the figures: exact with
at most ``RESERVOIR`` samples, else estimates from a uniform sample of that size. See
:mod:`sumo_drvpw.fit.stream` for the calibration side and the merge rules.

A battery or fuel target (``target``) compares each equation's energy chain with the
measured battery V·I or fuel power, as :func:`sumo_drvpw.fit.compare.compare` does: the
prediction is the chain's, the category energies stay at the wheel; besides, the chain's
traction Σ max(P̂, 0)·Δt, its inputs unknown on some samples (per column: samples and
trips) and the battery sign test's sums (tested on all batches at the end) are summed.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np

from sumo_drvpw.data.trips import trip_signatures
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.trip_energy import left_out_by_trip, with_fuel_volumes, with_left_out
from sumo_drvpw.fit.stream import Moments, _add_counts, _trip_codes, trip_twice
from sumo_drvpw.fit.stream_metrics import _EqStats, _corr, _high_speed, _metrics, _speed_bins, _unknown_doc
from sumo_drvpw.model.constants import HEAVY_LOAD_W, HIGH_SPEED_MPS
from sumo_drvpw.model.terms import CATEGORIES, parse_term

#: Samples kept for percentiles and figures in compare.
RESERVOIR = 250_000


def _keys(ids, starts: np.ndarray, n: int) -> np.ndarray:
    """A deterministic uniform key in [0, 1) per sample from its trip id and position in
    the trip, so the reservoir is the same whatever the batching or engine.

    ``ids``: the trip id of each run of samples; ``starts``: the first row of each run;
    ``n``: rows."""
    out = np.empty(n)
    bounds = np.r_[starts, n]
    for t, a, b in zip(ids, bounds[:-1], bounds[1:]):
        seed = zlib.crc32(str(t).encode())
        out[a:b] = np.random.default_rng(seed).random(b - a)
    return out


@dataclass
class _Reservoir:
    """Bottom-k sample by key: columns (dict name → array) of the k smallest keys. Batches
    wait in ``pending`` until k/4 samples do, then are selected from at once (not the whole
    sample copied per batch); ``key`` and ``cols`` are read with the waiting ones selected."""

    k: int
    _key: np.ndarray
    _cols: dict
    pending: list = field(default_factory=list)
    waiting: int = 0

    def add(self, key: np.ndarray, cols: dict) -> "_Reservoir":
        self.pending.append((key, cols))
        self.waiting += len(key)
        return self.flush() if self.waiting >= self.k // 4 else self

    def flush(self) -> "_Reservoir":
        if not self.pending:
            return self
        allk = np.concatenate([self._key] + [k for k, _ in self.pending])
        allc = {c: np.concatenate(([self._cols[c]] if c in self._cols else []) + [p[c] for _, p in self.pending])
                for c in self.pending[-1][1]}
        self.pending, self.waiting = [], 0
        if len(allk) > self.k:
            keep = np.argpartition(allk, self.k - 1)[:self.k]
            keep.sort()
            allk = allk[keep]
            allc = {c: v[keep] for c, v in allc.items()}
        self._key, self._cols = allk, allc
        return self

    @property
    def key(self) -> np.ndarray:
        return self.flush()._key

    @property
    def cols(self) -> dict:
        return self.flush()._cols


def _minmax(cols: list) -> tuple[np.ndarray, np.ndarray]:
    """Per column (min, max); +inf/−inf for columns without samples."""
    lo = [c.min() if len(c) else np.inf for c in cols]
    hi = [c.max() if len(c) else -np.inf for c in cols]
    return np.array(lo, float), np.array(hi, float)


def _categories(pw: dict) -> list:
    """Categories compare() keeps: the four physical ones always, others when non-zero."""
    return [c for c, p in pw.items() if c in CATEGORIES or np.any(p != 0.0)]


class CompareStats:
    """Mergeable statistics of :func:`sumo_drvpw.fit.compare.compare` over batches.

    Parameters
    ----------
    equations : the equations compared (unique names)
    reference : optional name of one of them (``error_reference_correlation``)
    reservoir : samples kept for percentiles and figures [-]
    target : ``wheel`` (driving power), ``battery`` or ``fuel`` (each equation's energy
        chain against the measured battery or fuel power; every equation needs a chain
        predicting it)
    """

    def __init__(self, equations, reference: str | None = None, reservoir: int = RESERVOIR,
                 target: str = "wheel"):
        self.equations, self.reference, self.k, self.target = list(equations), reference, int(reservoir), target
        self.sign = None          # the battery sign test's sums (data.measured.sign_sums)
        self.battery_seen = False # a fuel target's hybrid battery V·I in some batch
        self.seen: set = set()    # log columns the batches had (a chain's inputs among them)
        self.n = self.rows = 0
        self.meas = Moments.empty(1)
        self.meas_traction = 0.0
        self.n_light = self.n_heavy = self.n_high = 0
        self.eq: dict[str, _EqStats] = {}
        self.ref_cats: list | None = None
        self.res: _Reservoir | None = None
        self.counts: dict = {}
        self.trips: dict = {}  # trip → the file(s) of the batch it came in
        self.left_out: dict = {}  # trip → its left-out samples (fit/trip_energy.py)
        self.source: str | None = None
        self.vehicle = None
        self.files: list = []
        self.signatures: dict = {}  # trip → its signature (data/trips.trip_signatures)

    def columns(self) -> frozenset | None:
        """Columns to read: the reader's canonical ones and the signals the equations name;
        with a battery or fuel target every column (the fuel flow, air flow and fuel trims
        are found by their names, as the in-memory reader finds them)."""
        from sumo_drvpw.data.stream import CANONICAL

        if self.target != "wheel":
            return None
        return CANONICAL | {s for eq in self.equations for t in eq.terms
                            for s in parse_term(t).columns}

    def add(self, m) -> "CompareStats":
        """Accumulate one batch: the usable samples of a Measured of whole trips."""
        from sumo_drvpw.fit.compare import SPEED_BIN_MPS, target_terms

        self._check_equations()  # after the batch was read: a log's refusal comes first, as in memory

        self.rows += len(m.power_w)
        self.counts = _add_counts(self.counts, m.counts)
        self.source = self.counts.get("power_source") or self.source or m.source  # of all batches
        self.vehicle = self.vehicle or m.vehicle
        self.files += [f for f in m.log.files if f not in self.files]
        self.signatures.update(trip_signatures(m.log.df))
        if self.target == "battery":
            from sumo_drvpw.data.measured import merge_sign_sums

            self.sign = merge_sign_sums(self.sign, m.sign_test)
        usable = np.asarray(m.usable, bool)
        every = bool(usable.all())
        idx = np.flatnonzero(usable)
        self.left_out.update(left_out_by_trip(m.power_w, usable, m.log.df["dt_s"].to_numpy(float),
                                              m.inputs.trip))
        if len(idx) == 0:
            return self
        x = m.inputs if every else m.inputs.take(idx)
        meas = np.asarray(m.power_w, float)
        dt = m.log.df["dt_s"].to_numpy(float)
        if not every:
            meas, dt = meas[idx], dt[idx]
        # trips by integer codes (contiguous runs), ids once per trip: no string per row
        tc = _trip_codes(m)
        tc = tc if every else tc[idx]
        first = np.empty(len(tc), bool)
        first[0] = True
        np.not_equal(tc[1:], tc[:-1], out=first[1:])
        starts = np.flatnonzero(first)
        codes = np.cumsum(first) - 1
        uniq = np.asarray(x.trip)[starts].astype(str)
        here = ", ".join(map(str, m.log.files))
        dup = sorted(set(self.trips).intersection(uniq))
        if dup:
            raise trip_twice(dup[0], self.trips[dup[0]], here)
        self.trips.update(dict.fromkeys(uniq, here))
        v = np.asarray(x.v, float)
        n = len(meas)
        sig, bat = self._chain_inputs(m, x, idx, every, n)
        self.n += n
        self.meas = self.meas.merge(Moments.of_columns([meas]))
        self.meas_traction += float(np.where(meas > 0.0, meas, 0.0) @ dt)
        heavy_all = meas >= HEAVY_LOAD_W
        self.n_heavy += int(heavy_all.sum())
        self.n_light += int(n - heavy_all.sum())
        self.n_high += int((v >= HIGH_SPEED_MPS).sum())
        pw = {eq.name: eq.category_powers(x) for eq in self.equations}
        if self.reference is not None and self.ref_cats is None:
            self.ref_cats = _categories(pw[self.reference])
        # the reservoir: only samples whose key is below the k-th smallest so far can enter
        key = _keys(uniq, starts, n)
        if self.res is not None and len(self.res._key) >= self.k:  # (the selected ones' max: a bound)
            enter = np.flatnonzero(key < self.res._key.max())
        else:
            enter = np.arange(n)
        cols = {"meas": meas[enter], "v": v[enter], "dt": dt[enter]}
        zero = np.zeros(n)
        pre = {}  # name → its terms, their powers, its driving and predicted power, terms at the target
        for eq in self.equations:
            prev = self.eq.get(eq.name)
            cats = prev.cats if prev is not None else _categories(pw[eq.name])
            cw = {c: np.asarray(pw[eq.name].get(c, zero), float) for c in cats}
            wheel = np.sum(list(cw.values()), axis=0) if cw else zero
            pred, at = wheel, cw
            if self.target != "wheel":  # (compare.target_terms: each term as it reaches the target)
                pred = eq.chain.target_power(wheel, x.v, sig, bat, x.a, x.theta, dt, x.trip)
                at = target_terms(eq.chain, cw, wheel, pred, x.v, sig, bat, x.a, x.theta, dt, x.trip)
            pre[eq.name] = (cats, cw, wheel, pred, at)
        for eq in self.equations:
            prev = self.eq.get(eq.name)
            cats, cw, wheel, pred, at = pre[eq.name]
            err = pred - meas
            ok = np.isfinite(err)
            sel = slice(None) if ok.all() else ok  # views when every prediction is finite
            e, mo, po, vo, dto = err[sel], meas[sel], pred[sel], v[sel], dt[sel]
            hv = mo >= HEAVY_LOAD_W
            cm = [cw[c][sel] for c in cats]
            am = cm if at is cw else [at[c][sel] for c in cats]  # (where the error is measured)
            # Σ of the categories is the wheel power (same sum, same order): traction weights
            wgt = np.where(wheel[sel] > 0.0, dto, 0.0) if cats else np.zeros(len(e))
            eref = rmin = rmax = None
            if self.reference is not None:
                rp = pre[self.reference][4]
                rm = [np.asarray(rp.get(c, zero), float)[sel] for c in self.ref_cats]
                eref = Moments.of_columns([e] + rm)
                rmin, rmax = _minmax(rm)
            hi = vo >= HIGH_SPEED_MPS
            ehi, elo = e[hi], e[~hi]
            hs = np.array([len(ehi), ehi.sum(), ehi @ ehi, len(elo), elo.sum(), elo @ elo], float)
            b = np.floor(np.maximum(vo, 0.0) / SPEED_BIN_MPS + 1e-9).astype(np.int64)
            nb = int(b.max()) + 1 if len(b) else 0
            bins = np.vstack([np.bincount(b, minlength=nb), np.bincount(b, e, nb),
                              np.bincount(b, e * e, nb)]).astype(float)
            pm = np.where(ok, pred, 0.0)
            k = len(uniq)
            sums = [np.bincount(codes, np.where(meas > 0.0, meas, 0.0) * dt, k),
                    np.bincount(codes, np.where(pm > 0.0, pm, 0.0) * dt, k),
                    np.bincount(codes, meas * dt, k), np.bincount(codes, pm * dt, k)]
            cmin, cmax = _minmax(am)
            el, eh = e[~hv], e[hv]
            st = _EqStats(
                cats, {"all": Moments.of_columns([mo, po]),
                       "light": Moments.of_columns([mo[~hv], po[~hv]]),
                       "heavy": Moments.of_columns([mo[hv], po[hv]])},
                {"all": float(e @ e), "light": float(el @ el), "heavy": float(eh @ eh)},
                {"all": float(e.sum()), "light": float(el.sum()), "heavy": float(eh.sum())},
                float(np.abs(e).sum()), Moments.of_columns([e] + am), cmin, cmax,
                eref, rmin, rmax, np.array([c @ wgt for c in cm]), hs, bins,
                {str(t): tuple(float(s[i]) for s in sums) for i, t in enumerate(uniq)},
                float(np.maximum(po, 0.0) @ dto), self._unknown(eq, sig, n, x.trip))
            self.eq[eq.name] = st if prev is None else prev.merge(st)
            cols[f"pred:{eq.name}"] = pred[enter]
            cols[f"ok:{eq.name}"] = ok[enter]
            for c in cats:
                cols[f"cat:{eq.name}:{c}"] = cw[c][enter]
        key = key[enter]
        self.res = (_Reservoir(self.k, np.zeros(0), {}) if self.res is None else self.res).add(key, cols)
        return self

    def _chain_inputs(self, m, x, idx, every: bool, n: int):
        """(signals, hybrid battery power) a chain reads on a batch's usable samples: a
        chain input the batch lacks is unknown (NaN) there, as in a log of several files
        read at once; a column no batch had is refused at the end (:meth:`comparison`)."""
        if self.target == "wheel":
            return x.signals, None
        sig = x.signals
        self.seen |= set(sig)
        need = {c for eq in self.equations for c in eq.chain.signals} - set(sig)
        if need:
            sig = {**sig, **{c: np.full(n, np.nan) for c in need}}
        bat = None
        if self.target == "fuel" and m.battery_w is not None:
            bat = np.asarray(m.battery_w, float)
            bat = bat if every else bat[idx]
            self.battery_seen = True  # (the comparison says its predictions take the battery off)
        return sig, bat

    def _unknown(self, eq, sig: dict, n: int, trip) -> dict | None:
        """A chain's inputs unknown on some of a batch's samples (sums of
        :meth:`~sumo_drvpw.model.chain.EnergyChain.unknown_inputs`)."""
        if self.target == "wheel":
            return None
        out = {}
        for c, u in eq.chain.unknown_inputs(sig, n).items():
            bad = ~np.isfinite(np.asarray(sig[c], float))
            out[c] = [u["samples"], u["read_as"], [np.unique(np.asarray(trip)[bad])]]
        return out

    def merge(self, o: "CompareStats") -> "CompareStats":
        """Add another CompareStats (e.g. a Dask partition's) to this one."""
        dup = sorted(set(self.trips) & set(o.trips))
        if dup:
            raise trip_twice(dup[0], self.trips[dup[0]], o.trips[dup[0]])
        self.trips.update(o.trips)
        self.left_out.update(o.left_out)
        self.signatures.update(o.signatures)
        self.n += o.n
        self.rows += o.rows
        self.counts = _add_counts(self.counts, o.counts)
        self.source = self.counts.get("power_source") or self.source or o.source
        self.vehicle = self.vehicle or o.vehicle
        self.files += [f for f in o.files if f not in self.files]
        self.meas = self.meas.merge(o.meas)
        self.meas_traction += o.meas_traction
        self.n_light += o.n_light
        self.n_heavy += o.n_heavy
        self.n_high += o.n_high
        self.ref_cats = self.ref_cats if self.ref_cats is not None else o.ref_cats
        from sumo_drvpw.data.measured import merge_sign_sums

        self.sign = merge_sign_sums(self.sign, o.sign)
        self.battery_seen = self.battery_seen or o.battery_seen
        self.seen |= o.seen
        for name, b in o.eq.items():
            self.eq[name] = b if name not in self.eq else self.eq[name].merge(b)
        if o.res is not None:
            self.res = o.res if self.res is None else self.res.add(o.res.key, o.res.cols)
        return self

    def comparison(self):
        """A :class:`~sumo_drvpw.fit.compare.Comparison` for the report: its arrays are
        the reservoir sample (figures, percentiles), its ``to_json`` reports the
        statistics of every sample streamed."""
        from sumo_drvpw.fit.compare import EquationResult

        if self.n == 0 or self.res is None:
            from sumo_drvpw.data.log import exclusions

            raise UserError(f"no usable sample among {self.counts.get('rows', 0)} rows (excluded: "
                            f"{exclusions(self.counts)}; any other row lacks a finite measured power or input)")
        self._check_equations()
        self._check_chain_inputs()
        order = np.argsort(self.res.key, kind="stable")
        r = {c: v[order] for c, v in self.res.cols.items()}
        comp = StreamedComparison(meas_w=r["meas"], speed_mps=r["v"], dt_s=r["dt"],
                                  measured_traction_energy_j=self.meas_traction,
                                  reference=self.reference, target=self.target,
                                  battery_corrected=self.target == "fuel" and self.battery_seen)
        comp.stats = self
        for eq in self.equations:
            s = self.eq[eq.name]
            ok = r[f"ok:{eq.name}"]
            e = (r[f"pred:{eq.name}"] - r["meas"])[ok]
            energy = {c: float(s.energy[i]) for i, c in enumerate(s.cats)}
            total = float(sum(energy.values()))
            energy["total"] = total
            share = {c: (energy[c] / total if total > 0.0 else math.nan) for c in s.cats}
            # the traction of what is compared: the terms' at the wheel, the chain's otherwise
            trac = total if self.target == "wheel" else s.ptrac
            comp.results[eq.name] = EquationResult(
                equation=eq, pred_w=r[f"pred:{eq.name}"],
                category_w={c: r[f"cat:{eq.name}:{c}"] for c in s.cats},
                metrics=_metrics(s), speed_bins=_speed_bins(s, e, r["v"][ok]),
                high_speed=_high_speed(s, e, r["v"][ok]),
                error_term_correlation=_corr(s.ecat, s.cats, s.cmin, s.cmax),
                energy_j=energy, energy_share=share,
                traction_energy_ratio=(trac / self.meas_traction if self.meas_traction > 0.0
                                       else math.nan), predicted_traction_j=trac,
                error_reference_correlation=(None if s.eref is None else
                                             _corr(s.eref, self.ref_cats, s.rmin, s.rmax)),
                unknown_inputs=_unknown_doc(s.unknown))
        return comp

    def _check_equations(self) -> None:
        """With a battery or fuel target, every equation has a chain predicting it."""
        if self.target == "wheel":
            return
        for eq in self.equations:
            if eq.chain is None or eq.chain.predicts != self.target:
                raise UserError(f"compare: equation '{eq.name}' ({eq.path or 'built in'}) has no energy "
                                f"chain predicting '{self.target}' (it predicts '{eq.predicts}')")

    def _check_chain_inputs(self) -> None:
        """What the in-memory reader refuses on all samples: a chain input no log has, a
        battery current whose sign is flipped (the test on the sums of every batch)."""
        if self.target == "wheel":
            return
        for eq in self.equations:
            for c in sorted(eq.chain.required_signals - self.seen):
                raise UserError(f"energy chain needs the log column '{c}', which the data do not have "
                                f"(available: {', '.join(sorted(self.seen)) or 'none'})")
        if self.target == "battery":
            from sumo_drvpw.data.measured import check_sign_sums

            where = self.files[0] if len(self.files) == 1 else f"{len(self.files)} files"
            check_sign_sums(where, self.source, self.sign)


def _streamed_comparison_class():
    from sumo_drvpw.fileio import plain as _jsonable
    from sumo_drvpw.fit.compare import Comparison
    from sumo_drvpw.fit.trip_energy import trip_block

    class StreamedComparison(Comparison):
        """A Comparison whose arrays are a reservoir sample and whose ``to_json`` reports
        the statistics of every sample streamed (``stats``, a :class:`CompareStats`)."""

        stats = None

        @property
        def n_samples(self) -> int:
            return int(self.meas_w.size)

        def to_json(self, trips: bool = True) -> dict:
            st = self.stats
            doc = Comparison.to_json(self)
            for name, d in doc["equations"].items():
                if trips:
                    s = st.eq[name]
                    d["trip_energy"] = _jsonable(with_left_out(trip_block(s.trip_e, net=False), st.left_out))
                    d["trip_net_energy"] = _jsonable(with_left_out(trip_block(s.trip_e, net=True),
                                                                   st.left_out, net=True))
                    with_fuel_volumes(d, self.target)  # litres of a fuel target, as in memory
            doc["n_samples"] = st.n
            doc["measured"] = _jsonable({
                "traction_energy_j": st.meas_traction,
                "mean_w": float(st.meas.mean[0]) if st.n else math.nan,
                "n_light": st.n_light, "n_heavy": st.n_heavy, "n_high_speed": st.n_high})
            doc["settings"]["percentiles"] = (
                "exact" if st.n <= st.k else
                f"estimated from a uniform random sample of {st.k} samples (figures too)")
            return doc

    return StreamedComparison


StreamedComparison = _streamed_comparison_class()
