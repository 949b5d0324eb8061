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
* compare (:mod:`sumo_drvpw.fit.stream_compare`): per equation the co-moments (Chan et al. pairwise update) of measured,
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
from dataclasses import dataclass, field

import numpy as np

from sumo_drvpw.data.trips import trip_signatures
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.ols import Gram
from sumo_drvpw.model.terms import parse_term, term_matrix



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
        return cls._of_t(np.array(x.T, order="C", copy=True))  # centred in place: a copy

    @classmethod
    def of_columns(cls, cols) -> "Moments":
        """Moments of d variables given as d arrays of n samples each (no n × d copy)."""
        if len(cols[0]) == 0:
            return cls.empty(len(cols))
        return cls._of_t(np.vstack([np.asarray(c, float) for c in cols]))

    @classmethod
    def _of_t(cls, xt: np.ndarray) -> "Moments":
        """From a d × n array (a copy, centred in place): each mean a contiguous
        (pairwise) sum, the co-moments one product."""
        mu = xt.mean(axis=1)
        xt -= mu[:, None]
        return cls(xt.shape[1], mu, xt @ xt.T)

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
    """Counts of two batches: numbers add, per-trip tables merge and lists join (batches
    hold whole trips), texts are kept (first seen; a grade source other than none wins:
    one batch without elevation does not make the logs carry none), except the
    acceleration's source: said of both from their mergeable ``accel_derivation``, as the
    reader says it of both read together (rows from the column, rows derived, the windows),
    and the grade's, wind's, air density's and measured power's: said from their rows per
    source (``grade_rows``, ``wind_rows``, ``air_density_rows``, ``power_rows``;
    :mod:`sumo_drvpw.data.conditions`).
    Of the reader's decimal counts, the seconds of logging gaps add (each batch's rounded to
    ms, as the reader rounds its sum) and the widest acceleration window is kept (the
    reader's max); other decimals (the options' limits) are kept as first seen."""
    out = dict(a)
    for k, v in b.items():
        if k in out and k == "time_gaps_s":
            out[k] = round(float(out[k]) + float(v), 3)
        elif k in out and k == "accel_window_s":
            out[k] = max(float(out[k]), float(v))
        elif k in out and isinstance(v, (int, np.integer)) and not isinstance(v, bool) \
                and isinstance(out[k], (int, np.integer)):
            out[k] = int(out[k]) + int(v)
        elif isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = {**out[k], **v}
        elif isinstance(v, list) and isinstance(out.get(k), list):
            out[k] = out[k] + [x for x in v if x not in out[k]]
        elif k == "grade_source" and str(out.get(k, "")).startswith("none") and not str(v).startswith("none"):
            out[k] = v
        elif k == "accel_outlier_limit_mps2" or k not in out:
            out.setdefault(k, v)
    if "accel_derivation" in a and "accel_derivation" in b:
        # the acceleration's source of both, as the reader says it of both read together
        from sumo_drvpw.data.resolution import accel_counts, merge_accel_derivation

        for k in ("accel_window_s", "accel_derived_rows"):
            out.pop(k, None)
        out.update(accel_counts(merge_accel_derivation(a["accel_derivation"], b["accel_derivation"])))
    from sumo_drvpw.data.conditions import ROWS_OF, merge_rows, source_counts

    if any(k in a and k in b for k in ROWS_OF):  # grade, wind, density: rows per source add
        for k in ROWS_OF:
            if k in a and k in b:
                out[k] = merge_rows(a[k], b[k], k)
        out.pop("grade_filled_rows", None)
        out.update(source_counts(out))
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
    a Householder QR at the cost of two Gram products and one product by a k × k matrix.

    CholeskyQR2 on the column-scaled matrix (Fukaya et al. 2014, "CholeskyQR2: a simple
    and communication-avoiding algorithm for computing a tall-skinny QR factorization"):
    R₁ = chol(SᵀS), Q₁ = S·R₁⁻¹, R₂ = chol(Q₁ᵀQ₁), R = R₂·R₁·D for S = a·D⁻¹ (SᵀS is
    taken as D⁻¹(aᵀa)D⁻¹ and Q₁ as a·(D⁻¹R₁⁻¹): no scaled copy of a). Columns that are
    zero, or a multiple c·a_i of an earlier column (e.g. aero and v³ in still air at one
    air density), get R's column c·R_i, which is exact: R = Qᵀa. Beyond a scaled condition
    number of 1e7 (or when a Cholesky fails) Householder QR is used.
    """
    k = a.shape[1]
    g0 = a.T @ a
    d = np.sqrt(np.maximum(np.diag(g0), 0.0))
    safe = np.where(d > 0, d, 1.0)
    g = g0 / np.outer(safe, safe)
    base = np.arange(k)          # column whose multiple each column is (itself if kept)
    coef = np.ones(k)
    near = np.abs(g) > 1.0 - 1e-13
    for j in range(k):
        if d[j] == 0:
            base[j], coef[j] = -1, 0.0
            continue
        for i in np.flatnonzero(near[:j, j]):
            if base[i] == i:
                base[j], coef[j] = i, np.sign(g[i, j]) * d[j] / d[i]
                break
    keep = np.flatnonzero(base == np.arange(k))
    if len(keep) == 0:
        return np.zeros((1, k))
    try:
        r1 = np.linalg.cholesky(g[np.ix_(keep, keep)]).T
        if np.linalg.cond(r1) > 1e7:
            raise np.linalg.LinAlgError("ill-conditioned")
        m = np.linalg.inv(r1) / safe[keep][:, None]        # D⁻¹R₁⁻¹ (rows of kept columns)
        q = a @ m if len(keep) == k else a[:, keep] @ m
        rk = (np.linalg.cholesky(q.T @ q).T @ r1) * d[keep]
    except np.linalg.LinAlgError:
        rk = np.linalg.qr(a[:, keep], mode="r")
    if len(keep) == k:
        return rk
    r = np.zeros((len(keep), k))
    r[:, keep] = rk
    pos = {c: n for n, c in enumerate(keep)}
    for j in range(k):
        if base[j] >= 0 and base[j] != j:
            r[:, j] = coef[j] * rk[:, pos[base[j]]]
    return r


def trip_twice(trip: str, first: str, again: str) -> UserError:
    """The refusal of a trip id met in two places (two files, or two places of one), naming
    where."""
    where = first if first == again else f"{first} and {again}"
    return UserError(f"{where}: trip_id '{trip}' appears in more than one place; samples of a trip "
                     "must be contiguous, give each trip its own id")


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
    #: trip → the file(s) of the batch it came in (to name both places of a repeated id)
    trip_files: dict = field(default_factory=dict)
    #: trip → its signature (data/trips.trip_signatures: the equation keeps them, so compare
    #: tells the trips it was calibrated on, from whatever file)
    signatures: dict = field(default_factory=dict)

    def columns(self) -> frozenset:
        """Columns to read: the reader's canonical ones and the signals the candidates name."""
        from sumo_drvpw.data.stream import CANONICAL

        return CANONICAL | {s for t in self.names for s in parse_term(t).columns}

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
        self.source = self.counts.get("power_source") or self.source or m.source  # of all batches
        self.vehicle = self.vehicle or m.vehicle
        for f in m.log.files:
            if f not in self.files:
                self.files.append(f)
        self.signatures.update(trip_signatures(m.log.df))
        idx = np.flatnonzero(use)
        if len(idx) == 0:
            return self
        self.ranges = _merge_ranges(self.ranges, tuple(
            (float(np.nanmin(a[idx])), float(np.nanmax(a[idx])))
            for a in (np.asarray(m.inputs.v, float), np.asarray(m.inputs.a, float))))
        k = len(self.names)
        every = len(idx) == len(y)
        codes = _trip_codes(m)
        codes = codes if every else codes[idx]
        starts = np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])
        ends = np.r_[starts[1:], len(idx)]
        ids = np.asarray(m.inputs.trip)[idx[starts]]
        x = _light_inputs(m.inputs, self.names)
        # blocks of whole trips of about BLOCK_ROWS: the design is built per block and
        # factored per trip while it is in cache (the batch's arrays are not)
        lo = 0
        while lo < len(starts):
            hi = lo + 1
            while hi < len(starts) and ends[hi - 1] - starts[lo] < BLOCK_ROWS:
                hi += 1
            a0, b0 = int(starts[lo]), int(ends[hi - 1])
            rows = slice(a0, b0) if every else idx[a0:b0]
            xy = np.empty((b0 - a0, k + 1))  # [X y]: a trip's rows are one contiguous view
            xy[:, :k] = term_matrix(self.names, x.take(rows))
            xy[:, k] = y[rows]
            here = ", ".join(map(str, m.log.files))
            for t, a, b in zip(ids[lo:hi], starts[lo:hi] - a0, ends[lo:hi] - a0):
                t = str(t)
                if t in self.trips:
                    raise trip_twice(t, self.trip_files.get(t, here), here)
                self.trips[t] = (tall_r(xy[a:b]), Moments.of(xy[a:b, k:]))
                self.trip_files[t] = here
            lo = hi
        return self

    def merge(self, o: "CalibrationStats") -> "CalibrationStats":
        dup = sorted(set(self.trips) & set(o.trips))
        if dup:
            raise trip_twice(dup[0], self.trip_files.get(dup[0], "?"), o.trip_files.get(dup[0], "?"))
        out = CalibrationStats(self.names, {**self.trips, **o.trips}, self.mass_sum + o.mass_sum,
                               self.mass_n + o.mass_n, _add_counts(self.counts, o.counts),
                               self.rows + o.rows, self.source or o.source,
                               self.vehicle or o.vehicle,
                               self.files + [f for f in o.files if f not in self.files],
                               self.rho_sum + o.rho_sum,
                               frozenset(list(self.speeds | o.speeds)[:2]), self.moving_mps,
                               _merge_ranges(self.ranges, o.ranges), {**self.trip_files, **o.trip_files},
                               {**self.signatures, **o.signatures})
        out.source = out.counts.get("power_source") or out.source  # of both
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


#: Rows of the design built at a time in calibrate's accumulation (whole trips; ~1 MB).
BLOCK_ROWS = 16_384


def _light_inputs(x, names):
    """The inputs the terms ``names`` read: the signals they name, trip ids only when a
    term names a trip (so taking rows copies nothing else)."""
    from sumo_drvpw.model.terms import Inputs

    sig = {s for t in names for s in parse_term(t).columns}
    trip = any(f.startswith("trip=") for t in names for f in parse_term(t).factors)
    return Inputs(x.v, x.a, x.theta, x.wind, x.mass, x.rho,
                  {s: v for s, v in x.signals.items() if s in sig},
                  x.trip if trip else None, x.v_acc)


def _trip_codes(m) -> np.ndarray:
    """Integer trip code per sample of a Measured batch (no Python strings)."""
    from sumo_drvpw.data.trips import trip_codes_of

    return trip_codes_of(m.log.df["trip_id"])


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
    from statsmodels.regression.linear_model import OLS  # not statsmodels.api: ~1 s of imports

    k = len(idx)
    rs = np.linalg.qr(r[:, list(idx) + [r.shape[1] - 1]], mode="r")
    design, target = np.zeros((k + 1, k)), np.zeros(k + 1)
    m = min(rs.shape[0], k + 1)
    design[:m] = rs[:m, :k]
    target[:m] = rs[:m, k]
    model = OLS(target, design, hasconst=False)
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
    from sumo_drvpw.fit.calibrate import CalibrationResult, select_terms

    cands = st.names
    g, r, mom = st.gram(trips)
    sel, trace, dropped = select_terms(g, p_enter, p_remove)
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
