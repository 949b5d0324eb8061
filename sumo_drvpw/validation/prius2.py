"""Toyota Prius Gen-2 (phone OBD, 2 trips): P_PTdrv against the EPA road load of that car.

P_PTdrv comes from MG1/MG2/engine through the power-split equations
(:mod:`sumo_drvpw.data.powertrain`); the reference is the EPA Test Car List target road
load of the car (prius2.toml [road_load]) with the EPA test weight as mass. Where they
disagree is tabulated by speed, acceleration and grade band; a lag scan shows the OBD
timing; DrvPw Indt var. 1 is calibrated on the first trip and tested on the second.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import KMH
from sumo_drvpw.validation.data import (Dataset, StudyResult, coefficient_block, compare_on,
                                        metrics_row, vehicle_ref, vehicle_table)

#: data-set folder read by this study
DATASET = "prius_gen2_torquepro"
#: Band edges of the disagreement tables [km/h], [m/s²], [%]; the outer edges stand for ±∞.
SPEED_BANDS_KMH = (0, 30, 60, 90, 200)
ACCEL_BANDS_MPS2 = (-10, -0.5, -0.1, 0.1, 0.5, 10)
GRADE_BANDS_PCT = (-60, -2, -0.5, 0.5, 2, 60)
#: Timing scan: lags of ±this many samples.
LAG_SCAN = 3


def epa_road_load_equation(vehicle):
    """EPA Test Car List target road load of a vehicle file's [road_load] as an Equation.

    P = F0·v + F1·v² + F2·v³ + m·v·a + m·g·v·sin θ with m = the EPA test weight (ETW),
    the inertia the dynamometer simulates; F0, F1, F2 [N, N/(m/s), N/(m/s)²] from the file
    (source: the EPA Test Car List data file named in the table).
    """
    from sumo_drvpw.model.equations import Equation

    rl = getattr(vehicle, "road_load", None) or vehicle_table(vehicle, "road_load")
    need = ("f0_N", "f1_N_per_mps", "f2_N_per_mps2", "etw_kg")
    miss = [k for k in need if k not in rl]
    if miss:
        raise UserError(f"{vehicle.path}: [road_load] lacks {', '.join(miss)}")
    return Equation(name=f"epa_{vehicle.name}",
                    terms={"v1": float(rl["f0_N"]), "v2": float(rl["f1_N_per_mps"]),
                           "v3": float(rl["f2_N_per_mps2"]), "acc": 1.0, "grade": 1.0},
                    mass_kg=float(rl["etw_kg"]),
                    description=f"EPA target road load of {vehicle.name} with ETW as mass",
                    source=f"{vehicle_ref(vehicle)} [road_load] ({rl.get('source_file', '')}; "
                           f"{rl.get('rows', '')})")


def bands(values, edges, meas, pred, dt, label) -> list[dict]:
    """Measured against predicted power in bands of ``values``.

    Parameters
    ----------
    values : the banding quantity per sample; edges : band edges (a band is [lo, hi))
    meas, pred : measured and predicted power per sample [W]; dt : sample duration [s]
    label : (lo, hi) → band label

    Returns one row per band: ``band``, ``lo``, ``hi``, ``n`` and, when n > 0, ``time_s``,
    ``mean_measured_w``, ``mean_predicted_w``, ``mean_error_w`` (pred − meas), ``rmse_w``.
    """
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (values >= lo) & (values < hi)
        n = int(m.sum())
        row = {"band": label(lo, hi), "lo": lo, "hi": hi, "n": n}
        if n:
            e = pred[m] - meas[m]
            row.update({"time_s": float(dt[m].sum()), "mean_measured_w": float(meas[m].mean()),
                        "mean_predicted_w": float(pred[m].mean()), "mean_error_w": float(e.mean()),
                        "rmse_w": float(np.sqrt(np.mean(e * e)))})
        rows.append(row)
    return rows


def _edge(x, inf: float) -> str:
    """Band edge for display: ±∞ beyond the outermost edges (|x| ≥ inf)."""
    if x <= -inf:
        return "−∞"
    if x >= inf:
        return "∞"
    return f"{x:g}".replace("-", "−")


def _speed_label(lo, hi):
    return f"{_edge(lo, SPEED_BANDS_KMH[-1])}–{_edge(hi, SPEED_BANDS_KMH[-1])} km/h"


def _accel_label(lo, hi):
    return f"{_edge(lo, ACCEL_BANDS_MPS2[-1])} … {_edge(hi, ACCEL_BANDS_MPS2[-1])} m/s²"


def _grade_label(lo, hi):
    return f"{_edge(lo, GRADE_BANDS_PCT[-1])} … {_edge(hi, GRADE_BANDS_PCT[-1])} %"


def lag_scan(meas, pred, usable, trips, max_lag: int = LAG_SCAN) -> list[dict]:
    """Correlation r of measured power at sample i with predicted power at i + k, within
    trips, for k = −max_lag … max_lag [samples]."""
    out = []
    for k in range(-max_lag, max_lag + 1):
        a_parts, b_parts = [], []
        for t in sorted(set(trips)):
            idx = np.flatnonzero(usable & (trips == t))
            n_t = len(idx)
            a_parts.append(meas[idx[max(0, -k):n_t - max(0, k)]])
            b_parts.append(pred[idx[max(0, k):n_t - max(0, -k)]])
        out.append({"lag_samples": k,
                    "r": float(np.corrcoef(np.concatenate(a_parts), np.concatenate(b_parts))[0, 1])})
    return out


def _per_trip(ds: Dataset, meas, pred) -> dict:
    """Duration, distance, elevation change and traction/net energy per trip [s, m, J]."""
    u, x, dt, trips = ds.usable, ds.inputs, ds.dt, ds.trip
    elev = ds.log.df["elevation_m"].to_numpy(float) if "elevation_m" in ds.log.df else None
    out = {}
    for t in sorted(set(trips)):
        m = u & (trips == t)
        d = {
            "n": int(m.sum()), "duration_s": float(dt[m].sum()),
            "distance_m": float((x.v[m] * dt[m]).sum()),
            "measured_traction_j": float((np.clip(meas[m], 0, None) * dt[m]).sum()),
            "epa_traction_j": float((np.clip(pred[m], 0, None) * dt[m]).sum()),
            "measured_net_j": float((meas[m] * dt[m]).sum()),
            "epa_net_j": float((pred[m] * dt[m]).sum()),
            "elevation_change_m": float(elev[m][-1] - elev[m][0]) if elev is not None else None,
        }
        d["traction_ratio_epa_over_measured"] = d["epa_traction_j"] / d["measured_traction_j"]
        out[t] = d
    return out


def study(ds: Dataset, out: Path) -> StudyResult:
    """P_PTdrv against the EPA road load; DrvPw calibrated on the first trip, tested on the second."""
    from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
    from sumo_drvpw.model.equations import vsp_from_specs
    from sumo_drvpw.report import figures as plots

    epa = epa_road_load_equation(ds.vehicle)
    u, x, meas, dt, trips = ds.usable, ds.inputs, ds.power_w, ds.dt, ds.trip
    pred = epa.power(x)
    tr = (meas > 0) & (pred > 0) & u
    grade_pct = 100 * np.tan(x.theta)
    v_kmh = x.v / KMH
    band_rows = {
        "speed_kmh": bands(v_kmh[u], SPEED_BANDS_KMH, meas[u], pred[u], dt[u], _speed_label),
        "accel_mps2": bands(x.a[u], ACCEL_BANDS_MPS2, meas[u], pred[u], dt[u], _accel_label),
        "grade_pct": bands(grade_pct[u], GRADE_BANDS_PCT, meas[u], pred[u], dt[u], _grade_label),
        # traction-only error by speed: where both say the powertrain pushes
        "speed_kmh_traction": bands(v_kmh[tr], SPEED_BANDS_KMH, meas[tr], pred[tr], dt[tr],
                                    _speed_label),
    }
    lags = lag_scan(meas, pred, u, trips)
    med_dt = float(np.median(np.diff(ds.log.df["time_s"].to_numpy(float))[trips[1:] == trips[:-1]]))
    # the regen-vs-brake gap: EPA road load says "negative" power the powertrain does not absorb
    brake = u & (pred < 0)
    # DrvPw: calibrate on the first trip, test on the last
    tids = sorted(set(trips))
    cal_t, test_t = tids[0], tids[-1]
    cal = u & (trips == cal_t)
    test = u & (trips == test_t)
    res = calibrate(x, meas, CANDIDATES["indt-var-1"], mask=cal,
                    reference_mass_kg=float(x.mass[cal].mean()))
    drv = res.to_equation("drvpw_prius2_var1")
    spec = vsp_from_specs(ds.vehicle)
    comp = compare_on(ds, u, [epa, spec])
    comp_test = compare_on(ds, test, [drv, epa, spec])
    figures = []
    for fname, fn in (("prius2_parity.png", plots.parity),
                      ("prius2_error_speed.png", plots.error_vs_speed)):
        fn(comp, out / fname)
        figures.append(fname)
    plots.band_means([(title, band_rows[key]) for key, title in
                      (("speed_kmh", "speed band"), ("accel_mps2", "acceleration band"),
                       ("grade_pct", "grade band"))],
                     "measured P_PTdrv", epa.name, out / "prius2_bands.png",
                     title_prefix="Prius Gen-2: ")
    figures.append("prius2_bands.png")
    summary = {
        **ds.provenance(),
        "vehicle": {"file": Path(ds.vehicle.path).name},
        "epa_equation": {"name": epa.name, "terms": dict(epa.terms), "mass_kg": epa.mass_kg,
                         "source": epa.source},
        "n_usable": int(u.sum()),
        "correlation_all": float(np.corrcoef(meas[u], pred[u])[0, 1]),
        "correlation_traction": float(np.corrcoef(meas[tr], pred[tr])[0, 1]),
        "lag_scan": lags, "median_dt_s": med_dt, "best_lag": max(lags, key=lambda r: r["r"]),
        "n_traction": int(tr.sum()),
        "per_trip": _per_trip(ds, meas, pred),
        "bands": band_rows,
        "braking": {"n": int(brake.sum()),
                    "epa_negative_j": float((pred[brake] * dt[brake]).sum()),
                    "measured_in_those_samples_j": float((meas[brake] * dt[brake]).sum())},
        "metrics": {e: metrics_row(comp, e) for e in (epa.name, spec.name)},
        "drvpw": {"calibration_trip": cal_t, "test_trip": test_t, "terms": coefficient_block(drv),
                  "r2_in_sample": res.r2, "n": res.n,
                  "test": {e: metrics_row(comp_test, e) for e in comp_test.results}},
    }
    return StudyResult(summary, test, [drv, epa, spec], figures)
