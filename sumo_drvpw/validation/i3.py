"""BMW i3 (TUM, 50 on-road trips): DrvPw calibrated on half the trips, tested on the rest.

Target: mechanical motor power τ·ω. Stepwise DrvPw (Indt var. 1 and 2, paper Table 3) is
calibrated on alternate trips within each season (in trip-id order) and evaluated on the
other half against ``vsp_ldv1999`` and VSP with the i3's physical specs (seed paper
Eq. 1), overall and per season.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from sumo_drvpw.model.constants import HEAVY_LOAD_W
from sumo_drvpw.validation.data import (Dataset, StudyResult, coefficient_block, compare_on,
                                        metrics_row)

#: data-set folder read by this study
DATASET = "bmw_i3_tum"
#: Rolling coefficient assumed for the i3's physical VSP when its vehicle file has none:
#: an ASSUMPTION (typical low-rolling-resistance tyre), stated in the report.
ROLLING_COEFFICIENT_ASSUMED = 0.008
#: Fewest test samples of a season for a per-season table.
MIN_SEASON_SAMPLES = 10


def vsp_with_specs(vehicle):
    """VSP with the i3's specs (seed paper Eq. 1); C_r assumed (stated) when the vehicle
    file has none. Returns (equation, note or None)."""
    from sumo_drvpw.model.equations import vsp_from_specs

    if "rolling_coefficient" in vehicle.body:
        return vsp_from_specs(vehicle), None
    vehicle = replace(vehicle, body=dict(vehicle.body, rolling_coefficient=ROLLING_COEFFICIENT_ASSUMED))
    eq = vsp_from_specs(vehicle)
    return eq, (f"{Path(vehicle.path).name} has no [body] rolling_coefficient: "
                f"C_r = {ROLLING_COEFFICIENT_ASSUMED} ASSUMED for {eq.name}")


def split_trips(trips: np.ndarray, season: np.ndarray) -> tuple[list[str], list[str]]:
    """Calibration and test trips: alternate trips (in id order) within each season."""
    order: dict[str, list[str]] = {}
    seen = set()
    for t, s in zip(trips, season):
        if t not in seen:
            seen.add(t)
            order.setdefault(str(s), []).append(str(t))
    cal, test = [], []
    for s in sorted(order):
        ids = sorted(order[s])
        cal += ids[0::2]
        test += ids[1::2]
    return sorted(cal), sorted(test)


def _speed_rows(bins: list[dict], keys) -> list[dict]:
    return [{k: b[k] for k in keys} for b in bins]


def study(ds: Dataset, out: Path) -> StudyResult:
    """Calibrate on half the trips, evaluate on the other half (module docstring)."""
    from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
    from sumo_drvpw.model.equations import load_equation
    from sumo_drvpw.report import figures as plots

    df = ds.log.df
    season = (df["season"].fillna("unknown").astype(str).to_numpy() if "season" in df  # (a trip the
              else np.full(len(df), "unknown"))                                        # overview lacks)
    trips = ds.trip
    cal_trips, test_trips = split_trips(trips, season)
    cal = ds.usable & np.isin(trips, cal_trips)
    test = ds.usable & np.isin(trips, test_trips)
    ref_mass = float(ds.inputs.mass[cal].mean())
    cals = {}
    for label, cset in (("var1", "indt-var-1"), ("var2", "indt-var-2")):
        res = calibrate(ds.inputs, ds.power_w, CANDIDATES[cset], mask=cal,
                        reference_mass_kg=ref_mass)
        cals[label] = (res, res.to_equation(f"drvpw_i3_{label}"))
    vsp_spec, note = vsp_with_specs(ds.vehicle)
    eqs = [cals["var1"][1], cals["var2"][1], load_equation("vsp_ldv1999"), vsp_spec]
    comp = compare_on(ds, test, eqs, reference=eqs[0].name)
    comp_cal = compare_on(ds, cal, eqs[:2])
    seasons = {}
    for s in sorted(set(season)):
        m = test & (season == s)
        if m.sum() < MIN_SEASON_SAMPLES:
            continue
        cs = compare_on(ds, m, eqs)
        seasons[s] = {"trips": sorted(set(trips[m])), "n": int(m.sum()),
                      "equations": {e.name: metrics_row(cs, e.name) for e in eqs},
                      "error_vs_speed": {e.name: _speed_rows(cs.results[e.name].speed_bins,
                                                             ("lo_kmh", "hi_kmh", "n", "mean_w"))
                                         for e in eqs}}
    jd = comp.to_json()
    speed = {e.name: _speed_rows(jd["equations"][e.name]["speed_bins"],
                                 ("lo_kmh", "hi_kmh", "n", "mean_w", "rmse_w")) for e in eqs}
    figures = []
    for fname, fn in (("i3_parity.png", plots.parity), ("i3_error_speed.png", plots.error_vs_speed)):
        fn(comp, out / fname)
        figures.append(fname)
    p_test = ds.power_w[test]
    pt = ds.vehicle.powertrain
    summary = {
        **ds.provenance(),
        "vehicle": {"file": Path(ds.vehicle.path).name, "gear_ratio": pt.get("gear_ratio"),
                    "wheel_radius_m": pt.get("wheel_radius_m")},
        "split": {"rule": "alternate trips in trip-id order within each season: 1st, 3rd, … "
                          "calibrate; 2nd, 4th, … test",
                  "calibration_trips": cal_trips, "test_trips": test_trips,
                  "n_calibration": int(cal.sum()), "n_test": int(test.sum())},
        "reference_mass_kg": ref_mass,
        "calibration": {lab: {"equation": eq.name, "candidates": list(res.settings["candidates"]),
                              "terms": coefficient_block(eq), "r2_in_sample": res.r2, "n": res.n,
                              "selection": [f"{t['action']} {t['term']}"
                                            + (f" ({t['reason']})" if "reason" in t else "")
                                            for t in res.trace]}
                        for lab, (res, eq) in cals.items()},
        "vsp_spec": {"equation": vsp_spec.name, "terms": dict(vsp_spec.terms), "note": note},
        "test": {e.name: metrics_row(comp, e.name) for e in eqs},
        "calibration_in_sample": {e.name: metrics_row(comp_cal, e.name) for e in eqs[:2]},
        "per_season": seasons,
        "error_vs_speed": speed,
        "measured": {"max_w": float(p_test.max()), "p99_w": float(np.percentile(p_test, 99)),
                     "n_heavy": int((p_test >= HEAVY_LOAD_W).sum()), "n": int(p_test.size)},
    }
    return StudyResult(summary, test, [cals["var1"][1], cals["var2"][1], vsp_spec], figures,
                       settings={"i3_rolling_coefficient_assumed": ROLLING_COEFFICIENT_ASSUMED})
