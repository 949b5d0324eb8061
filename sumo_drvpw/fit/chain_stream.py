"""`calibrate --target battery|fuel` streamed: the chain fit from per-batch sums (issue #14).

The chain fits of :mod:`sumo_drvpw.fit.chain` solve bounded least squares on the
triangular factor R of the weighted design [√w·X √w·y] (TSQR), so a batch of whole trips
adds its own factor, stacked and factored again (:class:`ChainStats`): one factor per
value of a profiled parameter. The fuel chain's grid (engine-off threshold × engine-on
speed) is fixed, so one pass over the logs holds every factor. The battery chain's
recuperation limits are quantiles of the braking power on the fitted samples; they are
found exactly, in bounded memory: that pass counts the braking powers per bin of their
leading 24 bits (sign, exponent and 12 bits of the mantissa: bins 1/4096 of their value
wide), a second keeps the distinct values (with their counts) of the (at most 16) bins
that hold the order statistics ``np.quantile`` interpolates (fit/chain_quantiles.py),
and a third factors the design at each limit (in one process, on the arrays the first pass
kept, up to :data:`KEEP_BYTES`: the logs are read once). R², RMSE and the energy ratio come from sums too: the
chain's prediction is the design times the coefficients, so Σw·e² is the fit's RSS and
Σw·P̂ the coefficients times Σw·X. The same numbers as the in-memory fit to rounding
(tests/test_chain_stream.py: 1e-9 relative).

Memory: one batch (the reader's: fewer rows of a wide log, :func:`sumo_drvpw.data.stream.rows_for`),
the factors (a few (k+1)² matrices per grid value) and the distinct values of the quantile
bins (braking powers within 1/4096 of an order statistic's value).
``--efficiency power|speed-power`` is not streamed (its knots are quantiles of the
driving power over speed classes): the command fits it in memory.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from sumo_drvpw.data.trips import trip_signatures
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.chain import (LIMIT_QUANTILES, ChainFit, _bic, _col, _covariance, battery_chain,
                                  battery_columns, battery_design, factor_rows, solve_factor, too_few_samples)
from sumo_drvpw.fit.chain_fixed import check_fixed, coefficients, solve_fixed
from sumo_drvpw.fit.chain_fuel import (CITY_SPEED_MPS, fuel_bounds, fuel_chain, fuel_design, fuel_grid,
                                       fuel_target_text, idles_at_stops, note_conventional, note_declared,
                                       note_idling, set_moving, set_rating, standing_sums, fuel_names)
from sumo_drvpw.fit.chain_quantiles import _keys, _merge_hist, quantile_bins, quantiles_of
from sumo_drvpw.fit.chain_windows import factored_lines, window_designs
from sumo_drvpw.fit.stream import _add_counts

#: A battery chain's scan keeps the arrays its later passes read (driving power, target,
#: weights, loads, mask: 25 B a row and 8 per load) up to this many bytes, so those passes
#: need not read the logs again (``keep``; beyond it they do)
KEEP_BYTES = 128 * 2**20


@dataclass
class ChainSpec:
    """What a streamed chain calibration reads: ``target`` battery or fuel; ``equation``
    the road load whose driving power is the chain's input where the log has no measured
    driving power (None: the log's must be used); logged ``loads``; ``hvac`` {column,
    setpoint_c} or None; ``candidates`` of the stepwise road load fitted in the same pass
    (None: none); the fuel, a declared overrun cut-off and the engine-off threshold of a
    fuel chain ("profile", −inf: never, or W), and the engine keys it fits or keeps as in memory
    (:func:`~sumo_drvpw.fit.chain_fuel.declared_engine`: ``moving_idle`` fitted, ``engine_max_w``
    [W] at the wheels kept)."""

    target: str
    equation: object = None
    loads: tuple = ()
    hvac: dict | None = None
    candidates: tuple | None = None
    moving_mps: float = 0.5
    fuel: str = "gasoline"
    fuel_cut_below_w: float | None = None
    engine_off: "str | float" = "profile"
    moving_idle: bool = False
    engine_max_w: float | None = None
    #: a battery chain's parameters held at given values (name → value; fit/chain_fixed.py)
    fixed: dict | None = None

    @property
    def held_limit(self) -> float | None:
        """The recuperation limit held (``fixed``), not profiled, or None."""
        return (self.fixed or {}).get("recuperation_limit_w")



def _wmoments(w, cols):
    """(Σw, weighted means, weighted centred co-moments) of the columns ``cols``."""
    x = np.vstack(cols)
    sw = float(w.sum())
    if sw == 0:
        return None
    mu = (x @ w) / sw
    d = x - mu[:, None]
    return sw, mu, (d * w) @ d.T


def _merge_wmoments(a, b):
    """Pairwise update of weighted moments (Chan et al. 1979)."""
    if a is None or b is None:
        return a or b
    w = a[0] + b[0]
    d = b[1] - a[1]
    return w, a[1] + d * (b[0] / w), a[2] + b[2] + np.outer(d, d) * (a[0] * b[0] / w)


class ChainStats:
    """Mergeable statistics of a chain calibration over batches of whole trips.

    ``phase``: ``scan`` (everything a chain needs but the battery's recuperation limits:
    counts, the checks' sums, the stepwise road load's statistics, the fuel grid's factors,
    the battery's factor without a limit and its braking powers' bin counts), ``collect``
    (the braking powers of the bins ``bins``) or ``fit`` (the battery's factors at the
    limits ``limits``). ``keep``: a battery chain's scan keeps each batch's arrays of the
    later passes in ``kept`` (per Part, per batch; None beyond :data:`KEEP_BYTES`), for
    :func:`replay` (one process only: a Dask worker's would travel back)."""

    def __init__(self, spec: ChainSpec, phase: str = "scan", limits: tuple = (), bins: tuple = (),
                 keep: bool = False):
        self.spec, self.phase, self.limits, self.bins = spec, phase, tuple(limits), np.asarray(bins, np.int64)
        keep = keep and phase == "scan" and spec.target == "battery"
        self.kept, self.kept_bytes = ([[]] if keep else None), 0
        self.target = spec.target
        self.rows, self.counts, self.files, self.source, self.vehicle = 0, {}, [], None, None
        self.inputs: dict = {}         # the chain's input (a measured source, or None) → its first file
        self.signatures: dict = {}     # trip → its signature (data/trips.trip_signatures), scanned
        self.hvac_trips: dict = {}     # trip → its HVAC regressors' sums (fit.chain_checks.hvac_trip_sums)
        self.wheel_error = None        # why a batch had no measured driving power
        self.sign = self.falling = None
        self.usable = self.nonzero = self.n_ok = self.unknown = 0
        self.mass_sum, self.mass_n = 0.0, 0  # the log's mass over usable samples (the 3.5-t warning)
        self.load_n = dict.fromkeys(spec.loads, 0)
        self.load_text: dict = {}      # load column → its first value where it is not numeric
        self.seen: set = set()
        self.ranges = [math.inf, -math.inf, math.inf, -math.inf]
        self.mom = None
        self.w_low = 0.0
        self.standing = np.zeros(3)    # [standing time, of it with fuel flowing, that fuel J] (fuel target)
        self.battery = False           # a hybrid battery's V·I in any batch (fuel target)
        self.fac: dict = {}            # grid value → [R, samples, Σw·X]
        self.hist = None
        self.values = None             # (distinct braking powers of the quantile bins, their counts)
        self.road = None
        if spec.candidates and phase == "scan":
            from sumo_drvpw.fit.stream import CalibrationStats

            self.road = CalibrationStats(tuple(spec.candidates), moving_mps=spec.moving_mps)
        self.grid, self.conv = None, []
        if spec.target == "fuel":
            self.grid = fuel_grid("profile" if spec.engine_off == "conventional" else spec.engine_off,
                                  fuel_cut_below_w=spec.fuel_cut_below_w)
            self.conv = [False] * len(self.grid)
            if spec.engine_off == "conventional":  # (no battery declared: the conventional grid, unless the
                # logs carry battery power — known after the scan — then the whole profile, as in memory)
                extra = [t for t in fuel_grid("conventional", fuel_cut_below_w=spec.fuel_cut_below_w,
                                              charge_sustaining=False) if t.engine_off_below_w > -np.inf]
                self.grid += extra
                self.conv += [True] * len(extra)
            for tmpl in self.grid:  # (as calibrate_fuel: the moving zero-output fuel's column, the rating kept)
                tmpl.moving_idle_fuel_power_w = 0.0 if spec.moving_idle else None
                tmpl.engine_max_w = None if spec.engine_max_w is None else float(spec.engine_max_w)

    def columns(self):
        return None  # every column: the fuel flow, air flow and fuel trims are found by name

    # ----------------------------------------------------------------- one batch
    def add(self, m) -> "ChainStats":
        from sumo_drvpw.data.measured import measure, merge_sign_sums

        self.rows += len(m.power_w)
        scan = self.phase == "scan"
        if scan:
            self.counts = _add_counts(self.counts, m.counts)
            self.source = self.source or m.source
            self.vehicle = self.vehicle or m.vehicle
            self.files += [f for f in m.log.files if f not in self.files]
            self.signatures.update(trip_signatures(m.log.df))
            if self.target == "battery":
                self.sign = merge_sign_sums(self.sign, m.sign_test)
        wc = dict(m.log.counts)
        wc.pop("excluded_charging", None)  # the target's own count
        try:  # the measured driving power, as load_measured_pair measures it
            mw = measure(dataclasses.replace(m.log, counts=wc), m.vehicle, lazy_signals=True)
        except UserError as e:
            mw, self.wheel_error = None, self.wheel_error or str(e)
        measured = mw is not None and not mw.source.startswith("battery")
        self.inputs.setdefault(mw.source if measured else None, m.log.files[0] if m.log.files else "?")
        if scan and self.road is not None and measured:
            self.road.add(mw)
        use = np.asarray(m.usable, bool)
        y = np.asarray(m.power_w, float)
        if scan:
            self._input_checks(m, y, use)
            self.mass_sum += float(np.sum(np.asarray(m.inputs.mass, float)[use]))
            self.mass_n += int(use.sum())
        if measured:
            p = np.asarray(mw.power_w, float)
        elif self.spec.equation is not None:
            p = np.asarray(self.spec.equation.power(m.inputs), float)
        else:
            return self  # no chain input: refused at the end (check_inputs)
        del mw
        w = m.log.df["dt_s"].to_numpy(float)
        v = np.asarray(m.inputs.v, float)
        need = set(self.spec.loads) | ({self.spec.hvac["column"]} if self.spec.hvac else set())
        sig = {c: np.asarray(m.inputs.signals[c], float) for c in need if c in m.inputs.signals}
        sig.update({c: np.full(len(y), np.nan) for c in need - set(sig)})  # unknown in this batch
        if scan:
            self._checks(p, y, v, use)
        if scan and self.target == "battery" and self.spec.hvac:  # what an HVAC gain rests on, per trip
            from sumo_drvpw.fit.chain_checks import hvac_trip_sums

            trip = m.log.df["trip_id"] if "trip_id" in m.log.df else m.inputs.trip
            hv = self.spec.hvac
            self.hvac_trips.update(hvac_trip_sums(trip, sig[hv["column"]], float(hv.get("setpoint_c", 20.0)), w, use))
        if self.target == "battery":
            view = getattr(m, "counter_view", None)
            self._battery(p, y, w, sig, use, view)
            if self.kept is not None:  # copies: a view would keep the batch's table
                self._keep([np.array(p, float), np.array(y, float), np.array(w, float),
                            {c: np.array(x, float) for c, x in sig.items()}, np.array(use, bool), view])
        else:
            self._fuel(m, p, y, w, v, sig, use)
        return self

    def _keep(self, arrays) -> None:
        self.kept_bytes += sum(a.nbytes for a in arrays[:3] + list(arrays[3].values()) + arrays[4:5])
        self.kept_bytes += arrays[5].nbytes if arrays[5] is not None else 0
        if self.kept_bytes > KEEP_BYTES:
            self.kept = None
        else:
            self.kept[-1].append(arrays)

    def _input_checks(self, m, y, use) -> None:
        """The sums of the in-memory path's checks of the target and the load columns
        (fit/chain_checks.py)."""
        self.usable += int(use.sum())
        self.nonzero += int(np.count_nonzero(np.nan_to_num(y[use])))
        need = set(self.spec.loads) | ({self.spec.hvac["column"]} if self.spec.hvac else set())
        self.seen |= {c for c in need if c in m.inputs.signals}
        for c in self.spec.loads:
            col = m.inputs.signals.get(c)
            if col is None and c in m.log.df.columns and c not in self.load_text:
                first = m.log.df[c].dropna()
                if len(first):
                    self.load_text[c] = first.iloc[0]
            if col is not None:
                from sumo_drvpw.fit.chain_checks import check_load_values

                check_load_values(m.log.describe(), c, col)  # as read in memory (batch rows)
                self.load_n[c] += int(np.isfinite(np.asarray(col, float)[use]).sum())

    def _checks(self, p, y, v, use) -> None:
        """The sums of the in-memory path's checks of the chain's input (fitted ranges, the
        battery current's sign against the driving power)."""
        from sumo_drvpw.data.measured import merge_sign_sums
        from sumo_drvpw.fit.chain_checks import SIGN_CHECK_W

        ok = use & np.isfinite(p) & np.isfinite(v)
        if ok.any():
            r = self.ranges
            self.ranges = [min(r[0], float(p[ok].min())), max(r[1], float(p[ok].max())),
                           min(r[2], float(v[ok].min())), max(r[3], float(v[ok].max()))]
        if self.target == "battery":
            s = use & np.isfinite(p) & np.isfinite(y) & (np.abs(p) > SIGN_CHECK_W)
            if s.any():
                d, e = p[s], y[s]
                md, me = float(d.mean()), float(e.mean())
                d, e = d - md, e - me
                self.falling = merge_sign_sums(self.falling, (int(s.sum()), md, me, float(d @ d),
                                                              float(e @ e), float(d @ e)))

    def _factor(self, key, x: np.ndarray, y: np.ndarray, w: np.ndarray, ok: np.ndarray) -> None:
        """Add the rows ``ok`` of the design ``x`` (target ``y``, weights ``w``) to the
        factor of the grid value ``key`` (TSQR)."""
        r, n = factor_rows(lambda sl: (x[sl], y[sl]), w, ok, x.shape[1])
        if n == 0:
            return
        sx = w[ok] @ x[ok]
        old = self.fac.get(key)
        if old is not None:
            r, n, sx = np.linalg.qr(np.vstack([old[0], r]), mode="r"), old[1] + n, old[2] + sx
        self.fac[key] = [r, n, sx]

    def _battery(self, p, y, w, sig, use, view=None) -> None:
        sp = self.spec
        cols, self.names, self.lb, self.ub, ok, unknown = battery_columns(p, y, w, sig, sp.loads, sp.hvac,
                                                                          mask=use)
        neg = np.minimum(p, 0.0)
        brake = -neg[ok & (neg < 0)]
        if self.phase == "collect":
            sel = brake[np.isin(_keys(brake), self.bins)]
            if sel.size:  # distinct values and counts: a power repeated many times is one entry
                self.values = _merge_hist(self.values, np.unique(sel, return_counts=True))
            return
        for lim in ((sp.held_limit,) if self.phase == "scan" else self.limits):
            x = np.column_stack(battery_design(cols, neg, slice(None), lim))
            self._factor(lim, x if view is None else view(x), y, w, ok)  # as the counters book it
        if self.phase == "scan":
            self.n_ok += int(ok.sum())
            self.unknown += unknown
            self.mom = _merge_wmoments(self.mom, _wmoments(w[ok], [y[ok]]))
            if brake.size:
                self.hist = _merge_hist(self.hist, np.unique(_keys(brake), return_counts=True))

    def _fuel(self, m, p, y, w, v, sig, use) -> None:
        n = len(y)
        pb = np.zeros(n) if m.battery_w is None else np.nan_to_num(np.asarray(m.battery_w, float))
        lcols = [_col(sig, c, n) for c in self.spec.loads]
        ok = np.isfinite(p) & np.isfinite(y) & np.isfinite(w) & use
        for i, tmpl in enumerate(self.grid):
            self._factor(i, fuel_design(tmpl, p, v, pb, lcols), y, w, ok)
        for key, x, yw, dur in window_designs(self.grid, p, v, y, w, m.battery_w, dict(zip(self.spec.loads, lcols)),
                                                   self.spec.loads, ok, m.inputs.trip):
            self._factor(key, x, yw, dur, np.ones(dur.size, bool))  # (the dilution check's refits)
        self.n_ok += int(ok.sum())
        self.mom = _merge_wmoments(self.mom, _wmoments(w[ok], [y[ok], pb[ok]]))
        self.w_low += float(w[ok & (v < CITY_SPEED_MPS)].sum())
        self.standing = self.standing + standing_sums(v, y, w, ok)
        self.battery |= m.battery_w is not None

    # ----------------------------------------------------------------- merging
    def merge(self, o: "ChainStats") -> "ChainStats":
        from sumo_drvpw.data.measured import merge_sign_sums

        self.rows += o.rows
        self.kept_bytes += o.kept_bytes
        self.kept = (None if self.kept is None or o.kept is None or self.kept_bytes > KEEP_BYTES
                     else self.kept + o.kept)
        self.counts = _add_counts(self.counts, o.counts)
        self.files += [f for f in o.files if f not in self.files]
        self.source, self.vehicle = self.source or o.source, self.vehicle or o.vehicle
        self.inputs = {**o.inputs, **self.inputs}
        self.signatures = {**self.signatures, **o.signatures}
        self.hvac_trips = {**self.hvac_trips, **o.hvac_trips}
        self.wheel_error = self.wheel_error or o.wheel_error
        self.sign, self.falling = merge_sign_sums(self.sign, o.sign), merge_sign_sums(self.falling, o.falling)
        self.usable += o.usable
        self.mass_sum, self.mass_n = self.mass_sum + o.mass_sum, self.mass_n + o.mass_n
        self.nonzero += o.nonzero
        self.n_ok += o.n_ok
        self.unknown += o.unknown
        for c, k in o.load_n.items():
            self.load_n[c] += k
        self.load_text = {**o.load_text, **self.load_text}
        self.seen |= o.seen
        r, s = self.ranges, o.ranges
        self.ranges = [min(r[0], s[0]), max(r[1], s[1]), min(r[2], s[2]), max(r[3], s[3])]
        self.mom = _merge_wmoments(self.mom, o.mom)
        self.w_low += o.w_low
        self.standing = self.standing + o.standing
        self.battery |= o.battery
        for key, (rr, n, sx) in o.fac.items():
            old = self.fac.get(key)
            self.fac[key] = [rr, n, sx] if old is None else [
                np.linalg.qr(np.vstack([old[0], rr]), mode="r"), old[1] + n, old[2] + sx]
        if o.hist is not None:
            self.hist = _merge_hist(self.hist, o.hist)
        if o.values is not None:
            self.values = _merge_hist(self.values, o.values)
        for a in ("names", "lb", "ub"):
            if not hasattr(self, a) and hasattr(o, a):
                setattr(self, a, getattr(o, a))
        if self.road is not None and o.road is not None:
            self.road = self.road.merge(o.road)
        return self

    # ----------------------------------------------------------------- at the end
    @property
    def where(self) -> str:
        return self.files[0] if len(self.files) == 1 else f"{len(self.files)} files"

    def check_inputs(self) -> None:
        """What the in-memory path refuses before the road load: the battery current's sign,
        no usable sample, a load or HVAC column missing, not numeric or without a number,
        batches with different chain inputs, no chain input at all."""
        from sumo_drvpw.data.log import exclusions
        from sumo_drvpw.data.measured import check_sign_sums

        if self.target == "battery":
            check_sign_sums(self.where, self.source, self.sign)
        if self.usable == 0:
            raise UserError(f"{self.where}: no usable sample among {self.rows} rows (excluded: "
                            f"{exclusions(self.counts)}; any other row lacks a finite measured power or input)")
        for c in self.spec.loads:
            if c in self.load_text:
                raise UserError(f"{self.where}: load column '{c}' is not numeric (first value "
                                f"{self.load_text[c]!r}): a load is power in W")
            if c not in self.seen:
                raise UserError(f"{self.where}: no load column '{c}'")
            if not self.load_n[c]:
                raise UserError(f"{self.where}: load column '{c}' has no number on the "
                                f"{self.usable} usable samples")
        if len(self.inputs) > 1:
            without = self.inputs.get(None)
            src, with_ = next((k, f) for k, f in sorted(self.inputs.items(), key=lambda kv: str(kv[0]))
                              if k is not None)
            raise UserError(f"{without}: no measured driving power (power_w, motor torque, the power-split "
                            f"signals) while {with_} has one ({src}): the chain takes one input for all "
                            "files; calibrate them apart, or give every file the same columns"
                            if without is not None else
                            f"{self.where}: the files measure the driving power differently "
                            f"({', '.join(sorted(self.inputs))}): the chain takes one input for all files; "
                            "calibrate them apart")

    @property
    def measured_input(self) -> str | None:
        """The measured driving power the chain was fitted on (its source), or None."""
        return next(iter(self.inputs), None)

    def check_chain(self) -> None:
        """What :func:`sumo_drvpw.fit.chain_checks._check_chain_inputs` refuses, from sums."""
        from sumo_drvpw.data.measured import _falling
        from sumo_drvpw.fit.chain_checks import SIGN_CHECK_W

        if self.usable and not self.nonzero:
            raise UserError(f"{self.where}: the measured {self.target} power ({self.source}) is 0 on every "
                            f"one of the {self.usable} usable samples: nothing to calibrate a "
                            "chain on (a voltage, current or fuel flow logged as 0?)")
        f = self.falling
        if f is not None and f[0] >= 50 and f[3] > 0 and f[4] > 0 and f[5] < 0:
            raise UserError(_falling(self.where, self.source, f[5] / math.sqrt(f[3] * f[4]), f[0],
                                     SIGN_CHECK_W, "the driving power"))
        k = len(getattr(self, "names", ())) or 3
        if self.n_ok < k + 2:
            raise too_few_samples(self.n_ok, k, self.unknown, self.spec.loads, self.spec.hvac, self.where)

    def brake_bins(self) -> tuple[list, tuple]:
        """(the order statistics' ranks np.quantile reads, the bins that hold them)."""
        n = int(self.hist[1].sum()) if self.hist is not None else 0
        if n <= 20:
            return [], ()
        return quantile_bins(self.hist, LIMIT_QUANTILES)

    def limits_from(self, collected: "ChainStats") -> list:
        """The recuperation limits tried: np.quantile of the braking powers at
        LIMIT_QUANTILES, from the values ``collected`` of the bins of :meth:`brake_bins`."""
        return sorted(set(quantiles_of(self.hist, collected.values, LIMIT_QUANTILES)))

    def fit(self, limits=()) -> ChainFit:
        """The chain: every grid value solved on its factor, the best by BIC."""
        if self.target == "fuel":
            return self._fit_fuel()
        sp, best, profile = self.spec, None, []
        fixed = check_fixed(sp.fixed, self.names)
        fx = coefficients(self.names, fixed)
        for lim in [sp.held_limit] if sp.held_limit is not None else [None] + list(limits):
            beta, rss, act, se = solve_fixed(self.fac[lim][0], self.fac[lim][1], self.lb, self.ub, fx)
            bic = _bic(rss, self.n_ok, len(self.names) - len(fx) + (lim is not None))
            profile.append({"recuperation_limit_w": lim, "rss": rss, "bic": bic})
            if best is None or bic < best[0]:
                best = (bic, lim, beta, rss, act, se)
        _, lim, beta, rss, act, se = best
        chain, params = battery_chain(self.names, beta, se, act, lim, sp.hvac, fixed=fixed, fx=fx)
        sw, mu, c = self.mom
        r2 = 1.0 - rss / float(c[0, 0]) if c[0, 0] > 0 else math.nan
        ey = sw * float(mu[0])
        ratio = float(self.fac[lim][2] @ beta) / ey if ey != 0 else math.nan
        return self._finish(chain, params, r2, math.sqrt(rss / sw), ratio, profile)

    def _fit_fuel(self) -> ChainFit:
        sp, best, profile = self.spec, None, []
        sw, mu, c = self.mom
        yy = float(c[0, 0] + sw * mu[0] ** 2)  # Σw·y² of the fuel power
        profiled = isinstance(sp.engine_off, str) and sp.engine_off in ("profile", "conventional")
        conventional = sp.engine_off == "conventional" and not self.battery
        idling = profiled and idles_at_stops(self.standing)  # then only one that runs standing
        for i, tmpl in enumerate(self.grid):
            if idling and tmpl.engine_off_below_w > -np.inf:
                continue
            if tmpl.engine_off_below_w > -np.inf and self.conv[i] != conventional:
                continue  # (the conventional grid or the whole profile: above)
            names = fuel_names(tmpl, sp.loads)
            beta, rss, act, xs = solve_factor(self.fac[i][0], self.fac[i][1], *fuel_bounds(names))
            off, von = tmpl.engine_off_below_w, tmpl.engine_on_above_mps
            bic = _bic(rss, self.n_ok, len(names) + 1 + (von is not None), yy)
            profile.append({"engine_off_below_w": off, "engine_on_above_mps": von, "rss": rss, "bic": bic})
            if best is None or bic < best[0]:
                best = (bic, i, beta, act, xs, rss)
        _, i, beta, act, xs, rss = best
        tmpl = self.grid[i]
        chain, params = fuel_chain(sp.loads, beta, _covariance(xs, rss, act), act, tmpl.engine_off_below_w,
                                   tmpl.engine_on_above_mps, self.w_low / max(sw, 1e-12), sp.fuel,
                                   sp.fuel_cut_below_w, tmpl.charge_sustaining, self.battery)
        if sp.moving_idle:
            set_moving(chain, params, beta, _covariance(xs, rss, act), act, sp.fuel)
        set_rating(chain, params, tmpl.engine_max_w, "declared")
        if idling:
            note_idling(params, self.standing)
        elif conventional:
            note_conventional(params)
        if not profiled:
            note_declared(params)
        b = chain.battery_fuel_factor  # the target: fuel + k·battery power (SOC-corrected)
        sst = float(c[0, 0] + 2 * b * c[0, 1] + b * b * c[1, 1])
        r2 = 1.0 - rss / sst if sst > 0 else math.nan
        et = sw * float(mu[0] + b * mu[1])
        ratio = (float(self.fac[i][2] @ beta) + b * sw * float(mu[1])) / et if et != 0 else math.nan
        fit = self._finish(chain, params, r2, math.sqrt(rss / sw), ratio, profile)
        chain.metrics["target"] = fuel_target_text(self.battery)
        fit.standing, fit.windowed = self.standing, factored_lines(self.fac, i, fuel_bounds(fuel_names(tmpl, sp.loads)))
        return fit

    def _finish(self, chain, params, r2, rmse, ratio, profile) -> ChainFit:
        chain.std_err = {k: p["std_err"] for k, p in params.items() if p["std_err"] is not None}
        chain.metrics = {"n": self.n_ok, "r2": r2, "rmse_w": rmse, "energy_ratio": ratio}
        return ChainFit(chain, params, self.n_ok, r2, rmse, ratio, profile, self.unknown)

    def fitted_ranges(self) -> dict:
        """:func:`sumo_drvpw.fit.chain_checks.fitted_ranges` from the streamed min/max."""
        r = self.ranges
        return {} if r[0] > r[1] else {"power_range_w": r[:2], "speed_range_mps": r[2:]}


def replay(make, kept) -> ChainStats:
    """A pass over the arrays a scan kept (``ChainStats.kept``) instead of the logs: the
    same batches added in the same order, per Part, the Parts merged in order, as
    :func:`sumo_drvpw.fit.engine.run` does locally, so the same numbers."""
    acc = None
    for part in kept:
        st = make()
        for p, y, w, sig, use, view in part:
            st._battery(p, y, w, sig, use, view)
        acc = st if acc is None else acc.merge(st)
    return acc


def calibrate_chain_streamed(reduce, st: ChainStats) -> ChainFit:
    """The chain of a scanned :class:`ChainStats` (``st``, checked): for a battery chain
    with enough braking samples, two more passes (``reduce(make)`` runs one over the logs
    and returns the merged accumulator; over the arrays the scan kept, when it kept them)
    find the recuperation limits and factor the design at each; a fuel chain needs none."""
    from functools import partial

    st.check_chain()
    if st.kept is not None:
        reduce = partial(replay, kept=st.kept)
    st.kept = None
    limits = []
    if st.target == "battery" and st.spec.held_limit is None:  # (a held limit: factored by the scan)
        _, bins = st.brake_bins()
        if bins:
            limits = st.limits_from(reduce(partial(ChainStats, st.spec, "collect", bins=bins)))
            st.fac.update(reduce(partial(ChainStats, st.spec, "fit", limits=tuple(limits))).fac)
    return st.fit(limits)
