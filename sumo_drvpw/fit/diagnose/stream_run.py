"""The residual tracer on logs of any length, in bounded memory (issue #14).

:func:`diagnose_stream` is :func:`sumo_drvpw.fit.diagnose.diagnose` for logs that do not
fit in memory. What differs is only where the sums come from:

1. **first look, on a sample** — the first ``sample_rows`` rows (whole trips, reading
   order: up to the end of the trip of row ``sample_rows`` − 1, whatever the chunk size):
   column screening and roles, two-valued columns, the sample interval of the lag
   search, the calibration on the spot (no declared equation) and the recuperation
   quantiles. With fewer rows than ``sample_rows`` the sample is all data.
2. **one read of the logs** — batch by batch of whole trips
   (:func:`~sumo_drvpw.fit.diagnose.source.read_batches`: chunks of at most
   ``BATCH_VALUES`` values, so a wide log in fewer rows; after the first look only the
   columns the trace reads) into the arrays the tracer needs
   (:class:`~sumo_drvpw.fit.diagnose.source.Batches`: in memory up to a budget, else in a
   temporary folder).
3. **passes** over the prepared batches for every statistic the search needs
   (:class:`~sumo_drvpw.fit.diagnose.streamed.StreamModel`): the lag search, the declared
   model, the candidates' block statistics (one pass per round), each finding's held-out
   evaluation. Neighbour effects — the lag shift, blocks, regimes — are per trip, and a
   batch holds whole trips, so they are exact.

Not evaluated here (the in-memory tracer does): the accelerometer grade (per-sample
smoothing of a second grade is left to the in-memory path; the report says so), and the
figures (no per-sample predictions are kept). Results equal the in-memory tracer's to
rounding when the sample is all data (tests/test_diagnose_stream.py).
"""

from __future__ import annotations

import math
import time
import weakref
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from sumo_drvpw.data.stream import BATCH_ROWS, plan
from sumo_drvpw.errors import UserError
from sumo_drvpw.fit.diagnose.candidates import Candidate, check_include, generate_candidates, screen_signals
from sumo_drvpw.fit.diagnose.options import DiagnoseOptions
from sumo_drvpw.fit.diagnose.result import DiagnoseResult, assemble, restore_held, zero_terms
from sumo_drvpw.fit.trip_energy import left_out_by_trip
from sumo_drvpw.fit.stream import _add_counts
from sumo_drvpw.fit.diagnose.source import (CACHE_MB, INPUT_FIELDS, SAMPLE_ROWS, Batches, View,
                                            concat_inputs, parquet_metadata, read_batches)
from sumo_drvpw.fit.diagnose.stream_lag import LagSums, coarse_lags, timing_step
from sumo_drvpw.fit.diagnose.streamed import StreamModel
from sumo_drvpw.fit.diagnose.streamed import _Moments
from sumo_drvpw.fit.diagnose.structural import (ACCELEROMETER_COLUMNS, accelerometer_candidate, accelerometer_grade_power, FUSION_TAU_S, P0_KPA, RECUP_QUANTILES,
                                                accelerometer_sin_grade, fused_sin_grade, lag_range, model_side_candidates,
                                                pressure_at_altitude_kpa)
from sumo_drvpw.model.terms import parse_term, term_matrix


@dataclass
class Prepared:
    """The prepared batches and what a view of them needs."""

    batches: Batches
    declared: list
    kept: list                          # offered signals (columns of each batch's ``sig``)
    trip_names: np.ndarray = None       # sorted trip ids of all rows
    derived: dict = field(default_factory=dict)   # name → f(view, batch, sel) → values
    sample_batches: int = 0                       # the first-look sample's batches

    @property
    def signal_names(self):
        return list(self.kept) + list(self.derived)

    def views(self, common: bool, lag: int):
        for d in self.batches:
            yield self.view(d, common, lag)

    def view(self, d: dict, common: bool, lag: int) -> View:
        """The view of one prepared batch (``common``: the lag search's samples only)."""
        sel = d["common"] if common else None
        gmap = np.searchsorted(self.trip_names, np.asarray(d["names"], dtype=str))
        view = View(d, sel, lag, gmap)
        view.signals = _Signals(view, d, sel, self.kept, self.derived)
        view.extra["batch"] = d
        return view


class _Signals(dict):
    """A view's signals, each computed when first asked for (derived ones cost a pass)."""

    def __init__(self, view, d, sel, kept, derived):
        super().__init__()
        # a weak reference: a cycle view ↔ signals would keep each batch's arrays alive
        # until the cyclic garbage collector runs (seen: +400 MB at 10 M rows)
        self._args = (weakref.proxy(view), d, sel)
        self._kept = {k: j for j, k in enumerate(kept)}
        self._derived = derived

    def __missing__(self, key):
        view, d, sel = self._args
        if key in self._kept:
            col = d["sig"][:, self._kept[key]]
            val = col if sel is None else col[sel]
        elif key in self._derived:
            val = self._derived[key](view, d, sel)
        else:
            raise KeyError(key)
        self[key] = val
        return val

    def __contains__(self, key):
        return dict.__contains__(self, key) or key in self._kept or key in self._derived


class _HeldNotZero(Exception):
    """A term held as 0 on the first-look sample is ≠ 0 in a later batch."""


def _prepare(m, eq, declared, kept, opt, lags, elev: bool, acc_col, held=()) -> dict:
    """The arrays of one batch (a Measured of whole trips) the tracer needs."""
    y_all = np.asarray(m.power_w, float)
    x_eq = m.inputs.with_mass(eq.mass_kg)
    decl = term_matrix(declared, x_eq)
    ana = np.asarray(m.usable, bool) & np.all(np.isfinite(decl), axis=1) & (x_eq.v >= opt.min_speed_mps)
    sig = [np.asarray(m.inputs.signals[k], float) for k in kept]
    for a in sig:
        ana &= np.isfinite(a)
    if held and np.any(np.nan_to_num(term_matrix(list(held), x_eq)[ana]) != 0):
        raise _HeldNotZero()
    df = m.log.df
    codes, names = _trip_codes(df["trip_id"])
    idx = np.flatnonzero(ana)
    # row positions and trip codes within a batch fit in 32 bits (half the bytes on disk)
    d = {"idx": idx.astype(np.int32), "y": y_all[idx], "dt": df["dt_s"].to_numpy(float)[idx],
         "t": df["time_s"].to_numpy(float)[idx], "tloc": codes[idx].astype(np.int32),
         "decl": np.ascontiguousarray(decl[idx]),
         "sig": np.column_stack(sig)[idx] if sig else np.zeros((len(idx), 0)),
         "names": [str(n) for n in names], "rows": len(y_all), "usable": int(np.sum(m.usable)),
         "left_out": left_out_by_trip(y_all, ana, df["dt_s"].to_numpy(float), df["trip_id"].astype(str).to_numpy())}
    for f in INPUT_FIELDS:
        d[f] = np.asarray(getattr(x_eq, f), float)[idx].copy()
    if len(lags) > 1:
        d["yrow"] = y_all
        d["common"] = _finite_at_every_shift(y_all, codes, int(lags[-1]))[idx]
    if acc_col is not None:
        d["imu"] = np.asarray(m.inputs.signals[acc_col], float)[idx]
    if elev and "elevation_m" in df:  # a batch without: NaN (the candidate then not offered)
        d["elev"] = df["elevation_m"].to_numpy(float)[idx]
    return d


def _columns_read(target: str, read_options, term_signals: set, kept, acc_col) -> frozenset | None:
    """The columns the batches after the first look are read with: the reader's canonical
    ones, the signals offered and those the declared terms name, the accelerometer and what
    the measurement corrections read; with a battery or fuel target every column (its fuel
    and air flows are found by name, as compare reads them)."""
    from sumo_drvpw.data.corrections import needed_columns
    from sumo_drvpw.data.stream import CANONICAL

    if target != "wheel":
        return None
    meas = getattr(read_options, "measurement", None)
    return frozenset(CANONICAL | set(kept) | term_signals | ({acc_col} if acc_col else set())
                     | needed_columns(meas))


def _trip_codes(trip: pd.Series):
    """Trip code per row and the trips' names (str), as ``pd.factorize`` of the ids as
    strings; factorized as they are (5× faster on Arrow strings) unless an id is missing
    or two ids read the same as strings."""
    codes, names = pd.factorize(trip)
    names = [str(n) for n in names]
    if (len(codes) and codes.min() < 0) or len(set(names)) != len(names):
        codes, names = pd.factorize(trip.astype(str).to_numpy())
        names = [str(n) for n in names]
    return codes, names


#: rows per chunk read at most [-]: half the calibrate/compare chunk (the prepared batches and
#: the per-block statistics share the memory budget); a wide log's chunks hold fewer, at most
#: data/stream.py BATCH_VALUES values of the columns read (source.read_batches)
READ_ROWS = BATCH_ROWS // 2


def _finite_at_every_shift(y: np.ndarray, trip: np.ndarray, big: int) -> np.ndarray:
    """Rows whose power read k rows later is finite and in the same trip for every shift
    |k| ≤ ``big`` (``shift_within_trips`` finite for all k), in one pass: the window
    i − big … i + big lies inside the row's trip and holds no non-finite power."""
    n = len(y)
    start = np.r_[True, trip[1:] != trip[:-1]]
    first = np.maximum.accumulate(np.where(start, np.arange(n), 0))
    end = np.r_[trip[1:] != trip[:-1], True]
    last = np.minimum.accumulate(np.where(end, np.arange(n), n)[::-1])[::-1]
    pos = np.arange(n)
    inside = (pos - big >= first) & (pos + big <= last)
    bad = np.r_[0, np.cumsum(~np.isfinite(y))]
    lo, hi = np.clip(pos - big, 0, n), np.clip(pos + big + 1, 0, n)
    return inside & (bad[hi] - bad[lo] == 0)


def diagnose_stream(paths, vehicle=None, equation=None, opt: DiagnoseOptions | None = None,
                    read_options=None, target: str = "wheel", rows: int = READ_ROWS,
                    sample_rows: int = SAMPLE_ROWS, cache_mb: float = CACHE_MB,
                    progress=None, bar=None, hold: bool = True) -> DiagnoseResult:
    """Trace the residual of ``equation`` on drive logs of any length (see module docstring).

    Parameters
    ----------
    paths : drive log files or folders
    vehicle : vehicle name or file (as ``load_measured``), or None
    equation : the declared :class:`~sumo_drvpw.model.equations.Equation`, or None
        (calibrated on the spot on the sample, stepwise on indt-var-1)
    opt : :class:`DiagnoseOptions`
    read_options : :class:`~sumo_drvpw.data.log.ReadOptions`
    target : what the measured power is (``load_measured``'s ``target``)
    rows : rows per chunk read at most [-] (a wide log's chunks hold fewer: at most
        data/stream.py ``BATCH_VALUES`` values)
    sample_rows : rows of the first-look sample [-]
    cache_mb : prepared batches kept in memory up to this size [MB], beyond on disk
    progress : optional callable(str) for progress messages
    bar : optional callable(rows) called per batch read (a progress bar)
    hold : hold declared terms that are 0 on every analysis sample of the first-look sample
        (result.zero_terms); when a later batch has them ≠ 0 the trace starts again without

    Returns the :class:`DiagnoseResult`; ``details["resources"]`` holds rows, seconds,
    passes and whether the batches were on disk.
    """
    from sumo_drvpw.data.plausible import check_distinct_trips
    from sumo_drvpw.data.roles import from_metadata, resolve
    from sumo_drvpw.fit.calibrate import CANDIDATES
    from sumo_drvpw.fit.physical import physical_calibration
    from sumo_drvpw.model.vehicles import load_vehicle

    t_start = time.perf_counter()
    opt = opt or DiagnoseOptions()
    opt.check()
    say = progress or (lambda s: None)
    veh = load_vehicle(vehicle) if isinstance(vehicle, str) else vehicle
    check_distinct_trips(paths)  # (per-trip sums and lags are keyed by trip id across batches)
    # diagnose reads a chunk at a time (no reading ahead in a thread: on this shared 2-core
    # machine at load 3 it cost 20-30 % wall time, 10 M rows); every column for the first
    # look (screening), then only those the trace reads
    want: dict = {"columns": None}
    gen = read_batches(paths, veh, read_options, target, rows, sample_rows=sample_rows, want=want)
    sample, n_sample = [], 0
    for m in gen:
        sample.append(m)
        n_sample += len(m.power_w)
        if bar:
            bar(len(m.power_w))
        if n_sample >= sample_rows:
            break
    if not sample:
        raise UserError("no drive log rows to trace")
    first_extra = list(sample[0].log.extra_columns)  # the columns whose roles are resolved
    files = list(dict.fromkeys(p.path for p in plan(paths)))
    y_s = np.concatenate([np.asarray(m.power_w, float) for m in sample])
    x_s = concat_inputs(sample)  # each batch then holds its signals as views of x_s's
    usable_s = np.concatenate([np.asarray(m.usable, bool) for m in sample])
    trip_s = np.concatenate([m.log.df["trip_id"].astype(str).to_numpy() for m in sample])
    t_s = np.concatenate([m.log.df["time_s"].to_numpy(float) for m in sample])
    codes_s, uniq_s = pd.factorize(trip_s)
    rank = np.empty(len(uniq_s), np.int64)
    rank[np.argsort(np.asarray(uniq_s, dtype=str), kind="stable")] = np.arange(len(uniq_s))
    tcodes_s = rank[codes_s]           # as np.unique(trip_s, return_inverse=True)
    source = sample[0].source
    check_include(x_s.signals, opt)  # before any work
    calibrated = False
    if equation is None:
        equation, phys = physical_calibration(x_s, y_s, CANDIDATES["indt-var-1"], mask=usable_s,
                                              reference_mass_kg=float(x_s.mass[usable_s].mean()))
        equation.name = "calibrated_indt_var_1"
        equation.provenance["logs"] = files
        calibrated = True
        say(f"calibrated on the spot on the first {n_sample:,} rows ({phys['used']}): "
            f"{', '.join(equation.term_names)}")
    declared = equation.term_names
    for s in equation.signals:
        if s not in x_s.signals:
            raise UserError(f"equation '{equation.name}' needs the log column '{s}', which the data lack")
    roles = resolve(first_extra, from_metadata(parquet_metadata(paths)))
    kept, skipped = screen_signals(dict(x_s.signals), y_s, x_s, tcodes_s, usable_s, opt, roles)
    for name in list(kept):
        if name in equation.signals:
            skipped.append({"column": name, "reason": "already a factor of a declared term"})
            kept.pop(name)
    kept_names = list(kept)
    declared_eq = equation  # terms 0 on the first rows' analysis samples are held (result.zero_terms)
    decl_s = term_matrix(declared, x_s.with_mass(equation.mass_kg))
    ana_s = usable_s & np.all(np.isfinite(decl_s), axis=1) & (x_s.v >= opt.min_speed_mps)
    for name in kept_names:
        ana_s &= np.isfinite(np.asarray(x_s.signals[name], float))
    held, equation = zero_terms(equation, decl_s, ana_s) if hold and not calibrated else ([], equation)
    if held:
        say(f"declared term(s) {', '.join(held)} 0 on every analysis sample of the first rows: kept at "
            "their declared coefficients, not fitted")
        declared = equation.term_names
    dt_med = float(np.median(np.diff(t_s)[np.diff(tcodes_s) == 0])) if len(t_s) > 1 else 0.0
    lags = lag_range(dt_med, opt.max_lag_s) if opt.structural and opt.max_lag_s > 0 else np.array([0])
    # air density at altitude: decided on all batches (their columns and the merged air
    # density source), as in memory on the whole log; each batch keeps its elevation till then
    elev = bool(opt.structural)
    seen_cols: set = set()
    acc_col = next((c for c in ACCELEROMETER_COLUMNS if c in x_s.signals), None) if opt.structural else None
    dt_acc = float(np.median(np.diff(t_s))) if len(t_s) > 1 else 1.0
    del x_s, y_s, usable_s, trip_s, t_s, tcodes_s
    term_signals = set(equation.signals) | set(declared_eq.signals)
    want["columns"] = _columns_read(target, read_options, term_signals, kept_names, acc_col)
    used = set(kept_names) | term_signals | {acc_col}
    for m in sample:  # the sample's other signals go with x_s
        m.inputs.signals = {k: v for k, v in m.inputs.signals.items() if k in used}
    # one read of the logs into prepared batches
    batches = Batches(cache_mb)
    n_rows = n_usable = 0
    names: set = set()
    left_out: dict = {}  # trip → what it lost to samples outside the analysis (fit/trip_energy.py)
    sample_idx = len(sample)
    try:
        reader_counts: dict = {}

        def consume(m):
            nonlocal n_rows, n_usable, reader_counts
            reader_counts = _add_counts(reader_counts, m.counts)
            seen_cols.update(c for c in ("elevation_m", "ambient_c", "pressure_kpa") if c in m.log.df)
            d = _prepare(m, equation, declared, kept_names, opt, lags, elev, acc_col, held)
            left_out.update(d.pop("left_out"))
            n_rows += d.pop("rows")
            n_usable += d.pop("usable")
            names.update(d["names"])
            batches.append(d)
        while sample:                      # each sample batch freed once prepared
            consume(sample.pop(0))
        for m in gen:
            consume(m)
            if bar:
                bar(len(m.power_w))
            del m
        if n_usable == 0:
            raise UserError(f"{', '.join(files)}: no usable sample among {n_rows} rows")
        prep = Prepared(batches, declared, kept_names, np.array(sorted(names)))
        prep.sample_batches = sample_idx
        say(f"{n_rows:,} rows read in {len(batches)} batch(es) in {time.perf_counter() - t_start:.1f} s, "
            f"peak RSS {_peak_mb():,.0f} MB"
            + (" (prepared arrays on disk)" if batches.on_disk else ""))
        # two-valued columns, on the sample's analysis samples
        binary = _binary(prep, sample_idx, sample_rows)
        elev = bool(elev and {"elevation_m", "ambient_c"} <= seen_cols and "pressure_kpa" not in seen_cols
                    and str(reader_counts.get("air_density_source", "")).startswith("ideal gas"))
        res = _trace(prep, equation, declared, opt, lags, dt_med, elev, (acc_col, dt_acc), binary, roles, say)
        tr = res["tr"]
        measured = _Measured(_Log(files, read_options), reader_counts.get("power_source") or source)  # of all
        out = assemble(tr=tr, measured=measured, equation=equation, declared=declared, calibrated=calibrated,
                       opt=opt, findings=res["findings"], rounds=res["rounds"], ev0=res["ev0"],
                       base_coefs=res["base_coefs"], plot={"findings": []}, n_rows=n_rows,
                       n_usable=n_usable, skipped=skipped, sig=dict.fromkeys(kept_names),
                       n_candidates=res["n_candidates"], n_trips=int((tr.trip_counts() > 0).sum()),
                       dropped=res["dropped"], roles={k: roles[k] for k in kept_names if k in roles},
                       extra=res["extra"], left_out=left_out)
        out = restore_held(out, declared_eq, held)
    except _HeldNotZero:  # ≠ 0 after the first rows (a folder of flat and hilly logs): no hold
        say(f"declared term(s) {', '.join(held)} ≠ 0 beyond the first rows: read again, fitting them")
        return diagnose_stream(paths, vehicle, declared_eq, opt, read_options, target, rows, sample_rows,
                               cache_mb, progress, bar, hold=False)
    finally:
        on_disk = batches.on_disk
        batches.close()
    passes = res["passes"] + tr.passes
    secs = time.perf_counter() - t_start
    #: what the log reader changed or assumed, summed over the batches (cli.note_counts)
    out.details["reader_counts"] = reader_counts
    out.details["resources"] = {"rows": n_rows, "seconds": secs, "passes": passes,
                                "batches_on_disk": on_disk, "sample_rows": n_sample}
    return out


def _peak_mb() -> float:
    from sumo_drvpw.fit.engine import peak_rss_mb

    return peak_rss_mb()


@dataclass
class _Log:
    files: list
    #: the reading options (their measurement corrections go into the traced equation)
    options: object = None


@dataclass
class _Measured:
    log: _Log
    source: str


def _binary(prep: Prepared, n_batches: int, limit: int) -> set:
    """Offered columns with at most two values on the sample's analysis samples."""
    vals: dict = {k: set() for k in prep.kept}
    seen = 0
    for i, d in enumerate(prep.batches):
        if i >= n_batches or seen >= limit:
            break
        seen += d["rows"] if "rows" in d else len(d["y"])
        for j, k in enumerate(prep.kept):
            if len(vals[k]) <= 2:
                vals[k].update(np.unique(d["sig"][:, j]).tolist()[:3])
    return {k for k, v in vals.items() if len(v) <= 2}


def _declared(prep, opt, declared, common, lag, hook=None, defer=False) -> StreamModel:
    cols = [Candidate(term, f"declared term {term}", tuple(parse_term(term).signals), "declared")
            for term in declared]
    return StreamModel(prep, opt, common=common, lag=lag, columns=cols, hook=hook, defer=defer)  # one pass


def _trace(prep, equation, declared, opt, lags, dt_med, elev, acc, binary, roles, say) -> dict:
    from sumo_drvpw.fit.diagnose.search import COARSE_LAGS, paired_test, search_rounds

    passes = 0
    timing_finding, lag_note = None, None
    if len(lags) > 1:
        hook = LagSums(np.array(coarse_lags(lags, COARSE_LAGS), dtype=np.int64), opt.folds)
        # one pass: the timing model (common samples: layout, terms, coarse lag sums) and the
        # model without a lag (all analysis samples: layout, terms)
        tr0 = _declared(prep, opt, declared, True, 0, hook, defer=True)
        trm = _declared(prep, opt, declared, False, 0, defer=True)
        for d in prep.batches:
            tr0.layout_step(prep.view(d, True, 0))
            trm.layout_step(prep.view(d, False, 0))
        tr0.layout_end()
        trm.layout_end()
        tr0.passes += 1
        tr = trm
        if tr0.n >= 50:
            timing_finding, lag_note, tr1 = timing_step(
                tr0, hook, lambda lag: _declared(prep, opt, declared, True, lag), opt, lags, dt_med, say,
                paired_test, COARSE_LAGS)
            passes += tr0.passes
            if timing_finding is not None:
                tr = tr1
        del tr0, hook                      # the timing model's block statistics are not needed again
    if len(lags) <= 1:
        tr = _declared(prep, opt, declared, False, 0)
    if tr.n < 50:
        raise UserError(f"only {tr.n} analysis samples (usable, with finite terms and signals); need at least 50")
    n_trips = int((tr.trip_counts() > 0).sum())
    say(f"{tr.n} analysis samples, {n_trips} trip(s), {tr.n_blocks} blocks, {len(prep.kept)} signal(s) offered "
        f"(peak RSS so far {_peak_mb():,.0f} MB)")
    cands = generate_candidates(dict.fromkeys(prep.kept), declared, n_trips, opt, binary)
    notes = {}
    if opt.structural:
        s_cands, notes = _structural(tr, prep, declared, elev, acc)
        cands = cands + s_cands
        tr.signals = {k: None for k in prep.signal_names}
    cands, dropped = tr.drop_spanned(cands)
    if dropped:
        say(f"{len(dropped)} candidate(s) dropped before scoring: identical to or spanned by earlier ones")
    ev0 = tr.evaluate(tr.fold_of(False))
    base_coefs, _ = tr.coefficients()
    findings = [timing_finding] if timing_finding is not None else []
    rounds, rejected = search_rounds(tr, cands, declared, roles, opt, say, findings, {"findings": []})
    return {"tr": tr, "findings": findings, "rounds": rounds, "ev0": ev0, "base_coefs": base_coefs,
            "dropped": dropped, "n_candidates": len(cands), "passes": passes,
            "extra": {"not_replicated": rejected, "timing": lag_note, "structural": notes}}


def _structural(tr: StreamModel, prep: Prepared, declared, elev: bool, acc):
    """Regimes, air density from altitude, a missing grade term and the accelerometer grade
    (as ``structural.structural_signals``; ``acc`` = (accelerometer column or None, its Δt [s]))."""
    cands, notes = [], {}
    f = tr.full_fit()
    coef = [(float(f["beta"][c.offset]), c.scale, j) for j, c in enumerate(tr.cols)]
    y_scale = tr.y_scale

    def base_pred(view, d=None, sel=None):
        if "base_pred" not in view.extra:
            pred = np.zeros(view.n)
            for b, s, j in coef:
                pred += b * (view.decl[:, j] / s) * y_scale
            view.extra["base_pred"] = pred
        return view.extra["base_pred"]
    # the regimes' share and quantiles on the first-look sample's batches (all data when
    # the sample is): a partial pass
    n_neg, n_seen, neg_vals = 0, 0, []
    for i, view in enumerate(tr._views(blocks=False)):
        if i >= prep.sample_batches:
            break
        pred = base_pred(view)
        neg = pred < 0
        n_neg += int(neg.sum())
        n_seen += view.n
        neg_vals.append(-pred[neg])
    if n_seen and n_neg / n_seen > 0.02:
        negs = np.concatenate(neg_vals)
        prep.derived["recuperation"] = lambda v, d, sel: np.where(base_pred(v) < 0, base_pred(v), 0.0)
        cands.append(Candidate("[recuperation]", "recuperation on its own coefficient: "
                               "drivetrain efficiency differs by direction (1 + c scales recuperation)",
                               (), "structural"))
        for q in RECUP_QUANTILES:
            lim = float(np.quantile(negs, q))
            if lim <= 0:
                continue
            name = f"recuperation_below_{lim / 1000:.3g}kW"
            prep.derived[name] = (lambda lim: lambda v, d, sel: np.minimum(base_pred(v) + lim, 0.0))(lim)
            cands.append(Candidate(f"[{name}]", f"a recuperation limit: beyond {lim / 1000:.3g} kW "
                                   "of predicted recuperation, friction brakes take over", (), "structural"))
    if elev:
        lo, hi, s1, fin = math.inf, -math.inf, 0.0, True
        for d in prep.batches:
            if "elev" not in d:  # a batch without elevation_m: NaN, as in memory
                fin = fin and not (d["common"].any() if tr.common else len(d["y"]))
                continue
            h = d["elev"] if not tr.common else d["elev"][d["common"]]
            fin &= bool(np.isfinite(h).all())
            if len(h):
                lo, hi = min(lo, float(h.min())), max(hi, float(h.max()))
                s1 += float((pressure_at_altitude_kpa(h) / P0_KPA - 1.0).sum())
        if fin and tr.n:
            prep.derived["air_density_altitude"] = lambda v, d, sel: (
                pressure_at_altitude_kpa(d["elev"] if sel is None else d["elev"][sel]) / P0_KPA - 1.0)
            notes["air_density_altitude"] = {"mean_relative_error_of_rho": s1 / tr.n, "altitude_m": [lo, hi]}
            for t in declared:
                if parse_term(t).category == "aero" and not parse_term(t).signals:
                    cands.append(Candidate(f"[air_density_altitude]*{t}",
                                           f"air density from altitude: the log's ρ assumes sea-level "
                                           f"pressure; {t} scaled by p(h)/p₀ − 1", (), "structural"))
    cands += model_side_candidates(declared, tr.theta_ptp)
    acc_col, dt_acc = acc
    grade_terms = [t for t in declared if parse_term(t).category == "grade" and not parse_term(t).signals]
    if acc_col is not None and grade_terms and all(np.isfinite(d["imu"] if not tr.common else d["imu"][d["common"]]).all()
                                                   for d in prep.batches):
        def sin_acc(v, d, sel):
            return accelerometer_sin_grade(d["imu"] if sel is None else d["imu"][sel], v.x.a, v.trip, dt_acc)
        prep.derived["grade_accelerometer"] = lambda v, d, sel: accelerometer_grade_power(v.x, sin_acc(v, d, sel))
        cands.append(accelerometer_candidate(acc_col))
        sums = {k: [0.0, _Moments()] for k in ("logged", "accelerometer", "fused")}
        xy = np.zeros(5)
        for view in tr._views(blocks=False):
            d = view.extra["batch"]
            sel = d["common"] if tr.common else None
            sa, sl = sin_acc(view, d, sel), np.sin(view.x.theta)
            fu = fused_sin_grade(sa, sl, view.trip, dt_acc)
            for k, arr in (("logged", np.clip(sl, -1, 1)), ("accelerometer", sa), ("fused", fu)):
                ang = np.arcsin(arr)
                sums[k][0] += float(np.abs(ang).sum())
                sums[k][1].add(ang)
            xy += [sa.sum(), sl.sum(), sa @ sa, sl @ sl, sa @ sl]
        n = tr.n
        out = {k: {"mean_abs_deg": float(np.degrees(v[0] / n)),
                   "sd_deg": float(np.degrees(math.sqrt(v[1].m2 / n)))} for k, v in sums.items()}
        out["fused"]["crossover_s"] = FUSION_TAU_S
        mx, my = xy[0] / n, xy[1] / n
        vx, vy, cxy = xy[2] / n - mx * mx, xy[3] / n - my * my, xy[4] / n - mx * my
        notes["grade_sources"] = {"accelerometer_column": acc_col, **out,
                                  "corr": float(cxy / math.sqrt(vx * vy)) if vy > 0 and vx > 0 else math.nan}
    return cands, notes
