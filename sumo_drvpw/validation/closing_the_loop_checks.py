"""The closing-the-loop study's checks beside the held-out splits
(:mod:`sumo_drvpw.validation.closing_the_loop`): a steady wind over trips driven in
different directions (:func:`wind_check`), and a constant power split into a standing and a
moving part (:func:`moving_check`)."""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from sumo_drvpw.validation.closing_the_loop_fit import _cv_args, evaluate, fit_terms
from sumo_drvpw.validation.closing_the_loop_read import corrected_measured, write_subset


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
