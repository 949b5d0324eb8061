"""The loop closed on real data, proven on held-out trips: the study behind
docs/closing-the-loop.md (its command: scripts/closing_the_loop.py).

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
   training trips (``closing_the_loop_fit.GRADE_CHOICE``, the default of ``grade_choice``);
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

The held-out trips then give R² and per-trip traction energy errors (Σ max(P, 0)·Δt,
predicted/measured − 1) before and after, against VSP LDV 1999 as a reference. The JLU
car: an equation calibrated on the dynamometer is taken onto the road, and the loop is
closed on road trips (grade, auxiliaries and temperature the dyno could not see; the constant
power split into a standing part ``v^0`` and a part drawn while moving, ``moving``, checked by
leave-one-trip-out over all road trips and against the power measured while standing).

The modules: this one (the splits, a car's runs, the deliverable on all trips, the JLU car,
:func:`run`), ``closing_the_loop_read`` (the logs read with their corrections, input
checks), ``closing_the_loop_fit`` (fits, the grade source and the physical candidates),
``closing_the_loop_checks`` (the wind and the standing/moving checks). The Markdown is
rendered by scripts/closing_the_loop_report.py.
"""

from __future__ import annotations

import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sumo_drvpw.validation.closing_the_loop_checks import moving_check, wind_check
from sumo_drvpw.validation.closing_the_loop_fit import (GRADE_CHOICE, SELECTION_ENERGY, _cv_args,
                                                        calibrate_physical, choose_tau, evaluate, fit_terms,
                                                        grade_and_physics, physical_stage, regime_eval)
from sumo_drvpw.validation.closing_the_loop_read import (CHECK_DROPOUTS, _load, _offsets, _trip_inputs,
                                                         corrected_measured, input_checks, load_checked,
                                                         write_subset)

HOLD_EVERY = 5
#: fewest training trips for trip-grouped cross-validation of choices (tau, physical terms)
MIN_CV_TRIPS = 5
#: cars whose trips are one day's drives in different directions (an out-and-back pair):
#: their logs imply one steady wind (wind_check). Not the i3 (no heading) nor the JLU car
#: (trips of different days: no common wind)
WIND_CHECK = ("prius2",)

#: fewest trips for a deliverable fitted on all of them (beside the held-out splits)
MIN_ALL_TRIPS = 10


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


def close_loop(name, df, vehicle, out_dir, declared=None, note="", roles=None, grade_choice=GRADE_CHOICE,
               selection_energy=SELECTION_ENERGY):
    """One car: per held-out group, calibrate + diagnose on the rest, evaluate held out
    (``grade_choice``, ``selection_energy``: closing_the_loop_fit.grade_and_physics)."""
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
                staged = grade_and_physics(train, vehicle, lag, base_eq.terms, m_train, f"{name}_closed",
                                           grade_choice, selection_energy)
                tau, m_corr = staged[0], staged[1]
            else:
                tau = (choose_tau(train, vehicle, lag, base_eq.terms, m_train, selection_energy)
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
                                         physical_stage(m_fit, list(base_eq.terms), f"{name}_closed",
                                                        selection_energy))
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


def final_fit(name, df, vehicle, out_dir, roles=None, grade_choice=GRADE_CHOICE,
              selection_energy=SELECTION_ENERGY) -> dict | None:
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
                                                             f"{name}_closed", grade_choice, selection_energy)
        else:
            tau = None
            m_corr = corrected_measured(path, vehicle, lag, False)
            eq, sel, rscale = physical_stage(m_corr, list(base_eq.terms), f"{name}_closed", selection_energy)
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


def jlu(data: Path, out_dir: Path, grade_choice=GRADE_CHOICE, selection_energy=SELECTION_ENERGY):
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
                     roles=road_rep.get("roles"), grade_choice=grade_choice, selection_energy=selection_energy)
    out["dyno_phys"] = dyno_phys
    with tempfile.TemporaryDirectory() as tmp:
        path = write_subset(road, sorted(road["trip_id"].unique()), Path(tmp) / "road.parquet", keep=True,
                            roles=road_rep.get("roles"))
        m = corrected_measured(path, "jlu_bev", out["runs"][0]["lag"], False)
        out["moving_check"] = moving_check(m, dyno_eq)
    return out


def run(data: Path, out_dir: Path, only=frozenset(), grade_choice: str = GRADE_CHOICE,
        selection_energy: str = SELECTION_ENERGY) -> list[dict]:
    """Every car of the study whose logs are in the folder ``data`` (read in place through
    their adapters; ``only``: names among i3, prius2, jlu, empty for all), each run's tracer
    report and closed-loop equation written under ``out_dir``; a car whose folder is absent
    is an entry saying so; ``grade_choice`` and ``selection_energy``: how the grade source and
    the physical candidates are chosen (closing_the_loop_fit.grade_and_physics). Returns the
    cars' results, as the report renders them."""
    from sumo_drvpw.data.adapters import read

    how = {"grade_choice": grade_choice, "selection_energy": selection_energy}
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
        car = close_loop(key, df, vehicle, out_dir, note=note, roles=rep.get("roles"), **how)
        car["wind"] = wind_check(key, df, vehicle, car, roles=rep.get("roles")) if key in WIND_CHECK else None
        car["all_trips"] = final_fit(key, df, vehicle, out_dir, roles=rep.get("roles"), **how)
        cars.append(car)
    if not only or "jlu" in only:
        if (data / "jlu_bev_road").exists() and (data / "jlu_bev_dyno").exists():
            cars.append(jlu(data, out_dir, **how))
        else:
            cars.append({"name": "jlu_road", "error": "not run: jlu_bev_road/ or jlu_bev_dyno/ not found"})
    return cars
