"""Generate docs/closing-the-loop.md: the loop closed on real data, proven on held-out trips.

    .venv/bin/python scripts/closing_the_loop.py --data ../shared/data --out docs

For each car the shared logs are read in place through their adapters (never copied) and
the trips are split before anything is fitted: every 5th trip in name order is held out
(BMW i3: 10 of 50; every 3rd below 10 trips, JLU road: 2 of 6); with two trips (Prius Gen-2) each trip is held out
once in turn. The i3 is run on a second split fixed by the same rule from another offset
(every 5th trip from the 3rd), to say how the findings replicate. On the training trips only:

1. the declared equation is calibrated (stepwise on indt-var-1) and read physically
   (:mod:`sumo_drvpw.fit.physical`); an implausible fit is refitted under physical
   constraints, saying why;
2. ``diagnose`` (default settings: conditions, loads and structural effects; responses
   left out) searches what the equation lacks, with trip-grouped cross-validation;
3. measurement-side findings are corrected in the data (a power–speed lag; when the
   tracer finds that the accelerometer carries grade the logged grade lacks, the grade is
   fused: accelerometer above a crossover, logged grade below it, which removes the
   accelerometer's mounting-pitch bias), and the equation is recalibrated on it. The
   grade source (a crossover over driven distance or in time, or the accelerometer alone)
   is chosen from TAU_GRID_S together with the physical candidates of step 4: for every
   source its own candidates, and the source whose closed-loop structure has the lowest
   trip-grouped 5-fold cross-validated mean absolute trip traction-energy error on the
   training trips (GRADE_CHOICE);
4. with at least 5 training trips, physical candidates in forms SUMO can evaluate
   (``fit.physical.PHYSICAL_CANDIDATES``: ρ(T, altitude) in the aero term, c_r(T),
   cold drivetrain drag, recuperation on its own coefficient, inertial power by direction, and a
   cornering drag where the logs carry a yaw rate — the shared ones do not) are chosen forward by the
   same trip-grouped cross-validation (``fit.physical.select_physical``), each kept only
   with a plausible coefficient; the closed-loop equation is fitted with them. The
   tracer's log-only findings (``[ambient_c]*…``) are reported, not carried: SUMO cannot
   evaluate a log column.

Before any of this, every log (training and held out) passes the input checks of
:mod:`sumo_drvpw.fit.input_checks` (inputs only): logger dropouts leave the usable samples;
declared mass, accelerometer offset and elevation are checked and reported per trip.

(The Markdown is rendered by scripts/closing_the_loop_report.py.) The held-out trips then give R² and per-trip traction energy errors (Σ max(P, 0)·Δt,
predicted/measured − 1) before and after, against VSP LDV 1999 as a reference. The JLU
car: an equation calibrated on the dynamometer is taken onto the road, and the loop is
closed on road trips (grade, auxiliaries and temperature the dyno could not see; the constant
power split into a standing part ``v^0`` and a part drawn while moving, ``moving``, checked by
leave-one-trip-out over all road trips and against the power measured while standing).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

CMD = ".venv/bin/python scripts/closing_the_loop.py --data ../shared/data --out docs"
HOLD_EVERY = 5
#: crossovers of the grade fusion tried, each by trip-grouped cross-validation on the
#: training trips only (criterion: mean absolute trip traction-energy error)
#: (inf: no logged grade at all, the accelerometer with one offset per trip fixed by the
#: elevation, Σ sin θ·ds = Δh: fit.input_checks.offset_corrected_sin_grade)
#: and LOGGER_OFFSET: no logged grade either, the accelerometer less one offset for the logger,
#: the median over the training trips of what each trip's elevation change implies
#: (data.corrections.logger_offset_mps2: one mounting pitch; per-trip elevation errors drop out)
#: Crossovers over driven distance are strings "<L> m" (the fusion's slow part weights each
#: sample by the road it drove, so the fused grade keeps each trip's logged elevation change:
#: data.corrections.fused_sin_grade_distance); numbers are crossovers in time [s] (their slow
#: part weights standing samples too, and the grade's integral drifts from the elevation).
LOGGER_OFFSET = "logger offset"
TAU_GRID_S = (60.0, 300.0, "250 m", "500 m", "1000 m", "2000 m", "4000 m", math.inf, LOGGER_OFFSET)
#: how the grade source and the physical candidates are chosen (``--grade-choice``):
#: "joint" (default) — for every grade source its own physical candidates, and the grade
#: source whose closed-loop structure cross-validates best; "sequential" — the grade source
#: with the calibrated terms first (a missing temperature term then dominates the trip errors
#: that choose it), the physical candidates on it; "recheck" — sequential, then the grade
#: source once more with the closed-loop terms. The comparison, a nested cross-validation
#: over all trips: scripts/grade_choice_cv.py, docs/closing-the-loop.md ("What this shows")
GRADE_CHOICES = ("joint", "sequential", "recheck")
GRADE_CHOICE = "joint"
#: the per-trip energy whose cross-validated error chooses the grade source and the physical
#: candidates (``--selection-energy``): "traction" (default; Σ max(P, 0)·Δt, the issue's
#: measure) or "net" (Σ P·Δt: recuperation and the climb's potential energy judged too, what a
#: battery follows). In a nested cross-validation over the 50 i3 trips "net" chose the same
#: structure in every fold and lowered the held-out traction, net and battery errors, but it
#: was tried after the traction result was seen (a descent's net error is bounded:
#: fit.trip_energy.net_energy_errors): scripts/battery_nested_cv.py, docs/energy-chain.md
SELECTION_ENERGIES = ("traction", "net")
SELECTION_ENERGY = "traction"
#: fewest training trips for trip-grouped cross-validation of choices (tau, physical terms)
MIN_CV_TRIPS = 5
#: cars whose trips are one day's drives in different directions (an out-and-back pair):
#: their logs imply one steady wind (wind_check). Not the i3 (no heading) nor the JLU car
#: (trips of different days: no common wind)
WIND_CHECK = ("prius2",)
#: take logger dropouts (held or linearly filled inputs) out of the usable samples of every
#: log, training and held out alike, for every equation (fit.input_checks.dropout_mask)
CHECK_DROPOUTS = True


def distance_crossover_m(tau) -> float | None:
    """The crossover [m] of a grid entry "<L> m" (a fusion over driven distance), else None."""
    if isinstance(tau, str) and tau.endswith(" m"):
        return float(tau[:-2])
    return None


def _log(msg):
    print(msg, file=sys.stderr, flush=True)


def split_trips(trips, every: int = HOLD_EVERY, second: bool = False):
    """Held-out groups of trip ids: every ``every``-th trip in name order (offset every−1);
    with ``second`` and at least 10 trips, also a second split fixed up front: every
    ``every``-th trip from the 3rd (offset 2); with two trips, each one in turn; with one
    trip, none (blocks inside the tracer)."""
    t = sorted(trips)
    if len(t) == 2:
        return [[t[0]], [t[1]]]
    if len(t) < 3:
        return []
    k = every if len(t) >= 10 else 3     # a third of a small set
    return [t[k - 1::k]] + ([t[2::k]] if second and len(t) >= 10 else [])


def write_subset(df, trips, path, keep: bool, roles: dict | None = None):
    """The trips (``keep``) or all but them, as a canonical log with the adapter's roles."""
    from sumo_drvpw.cli.import_ import write_log

    sub = df[df["trip_id"].isin(trips) == keep].reset_index(drop=True)
    write_log(sub, {"roles": {c: r for c, r in (roles or {}).items() if c in sub.columns}}, path)
    return path


def _has_accelerometer(path) -> bool:
    import pyarrow.parquet as pq

    from sumo_drvpw.data.corrections import ACCELEROMETER_COLUMNS

    return any(c in pq.read_schema(path).names for c in ACCELEROMETER_COLUMNS)


def _load(path, vehicle, meas):
    """load_measured with the measurement corrections ``meas`` (data/corrections.py, as any
    command reads a log whose equation declares them); ``m.dropouts`` = trip → seconds of
    logger dropouts taken out (None without the check)."""
    from sumo_drvpw.data.dropouts import dropout_report, log_dropouts
    from sumo_drvpw.data.log import ReadOptions
    from sumo_drvpw.data.measured import load_measured

    m = load_measured([path], vehicle, ReadOptions(measurement=meas))
    m.dropouts = None
    if meas is not None and meas.exclude_dropouts:
        df = m.log.df
        drop = log_dropouts(m.log)
        m.dropouts = dropout_report(drop, df["trip_id"].to_numpy(), df["dt_s"].to_numpy(float))
    return m


def load_checked(path, vehicle):
    """load_measured with the logger-dropout check (data.dropouts: speed and a longitudinal
    accelerometer exactly linear in time for ≥ 5 s, and the grade-smoothing distance around
    it; inputs only) taken out of the usable samples — ``[measurement] exclude_dropouts``."""
    from sumo_drvpw.model.measurement import Measurement

    return _load(path, vehicle, Measurement(exclude_dropouts=_has_accelerometer(path)))


def _offsets(m):
    from sumo_drvpw.data.corrections import accelerometer_column, driven_path
    from sumo_drvpw.fit.input_checks import accelerometer_offsets

    df = m.log.df
    return accelerometer_offsets(df[accelerometer_column(df.columns)], m.inputs.a, df["speed_mps"], df["elevation_m"],
                                 df["dt_s"], df["trip_id"], driven_path(m.log, m.inputs.v))


def _trip_inputs(m) -> dict:
    """Per trip, what its inputs say (no power): weather, mean ambient, declared mass,
    net elevation change, distance and share of standstill."""
    df = m.log.df
    out = {}
    for t, i in df.groupby("trip_id", sort=True).indices.items():
        u = m.usable[i]
        r = {}
        if "weather" in df:
            r["weather"] = str(df["weather"].iloc[i[0]])
        if "ambient_c" in df:
            r["ambient_c"] = float(np.nanmean(df["ambient_c"].to_numpy(float)[i][u]))
        r["mass_kg"] = float(np.nanmedian(m.inputs.mass[i][u]))
        if "elevation_m" in df:
            h = df["elevation_m"].to_numpy(float)[i][u]
            h = h[np.isfinite(h)]
            r["dh_m"] = float(h[-1] - h[0]) if len(h) else math.nan
        v = m.inputs.v[i][u]
        r["distance_km"] = float(np.sum(v * df["dt_s"].to_numpy(float)[i][u])) / 1000.0
        r["standstill"] = float(np.mean(v < 0.1))
        out[str(t)] = r
    return out


def input_checks(m_train, eq, held) -> dict:
    """Plausibility of the declared inputs (fit.input_checks): per training trip the inertial
    mass seen in the measured power (relative to the declared mass × the calibrated mass
    factor ``acc``: a check of the declared mass, never substituted); per trip (training and,
    added later, held out: inputs only) the accelerometer offset from standstill and from the
    elevation; dropouts taken out."""
    from sumo_drvpw.fit.input_checks import inertial_mass

    df = m_train.log.df
    out = {"dropouts_train": getattr(m_train, "dropouts", None), "offsets": {}, "mass": {}}
    acc = float(eq.terms.get("acc", np.nan))
    # a comparison across trips: with fewer than 3 training trips it only restates the fit
    if "mass_kg" in df and np.isfinite(acc) and df["trip_id"].nunique() >= 3:
        im = inertial_mass(m_train.power_w, m_train.inputs, m_train.usable, df["trip_id"].to_numpy())
        for t, r in im.items():
            r["vs_declared"] = r["ratio"] / acc - 1.0
        out["mass"] = im
        out["acc"] = acc
    if "imu_accel_mps2" in df and "elevation_m" in df:
        out["offsets"] = _offsets(m_train)
    return out


def measurement_of(path, lag_s: float, accel_grade: bool, tau_s=None, offset_mps2: float | None = None):
    """The corrections of a log (:class:`sumo_drvpw.model.measurement.Measurement`): the power
    read ``lag_s`` later within trips; the grade fused from the accelerometer (fast part) and
    the logged grade (slow part, free of the accelerometer's mounting pitch; ``tau_s`` a
    crossover in time [s] or over driven distance, "<L> m"), or with ``tau_s`` = ∞ the
    accelerometer alone with its per-trip offset fixed by the elevation, or
    with ``tau_s`` = LOGGER_OFFSET the accelerometer less the logger's offset ``offset_mps2``;
    ρ at the logged altitude (standard atmosphere) when pressure is not logged; logger
    dropouts left out (CHECK_DROPOUTS). The closed-loop equations carry it as their
    ``[measurement]``, so `sumo-drvpw compare` reads new logs the same way."""
    import pyarrow.parquet as pq

    from sumo_drvpw.model.measurement import Measurement

    cols = set(pq.read_schema(path).names)
    acc = _has_accelerometer(path)
    dist_m = distance_crossover_m(tau_s)
    timed = isinstance(tau_s, (int, float)) and not isinstance(tau_s, bool) and math.isfinite(tau_s)
    fused = timed or dist_m is not None
    grade, offset = "logged", None
    if accel_grade and acc:
        grade = "accelerometer" if tau_s is not None and not fused else "fused"
        if tau_s == LOGGER_OFFSET:
            offset = float(offset_mps2)
    return Measurement(
        power_lag_s=float(lag_s), grade=grade, accelerometer_offset_mps2=offset,
        fusion_tau_s=float(tau_s) if timed else None, fusion_distance_m=dist_m,
        air_density="altitude" if {"elevation_m", "ambient_c"} <= cols and "pressure_kpa" not in cols else "logged",
        exclude_dropouts=CHECK_DROPOUTS and acc)


def corrected_measured(path, vehicle, lag_s: float, accel_grade: bool, tau_s=None,
                       offset_mps2: float | None = None):
    """Measured power and inputs of a log with the corrections of :func:`measurement_of`."""
    return _load(path, vehicle, measurement_of(path, lag_s, accel_grade, tau_s, offset_mps2))


def logger_offset(m) -> dict:
    """The logger's accelerometer offset from a Measured's inputs (never its power): the
    median over its trips of the offsets their elevation changes imply
    (data.corrections.logger_offset_mps2), with the per-trip spread it replaces."""
    from sumo_drvpw.data.corrections import accelerometer_column, logger_offset_mps2

    if "elevation_m" not in m.log.df or accelerometer_column(m.log.df.columns) is None:
        return {"offset_mps2": math.nan, "trips": 0, "iqr_mps2": [math.nan, math.nan]}
    per = _offsets(m)
    offs = [d["offset_elevation"] for d in per.values()]
    est = logger_offset_mps2(offs, [d["distance_m"] for d in per.values()])
    q = np.nanpercentile(offs, [25, 75]) if len(offs) else [math.nan, math.nan]
    return {"offset_mps2": est, "trips": len(offs), "iqr_mps2": [float(q[0]), float(q[1])]}


def evaluate(m, equations) -> dict:
    """Held-out metrics and per-trip energy of each equation on a Measured."""
    from sumo_drvpw.fit.compare import compare

    u = m.usable
    comp = compare(m.power_w[u], m.inputs.take(u), equations, dt_s=m.log.df["dt_s"].to_numpy()[u],
                   trip=m.log.df["trip_id"].to_numpy()[u])
    return comp.to_json()["equations"]


def calibrate_physical(m, name: str):
    from sumo_drvpw.fit.calibrate import CANDIDATES
    from sumo_drvpw.fit.physical import physical_calibration

    eq, rep = physical_calibration(m.inputs, m.power_w, CANDIDATES["indt-var-1"], mask=m.usable,
                                   reference_mass_kg=float(np.mean(m.inputs.mass[m.usable])))
    eq.name = name
    return eq, rep


def fit_terms(m, terms, name: str, fixed: dict | None = None):
    """Least squares of ``terms`` on a Measured's usable samples; physical constraints
    (fit.physical.DEFAULT_CONSTRAINTS) when the free fit is implausible; ``fixed``: term →
    value kept as given. Returns (Equation, {"used", "reading", "free", "why", "active"})."""
    from sumo_drvpw.fit.ols import gram
    from sumo_drvpw.fit.physical import (DEFAULT_CONSTRAINTS, constrained_fit, implausible,
                                         physical_reading)
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.terms import term_matrix

    terms = tuple(dict.fromkeys(terms))
    use = m.usable & np.all(np.isfinite(term_matrix(terms, m.inputs)), axis=1)
    g = gram(m.inputs, np.where(use, m.power_w, 0.0), terms, use)
    rho = float(np.mean(m.inputs.rho[use]))
    fixed_c = {t: {"fixed": float(v)} for t, v in (fixed or {}).items() if t in terms}
    free = constrained_fit(g, fixed_c)
    bad = [t for t in implausible(physical_reading(free.params, rho)) if t not in fixed_c]
    info = {"free": free.params, "used": "unconstrained", "why": ""}
    fit = free
    if bad:
        cons = dict({t: c for t, c in DEFAULT_CONSTRAINTS.items() if t not in fixed_c}, **fixed_c)
        fit = constrained_fit(g, cons)
        info.update(used="constrained", why="free fit implausible: " + ", ".join(bad))
    info["reading"], info["active"] = physical_reading(fit.params, rho), list(fit.active)
    return Equation(name=name, terms=dict(fit.params)), info


def _cv_args(m):
    u = np.asarray(m.usable, bool) & np.isfinite(m.power_w)
    return (m.inputs, np.asarray(m.power_w, float), u, m.log.df["dt_s"].to_numpy(float),
            m.log.df["trip_id"].to_numpy().astype(str))


def _cv_summary(cv: dict) -> dict:
    """What a grade-source choice keeps of a fit.physical.trip_cv result."""
    return {k: cv[k] for k in ("mean_abs_error", "max_abs_error", "rmse_w")}


def each_grade_source(path, vehicle, lag, off):
    """(grade source, the log ``path`` read with it) for each entry of TAU_GRID_S, one at a
    time; the logger offset ``off`` (:func:`logger_offset`) left out when it could not be
    estimated."""
    for tau in TAU_GRID_S:
        if tau == LOGGER_OFFSET and not math.isfinite(off["offset_mps2"]):
            continue
        yield tau, corrected_measured(path, vehicle, lag, True, tau, off["offset_mps2"])


def choose_tau(train, vehicle, lag, terms, m_train) -> dict:
    """The grade source from TAU_GRID_S (fusion crossovers, the accelerometer with per-trip
    offsets, the accelerometer with the logger's offset estimated on ``m_train``'s inputs)
    with the lowest trip-grouped cross-validated mean absolute trip traction-energy error of
    ``terms`` on the training log ``train``."""
    from sumo_drvpw.fit.physical import trip_cv

    off = logger_offset(m_train)
    cv = {}
    for tau, m in each_grade_source(train, vehicle, lag, off):
        cv[tau] = _cv_summary(trip_cv(*_cv_args(m), list(terms), energy=SELECTION_ENERGY))
    best = min(cv, key=lambda t: cv[t]["mean_abs_error"])
    return {"tau_s": best, "cv": cv, "logger_offset": off, "energy": SELECTION_ENERGY}


def grade_and_physics(path, vehicle, lag, base_terms, m_train, name):
    """The grade source and the physical candidates, chosen by trip-grouped CV on the
    training log ``path`` as GRADE_CHOICE says: jointly (:func:`joint_grade_and_physics`), or
    the grade source with the calibrated terms (:func:`choose_tau`) and then the physical
    candidates on data read that way (:func:`physical_stage`) — with "recheck", the grade
    source once more with the closed-loop terms and, if that choice differs, the physical
    candidates again on data read the new way. Returns (tau, m_corr, equation, selection,
    regime r); ``tau["first"]`` is the first choice when the second replaced it."""
    if GRADE_CHOICE == "joint":
        return joint_grade_and_physics(path, vehicle, lag, base_terms, m_train, name)
    tau = choose_tau(path, vehicle, lag, base_terms, m_train)
    off = tau["logger_offset"]["offset_mps2"]
    m_corr = corrected_measured(path, vehicle, lag, True, tau["tau_s"], off)
    eq, sel, r = physical_stage(m_corr, list(base_terms), name)
    if GRADE_CHOICE != "recheck":
        return tau, m_corr, eq, sel, r
    again = choose_tau(path, vehicle, lag, eq.terms, m_train)
    again["terms"] = list(eq.terms)
    if again["tau_s"] == tau["tau_s"]:
        tau["recheck"] = again
        return tau, m_corr, eq, sel, r
    again["first"] = tau
    m_corr = corrected_measured(path, vehicle, lag, True, again["tau_s"], off)
    eq, sel, r = physical_stage(m_corr, list(base_terms), name)
    return again, m_corr, eq, sel, r


def joint_grade_and_physics(path, vehicle, lag, base_terms, m_train, name):
    """The grade source and the physical candidates chosen together on the training log
    ``path``: for every grade source of TAU_GRID_S, the data read that way and the physical
    candidates chosen on it (:func:`physical_stage`, trip-grouped 5-fold CV); the grade source
    whose closed-loop structure has the lowest cross-validated mean absolute trip
    traction-energy error. Each grade source is judged with the terms it would be used with,
    so a missing temperature term cannot decide it. Returns what :func:`grade_and_physics`
    does; ``tau["cv"][source]`` carries the candidates chosen with that source."""
    off = logger_offset(m_train)
    cv, best = {}, None
    for tau, m in each_grade_source(path, vehicle, lag, off):
        eq, sel, r = physical_stage(m, list(base_terms), name)
        cv[tau] = dict(_cv_summary(sel["cv"]), chosen=list(sel["chosen"]))
        if best is None or cv[tau]["mean_abs_error"] < cv[best[0]]["mean_abs_error"]:
            best = (tau, m, eq, sel, r)  # one Measured kept at a time: each is the whole log
    tau, m, eq, sel, r = best
    return {"tau_s": tau, "cv": cv, "logger_offset": off, "joint": True, "energy": SELECTION_ENERGY}, m, eq, sel, r


def physical_stage(m, base_terms, name):
    """Physical candidates chosen on whole training trips (fit.physical.select_physical),
    then the closed-loop equation fitted on all training trips (traction coefficients; with
    the regime, recuperation on its own scale 1 + r kept in the provenance)."""
    from sumo_drvpw.fit.physical import regime_fit, select_physical
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.terms import term_matrix

    args = _cv_args(m)
    sel = select_physical(*args, list(base_terms), energy=SELECTION_ENERGY)
    X = term_matrix(sel["terms"], m.inputs)
    ok = args[2] & np.all(np.isfinite(X), axis=1)
    b, r = regime_fit(X[ok], args[1][ok], sel["regime"])
    eq = Equation(name=name, terms=dict(zip(sel["terms"], map(float, b))))
    eq.provenance["physical_candidates"] = sel["chosen"]
    if sel["regime"]:
        eq.provenance["recuperation_scale"] = 1.0 + r
    return eq, sel, r


def regime_eval(m, eq, scale):
    """Held-out R² and trip energies of ``eq`` with its predicted recuperation × ``scale``."""
    from sumo_drvpw.fit.compare import metrics, trip_energy, trip_net_energy

    u = np.asarray(m.usable, bool)
    p = eq.power(m.inputs.take(u))
    p = np.where(p < 0, scale * p, p)
    y, dt, tr = m.power_w[u], m.log.df["dt_s"].to_numpy()[u], m.log.df["trip_id"].to_numpy()[u]
    return {"r2": metrics(p, y)["r2"], "trip_energy": trip_energy(p, y, dt, tr),
            "trip_net_energy": trip_net_energy(p, y, dt, tr)}


def close_loop(name, df, vehicle, out_dir, declared=None, note="", roles=None):
    """One car: per held-out group, calibrate + diagnose on the rest, evaluate held out."""
    from sumo_drvpw.report.diagnose import write_outputs
    from sumo_drvpw.fit.diagnose import DiagnoseOptions, diagnose
    from sumo_drvpw.model.equations import load_equation

    groups = split_trips(df["trip_id"].unique(), second=declared is None)
    runs = []
    two_splits = len(groups) == 2 and len(groups[0]) > 1
    for gi, held in enumerate(groups):
        tag = (name if gi == 0 else f"{name}_split2") if two_splits or len(groups) == 1 else f"{name}_fold{gi + 1}"
        with tempfile.TemporaryDirectory() as tmp:
            train = write_subset(df, held, Path(tmp) / "train.parquet", keep=False, roles=roles)
            test = write_subset(df, held, Path(tmp) / "test.parquet", keep=True, roles=roles)
            t0 = time.perf_counter()
            m_train = load_checked(train, vehicle) if CHECK_DROPOUTS else _load(train, vehicle, None)
            base_eq, base_phys = calibrate_physical(m_train, f"{name}_calibrated")
            checks = input_checks(m_train, base_eq, held)
            decl = declared if declared is not None else base_eq
            res = diagnose(m_train, decl, DiagnoseOptions(), progress=lambda s: _log(f"[{tag}] {s}"))
            write_outputs(res, out_dir / tag, figures=True)
            lag = float(res.equation.provenance.get("power_lag_s", 0.0))
            acc_grade = any(f["term"] == "[grade_accelerometer]" for f in res.report["findings"])
            n_train = int(df["trip_id"].nunique() - len(held))
            physical = declared is None and n_train >= MIN_CV_TRIPS
            staged = None
            if acc_grade and physical:
                staged = grade_and_physics(train, vehicle, lag, base_eq.terms, m_train, f"{name}_closed")
                tau, m_corr = staged[0], staged[1]
            else:
                tau = (choose_tau(train, vehicle, lag, base_eq.terms, m_train)
                       if acc_grade and n_train >= MIN_CV_TRIPS else None)
                m_corr = None
            tau_s = None if tau is None else tau["tau_s"]
            off = None if tau is None else tau["logger_offset"]["offset_mps2"]
            if m_corr is None:
                m_corr = corrected_measured(train, vehicle, lag, acc_grade, tau_s, off)
            corr_eq, corr_phys = calibrate_physical(m_corr, f"{name}_corrected")
            # the equation for SUMO: declared physics (+ the conditions and loads the tracer
            # found) on the corrected data; a dynamometer equation keeps its road load
            extra = [f["term"] for f in res.report["findings"] if f.get("role") in ("condition", "load")]
            m_fit = m_corr
            sel, rscale = None, 0.0
            if declared is not None:
                base_terms = list(declared.terms) + ["grade", "v^0", "moving"]
                keep = {t: c for t, c in declared.terms.items() if t in ("aero", "roll")}
                final_eq, final_info = fit_terms(m_fit, base_terms + extra, f"{name}_closed", keep)
            elif physical:
                # a form SUMO can evaluate: physical candidates, not the log-only columns the
                # tracer named (those are reported above)
                final_eq, sel, rscale = (staged[2:] if staged is not None else
                                         physical_stage(m_fit, list(base_eq.terms), f"{name}_closed"))
                rho = float(np.mean(m_fit.inputs.rho[m_fit.usable]))
                from sumo_drvpw.fit.physical import physical_reading
                final_info = {"free": final_eq.terms, "used": "unconstrained", "why": "",
                              "reading": physical_reading(final_eq.terms, rho)}
            else:
                final_eq, final_info = fit_terms(m_fit, list(base_eq.terms) + extra, f"{name}_closed")
            m_test = load_checked(test, vehicle) if CHECK_DROPOUTS else _load(test, vehicle, None)
            eqs = [base_eq, load_equation("vsp_ldv1999")]
            if declared is not None:
                eqs.insert(0, declared)
            held_raw = evaluate(m_test, eqs)
            # the closed-loop equations declare the corrections their logs need: compare
            # (and anyone's later run of it) reads new logs the same way
            corr_eq.measurement = final_eq.measurement = m_corr.measurement
            from sumo_drvpw.model.equations import save_equation

            final_eq.description = (f"{name}: the loop closed on {n_train} training trips "
                                    f"(scripts/closing_the_loop.py); held out: {', '.join(held)}")
            final_eq.provenance.update({"method": "scripts/closing_the_loop.py", "held_out": list(held),
                                        "vehicle": vehicle})
            save_equation(final_eq, out_dir / tag / "closed_equation.toml")
            # the held-out trips read with the training trips' choices (the logger offset too)
            m_test_corr = corrected_measured(test, vehicle, lag, acc_grade, tau_s, off)
            held_corr = evaluate(m_test_corr, [e for e in (corr_eq, final_eq) if e is not None])
            # the corrected grade against each held-out trip's logged elevation change (inputs only)
            checks["grade_gaps_held"] = {
                "trips": int(m_test_corr.log.counts.get("grade_elevation_gap_trips", 0) or 0),
                "gaps": dict(m_test_corr.log.counts.get("grade_elevation_gap_m") or {}),
                "checked": m_test_corr.measurement is not None and m_test_corr.measurement.grade != "logged"}
            held_regime = (regime_eval(m_test_corr, final_eq, 1.0 + rscale)
                           if sel is not None and sel["regime"] else None)
            runs.append({"rho_alt": "elevation_m" in df and "pressure_kpa" not in df and "ambient_c" in df,
                         "tag": tag, "held": list(held), "train_trips": n_train,
                         "res": res, "base_eq": base_eq, "base_phys": base_phys, "corr_eq": corr_eq,
                         "corr_phys": corr_phys, "lag": lag, "acc_grade": acc_grade,
                         "held_raw": held_raw, "held_corr": held_corr,
                         "took_s": time.perf_counter() - t0, "declared": declared,
                         "final_eq": final_eq, "final_info": final_info, "extra": extra,
                         "tau": tau, "tau_s": tau_s, "sel": sel, "rscale": rscale,
                         "held_regime": held_regime, "checks": checks, "vehicle": vehicle})
            checks["dropouts_held"] = getattr(m_test, "dropouts", None)
            checks["held_inputs"] = _trip_inputs(m_test)
            if "imu_accel_mps2" in m_test.log.df:
                checks["offsets"].update(_offsets(m_test))
    return {"name": name, "vehicle": vehicle, "note": note, "runs": runs}


def wind_check(name, df, vehicle, car, roles=None) -> dict | None:
    """A steady wind over trips of one day driven in different directions (fit.wind): the
    wind the car's trips imply together with the road load of its closed-loop equation
    (coefficients held as the first fold's constrained fit held them), the drag with and
    without it, each trip's traction-energy error with and without it (both trips in the
    fit: a diagnosis, not a held-out result), and each fold again on logs that carry that
    wind (``import --wind``; the wind came from both trips, so this shows what a weather
    record of the day would do, not a held-out result). None without a heading or runs."""
    from sumo_drvpw.data.wind import HEADING_COLUMNS, add_wind, heading_of, tailwind_mps
    from sumo_drvpw.fit.compare import trip_energy
    from sumo_drvpw.fit.physical import physical_reading
    from sumo_drvpw.fit.wind import estimate_wind
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.vehicles import load_vehicle

    runs = car.get("runs") or []
    if not runs or not (set(HEADING_COLUMNS) & set(df.columns)):
        return None
    lag = float(np.mean([r["lag"] for r in runs]))
    eq0 = runs[0]["final_eq"]
    terms = list(eq0.terms)
    fixed = {t: 1.0 for t in ("acc", "grade") if eq0.terms.get(t) == 1.0}
    with tempfile.TemporaryDirectory() as tmp:
        path = write_subset(df, [], Path(tmp) / "all.parquet", keep=False, roles=roles)
        m = corrected_measured(path, vehicle, lag, False)
        heading, source = heading_of(m.log.df)
        x, y, use, dt, trip = _cv_args(m)
        w = estimate_wind(x, y, use, heading, terms, fixed)
        rho = float(np.mean(x.rho[use]))
        still = Equation("still", w["terms_still_air"]).power(x)
        calm = Equation("calm", w["terms"]).power(x)
        x_wind = x.take(np.arange(len(y)))
        x_wind.wind = tailwind_mps(heading, w["speed_mps"], w["from_deg"])
        windy = Equation("windy", w["terms"]).power(x_wind)
        per = {}
        for label, p in (("still air", still), ("with the wind", windy), ("calm", calm)):
            te = trip_energy(p[use], y[use], dt[use], trip[use])["trips"]
            per[label] = {t: v["error"] for t, v in te.items()}
        # each fold again on logs that carry the wind (constrained as the fold's fit was)
        windy_df, _ = add_wind(df, w["speed_mps"], w["from_deg"])
        folds = {}
        for r in runs:
            held = r["held"]
            train = write_subset(windy_df, held, Path(tmp) / "wtrain.parquet", keep=False, roles=roles)
            test = write_subset(windy_df, held, Path(tmp) / "wtest.parquet", keep=True, roles=roles)
            keep = {t: v for t, v in r["final_eq"].terms.items() if t in fixed}
            eq, info = fit_terms(corrected_measured(train, vehicle, r["lag"], False), terms,
                                 f"{name}_wind", keep)
            got = evaluate(corrected_measured(test, vehicle, r["lag"], False), [eq])[eq.name]
            folds[r["tag"]] = {"errors": {t: v["error"] for t, v in got["trip_energy"]["trips"].items()},
                               "terms": eq.terms,
                               "reading": physical_reading(eq.terms, rho)}
    read = lambda t: physical_reading(t, rho).get("aero", {}).get("value", math.nan)  # noqa: E731
    body = load_vehicle(vehicle).body or {}
    published = (body["drag_coefficient"] * body["frontal_area_m2"]
                 if {"drag_coefficient", "frontal_area_m2"} <= set(body) else None)
    times = ({t: [str(g.iloc[0]), str(g.iloc[-1])] for t, g in df.groupby("trip_id")["gps_time"]}
             if "gps_time" in df else {})
    return {"wind": w, "heading_source": source, "lag_s": lag, "fixed": fixed, "rho": rho,
            "cda_published": published, "times": times,
            "cda_still": read(w["terms_still_air"]), "cda_wind": read(w["terms"]),
            "trips": per, "folds": folds}


#: fewest trips for a deliverable fitted on all of them (beside the held-out splits)
MIN_ALL_TRIPS = 10


def final_fit(name, df, vehicle, out_dir, roles=None) -> dict | None:
    """The deliverable: the same pipeline on all trips of a car (calibration, tracer,
    corrections, physical candidates by trip-grouped CV), written as
    ``<out_dir>/<name>_all_trips/closed_equation.toml`` with its ``[measurement]``. Nothing
    is held out here: its held-out quality is that of the splits. None below
    MIN_ALL_TRIPS trips."""
    from sumo_drvpw.fit.diagnose import DiagnoseOptions, diagnose
    from sumo_drvpw.fileio import write_json
    from sumo_drvpw.model.equations import save_equation
    from sumo_drvpw.report.diagnose import write_outputs

    trips = sorted(df["trip_id"].unique())
    if len(trips) < MIN_ALL_TRIPS:
        return None
    tag = f"{name}_all_trips"
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        path = write_subset(df, trips, Path(tmp) / "all.parquet", keep=True, roles=roles)
        m = load_checked(path, vehicle) if CHECK_DROPOUTS else _load(path, vehicle, None)
        base_eq, _ = calibrate_physical(m, f"{name}_calibrated")
        res = diagnose(m, base_eq, DiagnoseOptions(), progress=lambda s: _log(f"[{tag}] {s}"))
        write_outputs(res, out_dir / tag, figures=False)
        lag = float(res.equation.provenance.get("power_lag_s", 0.0))
        acc_grade = any(f["term"] == "[grade_accelerometer]" for f in res.report["findings"])
        if acc_grade:
            tau, m_corr, eq, sel, rscale = grade_and_physics(path, vehicle, lag, base_eq.terms, m,
                                                             f"{name}_closed")
        else:
            tau = None
            m_corr = corrected_measured(path, vehicle, lag, False)
            eq, sel, rscale = physical_stage(m_corr, list(base_eq.terms), f"{name}_closed")
        tau_s = None if tau is None else tau["tau_s"]
        floor = repeat_floor(m_corr, eq, sel, df)
    eq.measurement = m_corr.measurement
    eq.description = (f"{name}: the loop closed on all {len(trips)} trips (scripts/closing_the_loop.py); "
                      "its held-out quality is that of the splits in docs/closing-the-loop.md")
    eq.provenance.update({"method": "scripts/closing_the_loop.py", "trips": trips, "vehicle": vehicle})
    save_equation(eq, out_dir / tag / "closed_equation.toml")
    out = {"tag": tag, "trips": len(trips), "equation": eq, "lag": lag, "tau": tau, "sel": sel,
           "rscale": rscale, "findings": [f["term"] for f in res.report["findings"]],
           "took_s": time.perf_counter() - t0, "floor": floor}
    write_json(out_dir / tag / "summary.json", {
        "trips": trips, "lag_s": lag, "grade_source": tau_s, "tracer_findings": out["findings"],
        "physical_candidates": list(sel["chosen"]), "terms": eq.terms,
        "measurement": eq.measurement.to_dict() if eq.measurement else None,
        "repeat_trips": floor})
    return out


def repeat_floor(m, eq, sel, df) -> dict | None:
    """How low the per-trip error can go on these logs (:mod:`sumo_drvpw.fit.repeats`): the
    closed-loop structure in trip-grouped 5-fold cross-validation over all trips (each trip
    predicted by coefficients fitted without it; the structure itself was chosen on all
    trips), and the scatter between repeat trips (same route, started within the hour) that
    no logged input explains. None without route and start columns."""
    from sumo_drvpw.fit.physical import trip_cv
    from sumo_drvpw.fit.repeats import repeat_pairs, repeat_scatter

    if not {"route", "trip_start"} <= set(df.columns):
        return None
    first = df.groupby("trip_id", sort=True)[["route", "trip_start"]].first()
    pairs = repeat_pairs(first["trip_start"].to_dict(), first["route"].to_dict())
    cv = trip_cv(*_cv_args(m), list(eq.terms), regime=bool(sel["regime"]))
    fit_all = trip_cv(*_cv_args(m), list(eq.terms), regime=bool(sel["regime"]), k=1)
    k = max(1, len(first) // HOLD_EVERY)
    out = repeat_scatter(cv["errors"], pairs, k=k)
    out.update(cv_mean_abs_error=cv["mean_abs_error"], cv_max_abs_error=cv["max_abs_error"],
               cv_folds=cv["folds"], cv_errors=cv["errors"],
               in_sample_mean_abs_error=fit_all["mean_abs_error"],
               in_sample_max_abs_error=fit_all["max_abs_error"], in_sample_errors=fit_all["errors"],
               starts={t: str(v) for t, v in first["trip_start"].items()})
    return out


def jlu(data: Path, out_dir: Path):
    """Dyno-calibrated equation taken onto the road, then the loop closed on road trips."""
    from sumo_drvpw.data.adapters import read
    from sumo_drvpw.data.measured import load_measured

    dyno, _ = read("jlu-dyno", data / "jlu_bev_dyno")
    road, road_rep = read("jlu-road", data / "jlu_bev_road")
    with tempfile.TemporaryDirectory() as tmp:
        p = Path(tmp) / "dyno.parquet"
        dyno.to_parquet(p)
        m = load_measured([p], "jlu_bev")
        dyno_eq, dyno_phys = calibrate_physical(m, "jlu_dyno_calibrated")
    _log(f"[jlu] dyno equation: {dyno_eq.terms}")
    out = close_loop("jlu_road", road, "jlu_bev", out_dir, declared=dyno_eq,
                     note="declared: the equation calibrated on the 46 dynamometer tests",
                     roles=road_rep.get("roles"))
    out["dyno_phys"] = dyno_phys
    with tempfile.TemporaryDirectory() as tmp:
        path = write_subset(road, sorted(road["trip_id"].unique()), Path(tmp) / "road.parquet", keep=True,
                            roles=road_rep.get("roles"))
        m = corrected_measured(path, "jlu_bev", out["runs"][0]["lag"], False)
        out["moving_check"] = moving_check(m, dyno_eq)
    return out


def moving_check(m, dyno_eq) -> dict:
    """Leave-one-trip-out over every road trip: the dyno's road load (aero, roll) and grade 1
    kept, acc and the constant power fitted, the constant drawn all the time (``v^0``) or split
    into a standing part (``v^0``) and a part drawn only while moving (``moving``). Per held-out
    trip the traction-energy error (as everywhere in this report)."""
    from sumo_drvpw.fit.compare import trip_energy
    from sumo_drvpw.model.constants import STANDSTILL_MPS
    from sumo_drvpw.model.terms import term_matrix

    keep = {t: c for t, c in dyno_eq.terms.items() if t in ("aero", "roll")}
    keep["grade"] = 1.0
    fixed_w = term_matrix(list(keep), m.inputs) @ np.array(list(keep.values()))
    trip = m.log.df["trip_id"].to_numpy().astype(str)
    dt = m.log.df["dt_s"].to_numpy(float)
    out = {}
    for name, terms in (("constant", ["acc", "v^0"]), ("split", ["acc", "v^0", "moving"])):
        X = term_matrix(terms, m.inputs)
        ok = m.usable & np.all(np.isfinite(X), axis=1) & np.isfinite(fixed_w) & np.isfinite(m.power_w)
        errs = {}
        for t in sorted(set(trip[ok])):
            tr, te = ok & (trip != t), ok & (trip == t)
            b = np.linalg.lstsq(X[tr], (m.power_w - fixed_w)[tr], rcond=None)[0]
            e = trip_energy(X[te] @ b + fixed_w[te], m.power_w[te], dt[te], trip[te])
            errs[t] = e["trips"][t]["error"]
        b = np.linalg.lstsq(X[ok], (m.power_w - fixed_w)[ok], rcond=None)[0]
        out[name] = {"errors": errs, "mean_abs_error": float(np.mean(np.abs(list(errs.values())))),
                     "coefficients": dict(zip(terms, map(float, b)))}
    a, b = out["constant"]["errors"], out["split"]["errors"]
    out["helped"] = sum(abs(b[t]) < abs(a[t]) for t in a)
    out["standing_share"] = {t: float(np.mean(m.inputs.v[trip == t] < STANDSTILL_MPS)) for t in sorted(set(trip))}
    # the power measured while standing: no road load acts there, so it is the standing
    # constant itself, measured rather than fitted
    st = (m.inputs.v < STANDSTILL_MPS) & np.isfinite(m.power_w)
    out["standing_measured_w"] = float(np.mean(m.power_w[st])) if st.any() else math.nan
    per = [float(np.mean(m.power_w[st & (trip == t)])) for t in sorted(set(trip)) if (st & (trip == t)).any()]
    out["standing_measured_range_w"] = [min(per), max(per)] if per else [math.nan, math.nan]
    return out


def command_line(argv) -> str:
    """The command this run was started with, as the report's header shows it (the
    documented regeneration, CMD, when it was that one)."""
    import shlex

    return ".venv/bin/python scripts/closing_the_loop.py" + ("".join(" " + shlex.quote(a) for a in argv))


def main(argv=None) -> int:
    """Run the loop and write the report; bad input (a data folder an adapter refuses) is one
    line on stderr, exit 2, nothing written."""
    from sumo_drvpw.errors import UserError

    try:
        return _main(sys.argv[1:] if argv is None else list(argv))
    except UserError as e:
        print(f"closing_the_loop.py: error: {e}", file=sys.stderr)
        return 2


def _main(argv) -> int:
    global GRADE_CHOICE, SELECTION_ENERGY
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get(
        "SUMO_DRVPW_DATA", str(Path(__file__).resolve().parents[2] / "shared" / "data")))
    ap.add_argument("--out", default="docs")
    ap.add_argument("--only", default="", help="comma list of i3, prius2, jlu (default: all)")
    ap.add_argument("--grade-choice", choices=GRADE_CHOICES, default=GRADE_CHOICE,
                    help="how the grade source and the physical candidates are chosen (see GRADE_CHOICE)")
    ap.add_argument("--selection-energy", choices=SELECTION_ENERGIES, default=SELECTION_ENERGY,
                    help="the per-trip energy whose error chooses the structure (see SELECTION_ENERGY)")
    a = ap.parse_args(argv)
    GRADE_CHOICE, SELECTION_ENERGY = a.grade_choice, a.selection_energy
    from sumo_drvpw.data.adapters import read
    from sumo_drvpw.fileio import write_text

    data, out = Path(a.data), Path(a.out)
    only = {s.strip() for s in a.only.split(",") if s.strip()}
    t0 = time.perf_counter()
    cars = []
    specs = [("i3", "bmw_i3", "bmw-i3-tum", "bmw_i3_tum", "target: mechanical motor power"),
             ("prius2", "prius2", "torquepro-prius2", "prius_gen2_torquepro",
              "target: power-split driving power from MG1, MG2 and engine")]
    for key, vehicle, fmt, folder, note in specs:
        if only and key not in only:
            continue
        if not (data / folder).exists():
            cars.append({"name": key, "error": f"not run: {data / folder} not found"})
            continue
        df, rep = read(fmt, data / folder)
        car = close_loop(key, df, vehicle, out / "closing-the-loop", note=note, roles=rep.get("roles"))
        car["wind"] = wind_check(key, df, vehicle, car, roles=rep.get("roles")) if key in WIND_CHECK else None
        car["all_trips"] = final_fit(key, df, vehicle, out / "closing-the-loop", roles=rep.get("roles"))
        cars.append(car)
    if not only or "jlu" in only:
        if (data / "jlu_bev_road").exists() and (data / "jlu_bev_dyno").exists():
            cars.append(jlu(data, out / "closing-the-loop"))
        else:
            cars.append({"name": "jlu_road", "error": "not run: jlu_bev_road/ or jlu_bev_dyno/ not found"})
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from closing_the_loop_report import render

    shared = Path(__file__).resolve().parents[2] / "shared" / "data"
    other = None if data.resolve() == shared.resolve() else str(data)
    write_text(out / "closing-the-loop.md", render(cars, time.perf_counter() - t0, command_line(argv),
                                                   other_data=other))
    print(f"wrote {out / 'closing-the-loop.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
