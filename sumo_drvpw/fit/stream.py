"""Sufficient statistics of calibrate and compare, accumulated batch by batch.

Everything the two commands report is a function of sums over samples, so a log of any
length is reduced batch by batch (:mod:`sumo_drvpw.data.stream`) into small, mergeable
accumulators — the same on one machine and on a Dask cluster
(:mod:`sumo_drvpw.fit.engine`):

* calibrate: per trip the triangular factor R of [X y] (X = all candidate terms; RᵀR
  holds XᵀX, Xᵀy and yᵀy) plus the mean and centred sum of squares of y (centred R²), so
  trip-grouped use (hold-out by trip) stays possible. Factors merge by stacking and one
  more QR (TSQR: Demmel et al. 2012, "Communication-optimal parallel and sequential QR"),
  which keeps the precision of a QR of the whole design — normal equations square the
  condition number, and v, v² and the rolling term are nearly collinear. Stepwise
  selection works on the Gram matrix RᵀR; the final fit is statsmodels OLS on the compact
  design the factor gives (:func:`ols_from_r`).
* compare: per equation the co-moments (Chan et al. pairwise update) of measured,
  predicted and category powers on all / light / heavy samples, Σ|e|, Σe², energies, per
  trip energies, min/max of each category power, and a bounded reservoir sample (bottom-k
  of a deterministic random key per sample) for the percentiles of the speed bins and
  the figures. With at most ``RESERVOIR`` samples the reservoir holds them all and the
  percentiles are exact; beyond, they are estimates from a uniform sample of that size
  (standard error of a 5th percentile about √(0.05·0.95/k) in probability).

Merging is order-independent up to rounding; the engines merge in Part order, so a
local and a Dask run add the same numbers in the same order.

Reference: Chan, Golub, LeVeque (1979), "Updating formulae and a pairwise algorithm for
computing sample variances", for merging means and centred co-moments.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.ols import Gram
from sumo_drvpw.model.constants import HEAVY_LOAD_W, HIGH_SPEED_MPS
from sumo_drvpw.model.terms import CATEGORIES, parse_term, term_matrix

#: Samples kept for percentiles and figures in compare.
RESERVOIR = 250_000


# ------------------------------------------------------------------------ moments

@dataclass
class Moments:
    """Count, mean (d) and centred co-moment matrix (d × d) of d variables."""

    n: int
    mean: np.ndarray
    m2: np.ndarray

    @classmethod
    def empty(cls, d: int) -> "Moments":
        return cls(0, np.zeros(d), np.zeros((d, d)))

    @classmethod
    def of(cls, x: np.ndarray) -> "Moments":
        """Moments of the rows of ``x`` (n × d)."""
        x = np.asarray(x, float)
        if len(x) == 0:
            return cls.empty(x.shape[1])
        mu = x.mean(axis=0)
        c = x - mu
        return cls(len(x), mu, c.T @ c)

    def merge(self, o: "Moments") -> "Moments":
        """Pairwise update (Chan et al. 1979): M2 = M2a + M2b + δδᵀ·na·nb/n."""
        if o.n == 0:
            return self
        if self.n == 0:
            return o
        n = self.n + o.n
        d = o.mean - self.mean
        return Moments(n, self.mean + d * (o.n / n),
                       self.m2 + o.m2 + np.outer(d, d) * (self.n * o.n / n))


def _add_counts(a: dict, b: dict) -> dict:
    """Counts of two batches: numbers add, texts are kept (first seen)."""
    out = dict(a)
    for k, v in b.items():
        if k in out and isinstance(v, (int, np.integer)) and not isinstance(v, bool) \
                and isinstance(out[k], (int, np.integer)):
            out[k] = int(out[k]) + int(v)
        elif k == "accel_outlier_limit_mps2" or k not in out:
            out.setdefault(k, v)
    return out


def calibration_mask(m, candidates) -> np.ndarray:
    """Samples :func:`sumo_drvpw.fit.calibrate.calibrate` uses: usable, finite power and
    finite values of every signal a candidate term reads."""
    y = np.asarray(m.power_w, float)
    use = np.asarray(m.usable, bool) & np.isfinite(y)
    for t in candidates:
        for s in parse_term(t).signals:
            if s in m.inputs.signals:
                use &= np.isfinite(np.asarray(m.inputs.signals[s], float))
    return use


# ---------------------------------------------------------------------- calibrate

def tall_r(a: np.ndarray) -> np.ndarray:
    """Upper triangular R with RᵀR = aᵀa of a tall matrix a (n × k), about as precise as
    a Householder QR at the cost of two Gram products.

    CholeskyQR2 on the column-scaled matrix (Fukaya et al. 2014, "CholeskyQR2: a simple
    and communication-avoiding algorithm for computing a tall-skinny QR factorization"):
    R₁ = chol(SᵀS), Q₁ = S·R₁⁻¹, R₂ = chol(Q₁ᵀQ₁), R = R₂·R₁·D for S = a·D⁻¹. Columns
    that are zero, or a multiple c·a_i of an earlier column (e.g. aero and v³ in still air
    at one air density), get R's column c·R_i, which is exact: R = Qᵀa. Beyond a scaled
    condition number of 1e7 (or when a Cholesky fails) Householder QR is used.
    """
    k = a.shape[1]
    d = np.sqrt(np.einsum("ij,ij->j", a, a))
    safe = np.where(d > 0, d, 1.0)
    s = a / safe
    g = s.T @ s
    base = np.arange(k)          # column whose multiple each column is (itself if kept)
    coef = np.ones(k)
    for j in range(k):
        if d[j] == 0:
            base[j], coef[j] = -1, 0.0
            continue
        for i in range(j):
            if base[i] == i and abs(g[i, j]) > 1.0 - 1e-13:
                base[j], coef[j] = i, np.sign(g[i, j]) * d[j] / d[i]
                break
    keep = np.flatnonzero(base == np.arange(k))
    if len(keep) == 0:
        return np.zeros((1, k))
    try:
        r1 = np.linalg.cholesky(g[np.ix_(keep, keep)]).T
        if np.linalg.cond(r1) > 1e7:
            raise np.linalg.LinAlgError("ill-conditioned")
        q = s[:, keep] @ np.linalg.inv(r1)
        rk = (np.linalg.cholesky(q.T @ q).T @ r1) * d[keep]
    except np.linalg.LinAlgError:
        rk = np.linalg.qr(a[:, keep], mode="r")
    r = np.zeros((len(keep), k))
    r[:, keep] = rk
    pos = {c: n for n, c in enumerate(keep)}
    for j in range(k):
        if base[j] >= 0 and base[j] != j:
            r[:, j] = coef[j] * rk[:, pos[base[j]]]
    return r


@dataclass
class CalibrationStats:
    """Mergeable sufficient statistics of the stepwise calibration.

    ``trips[id] = (R, moments_of_y)`` of the used samples of that trip: R the upper
    triangular factor of [X y] (columns: the candidate terms, then y);
    ``mass_sum``/``mass_n`` over usable samples (the reference mass); ``counts`` as
    :attr:`sumo_drvpw.data.measured.Measured.counts`, summed over batches.
    """

    names: tuple[str, ...]
    trips: dict = field(default_factory=dict)
    mass_sum: float = 0.0
    mass_n: int = 0
    counts: dict = field(default_factory=dict)
    rows: int = 0
    source: str | None = None
    vehicle: object = None
    files: list = field(default_factory=list)
    #: Σ air density over usable samples [kg/m³] (the mean reads the aero coefficient)
    rho_sum: float = 0.0
    #: up to two distinct speeds (0.1 m/s steps) above ``moving_mps``: can v-terms be told apart?
    speeds: frozenset = frozenset()
    moving_mps: float = 0.5
    #: (min, max) of speed [m/s] and acceleration [m/s²] over the used samples
    ranges: tuple = ((math.inf, -math.inf), (math.inf, -math.inf))

    def columns(self) -> frozenset:
        """Columns to read: the reader's canonical ones and the signals the candidates name."""
        from sumo_drvpw.data.stream import CANONICAL

        return CANONICAL | {s for t in self.names for s in parse_term(t).signals}

    def add(self, m) -> "CalibrationStats":
        """Accumulate one batch (a :class:`~sumo_drvpw.data.measured.Measured` of whole trips)."""
        use = calibration_mask(m, self.names)
        y = np.asarray(m.power_w, float)
        u = np.asarray(m.usable, bool)
        self.mass_sum += float(np.sum(m.inputs.mass[u]))
        self.rho_sum += float(np.sum(m.inputs.rho[u]))
        self.mass_n += int(u.sum())
        if len(self.speeds) < 2:
            v = np.asarray(m.inputs.v, float)
            mv = np.unique(np.round(v[u & (v > self.moving_mps)], 1))[:2]
            self.speeds = frozenset(list(self.speeds | set(mv.tolist()))[:2])
        self.rows += len(y)
        c = m.counts
        c["excluded_nonfinite_power"] = int((~np.isfinite(y)).sum())
        self.counts = _add_counts(self.counts, c)
        self.source = self.source or m.source
        self.vehicle = self.vehicle or m.vehicle
        for f in m.log.files:
            if f not in self.files:
                self.files.append(f)
        idx = np.flatnonzero(use)
        if len(idx) == 0:
            return self
        self.ranges = _merge_ranges(self.ranges, tuple(
            (float(np.nanmin(a[idx])), float(np.nanmax(a[idx])))
            for a in (np.asarray(m.inputs.v, float), np.asarray(m.inputs.a, float))))
        x = term_matrix(self.names, m.inputs.take(idx))
        yu = y[idx]
        trip = np.asarray(m.inputs.trip)[idx]
        starts = np.flatnonzero(np.r_[True, trip[1:] != trip[:-1]])
        for a, b in zip(starts, np.r_[starts[1:], len(idx)]):
            xs, ys = x[a:b], yu[a:b]
            t = str(trip[a])
            if t in self.trips:
                raise UserError(f"trip_id '{t}' appears in more than one place; give each "
                                "trip its own id")
            self.trips[t] = (tall_r(np.column_stack([xs, ys])), Moments.of(ys[:, None]))
        return self

    def merge(self, o: "CalibrationStats") -> "CalibrationStats":
        dup = set(self.trips) & set(o.trips)
        if dup:
            raise UserError(f"trip_id '{sorted(dup)[0]}' appears in more than one place; give "
                            "each trip its own id")
        out = CalibrationStats(self.names, {**self.trips, **o.trips}, self.mass_sum + o.mass_sum,
                               self.mass_n + o.mass_n, _add_counts(self.counts, o.counts),
                               self.rows + o.rows, self.source or o.source,
                               self.vehicle or o.vehicle,
                               self.files + [f for f in o.files if f not in self.files],
                               self.rho_sum + o.rho_sum,
                               frozenset(list(self.speeds | o.speeds)[:2]), self.moving_mps,
                               _merge_ranges(self.ranges, o.ranges))
        return out

    def factor(self, trips=None) -> tuple[np.ndarray, Moments]:
        """R of [X y] over all (or the named) trips (TSQR) and the moments of y."""
        k = len(self.names)
        rs, mom = [np.zeros((0, k + 1))], Moments.empty(1)
        for t in (self.trips if trips is None else trips):
            r, mm = self.trips[t]
            rs.append(r)
            mom = mom.merge(mm)
        stack = np.vstack(rs)
        return np.linalg.qr(stack, mode="r") if len(stack) else np.zeros((1, k + 1)), mom

    def gram(self, trips=None):
        """The :class:`~sumo_drvpw.fit.ols.Gram` (XᵀX, Xᵀy, yᵀy, n) of all or the named
        trips, the factor R of [X y] and the moments of y."""
        r, mom = self.factor(trips)
        k = len(self.names)
        x, y = r[:, :k], r[:, k]
        return Gram(x.T @ x, x.T @ y, float(y @ y), mom.n, self.names), r, mom


def _merge_ranges(a: tuple, b: tuple) -> tuple:
    return tuple((min(x[0], y[0]), max(x[1], y[1])) for x, y in zip(a, b))


def ols_from_r(r: np.ndarray, idx: list[int], n: int):
    """statsmodels OLS results of the columns ``idx`` from the triangular factor alone.

    Parameters
    ----------
    r : upper triangular R of [X y] ((k+1) × (k+1), or any matrix with RᵀR = [X y]ᵀ[X y])
    idx : the columns of X to regress on; n : the number of samples [-]

    With [X_S y] = Q·[R_S z; 0 ρ] (QR of the selected columns), OLS of [z; ρ] on the
    (|S|+1) × |S| design [R_S; 0] has the same params, XᵀX, Xᵀy, ssr (ρ²) and uncentred
    TSS (yᵀy) as the full regression; nobs and df_resid are set to the real n and n − |S|,
    so bse, t and p-values, llf, AIC/BIC, R² (uncentred: no intercept, ``hasconst=False``)
    and the condition number are exact. Residual diagnostics of ``summary()`` (Omnibus,
    Jarque–Bera, Durbin–Watson, skew, kurtosis) describe the compact design, not the
    samples: they are not meaningful here.
    """
    import statsmodels.api as sm

    k = len(idx)
    rs = np.linalg.qr(r[:, list(idx) + [r.shape[1] - 1]], mode="r")
    design, target = np.zeros((k + 1, k)), np.zeros(k + 1)
    m = min(rs.shape[0], k + 1)
    design[:m] = rs[:m, :k]
    target[:m] = rs[:m, k]
    model = sm.OLS(target, design, hasconst=False)
    model.nobs = float(n)
    model.df_resid = float(n - k)
    res = model.fit()
    inner = getattr(res, "_results", res)
    inner.__dict__["_nobs_int"] = float(n)
    inner._cache["nobs"] = float(n)
    res.model.__dict__.pop("pinv_wexog", None)
    return res


def calibrate_from_stats(st: CalibrationStats, p_enter: float = 0.10, p_remove: float = 0.15,
                         counts: dict | None = None, reference_mass_kg: float | None = None,
                         trips=None):
    """:func:`sumo_drvpw.fit.calibrate.calibrate` on accumulated statistics (same result).

    Parameters
    ----------
    st : :class:`CalibrationStats` over the candidates
    p_enter, p_remove : p-value thresholds of forward–backward selection
    counts : sample counts for the provenance (default ``st.counts``)
    reference_mass_kg : mean mass of the usable samples [kg] (default from ``st``)
    trips : optional subset of trip ids to fit on (e.g. a training fold)
    """
    from sumo_drvpw.fit.calibrate import CalibrationResult, stepwise

    cands = st.names
    g, r, mom = st.gram(trips)
    if g.n <= len(cands):
        raise UserError(f"too few usable samples ({g.n}) to calibrate {len(cands)} candidate terms")
    if not np.all(np.isfinite(g.xtx)):
        bad = [cands[j] for j in range(len(cands)) if not np.isfinite(g.xtx[j, j])]
        raise UserError(f"candidate term(s) {bad} are not finite on the usable samples")
    sel, trace = stepwise(g, p_enter, p_remove)
    dropped = [{"term": t["term"], "reason": t["reason"]} for t in trace if t["action"] == "drop"]
    if not sel:
        raise UserError("no candidate term entered the model at p-to-enter "
                        f"{p_enter}: the measured power is not explained by {list(cands)}")
    res = ols_from_r(r, [cands.index(s) for s in sel], g.n)
    res.model.data.xnames = list(sel)
    sst = float(mom.m2[0, 0])
    r2 = 1.0 - float(res.ssr) / sst if sst > 0 else float("nan")
    counts = dict(st.counts if counts is None else counts)
    counts["files"] = len(st.files)
    counts["used"] = g.n
    if reference_mass_kg is None and st.mass_n:
        reference_mass_kg = st.mass_sum / st.mass_n
    return CalibrationResult(
        terms=list(sel), params=dict(zip(sel, map(float, res.params))),
        std_err=dict(zip(sel, map(float, res.bse))), p_values=dict(zip(sel, map(float, res.pvalues))),
        r2=r2, r2_uncentered=float(res.rsquared), n=g.n, counts=counts, trace=trace,
        settings={"candidates": list(cands), "p_enter": p_enter, "p_remove": p_remove},
        reference_mass_kg=reference_mass_kg, results=res, dropped=dropped,
        # the validity range of all trips streamed (also when fitted on a subset of them)
        speed_range_mps=st.ranges[0], accel_range_mps2=st.ranges[1])


# ------------------------------------------------------------------------ compare

def _keys(trip: np.ndarray) -> np.ndarray:
    """A deterministic uniform key in [0, 1) per sample from its trip id and position in
    the trip, so the reservoir is the same whatever the batching or engine."""
    out = np.empty(len(trip))
    starts = np.flatnonzero(np.r_[True, trip[1:] != trip[:-1]]) if len(trip) else []
    bounds = np.r_[starts, len(trip)]
    for a, b in zip(bounds[:-1], bounds[1:]):
        seed = zlib.crc32(str(trip[a]).encode())
        out[a:b] = np.random.default_rng(seed).random(b - a)
    return out


@dataclass
class _Reservoir:
    """Bottom-k sample by key: columns (dict name → array) of the k smallest keys."""

    k: int
    key: np.ndarray
    cols: dict

    def add(self, key: np.ndarray, cols: dict) -> "_Reservoir":
        allk = np.r_[self.key, key]
        allc = {c: np.r_[self.cols[c], cols[c]] if c in self.cols else cols[c] for c in cols}
        if len(allk) > self.k:
            keep = np.argpartition(allk, self.k - 1)[:self.k]
            keep.sort()
            allk = allk[keep]
            allc = {c: v[keep] for c, v in allc.items()}
        return _Reservoir(self.k, allk, allc)


@dataclass
class _EqStats:
    """Per-equation sums of a comparison over the samples with a finite prediction."""

    cats: list
    mom: dict            # subset → Moments of [meas, pred] (all, light, heavy)
    sse: dict            # subset → Σe²
    se: dict             # subset → Σe
    sae: float           # Σ|e|
    ecat: Moments        # [e, category powers]
    cmin: np.ndarray
    cmax: np.ndarray
    eref: Moments | None  # [e, reference category powers]
    rmin: np.ndarray | None
    rmax: np.ndarray | None
    energy: np.ndarray   # Σ P_cat·Δt over samples with positive total
    hs: np.ndarray       # n, Σe, Σe² at ≥ 80 km/h, then below
    bins: np.ndarray     # (3, nbins): n, Σe, Σe² per 10 km/h speed bin
    trip_e: dict         # trip → (E⁺meas, E⁺pred, E_net meas, E_net pred)

    def merge(self, b: "_EqStats") -> "_EqStats":
        if self.cats != b.cats:
            raise UserError(f"compare: the categories of an equation differ between batches "
                            f"({self.cats} and {b.cats})")
        nb = max(self.bins.shape[1], b.bins.shape[1])
        bins = np.zeros((3, nb))
        bins[:, :self.bins.shape[1]] += self.bins
        bins[:, :b.bins.shape[1]] += b.bins
        return _EqStats(
            self.cats, {k: self.mom[k].merge(b.mom[k]) for k in self.mom},
            {k: self.sse[k] + b.sse[k] for k in self.sse}, {k: self.se[k] + b.se[k] for k in self.se},
            self.sae + b.sae, self.ecat.merge(b.ecat),
            np.minimum(self.cmin, b.cmin), np.maximum(self.cmax, b.cmax),
            None if self.eref is None else self.eref.merge(b.eref),
            None if self.rmin is None else np.minimum(self.rmin, b.rmin),
            None if self.rmax is None else np.maximum(self.rmax, b.rmax),
            self.energy + b.energy, self.hs + b.hs, bins, {**self.trip_e, **b.trip_e})


def _minmax(m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if len(m) == 0:
        return np.full(m.shape[1], np.inf), np.full(m.shape[1], -np.inf)
    return m.min(axis=0), m.max(axis=0)


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
    """

    def __init__(self, equations, reference: str | None = None, reservoir: int = RESERVOIR):
        self.equations = list(equations)
        self.reference = reference
        self.k = int(reservoir)
        self.n = 0
        self.rows = 0
        self.meas = Moments.empty(1)
        self.meas_traction = 0.0
        self.n_light = self.n_heavy = self.n_high = 0
        self.eq: dict[str, _EqStats] = {}
        self.ref_cats: list | None = None
        self.res: _Reservoir | None = None
        self.counts: dict = {}
        self.trips: set = set()
        self.source: str | None = None
        self.vehicle = None
        self.files: list = []

    def columns(self) -> frozenset:
        """Columns to read: the reader's canonical ones and the signals the equations name."""
        from sumo_drvpw.data.stream import CANONICAL

        return CANONICAL | {s for eq in self.equations for t in eq.terms
                            for s in parse_term(t).signals}

    def add(self, m) -> "CompareStats":
        """Accumulate one batch: the usable samples of a Measured of whole trips."""
        from sumo_drvpw.fit.compare import SPEED_BIN_MPS

        self.rows += len(m.power_w)
        self.counts = _add_counts(self.counts, m.counts)
        self.source = self.source or m.source
        self.vehicle = self.vehicle or m.vehicle
        self.files += [f for f in m.log.files if f not in self.files]
        idx = np.flatnonzero(np.asarray(m.usable, bool))
        if len(idx) == 0:
            return self
        x = m.inputs.take(idx)
        meas = np.asarray(m.power_w, float)[idx]
        dt = m.log.df["dt_s"].to_numpy(float)[idx]
        codes, uniq = pd.factorize(np.asarray(x.trip), sort=False)  # hashing, not sorting text
        uniq = np.asarray(uniq).astype(str)
        trip = np.asarray(x.trip)
        if self.trips.intersection(uniq):
            raise UserError(f"trip_id '{sorted(self.trips.intersection(uniq))[0]}' appears in "
                            "more than one place; give each trip its own id")
        self.trips.update(uniq)
        v = np.asarray(x.v, float)
        n = len(meas)
        self.n += n
        self.meas = self.meas.merge(Moments.of(meas[:, None]))
        self.meas_traction += float(np.where(meas > 0.0, meas, 0.0) @ dt)
        heavy_all = meas >= HEAVY_LOAD_W
        self.n_heavy += int(heavy_all.sum())
        self.n_light += int(n - heavy_all.sum())
        self.n_high += int((v >= HIGH_SPEED_MPS).sum())
        pw = {eq.name: eq.category_powers(x) for eq in self.equations}
        if self.reference is not None and self.ref_cats is None:
            self.ref_cats = _categories(pw[self.reference])
        cols = {"meas": meas, "v": v, "dt": dt}
        for eq in self.equations:
            prev = self.eq.get(eq.name)
            cats = prev.cats if prev is not None else _categories(pw[eq.name])
            zero = np.zeros(n)
            cw = {c: np.asarray(pw[eq.name].get(c, zero), float) for c in cats}
            pred = np.sum(list(cw.values()), axis=0) if cw else zero
            err = pred - meas
            ok = np.isfinite(err)
            e, mo, po, vo, dto = err[ok], meas[ok], pred[ok], v[ok], dt[ok]
            hv = mo >= HEAVY_LOAD_W
            cm = np.column_stack([cw[c][ok] for c in cats]) if cats else np.zeros((len(e), 0))
            wgt = np.where(cm.sum(axis=1) > 0.0, dto, 0.0)
            eref = rmin = rmax = None
            if self.reference is not None:
                rp = pw[self.reference]
                rm = np.column_stack([np.asarray(rp.get(c, zero), float)[ok] for c in self.ref_cats]) \
                    if self.ref_cats else np.zeros((len(e), 0))
                eref = Moments.of(np.column_stack([e, rm]))
                rmin, rmax = _minmax(rm)
            hi = vo >= HIGH_SPEED_MPS
            hs = np.array([hi.sum(), e[hi].sum(), e[hi] @ e[hi],
                           (~hi).sum(), e[~hi].sum(), e[~hi] @ e[~hi]], float)
            b = np.floor(np.maximum(vo, 0.0) / SPEED_BIN_MPS + 1e-9).astype(np.int64)
            nb = int(b.max()) + 1 if len(b) else 0
            bins = np.vstack([np.bincount(b, minlength=nb), np.bincount(b, e, nb),
                              np.bincount(b, e * e, nb)]).astype(float)
            pm = np.where(ok, pred, 0.0)
            k = len(uniq)
            sums = [np.bincount(codes, np.where(meas > 0.0, meas, 0.0) * dt, k),
                    np.bincount(codes, np.where(pm > 0.0, pm, 0.0) * dt, k),
                    np.bincount(codes, meas * dt, k), np.bincount(codes, pm * dt, k)]
            cmin, cmax = _minmax(cm)
            st = _EqStats(
                cats, {"all": Moments.of(np.column_stack([mo, po])),
                       "light": Moments.of(np.column_stack([mo[~hv], po[~hv]])),
                       "heavy": Moments.of(np.column_stack([mo[hv], po[hv]]))},
                {"all": float(e @ e), "light": float(e[~hv] @ e[~hv]), "heavy": float(e[hv] @ e[hv])},
                {"all": float(e.sum()), "light": float(e[~hv].sum()), "heavy": float(e[hv].sum())},
                float(np.abs(e).sum()), Moments.of(np.column_stack([e, cm])), cmin, cmax,
                eref, rmin, rmax, cm.T @ wgt, hs, bins,
                {str(t): tuple(float(s[i]) for s in sums) for i, t in enumerate(uniq)})
            self.eq[eq.name] = st if prev is None else prev.merge(st)
            cols[f"pred:{eq.name}"] = pred
            cols[f"ok:{eq.name}"] = ok
            for c in cats:
                cols[f"cat:{eq.name}:{c}"] = cw[c]
        batch = _Reservoir(self.k, np.zeros(0), {}).add(_keys(trip), cols)
        self.res = batch if self.res is None else self.res.add(batch.key, batch.cols)
        return self

    def merge(self, o: "CompareStats") -> "CompareStats":
        """Add another CompareStats (e.g. a Dask partition's) to this one."""
        dup = self.trips & o.trips
        if dup:
            raise UserError(f"trip_id '{sorted(dup)[0]}' appears in more than one place; give "
                            "each trip its own id")
        self.trips |= o.trips
        self.n += o.n
        self.rows += o.rows
        self.counts = _add_counts(self.counts, o.counts)
        self.source = self.source or o.source
        self.vehicle = self.vehicle or o.vehicle
        self.files += [f for f in o.files if f not in self.files]
        self.meas = self.meas.merge(o.meas)
        self.meas_traction += o.meas_traction
        self.n_light += o.n_light
        self.n_heavy += o.n_heavy
        self.n_high += o.n_high
        self.ref_cats = self.ref_cats if self.ref_cats is not None else o.ref_cats
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
            raise UserError(f"no usable samples (all excluded: {self.counts})")
        order = np.argsort(self.res.key, kind="stable")
        r = {c: v[order] for c, v in self.res.cols.items()}
        comp = StreamedComparison(meas_w=r["meas"], speed_mps=r["v"], dt_s=r["dt"],
                                  measured_traction_energy_j=self.meas_traction,
                                  reference=self.reference)
        comp.stats = self
        for eq in self.equations:
            s = self.eq[eq.name]
            ok = r[f"ok:{eq.name}"]
            e = (r[f"pred:{eq.name}"] - r["meas"])[ok]
            energy = {c: float(s.energy[i]) for i, c in enumerate(s.cats)}
            total = float(sum(energy.values()))
            energy["total"] = total
            share = {c: (energy[c] / total if total > 0.0 else math.nan) for c in s.cats}
            comp.results[eq.name] = EquationResult(
                equation=eq, pred_w=r[f"pred:{eq.name}"],
                category_w={c: r[f"cat:{eq.name}:{c}"] for c in s.cats},
                metrics=_metrics(s), speed_bins=_speed_bins(s, e, r["v"][ok]),
                high_speed=_high_speed(s, e, r["v"][ok]),
                error_term_correlation=_corr(s.ecat, s.cats, s.cmin, s.cmax),
                energy_j=energy, energy_share=share,
                traction_energy_ratio=(total / self.meas_traction if self.meas_traction > 0.0
                                       else math.nan),
                error_reference_correlation=(None if s.eref is None else
                                             _corr(s.eref, self.ref_cats, s.rmin, s.rmax)))
        return comp


def _mean_rmse(n, s1, s2) -> tuple[float, float]:
    return (s1 / n, math.sqrt(s2 / n)) if n else (math.nan, math.nan)


def _speed_bins(s: _EqStats, e_sample, v_sample) -> list[dict]:
    """:func:`sumo_drvpw.fit.compare.speed_bins` with exact n, mean and RMSE per bin and
    percentiles from the reservoir sample."""
    from sumo_drvpw.fit.compare import SPEED_BIN_MPS, _error_summary
    from sumo_drvpw.model.constants import KMH

    b = np.floor(np.maximum(v_sample, 0.0) / SPEED_BIN_MPS + 1e-9).astype(np.int64)
    out = []
    for k in range(s.bins.shape[1]):  # a handful of bins, not samples
        lo, hi = k * SPEED_BIN_MPS, (k + 1) * SPEED_BIN_MPS
        row = {"lo_kmh": lo / KMH, "hi_kmh": hi / KMH, "lo_mps": lo, "hi_mps": hi}
        row.update(_error_summary(e_sample[b == k]))
        n = int(s.bins[0, k])
        row["n"] = n
        row["mean_w"], row["rmse_w"] = _mean_rmse(n, s.bins[1, k], s.bins[2, k])
        out.append(row)
    return out


def _high_speed(s: _EqStats, e_sample, v_sample) -> dict:
    """:func:`sumo_drvpw.fit.compare.high_speed_summary`: counts, means and RMSE exact,
    percentiles from the reservoir sample."""
    from sumo_drvpw.fit.compare import high_speed_summary

    out = high_speed_summary(e_sample, v_sample)
    n_hi, s1, s2, n_lo, b1, b2 = s.hs
    n = n_hi + n_lo
    out["fraction"] = n_hi / n if n else math.nan
    out["n"] = int(n_hi)
    out["mean_w"], out["rmse_w"] = _mean_rmse(n_hi, s1, s2)
    out["mean_below_w"], out["rmse_below_w"] = _mean_rmse(n_lo, b1, b2)
    return out


def _metrics(s: _EqStats) -> dict:
    """:func:`sumo_drvpw.fit.compare.metrics` from sums (same keys and conventions)."""
    from sumo_drvpw.fit.compare import MIN_SAMPLES

    def r2(k):
        m = s.mom[k]
        sst = float(m.m2[0, 0])
        return 1.0 - s.sse[k] / sst if m.n >= MIN_SAMPLES and sst > 0.0 else math.nan

    def r2c(k):
        m = s.mom[k]
        den = float(m.m2[0, 0]) * float(m.m2[1, 1])
        return float(m.m2[0, 1]) ** 2 / den if m.n >= MIN_SAMPLES and den > 0.0 else math.nan

    def mr(k):
        return _mean_rmse(s.mom[k].n, s.se[k], s.sse[k])

    n = s.mom["all"].n
    return {"n": n, "r2": r2("all"), "r2_light": r2("light"), "r2_heavy": r2("heavy"),
            "rmse_w": mr("all")[1], "mae_w": s.sae / n if n else math.nan, "bias_w": mr("all")[0],
            "n_light": s.mom["light"].n, "n_heavy": s.mom["heavy"].n,
            "rmse_light_w": mr("light")[1], "rmse_heavy_w": mr("heavy")[1],
            "bias_light_w": mr("light")[0], "bias_heavy_w": mr("heavy")[0],
            "r2_corr": r2c("all"), "r2_corr_light": r2c("light"), "r2_corr_heavy": r2c("heavy")}


def _corr(mom: Moments, cats: list, cmin: np.ndarray, cmax: np.ndarray) -> dict:
    """:func:`sumo_drvpw.fit.compare.error_term_correlation` from the co-moments of
    [error, category powers] (same conventions)."""
    from sumo_drvpw.fit.compare import MIN_SAMPLES

    n = mom.n
    see = float(mom.m2[0, 0])
    out, names, idx = {}, [], []
    for i, c in enumerate(cats):
        spp = float(mom.m2[i + 1, i + 1])
        r = slope = math.nan
        big = max(1.0, abs(float(cmin[i])), abs(float(cmax[i]))) if n else 1.0
        if n >= MIN_SAMPLES and spp > 0.0 and float(cmax[i] - cmin[i]) > 1e-9 * big:
            sep = float(mom.m2[0, i + 1])
            slope = sep / spp
            r = sep / math.sqrt(spp * see) if see > 0.0 else math.nan
            names.append(c)
            idx.append(i + 1)
        out[c] = {"r": r, "slope": slope, "partial_slope": math.nan}
    if names and n > len(names) + 1:
        fit = Gram(mom.m2[np.ix_(idx, idx)], mom.m2[idx, 0], see, n, tuple(names)).fit(
            list(range(len(names))))
        if fit is not None:  # collinear category powers: no partial slope (NaN)
            for c, v in zip(names, fit["beta"]):
                out[c]["partial_slope"] = float(v)
    return out


def _trip_block(trip_e: dict, net: bool) -> dict:
    """:func:`sumo_drvpw.fit.compare.trip_energy` (``net``: ``trip_net_energy``) from sums."""
    trips, errs = {}, []
    for t, (pm, pp, nm, npd) in trip_e.items():
        em, ep = (nm, npd) if net else (pm, pp)
        err = ep / em - 1.0 if em != 0.0 else math.nan
        trips[t] = {"measured_j": em, "predicted_j": ep, "error": err}
        if math.isfinite(err):
            errs.append(abs(err))
    return {"mean_abs_error": float(np.mean(errs)) if errs else math.nan,
            "max_abs_error": float(np.max(errs)) if errs else math.nan, "trips": trips}


def _streamed_comparison_class():
    from sumo_drvpw.fileio import plain as _jsonable
    from sumo_drvpw.fit.compare import Comparison

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
                    d["trip_energy"] = _jsonable(_trip_block(s.trip_e, net=False))
                    d["trip_net_energy"] = _jsonable(_trip_block(s.trip_e, net=True))
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
