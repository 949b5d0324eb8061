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
   crossover is chosen from TAU_GRID_S by trip-grouped 5-fold cross-validation on the
   training trips (mean absolute trip traction-energy error);
4. with at least 5 training trips, physical candidates in forms SUMO can evaluate
   (``fit.physical.PHYSICAL_CANDIDATES``: ρ(T, altitude) in the aero term, c_r(T),
   cold drivetrain drag, recuperation on its own coefficient) are chosen forward by the
   same trip-grouped cross-validation (``fit.physical.select_physical``), each kept only
   with a plausible coefficient; the closed-loop equation is fitted with them. The
   tracer's log-only findings (``[ambient_c]*…``) are reported, not carried: SUMO cannot
   evaluate a log column.

Before any of this, every log (training and held out) passes the input checks of
:mod:`sumo_drvpw.fit.input_checks` (inputs only): logger dropouts leave the usable samples;
declared mass, accelerometer offset and elevation are checked and reported per trip.

The held-out trips then give R² and per-trip traction energy errors (Σ max(P, 0)·Δt,
predicted/measured − 1) before and after, against VSP LDV 1999 as a reference. The JLU
car: an equation calibrated on the dynamometer is taken onto the road, and the loop is
closed on road trips (grade, auxiliaries and temperature the dyno could not see).
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
TAU_GRID_S = (30.0, 60.0, 120.0, 300.0, 600.0, math.inf)
#: fewest training trips for trip-grouped cross-validation of choices (tau, physical terms)
MIN_CV_TRIPS = 5
#: take logger dropouts (held or linearly filled inputs) out of the usable samples of every
#: log, training and held out alike, for every equation (fit.input_checks.dropout_mask)
CHECK_DROPOUTS = True
#: largest gap between logged and accelerometer elevation along a trip reported as a finding [m]
ELEVATION_GAP_M = 40.0


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


def load_checked(path, vehicle):
    """load_measured with the logger-dropout check (fit.input_checks.dropout_mask, inputs
    only: speed and a longitudinal accelerometer exactly linear in time for ≥ 5 s, and the
    grade-smoothing distance around it) taken out of the usable samples. Returns the
    Measured; ``m.dropouts`` = trip → seconds taken out."""
    from sumo_drvpw.data.measured import load_measured
    from sumo_drvpw.fit.diagnose.structural import ACCELEROMETER_COLUMNS
    from sumo_drvpw.fit.input_checks import dropout_mask, dropout_report

    m = load_measured([path], vehicle)
    df = m.log.df
    acc = [c for c in ACCELEROMETER_COLUMNS if c in df]
    m.dropouts = None
    if acc:
        codes = np.unique(df["trip_id"].to_numpy(), return_inverse=True)[1]
        drop = dropout_mask(df["time_s"].to_numpy(float), [df["speed_mps"].to_numpy(float),
                                                           df[acc[0]].to_numpy(float)],
                            codes, df["speed_mps"].to_numpy(float), margin_m=m.log.options.grade_window_m)
        m.dropouts = dropout_report(drop & m.usable, df["trip_id"].to_numpy(), df["dt_s"].to_numpy(float))
        m.usable = m.usable & ~drop
    return m


def _offsets(m):
    from sumo_drvpw.fit.input_checks import accelerometer_offsets

    df = m.log.df
    return accelerometer_offsets(df["imu_accel_mps2"], m.inputs.a, df["speed_mps"], df["elevation_m"],
                                 df["dt_s"], df["trip_id"], m.usable)


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


def corrected_measured(path, vehicle, lag_s: float, accel_grade: bool, tau_s: float | None = None):
    """Measured power and inputs of a log with the measurement-side corrections applied:
    the power read ``lag_s`` later within trips; the grade fused from the accelerometer (fast
    part) and the logged grade (slow part, free of the accelerometer's mounting pitch); ρ at
    the logged altitude (standard atmosphere) when pressure is not logged."""
    from sumo_drvpw.data.measured import load_measured
    from sumo_drvpw.fit.diagnose.structural import (FUSION_TAU_S, P0_KPA, accelerometer_sin_grade, fused_sin_grade,
                                                    pressure_at_altitude_kpa, shift_within_trips)

    m = load_checked(path, vehicle) if CHECK_DROPOUTS else load_measured([path], vehicle)
    df = m.log.df
    if "elevation_m" in df and "pressure_kpa" not in df and "ambient_c" in df:
        # ρ from altitude and temperature: the reader assumed sea-level pressure
        h = df["elevation_m"].to_numpy(float)
        m.inputs.rho = np.where(np.isfinite(h), m.inputs.rho * pressure_at_altitude_kpa(h) / P0_KPA,
                                m.inputs.rho)
    trip = m.log.df["trip_id"].to_numpy()
    codes = np.unique(trip, return_inverse=True)[1]
    t = m.log.df["time_s"].to_numpy(float)
    dt = float(np.median(np.diff(t)[np.diff(codes) == 0]))
    if lag_s:
        m.power_w = shift_within_trips(np.asarray(m.power_w, float), codes, int(round(lag_s / dt)))
        m.usable = m.usable & np.isfinite(m.power_w)
    if accel_grade and "imu_accel_mps2" in m.inputs.signals:
        s_acc = accelerometer_sin_grade(m.inputs.signals["imu_accel_mps2"], m.inputs.a, codes, dt)
        if tau_s is not None and math.isinf(tau_s):
            from sumo_drvpw.fit.input_checks import offset_corrected_sin_grade

            # the accelerometer alone, its per-trip offset fixed by the elevation
            m.inputs.theta = np.arcsin(offset_corrected_sin_grade(
                s_acc, m.inputs.v, df["dt_s"].to_numpy(float), codes, df["elevation_m"].to_numpy(float),
                m.usable & np.isfinite(m.power_w)))
        else:
            m.inputs.theta = np.arcsin(fused_sin_grade(s_acc, np.sin(m.inputs.theta), codes, dt,
                                                       FUSION_TAU_S if tau_s is None else tau_s))
        m.usable = m.usable & np.isfinite(m.inputs.theta)
    return m


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
    value kept as given. Returns (Equation, {"used", "reading", "free", "why"})."""
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
    info["reading"] = physical_reading(fit.params, rho)
    return Equation(name=name, terms=dict(fit.params)), info


def _cv_args(m):
    u = np.asarray(m.usable, bool) & np.isfinite(m.power_w)
    return (m.inputs, np.asarray(m.power_w, float), u, m.log.df["dt_s"].to_numpy(float),
            m.log.df["trip_id"].to_numpy().astype(str))


def choose_tau(train, vehicle, lag, terms) -> dict:
    """The fusion crossover from TAU_GRID_S with the lowest trip-grouped cross-validated mean
    absolute trip traction-energy error of ``terms`` on the training log ``train``."""
    from sumo_drvpw.fit.physical import trip_cv

    cv = {}
    for tau in TAU_GRID_S:
        m = corrected_measured(train, vehicle, lag, True, tau)
        r = trip_cv(*_cv_args(m), list(terms))
        cv[tau] = {"mean_abs_error": r["mean_abs_error"], "max_abs_error": r["max_abs_error"],
                   "rmse_w": r["rmse_w"]}
    best = min(cv, key=lambda t: cv[t]["mean_abs_error"])
    return {"tau_s": best, "cv": cv}


def physical_stage(m, base_terms, name):
    """Physical candidates chosen on whole training trips (fit.physical.select_physical),
    then the closed-loop equation fitted on all training trips (traction coefficients; with
    the regime, recuperation on its own scale 1 + r kept in the provenance)."""
    from sumo_drvpw.fit.physical import regime_fit, select_physical
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.terms import term_matrix

    args = _cv_args(m)
    sel = select_physical(*args, list(base_terms))
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
    from sumo_drvpw.data.measured import load_measured
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
            m_train = load_checked(train, vehicle) if CHECK_DROPOUTS else load_measured([train], vehicle)
            base_eq, base_phys = calibrate_physical(m_train, f"{name}_calibrated")
            checks = input_checks(m_train, base_eq, held)
            decl = declared if declared is not None else base_eq
            res = diagnose(m_train, decl, DiagnoseOptions(), progress=lambda s: _log(f"[{tag}] {s}"))
            write_outputs(res, out_dir / tag, figures=True)
            lag = float(res.equation.provenance.get("power_lag_s", 0.0))
            acc_grade = any(f["term"] == "[grade_accelerometer]" for f in res.report["findings"])
            n_train = int(df["trip_id"].nunique() - len(held))
            tau = choose_tau(train, vehicle, lag, base_eq.terms) if acc_grade and n_train >= MIN_CV_TRIPS else None
            tau_s = None if tau is None else tau["tau_s"]
            m_corr = corrected_measured(train, vehicle, lag, acc_grade, tau_s)
            corr_eq, corr_phys = calibrate_physical(m_corr, f"{name}_corrected")
            # the equation for SUMO: declared physics (+ the conditions and loads the tracer
            # found) on the corrected data; a dynamometer equation keeps its road load
            extra = [f["term"] for f in res.report["findings"] if f.get("role") in ("condition", "load")]
            m_fit = m_corr
            sel, rscale = None, 0.0
            if declared is not None:
                base_terms = list(declared.terms) + ["grade", "v^0"]
                keep = {t: c for t, c in declared.terms.items() if t in ("aero", "roll")}
                final_eq, final_info = fit_terms(m_fit, base_terms + extra, f"{name}_closed", keep)
            elif n_train >= MIN_CV_TRIPS:
                # a form SUMO can evaluate: physical candidates, not the log-only columns the
                # tracer named (those are reported above)
                final_eq, sel, rscale = physical_stage(m_fit, list(base_eq.terms), f"{name}_closed")
                rho = float(np.mean(m_fit.inputs.rho[m_fit.usable]))
                from sumo_drvpw.fit.physical import physical_reading
                final_info = {"free": final_eq.terms, "used": "unconstrained", "why": "",
                              "reading": physical_reading(final_eq.terms, rho)}
            else:
                final_eq, final_info = fit_terms(m_fit, list(base_eq.terms) + extra, f"{name}_closed")
            m_test = load_checked(test, vehicle) if CHECK_DROPOUTS else load_measured([test], vehicle)
            eqs = [base_eq, load_equation("vsp_ldv1999")]
            if declared is not None:
                eqs.insert(0, declared)
            held_raw = evaluate(m_test, eqs)
            m_test_corr = corrected_measured(test, vehicle, lag, acc_grade, tau_s)
            held_corr = evaluate(m_test_corr, [e for e in (corr_eq, final_eq) if e is not None])
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
                         "held_regime": held_regime, "checks": checks})
            checks["dropouts_held"] = getattr(m_test, "dropouts", None)
            checks["held_inputs"] = _trip_inputs(m_test)
            if "imu_accel_mps2" in m_test.log.df:
                checks["offsets"].update(_offsets(m_test))
    return {"name": name, "vehicle": vehicle, "note": note, "runs": runs}


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
    return out


# --------------------------------------------------------------------------- report

def _f(x, nd=3):
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.{nd}f}"


def _pct(x):
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{100 * x:+.1f} %"


def _abs_pct(x):
    return "–" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{100 * x:.1f} %"


def _tau(t):
    return "per-trip offset (∞)" if math.isinf(t) else f"{t:g} s"


def _terms(eq):
    return ", ".join(f"{t} {c:.4g}" for t, c in eq.terms.items())


def _reading(phys):
    r = phys["reading"] if phys["used"] == "unconstrained" else phys["constrained"]["reading"]
    parts = []
    for t, x in r.items():
        if x["value"] is None:
            continue
        parts.append(f"{t}: {x['reads_as']} = {x['value']:.4g}{' ' + x['unit'] if x['unit'] not in ('', '-') else ''}"
                     + ("" if x["plausible"] else " (implausible)"))
    return "; ".join(parts)


def _render_checks(run) -> list[str]:
    """The input checks of one run (fit.input_checks), as Markdown lines."""
    c = run.get("checks") or {}
    L = []
    dtr, dho = c.get("dropouts_train"), c.get("dropouts_held")
    if dtr is not None or dho is not None:
        both = dict(dtr or {}, **(dho or {}))
        L.append("- input check, logger dropouts (speed and accelerometer exactly linear in time for "
                 "≥ 5 s — held or linearly filled — plus the 100-m grade window around; taken out of the "
                 "usable samples of training and held-out trips for every equation): "
                 + (", ".join(f"{t} {s:.0f} s" + (" (held out)" if t in (dho or {}) else "")
                              for t, s in sorted(both.items())) or "none"))
    mass = c.get("mass") or {}
    if mass:
        far = {t: r for t, r in mass.items() if abs(r["vs_declared"]) > 0.10}
        vals = np.array([r["vs_declared"] for r in mass.values()])
        loaded = {t: r for t, r in mass.items() if r["declared_kg"] > min(x["declared_kg"] for x in mass.values())}
        L.append(f"- input check, declared mass (training trips; per-trip least squares of P on m·a·v, v, v³, "
                 f"m·g·sin θ·v for 2–20 m/s, relative to the declared mass × the calibrated acc {c['acc']:.3g}; "
                 f"reported, never substituted): median {100 * np.median(vals):+.1f} %, spread (IQR) "
                 f"{100 * (np.percentile(vals, 75) - np.percentile(vals, 25)):.1f} points; beyond ±10 %: "
                 + (", ".join(f"{t} {100 * r['vs_declared']:+.1f} % (declared {r['declared_kg']:.0f} kg)"
                              for t, r in sorted(far.items())) or "none")
                 + ("; trips with added load: " + ", ".join(
                     f"{t} {r['declared_kg']:.0f} kg → {100 * r['vs_declared']:+.1f} %" for t, r in sorted(loaded.items()))
                    if loaded else ""))
    off = c.get("offsets") or {}
    if off:
        held = set(run["held"])
        oe = np.array([r["offset_elevation"] for r in off.values()], float)
        ost = np.array([r["offset_standstill"] for r in off.values()], float)
        far = [t for t, r in off.items() if abs(r["offset_elevation"] - np.nanmedian(oe)) > 0.05]
        L.append(f"- input check, accelerometer offset per trip (inputs only, all trips of this split): from the "
                 f"elevation (Σ sin θ·ds = Δh) median {np.nanmedian(oe):+.3f} m/s² (IQR "
                 f"{np.nanpercentile(oe, 25):+.3f} … {np.nanpercentile(oe, 75):+.3f}); from standstill samples median "
                 f"{np.nanmedian(ost):+.3f} m/s² (IQR {np.nanpercentile(ost, 25):+.3f} … "
                 f"{np.nanpercentile(ost, 75):+.3f}: the car also stands on slopes); elevation-based offset more "
                 f"than 0.05 m/s² from the median: "
                 + (", ".join(f"{t}{' (held out)' if t in held else ''} {off[t]['offset_elevation']:+.3f} m/s² "
                              f"(Δh logged {off[t]['dh_m']:+.0f} m, accelerometer {off[t]['dh_accelerometer_m']:+.0f} m)"
                              for t in sorted(far)) or "none")
                 + ". The fused grade takes the slow part from the elevation, so such an offset does not "
                 "reach the equation.")
        gaps = {t: r["max_gap_m"] for t, r in off.items() if np.isfinite(r.get("max_gap_m", np.nan))}
        far = sorted((t for t, g in gaps.items() if g > ELEVATION_GAP_M), key=lambda t: -gaps[t])
        L.append(f"- input check, logged elevation against the accelerometer's integral (its per-trip offset fixed "
                 f"by Δh): median largest gap along a trip {np.median(list(gaps.values())):.0f} m; beyond "
                 f"{ELEVATION_GAP_M:g} m (elevation settling or drifting — the fused grade's slow part is then "
                 f"wrong there): " + (", ".join(f"{t}{' (held out)' if t in held else ''} {gaps[t]:.0f} m"
                                                for t in far) or "none"))
    return L


def render(cars, took) -> str:
    from sumo_drvpw.fit.diagnose.structural import FUSION_TAU_S
    from sumo_drvpw.fit.physical import PHYSICAL_CANDIDATES

    global FUSION_TAU, PHYS_DESC
    FUSION_TAU, PHYS_DESC = FUSION_TAU_S, {k: v[0] for k, v in PHYSICAL_CANDIDATES.items()}
    L = ["# Closing the loop on measured data", "",
         "Generated by (from the repository root; the shared data are read in place):", "",
         "```", CMD, "```", "", f"Run time {took:.0f} s. Method: `scripts/closing_the_loop.py` (docstring); "
         "tracer: `sumo_drvpw/fit/diagnose/`; physics: `sumo_drvpw/fit/physical.py`. Trips are split "
         "before any fit; every number under *held out* comes from trips the calibration and the tracer "
         "never saw. Per-run tracer reports (every round, every column left out and why) are linked.", ""]
    L += ["## Summary (held-out trips; the issue's targets in brackets)", "",
          "| car / fold | lag found [s] | grade coefficient, free fit after corrections | response findings | "
          "findings rejected | closed-loop R² | mean / worst trip traction-energy error |",
          "|---|---|---|---|---|---|---|"]
    for car in cars:
        for run in car.get("runs", []):
            d, r = run["res"].details, run["res"].report
            free = (run["corr_phys"] or run["base_phys"])["unconstrained"] if run["declared"] is None \
                else run["final_info"]["free"]
            doc = run.get("held_regime") or (run["held_corr"] or {}).get(run["final_eq"].name) \
                or run["held_raw"].get(run["final_eq"].name, {})
            te = doc.get("trip_energy", {})
            resp = sum(1 for f in r["findings"] if f.get("role") == "response")
            sumo_doc = (run["held_corr"] or {}).get(run["final_eq"].name, {})
            r2 = _f(doc.get("r2")) if not run.get("held_regime") else \
                f"{_f(sumo_doc.get('r2'))} ({_f(doc.get('r2'))} with the recuperation scale)"
            L.append(f"| {run['tag']} | {run['lag']:+.3g} | {_f(free.get('grade'))} | {resp} | "
                     f"{len(d.get('not_replicated', []))} | {r2} | "
                     f"{_abs_pct(te.get('mean_abs_error'))} / {_abs_pct(te.get('max_abs_error'))} |")
    L += ["", "Targets (issue #11): Prius Gen-2 lag found and corrected; i3 grade within 10 % of 1; no "
          "response column as a finding; held-out i3 mean trip traction-energy error ≤ 3 %, worst ≤ 6 %, "
          "R² ≥ 0.95. The grade column is the free least-squares coefficient on the corrected training data "
          "(behind a drivetrain it reads 1/η, so slightly above 1 is physical).", ""]
    for car in cars:
        L += [f"## {car['name']} (vehicle `{car['vehicle']}`)", ""]
        if car.get("error"):
            L += [car["error"], ""]
            continue
        if car["note"]:
            L += [f"{car['note']}.", ""]
        if "dyno_phys" in car:
            dp = car["dyno_phys"]
            L += [f"Dynamometer calibration ({dp['used']}): {_terms(car['runs'][0]['declared'])}. "
                  f"Reading: {_reading(dp)}.", ""]
        for run in car["runs"]:
            res, r, d = run["res"], run["res"].report, run["res"].details
            bp = run["base_phys"]
            L += [f"### {run['tag']}: held out {', '.join(run['held'])}", "",
                  f"- training: {run['train_trips']} trips, {r['n_samples']} analysis samples; "
                  f"tracer validation: {r['validation']}; run time {run['took_s']:.0f} s "
                  f"([tracer report]({Path('closing-the-loop') / run['tag'] / 'trace.md'}))",
                  f"- calibrated on the training trips ({bp['used']}"
                  + (f": {bp['why']}" if bp["used"] == "constrained" else "") + f"): {_terms(run['base_eq'])}",
                  f"  - unconstrained: {', '.join(f'{t} {c:.4g}' for t, c in bp['unconstrained'].items())}",
                  f"  - physical reading: {_reading(bp)}",
                  f"- columns left out by role (responses): "
                  f"{', '.join(s['column'] for s in d['signals_skipped'] if s.get('role') == 'response') or 'none'}",
                  "- offered: " + (", ".join(c + " (" + str(v.get("role")) + ")"
                                            for c, v in d.get("signal_roles", {}).items()) or "none"),
                  ""]
            L += ["**Findings** (on the training trips, trip-grouped cross-validation):", ""]
            if not r["findings"]:
                L.append("- none")
            for f in r["findings"]:
                rep = f.get("replication") or {}
                share = "" if f["energy_share"] is None else f", energy share {100 * f['energy_share']:.2f} %"
                co = f["coefficient"]
                co = (f"{len(co)} per-trip values" if isinstance(co, dict) else f"{co:.4g}")
                L.append(f"- `{f['term']}` ({f.get('role')}): {f['effect']}; coefficient {co}{share}; "
                         f"held-out RMSE {f['metrics_before']['rmse_w']:.0f} → {f['metrics_after']['rmse_w']:.0f} W; "
                         f"helped on {rep.get('helped_trips', '–')} of {rep.get('trips', '–')} trips")
            for x in d.get("not_replicated", []):
                L.append(f"- rejected `{x['term']}`: {x['reason']}")
            if d.get("timing"):
                tm = d["timing"]
                L.append(f"- timing: best lag {tm['lag_s']:+.3g} s (p = {tm['p_value']:.2g}, gain "
                         f"{100 * tm['rmse_gain']:.1f} %) → {'corrected in the data' if tm['accepted'] else 'not applied'}")
            if run.get("tau"):
                cvs = ", ".join(f"{_tau(t)} {100 * c['mean_abs_error']:.1f} %" for t, c in run["tau"]["cv"].items())
                L.append(f"- fusion crossover chosen on the training trips (trip-grouped 5-fold cross-validation, "
                         f"mean abs. trip traction-energy error of the calibrated equation): {cvs} → "
                         f"**{_tau(run['tau_s'])}** (the tracer's own test used {FUSION_TAU:g} s)")
            gs = d.get("structural", {}).get("grade_sources")
            if gs:
                L.append(f"- grade from each source: logged s.d. {gs['logged']['sd_deg']:.2f}°, accelerometer "
                         f"s.d. {gs['accelerometer']['sd_deg']:.2f}° (correlation with logged {gs['corr']:.2f}), "
                         f"fused (crossover {gs['fused']['crossover_s']:g} s) s.d. {gs['fused']['sd_deg']:.2f}°")
            if run["corr_eq"] is not None:
                cp = run["corr_phys"]
                L.append(f"- recalibrated on the corrected training data ({cp['used']}): {_terms(run['corr_eq'])}; "
                         f"unconstrained: {', '.join(f'{t} {c:.4g}' for t, c in cp['unconstrained'].items())}; "
                         f"reading: {_reading(cp)}")
            sel = run.get("sel")
            if sel:
                b = sel["base_cv"]
                L.append(f"- physical candidates (forms SUMO evaluates; chosen on whole training trips, "
                         f"trip-grouped {b['folds']}-fold cross-validation: kept when the mean abs. trip "
                         f"traction-energy error falls, on more than half of the trips, significantly, with a plausible "
                         f"coefficient); start: {100 * b['mean_abs_error']:.2f} % (worst "
                         f"{100 * b['max_abs_error']:.1f} %):")
                for st in sel["steps"]:
                    rd = st["reading"]
                    L.append(f"  - {'**kept**' if st['accepted'] else 'rejected'} `{st['candidate']}` "
                             f"({PHYS_DESC[st['candidate']]}) after [{', '.join(st['after']) or 'none'}]: "
                             f"CV {100 * st['cv']['mean_abs_error']:.2f} % (worst {100 * st['cv']['max_abs_error']:.1f} %), "
                             f"helped on {st['helped']} of {st['trips']} trips (Wilcoxon p = {st['p_value']:.2g}); {rd['reads_as']} = {rd['value']:.4g}"
                             f"{' ' + rd['unit'] if rd['unit'] not in ('', '-') else ''}"
                             + (f" — {st['why']}" if st["why"] else ""))
                if sel["regime"]:
                    L.append(f"  - recuperation scale 1 + r = {1 + run['rscale']:.3f}: the closed-loop equation's "
                             "coefficients are the traction side; its predicted recuperation × this scale is "
                             "what the motor shaft recovers (the term grammar has no regime: in SUMO the "
                             "equation books traction as here and its recuperable energy unscaled)")
            fi = run["final_info"]
            L.append(f"- closed-loop equation `{run['final_eq'].name}` ({fi['used']}"
                     + (f"; {fi['why']}" if fi["why"] else "") + f"): {_terms(run['final_eq'])}"
                     + (f" (road load kept from the dynamometer: aero, roll)" if run["declared"] is not None else "")
                     + (f"; findings carried: {', '.join(run['extra'])}" if run["extra"] and not sel else "")
                     + (f"; physical candidates carried: {', '.join(sel['chosen']) or 'none'}" if sel else ""))
            L += _render_checks(run)
            L += ["", "**Held out** (trips never used above):", "",
                  "| equation | data | R² | mean abs. trip traction-energy error | worst | per trip |",
                  "|---|---|---|---|---|---|"]

            def row(eqname, doc, data):
                te = doc.get("trip_energy", {})
                per = ", ".join(f"{k} {_pct(v['error'])}" for k, v in te.get("trips", {}).items())
                return (f"| `{eqname}` | {data} | {_f(doc['r2'])} | {_abs_pct(te.get('mean_abs_error'))} | "
                        f"{_abs_pct(te.get('max_abs_error'))} | {per} |")
            for eqname, doc in run["held_raw"].items():
                L.append(row(eqname, doc, "as logged"))
            if run["held_corr"]:
                fixes = [x for x in (f"lag {run['lag']:+.3g} s" if run["lag"] else "",
                                     "fused accelerometer grade" if run["acc_grade"] else "",
                                     "ρ at altitude" if run.get("rho_alt") else "") if x]
                if run.get("tau_s") is not None:
                    fixes = [f"fused accelerometer grade, crossover {_tau(run['tau_s'])}" if "fused" in x else x
                             for x in fixes]
                for eqname, doc in run["held_corr"].items():
                    L.append(row(eqname, doc, f"corrected ({', '.join(fixes)})" if fixes else "as logged"))
                if run.get("held_regime"):
                    L.append(row(run["final_eq"].name + " × recuperation scale", run["held_regime"],
                                 f"corrected ({', '.join(fixes)})"))
            fdoc = (run["held_corr"] or {}).get(run["final_eq"].name) or run["held_raw"].get(run["final_eq"].name)
            if fdoc and fdoc.get("trip_energy"):
                net = fdoc.get("trip_net_energy", {}).get("trips", {})
                far = [f"{k} {_pct(v['error'])} (net energy {_pct(net.get(k, {}).get('error'))})"
                       for k, v in fdoc["trip_energy"]["trips"].items()
                       if v["error"] is not None and math.isfinite(v["error"]) and abs(v["error"]) > 0.06]
                L += ["", f"Held-out trips of `{run['final_eq'].name}` beyond 6 %: {', '.join(far) or 'none'}. "
                      "A net-energy error of the same size says the gap is not in the split between traction "
                      "and recuperation."]
                hi = (run.get("checks") or {}).get("held_inputs") or {}
                bad = [k for k, v in fdoc["trip_energy"]["trips"].items()
                       if v["error"] is not None and math.isfinite(v["error"]) and abs(v["error"]) > 0.06]
                if bad and hi:
                    L.append("Their inputs (no power): " + "; ".join(
                        f"{k}: " + ", ".join(x for x in (
                            f"{hi[k]['weather']}" if "weather" in hi[k] else "",
                            f"{hi[k]['ambient_c']:.1f} °C" if "ambient_c" in hi[k] else "",
                            f"{hi[k]['mass_kg']:.0f} kg declared",
                            f"Δh {hi[k]['dh_m']:+.0f} m" if "dh_m" in hi[k] else "",
                            f"{hi[k]['distance_km']:.1f} km, {100 * hi[k]['standstill']:.0f} % standstill") if x)
                        for k in bad if k in hi) + ".")
            L.append("")
    L += ["## What this shows, and what it does not", "",
          "- Findings are kept only when they pass the held-out block test, lower the held-out error on most "
          "training trips and carry a plausible energy share; responses of the target (pedal, torques, "
          "currents, SOC, counters) are never offered by default.",
          "- Structural terms found by the tracer (recuperation regimes, brake limits, per-trip offsets) are "
          "reported with their size; the closed-loop equation carries only what passed the physical-candidate "
          "stage on whole training trips (i3) or the tracer's condition and load findings (Prius, JLU). "
          "Traction energy needs only the traction-side coefficients: when the recuperation regime is kept, "
          "its fit keeps braking samples from bending them, and the positive part of the equation is the same "
          "with or without the recuperation scale (the row '× recuperation scale' differs in R² only).",
          "- The tracer refits declared coefficients without constraints inside its folds; the physical "
          "constraints act on the calibration.",
          "- The fusion crossover is chosen inside the training trips (grid and criterion fixed in the script: "
          "TAU_GRID_S, mean abs. trip traction-energy error under trip-grouped 5-fold cross-validation). "
          "Disclosure: an earlier session tried 30/60/120/300 s on the first i3 split's held-out trips; the "
          "grid includes those values. Cross-validated RMSE keeps falling towards the pure accelerometer "
          "(longer crossovers) while the trip energy error rises: the accelerometer's pitch bias enters the "
          "mean grade; trip energy is the criterion because it is the product's.",
          "- Disclosure: the plausibility bound of the c_r(T) coefficient k (0 … 0.03 /K, `K_CR_MAX` in "
          "`fit/physical.py`; ISO 28580 corrects tyres with 0.008 /K) was written after seeing an estimate of "
          "about 0.02 /K on the shared i3 data; the extra room is for bearings and the drivetrain share of the "
          "`roll` term (a motor-shaft target).",
          "- The temperature effect replicates on both i3 splits but its form does not separate: `cold drag` "
          "(v²·(T_ref − T)) and `c_r(T)` (m·g·v·(T_ref − T)) are nearly collinear on these trips; the cross-"
          "validation picks one and then rejects the other.",
          "- Input checks (`sumo_drvpw/fit/input_checks.py`) read inputs only, never a held-out target: a "
          "logger dropout (speed and accelerometer exactly linear in time for ≥ 5 s within the logged digits: a "
          "held or linearly filled stretch; a real accelerometer never draws a straight line for seconds) is taken "
          "out of the usable samples of training and held-out logs alike, for every equation, with the 100-m grade "
          "window around it (the elevation jumps where the log resumes). The power logged across such a stretch "
          "is filled the same way, so it is not a measurement. The inertial mass of each training trip is a check "
          "of the declared mass (reported, never substituted); the accelerometer's per-trip offset and the "
          "elevation's agreement with the accelerometer are reported per trip.",
          "- Conditions read from the trip notes are reported beside each remaining miss. A wet road raises "
          "rolling resistance: it would make a rainy trip need more energy than predicted, so a rainy trip "
          "predicted too high is not explained by rain. The remaining misses are not explained by the inputs "
          "checked here (declared mass, dropouts, accelerometer offset, net elevation).",
          "- In SUMO the `cold` factor reads the signal `ambient_c`; a run that does not pass the air "
          "temperature evaluates the equation at the reference 20 °C (the factor is 0).", ""]
    return "\n".join(L) + "\n"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", default=os.environ.get(
        "SUMO_DRVPW_DATA", str(Path(__file__).resolve().parents[2] / "shared" / "data")))
    ap.add_argument("--out", default="docs")
    ap.add_argument("--only", default="", help="comma list of i3, prius2, jlu (default: all)")
    a = ap.parse_args()
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
        cars.append(close_loop(key, df, vehicle, out / "closing-the-loop", note=note, roles=rep.get("roles")))
    if not only or "jlu" in only:
        if (data / "jlu_bev_road").exists() and (data / "jlu_bev_dyno").exists():
            cars.append(jlu(data, out / "closing-the-loop"))
        else:
            cars.append({"name": "jlu_road", "error": "not run: jlu_bev_road/ or jlu_bev_dyno/ not found"})
    write_text(out / "closing-the-loop.md", render(cars, time.perf_counter() - t0))
    print(f"wrote {out / 'closing-the-loop.md'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
