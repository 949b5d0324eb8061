"""The residual tracer: find effects a declared DrvPw equation lacks, on held-out data.

Starting from a declared equation (its terms; coefficients refitted on training folds),
the tracer builds candidate effects from the log itself, scores each on held-out data,
adds the best one only when it improves held-out error significantly, refits, and
repeats until nothing significant remains.

Candidates (generated from the data, no fixed list of culprits)
----------------------------------------------------------------
For every screened extra column ``c`` of the log (numeric or boolean):

* ``[c]*v^k`` (k = 0…3; written ``[c]`` for k = 0): an additive load c·vᵏ [W per unit];
* ``[c]*TERM`` for each declared term: c changes an existing term (e.g. rolling
  resistance growing with a tyre temperature, aero with a roof-box flag);
* ``[c]^2*v^k`` (k = 0…3, not for two-valued columns): squared forms.

Plus ``v^k`` (k = 0…4) not already spanned by the model (a function of speed alone: the
seed paper's residual followed a quadratic in speed), and two per-trip effects when the
data hold ≥ 2 trips: a per-trip offset (one constant per trip, ``trip=ID``) and a
per-trip mass change (one factor per trip on the mass-bearing part of the current model,
Σ cₖ·termₖ over the terms that carry m; written to the equation as ``trip=ID*TERM``).

Column screening (leakage and junk)
-----------------------------------
A column is not offered when it (in this order): is one of the spec's measured-power
source columns (``power_w``, motor/MG1/MG2/engine torque and speed, battery voltage
and current — the target or a component of it, whichever source was used); matches
``exclude`` or misses ``include`` (glob patterns); has more than ``max_nan`` NaN among
usable samples; is constant; is id-like (monotone within every trip with > 50 %
distinct values: a clock, counter or odometer); is derived from the model inputs
(R² ≥ ``derived_r2`` of an OLS on 1, v, a, sin θ, wind — e.g. a GPS speed or an IMU
acceleration); is the same quantity as a source column under another name (|corr| ≥
``proxy_corr`` with a source column present in the log, e.g. an "executed" MG2
torque); or is a proxy of the target (|corr(c·vᵏ, P)| ≥ ``proxy_corr`` for some
k = 0…3 — a logged power, a torque, a pedal that *is* the demand). The reasons are
reported. Driver-command columns below the proxy threshold (pedal position, throttle)
are still offered; exclude them with ``exclude`` when they should not count as effects.

Samples: usable samples (``workflow.load_measured``) with finite declared terms and
offered signals, moving at ≥ ``min_speed_mps`` (0.1 m/s): at standstill the driving
power is zero by definition of the target and every declared term vanishes, so those
samples carry no information about effects and would only penalize loads that exist
while moving.

Validation and the test
-----------------------
Samples are cut into contiguous blocks of ``block_s`` seconds within trips. With ≥ 3
trips (``validation='auto'`` or ``'trip'``) the folds are groups of whole trips (K =
min(folds, trips)); otherwise folds are blocks, interleaved within each trip (block j of
a trip goes to fold j mod K). Per-trip candidates cannot be evaluated on a trip that was
held out entirely, so they — and every candidate once a per-trip effect is in the model
— are scored on the block folds. For each fold the model (current terms + candidate) is
fitted on the other folds by OLS from per-block sufficient statistics (ZᵀZ, Zᵀy, yᵀy;
one pass over the samples per candidate) and evaluated on the held-out fold. The unit
of the test is the held-out block: d_b = SSE_b(model) − SSE_b(model + candidate). The
best candidate (smallest held-out SSE) is accepted when its one-sided p-value — twice
the smaller of a paired t-test of mean(d_b) > 0 and a Wilcoxon signed-rank test of a
positive shift of d_b (Bonferroni over the two) — times m, the number of candidates
scored in that round (Bonferroni), is < ``alpha``, **and** its relative held-out RMSE
gain 1 − √(SSE_c/SSE_0) ≥ ``min_gain``.

Reported numbers: coefficients and their standard errors come from an OLS fit on all
analysis samples (classical standard errors; autocorrelated residuals make them
optimistic), ``p_value`` is the Bonferroni-corrected held-out test p-value; metrics
(``compare.metrics``) are on the concatenated held-out predictions; the energy share of
a term is its traction energy (Σ P_term·Δt over samples with predicted power > 0) over
the model's total traction energy.
"""

from __future__ import annotations

import datetime as _dt
import fnmatch
import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
from sumo_drvpw.fit.compare import metrics as _metrics
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.errors import UserError
from sumo_drvpw.model.terms import Inputs, parse_term, term_matrix

#: Columns from which the spec derives measured power: never offered as effects.
POWER_SOURCE_COLUMNS = ("power_w", "motor_torque_nm", "motor_speed_rpm", "mg1_speed_rpm",
                        "mg1_torque_nm", "mg2_speed_rpm", "mg2_torque_nm", "ice_speed_rpm",
                        "battery_voltage_v", "battery_current_a")
METRIC_KEYS = ("rmse_w", "mae_w", "r2", "r2_light", "r2_heavy", "bias_w")
_ROW_CHUNK = 65536


@dataclass
class TraceOptions:
    """Settings of the tracer (see the module docstring for their meaning)."""

    validation: str = "auto"      # auto | trip | blocks
    block_s: float = 60.0         # block length [s]
    folds: int = 5
    alpha: float = 0.05
    min_gain: float = 0.01        # minimum relative held-out RMSE gain
    max_findings: int = 5
    include: tuple = ()           # glob patterns of columns to offer (empty: all)
    exclude: tuple = ()           # glob patterns of columns never to offer
    max_nan: float = 0.05
    proxy_corr: float = 0.9
    derived_r2: float = 0.99
    per_trip: bool = True
    min_speed_mps: float = 0.1    # samples below this speed are left out [m/s]
    max_trips_per_trip_effects: int = 400
    batch: int = 16

    def check(self):
        if self.validation not in ("auto", "trip", "blocks"):
            raise UserError(f"--validation must be auto, trip or blocks, got '{self.validation}'")
        if not self.block_s > 0:
            raise UserError(f"--block-s must be > 0, got {self.block_s}")
        if self.folds < 2:
            raise UserError(f"--folds must be ≥ 2, got {self.folds}")
        if not 0 < self.alpha < 1:
            raise UserError(f"--alpha must be between 0 and 1, got {self.alpha}")
        if not 0 <= self.min_gain < 1:
            raise UserError(f"--min-gain must be in [0, 1), got {self.min_gain}")
        if self.max_findings < 0:
            raise UserError(f"--max-findings must be ≥ 0, got {self.max_findings}")
        if not 0 <= self.max_nan <= 1:
            raise UserError(f"--max-nan must be in [0, 1], got {self.max_nan}")


# ------------------------------------------------------------------ candidates

@dataclass
class Candidate:
    """One candidate effect: a column (or a per-trip family of columns) to add."""

    term: str                 # term as added ("[c]*v^1", "v^2", "trip=*", "trip=*·mass")
    effect: str               # plain-language name
    signals: tuple[str, ...]
    kind: str                 # signal | signal_x_term | signal_sq | speed | trip_offset | trip_mass
    scatter: bool = False     # one coefficient per trip


@dataclass
class _Col:
    """A column of the model: values on analysis samples, scale, per-trip or not."""

    cand: Candidate
    values: np.ndarray
    scale: float
    offset: int = 0          # first position in the full coefficient vector
    mass_terms: dict = field(default_factory=dict)  # per-trip mass: term → coefficient at build



def _vname(k: int) -> str:
    return {0: "", 1: " × v (a force proportional to it)", 2: " × v²",
            3: " × v³ (drag-like)"}[k]


def _glob_any(name: str, patterns) -> bool:
    return any(fnmatch.fnmatchcase(name, p) for p in patterns)


def screen_signals(signals: dict, y: np.ndarray, x: Inputs, trip_codes: np.ndarray,
                   usable: np.ndarray, opt: TraceOptions) -> tuple[dict, list[dict]]:
    """Pick the extra columns to offer as candidate signals (see module docstring).

    Returns (name → float array over all samples, list of {column, reason} skipped).
    """
    kept, skipped = {}, []
    u = usable
    v, a, th, w = x.v[u], x.a[u], x.theta[u], x.wind[u]
    kin = np.column_stack([np.ones(u.sum()), v, a, np.sin(th), w])
    kin_q, _ = np.linalg.qr(kin)
    yu = y[u]
    yc = yu - yu.mean()
    tc = trip_codes[u]
    same_trip = tc[1:] == tc[:-1]
    src = {}
    for c in POWER_SOURCE_COLUMNS:
        if c in signals:
            a = np.asarray(signals[c], float)[u]
            a = np.where(np.isfinite(a), a, np.nanmean(a) if np.isfinite(a).any() else 0.0)
            if a.std() > 0:
                proj = kin_q.T @ a
                r2 = 1.0 - max(float(a @ a) - float(proj @ proj), 0.0) / float(((a - a.mean()) ** 2).sum())
                if r2 < opt.derived_r2:  # a motor speed ∝ vehicle speed is no power component to match
                    src[c] = (a - a.mean()) / a.std()
    for name in signals:
        arr = np.asarray(signals[name], dtype=float)
        if name in POWER_SOURCE_COLUMNS:
            skipped.append({"column": name, "reason": "measured-power source column (target or a component of it)"})
            continue
        if opt.include and not _glob_any(name, opt.include):
            skipped.append({"column": name, "reason": "not in --signals"})
            continue
        if opt.exclude and _glob_any(name, opt.exclude):
            skipped.append({"column": name, "reason": "excluded by --exclude"})
            continue
        s = arr[u]
        fin = np.isfinite(s)
        nan_frac = 1.0 - fin.mean() if len(s) else 1.0
        if nan_frac > opt.max_nan:
            skipped.append({"column": name, "reason": f"{100 * nan_frac:.1f} % NaN among usable samples (> {100 * opt.max_nan:g} %)"})
            continue
        sf = s[fin]
        if len(sf) == 0 or np.nanmax(sf) == np.nanmin(sf):
            skipped.append({"column": name, "reason": "constant"})
            continue
        ds = np.diff(s)
        ok = same_trip & np.isfinite(ds)
        if ok.any() and (np.all(ds[ok] >= 0) or np.all(ds[ok] <= 0)) and len(np.unique(sf)) > 0.5 * len(sf):
            skipped.append({"column": name, "reason": "id-like (monotone within every trip: clock, counter or odometer)"})
            continue
        sz = np.where(fin, s, np.nanmean(sf))
        sc = sz - sz.mean()
        ss = float(sc @ sc)
        if ss > 0:
            proj = kin_q.T @ sz
            r2 = 1.0 - max(float(sz @ sz) - float(proj @ proj), 0.0) / ss
            if r2 >= opt.derived_r2:
                skipped.append({"column": name, "reason": f"derived from the model inputs (R² = {r2:.4f} on 1, v, a, sin θ, wind)"})
                continue
        dup = None
        if sz.std() > 0:
            zs = (sz - sz.mean()) / sz.std()
            for c, a in src.items():
                r = abs(float(zs @ a)) / len(zs)
                if r >= opt.proxy_corr:
                    dup = (c, r)
                    break
        if dup:
            skipped.append({"column": name, "reason": f"same quantity as the measured-power source column "
                                                      f"'{dup[0]}' (|corr| = {dup[1]:.3f})"})
            continue
        best = 0.0
        for k in range(4):
            f = sz * v ** k
            fc = f - f.mean()
            den = math.sqrt(float(fc @ fc) * float(yc @ yc))
            if den > 0:
                best = max(best, abs(float(fc @ yc)) / den)
        if best >= opt.proxy_corr:
            skipped.append({"column": name, "reason": f"proxy of the target (|corr(c·vᵏ, P)| = {best:.3f} ≥ {opt.proxy_corr:g})"})
            continue
        kept[name] = arr
    return kept, skipped


def generate_candidates(signals: dict, declared_terms, n_trips: int, opt: TraceOptions,
                        binary: set) -> list[Candidate]:
    """All candidate effects for the screened signals and the declared terms."""
    out = []
    for c in signals:
        for k in range(4):
            term = f"[{c}]" if k == 0 else f"[{c}]*v^{k}"
            what = "an additive load proportional to" if k == 0 else "a load"
            out.append(Candidate(term, f"{what} '{c}'{_vname(k)}", (c,), "signal"))
        for t in declared_terms:
            if parse_term(t).signals:
                continue
            cat = parse_term(t).category
            label = {"acc": "inertia", "grade": "grade", "aero": "aerodynamic drag",
                     "roll": "rolling-resistance"}.get(cat, cat)
            out.append(Candidate(f"[{c}]*{t}", f"'{c}' changes the {label} term '{t}'", (c,),
                                 "signal_x_term"))
        if c not in binary:
            for k in range(4):
                term = f"[{c}]^2" if k == 0 else f"[{c}]^2*v^{k}"
                out.append(Candidate(term, f"a load with the square of '{c}'{_vname(k)}", (c,), "signal_sq"))
    for k in range(5):
        out.append(Candidate(f"v^{k}", f"a function of speed alone: v^{k} (the declared terms lack it)",
                             (), "speed"))
    if opt.per_trip and 2 <= n_trips <= opt.max_trips_per_trip_effects:
        out.append(Candidate("trip=*", "a per-trip constant load (one offset per trip)", (), "trip_offset", True))
        out.append(Candidate("trip=*·mass", "a per-trip mass change (one factor per trip on the "
                             "mass-bearing terms)", (), "trip_mass", True))
    return out


# ---------------------------------------------------------------- block statistics

def _block_sums(m: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """Sum rows of ``m`` (n × …) within contiguous blocks starting at ``starts``."""
    return np.add.reduceat(m, starts, axis=0)


class _Tracer:
    """Model state and candidate scoring on per-block sufficient statistics."""

    def __init__(self, x: Inputs, y: np.ndarray, dt: np.ndarray, t: np.ndarray,
                 trip_codes: np.ndarray, trip_names, signals: dict, opt: TraceOptions):
        self.x, self.y, self.dt, self.opt = x, y, dt, opt
        self.n = len(y)
        self.trip = trip_codes
        self.trip_names = list(trip_names)
        self.T = len(self.trip_names)
        self.signals = signals
        # blocks: contiguous runs of block_s seconds within a trip
        t0 = np.zeros(self.n)
        tstart = np.r_[True, trip_codes[1:] != trip_codes[:-1]]
        first = np.maximum.accumulate(np.where(tstart, np.arange(self.n), 0))
        t0 = t - t[first]
        bidx = np.floor(t0 / opt.block_s).astype(np.int64)
        newb = np.r_[True, (trip_codes[1:] != trip_codes[:-1]) | (bidx[1:] != bidx[:-1])]
        self.starts = np.flatnonzero(newb)
        self.B = len(self.starts)
        self.block_of = np.cumsum(newb) - 1
        self.block_trip = trip_codes[self.starts]
        self.block_n = np.diff(np.r_[self.starts, self.n])
        # block folds: interleaved within each trip
        k_b = opt.folds
        rank = np.zeros(self.B, dtype=np.int64)
        bstart = np.r_[True, self.block_trip[1:] != self.block_trip[:-1]]
        firstb = np.maximum.accumulate(np.where(bstart, np.arange(self.B), 0))
        rank = np.arange(self.B) - firstb
        self.fold_blocks = (rank % k_b).astype(np.int64)
        n_trips_present = len(np.unique(trip_codes))
        if opt.validation == "trip" and n_trips_present < 3:
            raise UserError(f"--validation trip needs ≥ 3 trips, the data hold {n_trips_present}")
        self.by_trip = opt.validation == "trip" or (opt.validation == "auto" and n_trips_present >= 3)
        if self.by_trip:
            k_t = min(opt.folds, n_trips_present)
            sizes = np.bincount(trip_codes, minlength=self.T)
            order = np.argsort(-sizes, kind="stable")
            load = np.zeros(k_t)
            tfold = np.zeros(self.T, dtype=np.int64)
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
        self.y_scale = float(np.sqrt(np.mean(y * y))) or 1.0
        self.ys = y / self.y_scale
        self.yy = _block_sums(self.ys * self.ys, self.starts)
        self.cols: list[_Col] = []
        self._factor_cache: dict = {}
        self.cand_cache: dict = {}   # term → (cz list per model column, cc, cy)
        self.n_scored = 0

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
        return [self.T if c.cand.scatter else 1 for c in self.cols]

    @property
    def P(self):
        return int(sum(self.widths()))

    def idx(self) -> np.ndarray:
        """Full coefficient index of each compact column, per block (B × q)."""
        q = len(self.cols)
        out = np.empty((self.B, q), dtype=np.int64)
        for j, c in enumerate(self.cols):
            out[:, j] = c.offset + (self.block_trip if c.cand.scatter else 0)
        return out

    def add(self, cand: Candidate, values: np.ndarray | None = None, mass_terms=None) -> None:
        vals = self.values(cand) if values is None else values
        scale = float(np.sqrt(np.mean(vals * vals)))
        if not scale > 0 or not np.isfinite(scale):
            raise UserError(f"term '{cand.term}' is zero or not finite on the analysis samples")
        col = _Col(cand, vals, scale, offset=self.P, mass_terms=dict(mass_terms or {}))
        z = vals / scale
        # stats of the new column against existing ones and itself
        q = len(self.cols)
        new_cross = np.empty((self.B, q + 1))
        for j, c in enumerate(self.cols):
            new_cross[:, j] = _block_sums(z * (c.values / c.scale), self.starts)
        new_cross[:, q] = _block_sums(z * z, self.starts)
        hz_new = _block_sums(z * self.ys, self.starts)
        if q == 0:
            self.Gz = new_cross[:, :, None].copy()
            self.hz = hz_new[:, None].copy()
        else:
            G = np.empty((self.B, q + 1, q + 1))
            G[:, :q, :q] = self.Gz
            G[:, :q, q] = new_cross[:, :q]
            G[:, q, :q] = new_cross[:, :q]
            G[:, q, q] = new_cross[:, q]
            self.Gz = G
            self.hz = np.column_stack([self.hz, hz_new])
        self.cols.append(col)
        self._full = None

    def replace_last(self, values: np.ndarray, mass_terms: dict) -> None:
        """Replace the values of the last model column (per-trip mass refinement)."""
        last = self.cols.pop()
        q = len(self.cols)
        self.Gz = self.Gz[:, :q, :q].copy()
        self.hz = self.hz[:, :q].copy()
        self.add(last.cand, values, mass_terms)

    def Z(self, j):
        c = self.cols[j]
        return c.values / c.scale

    def fold_of(self, scatter_scoring: bool) -> np.ndarray:
        if self.fold_trips is None or scatter_scoring or any(c.cand.scatter for c in self.cols):
            return self.fold_blocks
        return self.fold_trips

    def _model_fold_stats(self, fold):
        K = int(fold.max()) + 1
        P = self.P
        idx = self.idx()
        A = np.zeros((K, P, P))
        b = np.zeros((K, P))
        np.add.at(A, (fold[:, None, None], idx[:, :, None], idx[:, None, :]), self.Gz)
        np.add.at(b, (fold[:, None], idx), self.hz)
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
        sse = (self.yy - 2 * np.einsum("bq,bq->b", bz, self.hz)
               + np.einsum("bi,bij,bj->b", bz, self.Gz, bz))
        return np.maximum(sse, 0.0), bz

    def cand_stats(self, cands: list[Candidate], vals: np.ndarray | None = None):
        """Block stats of candidate columns: cz (B × m × q), cc (B × m), cy (B × m), scales."""
        m = len(cands)
        q = len(self.cols)
        cz = np.empty((self.B, m, q))
        cc = np.empty((self.B, m))
        cy = np.empty((self.B, m))
        scales = np.empty(m)
        need_vals = [cd for cd in cands]
        for i, cd in enumerate(need_vals):
            cached = self.cand_cache.get(cd.term) if cd.kind != "trip_mass" else None
            if cached is not None and cached[0].shape[1] == q:
                cz[:, i], cc[:, i], cy[:, i], scales[i] = cached
                continue
            v = self.values(cd) if vals is None else vals[:, i]
            s = float(np.sqrt(np.mean(v * v)))
            if not (s > 0 and np.isfinite(s)):
                s = np.nan
                cz[:, i], cc[:, i], cy[:, i], scales[i] = 0.0, 0.0, 0.0, s
                continue
            z = v / s
            q0 = 0
            if cached is not None and np.isfinite(cached[3]):
                q0 = cached[0].shape[1]
                cz[:, i, :q0] = cached[0]
            for j in range(q0, q):
                cz[:, i, j] = _block_sums(z * self.Z(j), self.starts)
            if cached is not None:
                cc[:, i], cy[:, i] = cached[1], cached[2]
            else:
                cc[:, i] = _block_sums(z * z, self.starts)
                cy[:, i] = _block_sums(z * self.ys, self.starts)
            scales[i] = s
            if cd.kind != "trip_mass":
                self.cand_cache[cd.term] = (cz[:, i].copy(), cc[:, i].copy(), cy[:, i].copy(), s)
        return cz, cc, cy, scales

    def score(self, cands: list[Candidate], scatter: bool, fold: np.ndarray):
        """Held-out per-block SSE of model + each candidate (B × m), valid mask (m)."""
        cz, cc, cy, scales = self.cand_stats(cands)
        m = len(cands)
        P = self.P
        w = self.T if scatter else 1
        D = P + w
        K = int(fold.max()) + 1
        Am, bm, idx = self._model_fold_stats(fold)
        A = np.zeros((K, m, D, D))
        b = np.zeros((K, m, D))
        A[:, :, :P, :P] = Am[:, None]
        b[:, :, :P] = bm[:, None]
        cpos = P + (self.block_trip if scatter else np.zeros(self.B, dtype=np.int64))
        fi = fold[:, None, None]
        mi = np.arange(m)[None, :, None]
        np.add.at(A, (fi, mi, idx[:, None, :], cpos[:, None, None]), cz)
        np.add.at(A, (fi, mi, cpos[:, None, None], idx[:, None, :]), cz)
        np.add.at(A, (fold[:, None], np.arange(m)[None, :], cpos[:, None], cpos[:, None]), cc)
        np.add.at(b, (fold[:, None], np.arange(m)[None, :], cpos[:, None]), cy)
        Atot, btot = A.sum(0), b.sum(0)
        # spanned check (full data): residual fraction of the candidate after the model
        valid = np.isfinite(scales)
        if P and not scatter:
            sol = self._solve(Atot[:, :P, :P], Atot[:, :P, P])
            resid = Atot[:, P, P] - np.einsum("mp,mp->m", sol, Atot[:, :P, P])
            valid &= resid > 1e-6 * np.maximum(Atot[:, P, P], 1e-300)
        beta = self._solve(Atot[None] - A, btot[None] - b)   # K × m × D
        bb = beta[fold]                                          # B × m × D
        bz = np.take_along_axis(bb, np.broadcast_to(idx[:, None, :], (self.B, m, idx.shape[1])), axis=2)
        bc = np.take_along_axis(bb, np.broadcast_to(cpos[:, None, None], (self.B, m, 1)), axis=2)[..., 0]
        sse = (self.yy[:, None] - 2 * (np.einsum("bmq,bq->bm", bz, self.hz) + bc * cy)
               + np.einsum("bmi,bij,bmj->bm", bz, self.Gz, bz)
               + 2 * bc * np.einsum("bmq,bmq->bm", bz, cz) + bc * bc * cc)
        self.n_scored += int(valid.sum())
        return np.maximum(sse, 0.0), valid

    # ---- fits and predictions
    def full_fit(self) -> dict:
        """OLS on all analysis samples: β (scaled), standard errors (scaled), rss."""
        if getattr(self, "_full", None) is not None:
            return self._full
        P = self.P
        idx = self.idx()
        A = np.zeros((P, P))
        b = np.zeros(P)
        np.add.at(A, (idx[:, :, None], idx[:, None, :]), self.Gz)
        np.add.at(b, idx, self.hz)
        beta = self._solve(A, b)
        rss = max(float(self.yy.sum() - beta @ b), 0.0)
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
            pred += coef[:, j] * self.Z(j)
        return pred * self.y_scale

    def column_power(self, j: int) -> np.ndarray:
        """Power [W] of model column j with the full-data fit."""
        f = self.full_fit()
        c = self.cols[j]
        if c.cand.scatter:
            coef = f["beta"][c.offset + self.trip]
        else:
            coef = f["beta"][c.offset]
        return coef * self.Z(j) * self.y_scale

    def coefficients(self) -> tuple[dict, dict]:
        """Unscaled coefficients and standard errors: term → value (per-trip: trip → value)."""
        f = self.full_fit()
        co, se = {}, {}
        for c in self.cols:
            k = self.y_scale / c.scale
            if c.cand.scatter:
                sl = slice(c.offset, c.offset + self.T)
                present = np.bincount(self.trip, minlength=self.T) > 0
                co[c.cand.term] = {self.trip_names[i]: float(v) * k
                                   for i, v in enumerate(f["beta"][sl]) if present[i]}
                se[c.cand.term] = {self.trip_names[i]: float(v) * k
                                   for i, v in enumerate(f["se"][sl]) if present[i]}
            else:
                co[c.cand.term] = float(f["beta"][c.offset]) * k
                se[c.cand.term] = float(f["se"][c.offset]) * k
        return co, se


def _pick_metrics(m: dict) -> dict:
    return {k: m[k] for k in METRIC_KEYS}


def _paired_test(d: np.ndarray) -> float:
    """One-sided p-value that held-out blocks improve: d_b = SSE_b(model) − SSE_b(model + c).

    Two tests, Bonferroni-combined (2 × the smaller p): the paired t-test of mean(d) > 0
    (power when the gain is concentrated in a few blocks) and the Wilcoxon signed-rank
    test of a positive shift (robust when a few heavy-tailed blocks dominate the mean).
    """
    d = d[np.isfinite(d)]
    if len(d) < 3:
        return 1.0
    sd = float(d.std(ddof=1))
    mean = float(d.mean())
    if sd == 0:
        return 0.0 if mean > 0 else 1.0
    tval = mean / (sd / math.sqrt(len(d)))
    p_t = float(stats.t.sf(tval, len(d) - 1))
    try:
        p_w = float(stats.wilcoxon(d, alternative="greater", zero_method="wilcox").pvalue) if np.any(d != 0) else 1.0
    except ValueError:
        p_w = 1.0
    return min(1.0, 2.0 * min(p_t, p_w))


# ---------------------------------------------------------------------- driver

@dataclass
class TraceResult:
    """What the tracer found: the report document, the final equation and plot data."""

    report: dict
    details: dict
    equation: Equation
    plot: dict
    n_candidates_scored: int


def trace(measured, equation: Equation | None = None, opt: TraceOptions | None = None,
          progress=None) -> TraceResult:
    """Trace the residual of ``equation`` against a log's measured power.

    Parameters
    ----------
    measured : :class:`sumo_drvpw.data.measured.Measured` (measured power [W], inputs, usable mask)
    equation : the declared equation (its terms are kept, coefficients refitted per fold);
        None: calibrate one by stepwise OLS on the indt-var-1 candidates
    opt : :class:`TraceOptions`
    progress : optional callable(str) for progress messages
    """
    opt = opt or TraceOptions()
    opt.check()
    say = progress or (lambda s: None)
    log = measured.log
    y_all = np.asarray(measured.power_w, float)
    x_all = measured.inputs
    usable = np.asarray(measured.usable, bool).copy()
    trip_all = np.asarray(log.df["trip_id"].astype(str).to_numpy())
    trip_names, trip_codes_all = np.unique(trip_all, return_inverse=True)
    t_all = log.df["time_s"].to_numpy(float)
    dt_all = log.df["dt_s"].to_numpy(float)

    # declared equation
    calibrated = False
    if equation is None:
        res = calibrate(x_all, y_all, CANDIDATES["indt-var-1"], mask=usable,
                        reference_mass_kg=float(x_all.mass[usable].mean()))
        equation = res.to_equation("calibrated_indt_var_1", provenance={"logs": log.files})
        calibrated = True
        say(f"calibrated on the spot: {', '.join(equation.term_names)}")
    declared = equation.term_names
    x_eq = x_all.with_mass(equation.mass_kg)
    for s in equation.signals:
        if s not in x_eq.signals:
            raise UserError(f"equation '{equation.name}' needs the log column '{s}', which the data lack")

    # screen signals
    binary = set()
    kept, skipped = screen_signals(dict(x_all.signals), y_all, x_all, trip_codes_all, usable, opt)
    for name in list(kept):
        if name in equation.signals:
            skipped.append({"column": name, "reason": "already a factor of a declared term"})
            kept.pop(name)
    # analysis samples: usable, declared terms finite, kept signals finite
    decl_vals = term_matrix(declared, x_eq)
    ana = usable & np.all(np.isfinite(decl_vals), axis=1) & (x_eq.v >= opt.min_speed_mps)
    for name, arr in kept.items():
        ana &= np.isfinite(arr)
    n = int(ana.sum())
    if n < 50:
        raise UserError(f"{log.describe()}: only {n} analysis samples (usable, with finite terms and signals); "
                        "need at least 50")
    idx = np.flatnonzero(ana)
    x = x_eq.take(idx)
    sig = {k: np.asarray(v, float)[idx] for k, v in kept.items()}
    for k, v in sig.items():
        if len(np.unique(v[: min(len(v), 200000)])) <= 2 and len(np.unique(v)) <= 2:
            binary.add(k)
    y = y_all[idx]
    dt = dt_all[idx]
    trip_codes = trip_codes_all[idx]
    n_trips = len(np.unique(trip_codes))
    tr = _Tracer(x, y, dt, t_all[idx], trip_codes, trip_names, sig, opt)
    for j, t in enumerate(declared):
        vals = decl_vals[idx, j]
        cand = Candidate(t, f"declared term {t}", tuple(parse_term(t).signals), "declared")
        tr._factor_cache[t] = vals
        tr.add(cand, vals)
    say(f"{n} analysis samples, {n_trips} trip(s), {tr.B} blocks, {len(sig)} signal(s) offered")

    cands = generate_candidates(sig, declared, n_trips, opt, binary)
    base_fold = tr.fold_of(False)
    pred0 = tr.heldout_pred(base_fold)
    m_base = _metrics(pred0, y)
    base_coefs, _ = tr.coefficients()
    findings, rounds = [], []
    plot = {"y": y, "v": x.v, "pred_base": pred0, "signals": sig, "findings": []}
    in_model = set(declared)
    for rnd in range(opt.max_findings):
        pool = [c for c in cands if c.term not in in_model]
        if not pool:
            break
        results = []  # (cand, sse_total, d per block, fold kind)
        for scatter in (False, True):
            group = [c for c in pool if c.scatter == scatter]
            if not group:
                continue
            fold = tr.fold_of(scatter)
            sse0, _ = tr.heldout_model(fold)
            if scatter:
                for c in group:
                    sse, valid = tr.score([c], True, fold)
                    if valid[0]:
                        results.append((c, float(sse[:, 0].sum()), sse0 - sse[:, 0], float(sse0.sum()), fold))
            else:
                for lo in range(0, len(group), opt.batch):
                    sub = group[lo:lo + opt.batch]
                    sse, valid = tr.score(sub, False, fold)
                    for i, c in enumerate(sub):
                        if valid[i]:
                            results.append((c, float(sse[:, i].sum()), sse0 - sse[:, i], float(sse0.sum()), fold))
        if not results:
            break
        m_scored = len(results)
        gains = [1.0 - math.sqrt(r[1] / r[3]) if r[3] > 0 else 0.0 for r in results]
        order = np.argsort(gains)[::-1]
        table = []
        for i in order[:10]:
            c, s, d, s0, _ = results[i]
            p = _paired_test(d)
            table.append({"term": c.term, "effect": c.effect, "rmse_gain": gains[i],
                          "p_value_bonferroni": min(1.0, p * m_scored)})
        best = int(order[0])
        cbest, sse_b, d_b, sse0_b, fold_b = results[best]
        p_raw = _paired_test(d_b)
        p_adj = min(1.0, p_raw * m_scored)
        accepted = p_adj < opt.alpha and gains[best] >= opt.min_gain
        rounds.append({"round": rnd + 1, "candidates_scored": m_scored, "best": cbest.term,
                       "rmse_gain": gains[best], "p_value_bonferroni": p_adj, "accepted": bool(accepted),
                       "top": table})
        say(f"round {rnd + 1}: {m_scored} candidates, best {cbest.term} gain {100 * gains[best]:.2f} % "
            f"p·m = {p_adj:.3g} → {'added' if accepted else 'stop'}")
        if not accepted:
            break
        before_pred = tr.heldout_pred(fold_b)
        m_before = _metrics(before_pred, y)
        mass_terms = {}
        if cbest.kind == "trip_mass":
            vals, mass_terms = tr.mass_part()
            tr.add(cbest, vals, mass_terms)
            # the composite was built with coefficients fitted without per-trip mass: rebuild it
            # from the refitted (mean-mass) coefficients until they settle (≤ 3 passes)
            for _ in range(3):
                vals, new_terms = tr.mass_part()
                change = max(abs(new_terms[k] / mass_terms[k] - 1.0) for k in mass_terms) if mass_terms else 0.0
                mass_terms = new_terms
                tr.replace_last(vals, mass_terms)
                if change < 1e-4:
                    break
        else:
            tr.add(cbest)
        in_model.add(cbest.term)
        fold_after = tr.fold_of(False)
        after_pred = tr.heldout_pred(fold_after)
        m_after = _metrics(after_pred, y)
        co, se = tr.coefficients()
        # energy share of the new term
        j_new = len(tr.cols) - 1
        powers = np.column_stack([tr.column_power(j) for j in range(len(tr.cols))])
        total = powers.sum(axis=1)
        wgt = np.where(total > 0, dt, 0.0)
        e_tot = float(total @ wgt)
        share = float(powers[:, j_new] @ wgt) / e_tot if e_tot > 0 else math.nan
        findings.append({
            "effect": cbest.effect, "signals": list(cbest.signals), "term": _term_label(cbest, mass_terms),
            "coefficient": co[cbest.term], "std_err": se[cbest.term], "p_value": p_adj,
            "energy_share": share, "metrics_before": _pick_metrics(m_before),
            "metrics_after": _pick_metrics(m_after)})
        plot["findings"].append({"cand": cbest, "before": before_pred, "after": after_pred})

    final_fold = tr.fold_of(False)
    pred_final = tr.heldout_pred(final_fold) if findings else pred0
    m_final = _metrics(pred_final, y)
    co, se = tr.coefficients()
    plot["pred_final"] = pred_final
    final_terms = _expand_terms(tr, co)
    eq_terms = {t: c for t, c in final_terms.items()}
    eq_se = _expand_terms(tr, se, std=True)
    now = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    prov = {"date": now, "method": "sumo-drvpw diagnose: residual tracer (sumo_drvpw.fit.diagnose)",
            "logs": list(log.files), "declared_equation": equation.name,
            "declared_terms": list(declared), "calibrated_on_the_spot": calibrated,
            "power_source": measured.source, "validation": tr.validation,
            "findings": [f["term"] for f in findings],
            "settings": {k: (list(v) if isinstance(v, tuple) else v) for k, v in vars(opt).items()}}
    final_eq = Equation(name=f"{equation.name}_traced", terms=eq_terms, mass_kg=equation.mass_kg,
                        description=f"{equation.name} refitted with the effects found by the residual tracer",
                        source="sumo-drvpw diagnose", std_err=eq_se, provenance=prov,
                        metrics={"heldout": _pick_metrics(m_final), "n": n})
    report = {
        "target": f"measured driving power [W] ({measured.source})",
        "n_samples": n,
        "validation": tr.validation,
        "baseline": {"terms": list(declared), "coefficients": {t: base_coefs[t] for t in declared},
                     "metrics": _pick_metrics(m_base)},
        "findings": findings,
        "final": {"terms": list(final_terms),
                  "coefficients": final_terms, "metrics": _pick_metrics(m_final)},
    }
    details = {"declared_equation": equation.name, "calibrated_on_the_spot": calibrated,
               "samples": {"rows": len(y_all), "usable": int(usable.sum()), "analysis": n,
                           "trips": n_trips, "blocks": tr.B},
               "signals_offered": sorted(sig), "signals_skipped": skipped,
               "candidates_per_round": len(cands), "candidates_scored": tr.n_scored,
               "rounds": rounds, "test": ("one-sided paired tests over held-out blocks of "
                                           "d = SSE(model) − SSE(model + candidate): 2 × min(p of t-test on "
                                           "mean d, p of Wilcoxon signed-rank), Bonferroni over the "
                                           f"candidates scored per round, alpha = {opt.alpha}, and relative "
                                           f"held-out RMSE gain ≥ {opt.min_gain}"),
               "final_std_err": se, "settings": prov["settings"]}
    return TraceResult(report, details, final_eq, plot, tr.n_scored)


def _term_label(c: Candidate, mass_terms: dict) -> str:
    if c.kind == "trip_offset":
        return "trip=ID (one per trip)"
    if c.kind == "trip_mass":
        inner = " + ".join(f"{v:.6g}·{t}" for t, v in mass_terms.items())
        return f"trip=ID*({inner}) (one factor per trip)"
    return c.term


def _expand_terms(tr: _Tracer, co: dict, std: bool = False) -> dict:
    """Terms of the final equation in the term grammar (per-trip effects expanded)."""
    out = {}
    for c in tr.cols:
        val = co[c.cand.term]
        if c.cand.kind == "trip_offset":
            for trip, v in val.items():
                out[f"trip={trip}"] = v
        elif c.cand.kind == "trip_mass":
            for trip, v in val.items():
                for t, ct in c.mass_terms.items():
                    out[f"trip={trip}*{t}"] = v * abs(ct) if std else v * ct
        else:
            out[c.cand.term] = val
    return out
