"""`sumo-drvpw validate`: the validation report on real measured data (../shared/data).

Reads the three real data sets through the adapters (in place, never copied), calibrates
and compares driving-power equations, and writes ``<out>.md`` beside the folder ``<out>``
(``--out docs/validation`` → ``docs/validation.md``), PNG figures and ``summary.json`` in
``<out>/``. Every number in the report is computed by this run.

Sections
--------
* BMW i3 (TUM, 50 on-road trips, target mechanical motor power τ·ω): stepwise DrvPw
  (Indt var. 1 and 2) calibrated on half the trips (alternate trips within each season,
  in trip-id order) and evaluated on the other half against ``vsp_ldv1999`` and VSP with
  the i3's physical specs; per season.
* Prius Gen-2 (phone OBD, 2 trips): P_PTdrv from MG1/MG2/engine through the power-split
  equations against the EPA Test Car List road load of that car (prius2.toml [road_load]).
* JLU dynamometer (46 tests, target battery power V·I): recover the dyno road load
  through a constant drivetrain efficiency, P_batt = (A·v + B·v² + C·v³ + m·a·v)/η + P_aux
  on traction samples (a ≥ 0, v > 2 m/s), and a separate fit of the same terms where that
  model's wheel power is negative (regeneration).
* Every built-in equation (plus the calibrated and physical ones) on every data set.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from sumo_drvpw.model.constants import HEAVY_LOAD_W, KMH
from sumo_drvpw.errors import UserError

#: data-set folder → (adapter format, vehicle)
DATASETS = {
    "bmw_i3_tum": ("bmw-i3-tum", "bmw_i3"),
    "prius_gen2_torquepro": ("torquepro-prius2", "prius2"),
    "jlu_bev_dyno": ("jlu-dyno", "jlu_bev"),
}
#: Rolling coefficient assumed for the i3's physical VSP when its vehicle file has none:
#: an ASSUMPTION (typical low-rolling-resistance tyre), stated in the report.
I3_ROLLING_COEFFICIENT_ASSUMED = 0.008
#: JLU traction samples: acceleration ≥ 0 and speed above this [m/s] (no use of the answer).
JLU_TRACTION_MIN_SPEED_MPS = 2.0
#: Speeds at which recovered and published road-load forces are tabulated [km/h].
FORCE_TABLE_KMH = (20, 50, 80, 110, 130)
#: Band edges of the Prius disagreement tables.
SPEED_BANDS_KMH = (0, 30, 60, 90, 200)
ACCEL_BANDS_MPS2 = (-10, -0.5, -0.1, 0.1, 0.5, 10)
GRADE_BANDS_PCT = (-60, -2, -0.5, 0.5, 2, 60)
#: Prius timing scan: lags of ±this many samples.
LAG_SCAN = 3
_KW = 1e-3
_KWH = 1.0 / 3.6e6


# ------------------------------------------------------------------------------- CLI


def _worst_band(bands: list[dict]) -> dict | None:
    """The non-empty band with the largest absolute mean error, None if all are empty."""
    return max((r for r in bands if r["n"]), key=lambda r: abs(r["mean_error_w"]), default=None)


def _provenance(ds) -> dict:
    """What every dataset section reports first: source, import report, reader counts."""
    return {"target": ds.source, "import": ds.import_report,
            "read_counts": {k: ds.log.counts[k] for k in ("rows", "trips", "grade_source",
                                                          "accel_source", "excluded_total")}}


def resolve_data(arg) -> Path:
    """The data folder: ``--data``, else $SUMO_DRVPW_DATA, else <repo>/../shared/data."""
    from sumo_drvpw.fileio import repo_root

    if arg:
        p, how = Path(arg), "--data"
    elif os.environ.get("SUMO_DRVPW_DATA"):
        p, how = Path(os.environ["SUMO_DRVPW_DATA"]), "$SUMO_DRVPW_DATA"
    else:
        p, how = repo_root().parent / "shared" / "data", "default <repo>/../shared/data"
    if not p.is_dir():
        raise UserError(f"{how}: data folder not found: {p}")
    missing = [d for d in DATASETS if not (p / d).is_dir()]
    if missing:
        raise UserError(f"{how} {p}: missing data set folder(s) {', '.join(missing)} "
                        f"(expected {', '.join(DATASETS)})")
    return p


def report_path(out: Path) -> Path:
    """``<out>.md`` beside the figure folder."""
    out = Path(out)
    return out.parent / f"{out.name}.md"


# --------------------------------------------------------------------------- loading

@dataclass
class Dataset:
    """One data set as the models see it: measured power, inputs, time weights."""

    name: str
    vehicle: object
    log: object
    power_w: np.ndarray
    source: str
    inputs: object
    usable: np.ndarray
    import_report: dict
    trip: np.ndarray  # trip id per sample (text)

    @property
    def dt(self) -> np.ndarray:
        return self.log.df["dt_s"].to_numpy(float)


def load_dataset(data: Path, folder: str) -> Dataset:
    """Adapter → DriveLog (log.from_frame) → measured power, inputs, usable mask."""
    from sumo_drvpw.data import adapters
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.data.powertrain import measured_power
    from sumo_drvpw.model.vehicles import load_vehicle

    fmt, vname = DATASETS[folder]
    veh = load_vehicle(vname)
    df, rep = adapters.read(fmt, data / folder)
    log = from_frame(df, veh, name=str(data / folder))
    p, source = measured_power(log, veh)
    x = log.inputs(veh.mass_kg)
    usable = ~log.excluded & np.isfinite(p)
    for arr in (x.v, x.a, x.theta, x.wind, x.mass, x.rho):
        usable &= np.isfinite(arr)
    short = {"rows_read": rep["rows_read"], "kept": rep["kept"], "dropped": rep["dropped"],
             "files": len(rep["files"])}
    return Dataset(folder, veh, log, np.asarray(p, float), source, x, usable, short,
                   log.df["trip_id"].to_numpy().astype(str))


def _metrics_row(comp, name: str) -> dict:
    r = comp.results[name]
    m = r.metrics
    return {"n": m["n"], "r2": m["r2"], "r2_light": m["r2_light"], "r2_heavy": m["r2_heavy"],
            "n_light": m["n_light"], "n_heavy": m["n_heavy"], "rmse_w": m["rmse_w"],
            "bias_w": m["bias_w"], "traction_energy_ratio": r.traction_energy_ratio}


def _compare(ds: Dataset, mask: np.ndarray, eqs, reference=None):
    from sumo_drvpw.fit.compare import compare

    return compare(ds.power_w[mask], ds.inputs.take(mask), eqs, dt_s=ds.dt[mask],
                   reference=reference)


def _coef_block(eq) -> dict:
    return {t: {"coef": float(c), "std_err": eq.std_err.get(t)} for t, c in eq.terms.items()}


# ---------------------------------------------------------------------------- BMW i3

def i3_vsp_spec(vehicle):
    """VSP with the i3's specs; C_r assumed (stated) when the vehicle file has none."""
    from sumo_drvpw.model.equations import vsp_from_specs

    note = None
    if "rolling_coefficient" not in vehicle.body:
        body = dict(vehicle.body, rolling_coefficient=I3_ROLLING_COEFFICIENT_ASSUMED)
        vehicle = replace(vehicle, body=body)
        note = (f"{Path(vehicle.path).name} has no [body] rolling_coefficient: "
                f"C_r = {I3_ROLLING_COEFFICIENT_ASSUMED} ASSUMED for vsp_bmw_i3spec")
    return vsp_from_specs(vehicle), note


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


def validate_i3(ds: Dataset, out: Path, figures: list) -> tuple[dict, dict]:
    """Calibrate on half the trips, evaluate on the other half (see module docstring)."""
    from sumo_drvpw.report import figures as plots
    from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
    from sumo_drvpw.model.equations import load_equation

    df = ds.log.df
    season = (df["season"].astype(str).to_numpy() if "season" in df
              else np.full(len(df), "unknown"))
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
    vsp_spec, note = i3_vsp_spec(ds.vehicle)
    eqs = [cals["var1"][1], cals["var2"][1], load_equation("vsp_ldv1999"), vsp_spec]
    comp = _compare(ds, test, eqs, reference=eqs[0].name)
    comp_cal = _compare(ds, cal, eqs[:2])
    seasons = {}
    for s in sorted(set(season)):
        m = test & (season == s)
        if m.sum() < 10:
            continue
        cs = _compare(ds, m, eqs)
        seasons[s] = {"trips": sorted(set(trips[m])), "n": int(m.sum()),
                      "equations": {e.name: _metrics_row(cs, e.name) for e in eqs},
                      "error_vs_speed": {e.name: [{k: b[k] for k in ("lo_kmh", "hi_kmh", "n", "mean_w")}
                                                  for b in cs.results[e.name].speed_bins]
                                         for e in eqs}}
    jd = comp.to_json()
    speed = {e.name: [{k: b[k] for k in ("lo_kmh", "hi_kmh", "n", "mean_w", "rmse_w")}
                      for b in jd["equations"][e.name]["speed_bins"]] for e in eqs}
    for fname, fn in (("i3_parity.png", plots.parity), ("i3_error_speed.png", plots.error_vs_speed)):
        fn(comp, out / fname)
        figures.append(fname)
    p_test = ds.power_w[test]
    summary = {
        **_provenance(ds),
        "split": {"rule": "alternate trips in trip-id order within each season: 1st, 3rd, … "
                          "calibrate; 2nd, 4th, … test",
                  "calibration_trips": cal_trips, "test_trips": test_trips,
                  "n_calibration": int(cal.sum()), "n_test": int(test.sum())},
        "reference_mass_kg": ref_mass,
        "calibration": {lab: {"equation": eq.name, "candidates": list(res.settings["candidates"]),
                              "terms": _coef_block(eq), "r2_in_sample": res.r2, "n": res.n,
                              "selection": [f"{t['action']} {t['term']}" + (f" ({t['reason']})" if "reason" in t else "")
                                            for t in res.trace]}
                        for lab, (res, eq) in cals.items()},
        "vsp_spec": {"equation": vsp_spec.name, "terms": dict(vsp_spec.terms), "note": note},
        "test": {e.name: _metrics_row(comp, e.name) for e in eqs},
        "calibration_in_sample": {e.name: _metrics_row(comp_cal, e.name) for e in eqs[:2]},
        "per_season": seasons,
        "error_vs_speed": speed,
        "measured": {"max_w": float(p_test.max()), "p99_w": float(np.percentile(p_test, 99)),
                     "n_heavy": int((p_test >= HEAVY_LOAD_W).sum()), "n": int(p_test.size)},
    }
    return summary, {"mask": test, "equations": [cals["var1"][1], cals["var2"][1], vsp_spec]}


# --------------------------------------------------------------------------- Prius 2

def epa_road_load_equation(vehicle):
    """EPA Test Car List target road load of a vehicle file's [road_load] as an Equation.

    P = F0·v + F1·v² + F2·v³ + m·v·a + m·g·v·sin θ with m = the EPA test weight (ETW),
    the inertia the dynamometer simulates; F0, F1, F2 [N, N/(m/s), N/(m/s)²] from the file.
    """
    from sumo_drvpw.model.equations import Equation

    rl = getattr(vehicle, "road_load", None) or _toml_table(vehicle.path, "road_load")
    need = ("f0_N", "f1_N_per_mps", "f2_N_per_mps2", "etw_kg")
    miss = [k for k in need if k not in rl]
    if miss:
        raise UserError(f"{vehicle.path}: [road_load] lacks {', '.join(miss)}")
    return Equation(name=f"epa_{vehicle.name}",
                    terms={"v1": float(rl["f0_N"]), "v2": float(rl["f1_N_per_mps"]),
                           "v3": float(rl["f2_N_per_mps2"]), "acc": 1.0, "grade": 1.0},
                    mass_kg=float(rl["etw_kg"]),
                    description=f"EPA target road load of {vehicle.name} with ETW as mass",
                    source=f"{_vehicle_ref(vehicle)} [road_load] ({rl.get('source_file', '')}; "
                           f"{rl.get('rows', '')})")


def _vehicle_ref(vehicle) -> str:
    """The vehicle file relative to the repository when it lives there (stable across checkouts)."""
    from sumo_drvpw.fileio import repo_root

    p = Path(vehicle.path).resolve()
    try:
        return str(p.relative_to(repo_root()))
    except ValueError:
        return p.name


def _toml_table(path, table: str) -> dict:
    import tomllib

    return tomllib.loads(Path(path).read_text(encoding="utf-8")).get(table, {})


def _bands(values, edges, meas, pred, dt, label_fmt) -> list[dict]:
    rows = []
    for lo, hi in zip(edges[:-1], edges[1:]):
        m = (values >= lo) & (values < hi)
        n = int(m.sum())
        row = {"band": label_fmt(lo, hi), "lo": lo, "hi": hi, "n": n}
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


def validate_prius2(ds: Dataset, out: Path, figures: list) -> tuple[dict, dict]:
    """P_PTdrv against the EPA road load; DrvPw calibrated on the first trip, tested on the second."""
    import matplotlib.pyplot as plt

    from sumo_drvpw.report import figures as plots
    from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
    from sumo_drvpw.model.equations import vsp_from_specs
    from sumo_drvpw.fileio import write_figure

    epa = epa_road_load_equation(ds.vehicle)
    u = ds.usable
    x = ds.inputs
    pred = epa.power(x)
    meas = ds.power_w
    dt = ds.dt
    trips = ds.trip
    tr = (meas > 0) & (pred > 0) & u
    per_trip = {}
    for t in sorted(set(trips)):
        m = u & (trips == t)
        per_trip[t] = {
            "n": int(m.sum()), "duration_s": float(dt[m].sum()),
            "distance_m": float((x.v[m] * dt[m]).sum()),
            "measured_traction_j": float((np.clip(meas[m], 0, None) * dt[m]).sum()),
            "epa_traction_j": float((np.clip(pred[m], 0, None) * dt[m]).sum()),
            "measured_net_j": float((meas[m] * dt[m]).sum()),
            "epa_net_j": float((pred[m] * dt[m]).sum()),
            "elevation_change_m": float(ds.log.df["elevation_m"].to_numpy(float)[m][-1]
                                        - ds.log.df["elevation_m"].to_numpy(float)[m][0])
            if "elevation_m" in ds.log.df else None,
        }
        pt = per_trip[t]
        pt["traction_ratio_epa_over_measured"] = pt["epa_traction_j"] / pt["measured_traction_j"]
    a = x.a
    grade_pct = 100 * np.tan(x.theta)
    v_kmh = x.v / KMH
    bands = {
        "speed_kmh": _bands(v_kmh[u], SPEED_BANDS_KMH, meas[u], pred[u], dt[u],
                            lambda lo, hi: f"{_edge(lo, 200)}–{_edge(hi, 200)} km/h"),
        "accel_mps2": _bands(a[u], ACCEL_BANDS_MPS2, meas[u], pred[u], dt[u],
                             lambda lo, hi: f"{_edge(lo, 10)} … {_edge(hi, 10)} m/s²"),
        "grade_pct": _bands(grade_pct[u], GRADE_BANDS_PCT, meas[u], pred[u], dt[u],
                            lambda lo, hi: f"{_edge(lo, 60)} … {_edge(hi, 60)} %"),
    }
    # traction-only error by speed: where both say the powertrain pushes
    bands["speed_kmh_traction"] = _bands(v_kmh[tr], SPEED_BANDS_KMH, meas[tr], pred[tr], dt[tr],
                                         lambda lo, hi: f"{_edge(lo, 200)}–{_edge(hi, 200)} km/h")
    corr_all = float(np.corrcoef(meas[u], pred[u])[0, 1])
    # timing: correlate P_PTdrv at sample i with the road load at i + k, within trips
    lag_scan = []
    for k in range(-LAG_SCAN, LAG_SCAN + 1):
        a_parts, b_parts = [], []
        for t in sorted(set(trips)):
            idx = np.flatnonzero(u & (trips == t))
            n_t = len(idx)
            a_parts.append(meas[idx[max(0, -k):n_t - max(0, k)]])
            b_parts.append(pred[idx[max(0, k):n_t - max(0, -k)]])
        lag_scan.append({"lag_samples": k,
                         "r": float(np.corrcoef(np.concatenate(a_parts), np.concatenate(b_parts))[0, 1])})
    med_dt = float(np.median(np.diff(ds.log.df["time_s"].to_numpy(float))[trips[1:] == trips[:-1]]))
    best_lag = max(lag_scan, key=lambda r: r["r"])
    corr_tr = float(np.corrcoef(meas[tr], pred[tr])[0, 1])
    # the regen-vs-brake gap: EPA road load says "negative" power the powertrain does not absorb
    brake = u & (pred < 0)
    brake_info = {"n": int(brake.sum()),
                  "epa_negative_j": float((pred[brake] * dt[brake]).sum()),
                  "measured_in_those_samples_j": float((meas[brake] * dt[brake]).sum())}
    # DrvPw: calibrate on the first trip, test on the second
    tids = sorted(set(trips))
    cal_t, test_t = tids[0], tids[-1]
    cal = u & (trips == cal_t)
    test = u & (trips == test_t)
    res = calibrate(x, meas, CANDIDATES["indt-var-1"], mask=cal,
                    reference_mass_kg=float(x.mass[cal].mean()))
    drv = res.to_equation("drvpw_prius2_var1")
    spec = vsp_from_specs(ds.vehicle)
    comp = _compare(ds, u, [epa, spec])
    comp_test = _compare(ds, test, [drv, epa, spec])
    for fname, fn, c in (("prius2_parity.png", plots.parity, comp),
                         ("prius2_error_speed.png", plots.error_vs_speed, comp)):
        fn(c, out / fname)
        figures.append(fname)
    # band figure
    fig, axes = plt.subplots(1, 3, figsize=(13, 3.6))
    for ax, key, title in zip(axes, ("speed_kmh", "accel_mps2", "grade_pct"),
                              ("speed band", "acceleration band", "grade band")):
        rows = [r for r in bands[key] if r["n"]]
        xs = np.arange(len(rows))
        ax.bar(xs - 0.2, [r["mean_measured_w"] * _KW for r in rows], 0.4, label="measured P_PTdrv")
        ax.bar(xs + 0.2, [r["mean_predicted_w"] * _KW for r in rows], 0.4, label=epa.name)
        ax.set_xticks(xs)
        ax.set_xticklabels([r["band"] for r in rows], fontsize=7, rotation=20)
        ax.axhline(0, color="k", lw=0.6)
        ax.set_title(f"Prius Gen-2: mean power by {title}", fontsize=9)
        ax.set_ylabel("mean power [kW]")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7)
    write_figure(out / "prius2_bands.png", fig)
    figures.append("prius2_bands.png")
    summary = {
        **_provenance(ds),
        "epa_equation": {"name": epa.name, "terms": dict(epa.terms), "mass_kg": epa.mass_kg,
                         "source": epa.source},
        "n_usable": int(u.sum()),
        "correlation_all": corr_all,
        "correlation_traction": corr_tr,
        "lag_scan": lag_scan, "median_dt_s": med_dt, "best_lag": best_lag,
        "n_traction": int(tr.sum()),
        "per_trip": per_trip,
        "bands": bands,
        "braking": brake_info,
        "metrics": {e: _metrics_row(comp, e) for e in (epa.name, spec.name)},
        "drvpw": {"calibration_trip": cal_t, "test_trip": test_t, "terms": _coef_block(drv),
                  "r2_in_sample": res.r2, "n": res.n,
                  "test": {e: _metrics_row(comp_test, e) for e in comp_test.results}},
    }
    return summary, {"mask": test, "equations": [drv, epa, spec]}


# ------------------------------------------------------------------------------- JLU

def published_jlu_road_load(vehicle) -> dict:
    """Published dyno road load of jlu_bev.toml in SI: A [N], B [N/(m/s)], C [N/(m/s)²]."""
    rl = _toml_table(vehicle.path, "road_load")
    return {"A_n": float(rl["a_n"]), "B_n_per_mps": float(rl["b_n_per_kmh"]) / KMH,
            "C_n_per_mps2": float(rl["c_n_per_kmh2"]) / KMH ** 2}


def _ols(X, y):
    """OLS without intercept column (the design carries its own): β, standard errors."""
    beta, *_ = np.linalg.lstsq(X, y, rcond=None)
    resid = y - X @ beta
    dof = max(len(y) - X.shape[1], 1)
    s2 = float(resid @ resid) / dof
    cov = s2 * np.linalg.pinv(X.T @ X)
    return beta, np.sqrt(np.clip(np.diag(cov), 0, None))


def validate_jlu(ds: Dataset, out: Path, figures: list) -> tuple[dict, dict]:
    """Recover the dyno road load through a drivetrain efficiency; per-cycle errors."""
    import matplotlib.pyplot as plt

    from sumo_drvpw.fit.compare import metrics
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.fileio import write_figure
    from sumo_drvpw.model.terms import term_matrix

    x, meas, u = ds.inputs, ds.power_w, ds.usable
    m_kg = float(np.median(x.mass[u]))
    pub = published_jlu_road_load(ds.vehicle)
    names = ["v1", "v2", "v3", "acc", "one"]
    trac = u & (x.a >= 0) & (x.v > JLU_TRACTION_MIN_SPEED_MPS)
    X_all = term_matrix(names, x)
    b, se = _ols(X_all[trac], meas[trac])
    eta = 1.0 / b[3]
    # regeneration regime: where the traction model's own wheel power is negative
    wheel_model = X_all[:, :4] @ b[:4]
    regen = u & (wheel_model < 0)
    rec = {"A_n": b[0] * eta, "B_n_per_mps": b[1] * eta, "C_n_per_mps2": b[2] * eta,
           "eta": eta, "p_aux_w": b[4]}
    # implied efficiency with the published road load held fixed: P = (F_pub·v + m·a·v)/η + P_aux
    wheel_pub = (pub["A_n"] * x.v + pub["B_n_per_mps"] * x.v ** 2 + pub["C_n_per_mps2"] * x.v ** 3
                 + x.mass * x.v * x.a)
    b2, se2 = _ols(np.column_stack([wheel_pub[trac], np.ones(int(trac.sum()))]), meas[trac])
    fixed = {"eta": 1.0 / b2[0], "p_aux_w": b2[1], "eta_se": se2[0] / b2[0] ** 2}
    # regeneration: P_batt = η_r·(wheel power) + P_aux with the published road load
    b3, _ = _ols(np.column_stack([wheel_pub[regen], np.ones(int(regen.sum()))]), meas[regen])
    # free fit on regen samples as well (all five terms)
    b4, _ = _ols(X_all[regen], meas[regen])
    pred_trac = X_all @ b
    pred_regen = X_all @ b4
    two_regime = np.where(wheel_model >= 0, pred_trac, pred_regen)
    m_all = metrics(two_regime[u], meas[u])
    cyc = ds.log.df["cycle"].astype(str).to_numpy()
    dt = ds.dt
    per_cycle = []
    for c in sorted(set(cyc[u])):
        m = u & (cyc == c)
        mt = metrics(two_regime[m], meas[m])
        e_meas = float((meas[m] * dt[m]).sum())
        e_pred = float((two_regime[m] * dt[m]).sum())
        dist = float((x.v[m] * dt[m]).sum())
        per_cycle.append({
            "cycle": c, "tests": int(len(set(ds.trip[m]))), "n": int(m.sum()),
            "mean_speed_kmh": float(x.v[m].mean() / KMH), "max_speed_kmh": float(x.v[m].max() / KMH),
            "rms_accel_mps2": float(np.sqrt(np.mean(x.a[m] ** 2))),
            "mean_measured_w": float(meas[m].mean()), "rmse_w": mt["rmse_w"], "bias_w": mt["bias_w"],
            "r2": mt["r2"], "net_energy_ratio": e_pred / e_meas if e_meas > 0 else None,
            "measured_wh_per_km": e_meas / 3600.0 / (dist / 1000.0) if dist > 0 else None,
            "relative_rmse": mt["rmse_w"] / max(float(np.sqrt(np.mean(meas[m] ** 2))), 1.0)})
    # constant-speed tests: mean battery power against speed, one point per test
    cs = []
    for t in sorted(set(ds.trip[u])):
        m = u & (ds.trip == t)
        c = cyc[m][0]
        if not (c.startswith("CS_") or c.startswith("SPEED_")):
            continue
        steady = m & (np.abs(x.a) < 0.05) & (x.v > 1.0)
        if steady.sum() < 200:
            continue
        v_mean = float(x.v[steady].mean())
        f_pub = pub["A_n"] + pub["B_n_per_mps"] * v_mean + pub["C_n_per_mps2"] * v_mean ** 2
        cs.append({"test": t, "cycle": c, "speed_kmh": v_mean / KMH,
                   "battery_w": float(meas[steady].mean()), "published_wheel_w": f_pub * v_mean,
                   "implied_eta_incl_aux": f_pub * v_mean / float(meas[steady].mean())})
    by_cycle: dict[str, list[float]] = {}
    for c in cs:
        by_cycle.setdefault(c["cycle"], []).append(c["battery_w"])
    spread = {c: (max(v) - min(v)) / float(np.mean(v)) for c, v in by_cycle.items() if len(v) > 1}
    forces = []
    for kmh in FORCE_TABLE_KMH:
        v = kmh * KMH
        fp = pub["A_n"] + pub["B_n_per_mps"] * v + pub["C_n_per_mps2"] * v * v
        fr = rec["A_n"] + rec["B_n_per_mps"] * v + rec["C_n_per_mps2"] * v * v
        forces.append({"speed_kmh": kmh, "published_n": fp, "recovered_n": fr,
                       "ratio": fr / fp})
    eq = Equation(name="drvpw_jlu_traction", terms=dict(zip(names, map(float, b))),
                  std_err=dict(zip(names, map(float, se))), mass_kg=None,
                  description="battery power of the JLU car on traction samples: "
                              "(A·v + B·v² + C·v³ + m·a·v)/η + P_aux")
    pub_eq = Equation(name="jlu_published_road_load",
                      terms={"v1": pub["A_n"], "v2": pub["B_n_per_mps"], "v3": pub["C_n_per_mps2"],
                             "acc": 1.0},
                      description="published dyno road load at the wheel (no losses)")
    # figures: force curve, per-cycle bias
    vv = np.linspace(0, 135, 100) * KMH
    fig, ax = plt.subplots(1, 2, figsize=(11, 3.8))
    ax[0].plot(vv / KMH, pub["A_n"] + pub["B_n_per_mps"] * vv + pub["C_n_per_mps2"] * vv ** 2,
               "k-", label="published dyno road load")
    ax[0].plot(vv / KMH, rec["A_n"] + rec["B_n_per_mps"] * vv + rec["C_n_per_mps2"] * vv ** 2,
               "tab:blue", ls="--", label=f"recovered (η = {eta:.3f})")
    if cs:
        ax[0].plot([c["speed_kmh"] for c in cs],
                   [fixed["eta"] * (c["battery_w"] - fixed["p_aux_w"]) / (c["speed_kmh"] * KMH)
                    for c in cs], "o", color="tab:orange", ms=4,
                   label="constant-speed tests: η·(P_batt − P_aux)/v")
    ax[0].set_xlabel("speed [km/h]")
    ax[0].set_ylabel("road-load force [N]")
    ax[0].set_title("JLU dyno: published vs recovered road load", fontsize=9)
    ax[0].legend(fontsize=7)
    ax[0].grid(alpha=0.3)
    xs = np.arange(len(per_cycle))
    ax[1].bar(xs - 0.2, [r["bias_w"] * _KW for r in per_cycle], 0.4, label="bias")
    ax[1].bar(xs + 0.2, [r["rmse_w"] * _KW for r in per_cycle], 0.4, label="RMSE")
    ax[1].set_xticks(xs)
    ax[1].set_xticklabels([r["cycle"] for r in per_cycle], rotation=60, fontsize=7, ha="right")
    ax[1].set_ylabel("battery power error [kW]")
    ax[1].set_title("JLU: two-regime model, error per cycle", fontsize=9)
    ax[1].axhline(0, color="k", lw=0.6)
    ax[1].legend(fontsize=7)
    ax[1].grid(alpha=0.3)
    write_figure(out / "jlu_road_load.png", fig)
    figures.append("jlu_road_load.png")
    summary = {
        **_provenance(ds),
        "mass_kg": m_kg,
        "model": "traction (a ≥ 0, v > 2 m/s): P_batt = c1·v + c2·v² + c3·v³ + c_acc·m·v·a + P_aux, "
                 "η = 1/c_acc, A = c1·η, B = c2·η, C = c3·η",
        "n_traction": int(trac.sum()), "n_regen": int(regen.sum()),
        "traction_fit": {"coef": dict(zip(names, map(float, b))), "std_err": dict(zip(names, map(float, se)))},
        "published": {**pub, "B_n_per_kmh": pub["B_n_per_mps"] * KMH,
                      "C_n_per_kmh2": pub["C_n_per_mps2"] * KMH ** 2},
        "recovered": {**rec, "B_n_per_kmh": rec["B_n_per_mps"] * KMH,
                      "C_n_per_kmh2": rec["C_n_per_mps2"] * KMH ** 2,
                      "A_se_n": se[0] * eta, "B_se_n_per_kmh": se[1] * eta * KMH,
                      "C_se_n_per_kmh2": se[2] * eta * KMH ** 2},
        "forces": forces,
        "published_road_load_fixed": fixed,
        "regen_with_published_road_load": {"eta_regen": float(b3[0]), "p_aux_w": float(b3[1])},
        "two_regime_all": m_all,
        "per_cycle": per_cycle,
        "constant_speed": cs,
        "constant_speed_repeat_spread": spread,
    }
    return summary, {"mask": u, "equations": [eq, pub_eq]}


# ------------------------------------------------------------------ all equations

def all_equations_table(datasets: dict, extra: dict) -> dict:
    """Every built-in equation plus each data set's calibrated/physical ones, per data set."""
    from sumo_drvpw.model.equations import builtin_names, load_equation

    out = {}
    builtins = [load_equation(n) for n in builtin_names()]
    for key, ds in datasets.items():
        mask = extra[key]["mask"]
        eqs = list(extra[key]["equations"])
        names = {e.name for e in eqs}
        eqs += [e for e in builtins if e.name not in names]
        comp = _compare(ds, mask, eqs)
        out[key] = {"n": int(mask.sum()), "target": ds.source,
                    "mass_kg_mean": float(ds.inputs.mass[mask].mean()),
                    "equations": {e.name: {**_metrics_row(comp, e.name),
                                           "fixed_mass_kg": e.mass_kg,
                                           "builtin": e.name in builtin_names()}
                                  for e in eqs}}
    return out


# ---------------------------------------------------------------------------- driver

def run_validation(data: Path, out: Path, command: str = "") -> dict:
    """Run every section, write figures, ``summary.json`` and ``<out>.md``; return the summary."""
    from sumo_drvpw.fileio import write_json, write_text

    t0 = time.perf_counter()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    figures: list[str] = []
    datasets, extra, sections, timing = {}, {}, {}, {}
    for key, fn in (("bmw_i3_tum", validate_i3), ("prius_gen2_torquepro", validate_prius2),
                    ("jlu_bev_dyno", validate_jlu)):
        t = time.perf_counter()
        ds = load_dataset(data, key)
        sections[key], extra[key] = fn(ds, out, figures)
        datasets[key] = ds
        timing[key] = time.perf_counter() - t
    t = time.perf_counter()
    table = all_equations_table(datasets, extra)
    timing["all_equations"] = time.perf_counter() - t
    summary = {
        "run": {"command": command, "data": str(data), "seconds": None,
                "section_seconds": timing},
        "bmw_i3": sections["bmw_i3_tum"],
        "prius2": sections["prius_gen2_torquepro"],
        "jlu": sections["jlu_bev_dyno"],
        "all_equations": table,
        "figures": figures,
        "settings": {"heavy_load_w": HEAVY_LOAD_W, "error": "predicted - measured",
                     "r2": "centred 1 - SSE/SST; light/heavy each on its own mean",
                     "i3_rolling_coefficient_assumed": I3_ROLLING_COEFFICIENT_ASSUMED,
                     "jlu_traction": f"a >= 0 and v > {JLU_TRACTION_MIN_SPEED_MPS} m/s",
                     "jlu_regen": "traction model's wheel power (A·v + B·v² + C·v³ + m·a·v)/η < 0"},
    }
    summary["run"]["seconds"] = time.perf_counter() - t0
    from sumo_drvpw.fit.compare import _jsonable

    summary = _jsonable(summary)
    write_json(out / "summary.json", summary)
    write_text(report_path(out), render(summary, out))
    return summary


# -------------------------------------------------------------------------- Markdown

def _n(x, nd=2, scale=1.0):
    if x is None:
        return "–"
    f = float(x) * scale
    if not math.isfinite(f):
        return "–"
    s = f"{f:.{nd}f}"
    if s.startswith("-") and float(s) == 0.0:
        s = s[1:]
    return s.replace("-", "−")


def _metrics_table(rows: dict, cols=("r2", "r2_light", "r2_heavy", "rmse_w", "bias_w",
                                     "traction_energy_ratio", "n", "n_heavy")) -> list[str]:
    head = {"r2": "R²", "r2_light": "R² < 50 kW", "r2_heavy": "R² ≥ 50 kW", "rmse_w": "RMSE [kW]",
            "bias_w": "bias [kW]", "traction_energy_ratio": "traction energy pred/meas",
            "n": "n", "n_heavy": "n ≥ 50 kW"}
    lines = ["| equation | " + " | ".join(head[c] for c in cols) + " |",
             "|---|" + "---|" * len(cols)]
    for name, r in rows.items():
        cells = []
        for c in cols:
            v = r.get(c)
            if c in ("rmse_w", "bias_w"):
                cells.append(_n(v, 2, _KW))
            elif c in ("n", "n_heavy", "n_light"):
                cells.append("–" if v is None else str(int(v)))
            else:
                cells.append(_n(v, 3))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def render(s: dict, out: Path) -> str:
    """The Markdown report from the summary (every number from this run)."""
    rel = out.name
    i3, pr, jl = s["bmw_i3"], s["prius2"], s["jlu"]
    L = ["# Validation against measured data", "",
         "Generated by `sumo-drvpw validate`; every number below comes from that run "
         "(`" + f"{rel}/summary.json" + "` holds them all, machine-readable). Do not edit by hand.", "",
         f"- **Command**: `{s['run']['command']}`",
         f"- **Data folder**: `{s['run']['data']}` (read in place, see its README for provenance)",
         f"- **Runtime**: {s['run']['seconds']:.1f} s (sections: "
         + ", ".join(f"{k} {v:.1f} s" for k, v in s["run"]["section_seconds"].items()) + ")",
         "- Error = predicted − measured; R² is centred (1 − SSE/SST), light (< 50 kW) and "
         "heavy (≥ 50 kW measured) each on their own mean; “traction energy pred/meas” is the "
         "predicted over the measured energy of samples with positive power.",
         "- No subsampling: every usable sample at the logged rate (10 Hz i3, ≈1.4 Hz Prius, "
         "20 Hz dyno) is used; scatter figures draw at most 50 000 points.", ""]

    # --- i3
    sp = i3["split"]
    L += ["## BMW i3 (TUM, real driving)", "",
          f"Target: {i3['target']} — mechanical motor power τ·ω, motor speed from vehicle speed, "
          "gear 9.665 and wheel radius (bmw_i3.toml). "
          f"{i3['import']['files']} trips, {i3['read_counts']['rows']} samples; grade: "
          f"{i3['read_counts']['grade_source']}; acceleration: {i3['read_counts']['accel_source']}.", "",
          f"**Split by trip** ({sp['rule']}): {len(sp['calibration_trips'])} calibration trips "
          f"({sp['n_calibration']} samples), {len(sp['test_trips'])} test trips ({sp['n_test']} "
          f"samples). Test trips: {', '.join(sp['test_trips'])}.", ""]
    if i3["vsp_spec"]["note"]:
        L += [f"Note: {i3['vsp_spec']['note']}.", ""]
    L += ["Calibrated coefficients (this project's basis: `acc` = m·v·a, `grade` = m·g·v·sin θ, "
          "`aero` = v³ (still air), `roll` = m·g·v·cos θ …), ± standard error:", "",
          "| equation | selected terms (stepwise order) | coefficients | R² in sample |", "|---|---|---|---|"]
    for lab, c in i3["calibration"].items():
        coefs = "<br>".join(f"`{t}` {v['coef']:.4g} ± {v['std_err']:.2g}" for t, v in c["terms"].items())
        L.append(f"| {c['equation']} | {', '.join(c['selection'])} | {coefs} | {_n(c['r2_in_sample'], 3)} |")
    ms = i3["measured"]
    L += ["", f"**Held-out test trips** ({ms['n']} samples). The i3's motor power rarely exceeds "
          f"50 kW: {ms['n_heavy']} test samples are ≥ 50 kW (99th percentile "
          f"{_n(ms['p99_w'], 1, _KW)} kW, max {_n(ms['max_w'], 1, _KW)} kW), so R² ≥ 50 kW rests on "
          "few samples.", ""]
    L += _metrics_table(i3["test"])
    L += ["", "Per season (test trips only):", ""]
    for season, d in i3["per_season"].items():
        L += [f"*{season}* ({len(d['trips'])} trips, {d['n']} samples):", ""]
        L += _metrics_table(d["equations"], cols=("r2", "r2_light", "r2_heavy", "rmse_w", "bias_w",
                                                  "traction_energy_ratio", "n_heavy"))
        L.append("")
    # error vs speed table (20 km/h groups of the 10 km/h bins)
    L += _speed_table(i3["error_vs_speed"], "all test trips")
    for season, d in i3["per_season"].items():
        L += _speed_table(d["error_vs_speed"], f"{season} test trips")
    t = i3["test"]
    best = min(t, key=lambda k: t[k]["rmse_w"])
    L += ["", f"Reading: on held-out trips the lowest RMSE is **{best}** "
          f"({_n(t[best]['rmse_w'], 2, _KW)} kW); vsp_ldv1999 has RMSE "
          f"{_n(t['vsp_ldv1999']['rmse_w'], 2, _KW)} kW and bias {_n(t['vsp_ldv1999']['bias_w'], 2, _KW)} kW "
          "(generic light-duty-fleet coefficients, no drivetrain or rotating-mass term fitted to this car). "
          "The error-against-speed tables show where each equation drifts.", ""]
    ps = i3["per_season"]
    if {"summer", "winter"} <= set(ps):
        d1 = {k: ps[k]["equations"]["drvpw_i3_var1"] for k in ("summer", "winter")}
        L += [f"Seasons: one DrvPw is fitted to both seasons; on held-out trips its bias is "
              f"{_n(d1['summer']['bias_w'], 2, _KW)} kW in summer and {_n(d1['winter']['bias_w'], 2, _KW)} kW "
              f"in winter (traction energy pred/meas {_n(d1['summer']['traction_energy_ratio'], 3)} and "
              f"{_n(d1['winter']['traction_energy_ratio'], 3)}). τ·ω contains no heater or A/C power, so a "
              "seasonal gap means the road load itself differs (possible causes: cold tyres and "
              "drivetrain, denser air, winter tyres, wet roads); a season term (e.g. `[winter]*roll`) "
              "is the candidate to try.", "",
          f"![i3 parity]({rel}/i3_parity.png)", "", f"![i3 error against speed]({rel}/i3_error_speed.png)", ""]

    # --- Prius 2
    e = pr["epa_equation"]
    L += ["## Toyota Prius Gen-2 (phone OBD, real driving)", "",
          f"Target: {pr['target']} with prius2.toml gearing and inertias. "
          f"{pr['import']['files']} trips, {pr['read_counts']['rows']} samples "
          f"({pr['n_usable']} usable); grade: {pr['read_counts']['grade_source']}.", "",
          f"Reference: **{e['name']}**, the EPA Test Car List target road load "
          f"(F = {e['terms']['v1']:.2f} N + {e['terms']['v2']:.4f} N/(m/s)·v + "
          f"{e['terms']['v3']:.4f} N/(m/s)²·v²) plus m·a·v and m·g·v·sin θ with m = ETW "
          f"{e['mass_kg']:.0f} kg; source: {e['source']}.", "",
          f"- Correlation of P_PTdrv with the EPA road-load power: **r = {_n(pr['correlation_all'], 3)}** "
          f"on all usable samples, r = {_n(pr['correlation_traction'], 3)} on the {pr['n_traction']} "
          "samples where both are positive (traction).", "",
          "Energy per trip:", "",
          "| trip | duration [min] | distance [km] | Δ elevation [m] | traction measured [kWh] | traction EPA [kWh] | EPA / measured | net measured [kWh] | net EPA [kWh] |",
          "|---|---|---|---|---|---|---|---|---|"]
    for tname, d in pr["per_trip"].items():
        L.append(f"| {tname} | {_n(d['duration_s'] / 60, 1)} | {_n(d['distance_m'] / 1000, 2)} | "
                 f"{_n(d['elevation_change_m'], 0)} | {_n(d['measured_traction_j'], 3, _KWH)} | "
                 f"{_n(d['epa_traction_j'], 3, _KWH)} | {_n(d['traction_ratio_epa_over_measured'], 3)} | "
                 f"{_n(d['measured_net_j'], 3, _KWH)} | {_n(d['epa_net_j'], 3, _KWH)} |")
    L += ["", "Where they disagree (mean over usable samples; error = EPA − measured) [kW]:", ""]
    for key, title in (("speed_kmh", "speed band"), ("speed_kmh_traction", "speed band, traction samples only"),
                       ("accel_mps2", "acceleration band"), ("grade_pct", "grade band")):
        L += [f"*By {title}*:", "", "| band | n | time [min] | measured | EPA | mean error | RMSE |",
              "|---|---|---|---|---|---|---|"]
        for r in pr["bands"][key]:
            if not r["n"]:
                continue
            L.append(f"| {r['band']} | {r['n']} | {_n(r['time_s'] / 60, 1)} | "
                     f"{_n(r['mean_measured_w'], 2, _KW)} | {_n(r['mean_predicted_w'], 2, _KW)} | "
                     f"{_n(r['mean_error_w'], 2, _KW)} | {_n(r['rmse_w'], 2, _KW)} |")
        L.append("")
    br = pr["braking"]
    L += [f"Braking: in the {br['n']} samples where the road load is negative, the EPA equation "
          f"asks for {_n(br['epa_negative_j'], 3, _KWH)} kWh while P_PTdrv shows "
          f"{_n(br['measured_in_those_samples_j'], 3, _KWH)} kWh: the difference is friction braking "
          "(and coasting with the engine dragging), which P_PTdrv does not see — so compare the two on "
          "traction energy, not on net energy.", ""]
    L += _prius_reading(pr)
    d = pr["drvpw"]
    L += ["", f"DrvPw calibrated on trip {d['calibration_trip']} (Indt var. 1, n = {d['n']}, in-sample "
          f"R² {_n(d['r2_in_sample'], 3)}), tested on trip {d['test_trip']}:", ""]
    L += _metrics_table(d["test"])
    L += ["", f"![Prius parity]({rel}/prius2_parity.png)", "",
          f"![Prius error against speed]({rel}/prius2_error_speed.png)", "",
          f"![Prius bands]({rel}/prius2_bands.png)", ""]

    # --- JLU
    pub, rec, fx = jl["published"], jl["recovered"], jl["published_road_load_fixed"]
    L += ["## JLU chassis dynamometer (BEV, 46 tests)", "",
          f"Target: {jl['target']} (current sign per jlu_bev.toml); no grade on a dyno; mass "
          f"{jl['mass_kg']:.0f} kg. {jl['import']['files']} tests, {jl['read_counts']['rows']} samples.", "",
          f"**Model** — {jl['model']}. Fitted by OLS on {jl['n_traction']} traction samples "
          "(selected by the kinematics only, not by the measured power or the answer). The "
          "efficiency η lumps motor, inverter and gear losses as one constant; P_aux is the "
          "constant auxiliary draw. The rotating inertia of the car's own driven wheels and motor "
          "(not in the dyno's 1919 kg) adds to c_acc, so 1/c_acc reads η/(1 + ε) and A, B, C come "
          "out low by the same factor 1 + ε (a few per cent).", "",
          "| coefficient | published | recovered (± s.e.) | recovered / published |", "|---|---|---|---|",
          f"| A [N] | {pub['A_n']:.1f} | {rec['A_n']:.1f} ± {rec['A_se_n']:.1f} | {_n(rec['A_n'] / pub['A_n'], 3)} |",
          f"| B [N/(km/h)] | {pub['B_n_per_kmh']:.3f} | {rec['B_n_per_kmh']:.3f} ± {rec['B_se_n_per_kmh']:.3f} | {_n(rec['B_n_per_kmh'] / pub['B_n_per_kmh'], 3)} |",
          f"| C [N/(km/h)²] | {pub['C_n_per_kmh2']:.4f} | {rec['C_n_per_kmh2']:.4f} ± {rec['C_se_n_per_kmh2']:.4f} | {_n(rec['C_n_per_kmh2'] / pub['C_n_per_kmh2'], 3)} |",
          f"| η (battery → wheel) | – | {rec['eta']:.3f} | |",
          f"| P_aux [W] | – | {rec['p_aux_w']:.0f} | |", "",
          "The three coefficients trade off against each other (v, v², v³ are strongly "
          "collinear over 0–130 km/h); the force they add up to is what the data pin down:", "",
          "| speed [km/h] | published force [N] | recovered force [N] | ratio |", "|---|---|---|---|"]
    for f in jl["forces"]:
        L.append(f"| {f['speed_kmh']} | {f['published_n']:.0f} | {f['recovered_n']:.0f} | {_n(f['ratio'], 3)} |")
    rg = jl["regen_with_published_road_load"]
    L += ["", f"With the published road load held fixed, the implied traction efficiency is "
          f"**η = {fx['eta']:.3f}** (P_aux {fx['p_aux_w']:.0f} W); in regeneration (samples where the "
          f"traction model's wheel power is negative, {jl['n_regen']} samples) the battery receives "
          f"{rg['eta_regen']:.3f} of the published-road-load wheel power (friction-brake blending "
          "included).", ""]
    if jl["constant_speed"]:
        L += ["Constant-speed tests (steady samples, |a| < 0.05 m/s²): published wheel power over "
              "mean battery power (efficiency including auxiliaries):", "",
              "| test | speed [km/h] | battery [kW] | published wheel power [kW] | ratio |", "|---|---|---|---|---|"]
        for c in jl["constant_speed"]:
            L.append(f"| {c['test']} | {c['speed_kmh']:.1f} | {_n(c['battery_w'], 2, _KW)} | "
                     f"{_n(c['published_wheel_w'], 2, _KW)} | {_n(c['implied_eta_incl_aux'], 3)} |")
        L.append("")
    m2 = jl["two_regime_all"]
    L += [f"**Per cycle** — two-regime model (the traction fit where its wheel power is ≥ 0, a "
          "separate free fit of the same five terms on the samples where it is negative), in sample "
          f"on all tests: R² {_n(m2['r2'], 3)}, RMSE {_n(m2['rmse_w'], 2, _KW)} kW, bias "
          f"{_n(m2['bias_w'], 2, _KW)} kW.", "",
          "| cycle | tests | mean / max speed [km/h] | RMS accel [m/s²] | measured [Wh/km] | RMSE [kW] | bias [kW] | RMSE / RMS power | net energy pred/meas |",
          "|---|---|---|---|---|---|---|---|---|"]
    for r in sorted(jl["per_cycle"], key=lambda r: -r["relative_rmse"]):
        L.append(f"| {r['cycle']} | {r['tests']} | {r['mean_speed_kmh']:.0f} / {r['max_speed_kmh']:.0f} | "
                 f"{_n(r['rms_accel_mps2'], 2)} | {_n(r['measured_wh_per_km'], 0)} | {_n(r['rmse_w'], 2, _KW)} | "
                 f"{_n(r['bias_w'], 2, _KW)} | {_n(r['relative_rmse'], 3)} | {_n(r['net_energy_ratio'], 3)} |")
    L += [""] + _jlu_reading(jl) + ["", f"![JLU road load]({rel}/jlu_road_load.png)", ""]

    # --- all equations
    L += ["## Every equation on every data set", "",
          "Built-in equations were calibrated or defined for other cars (Prius Gen-3, a MOVES "
          "passenger car, the VSP fleet average): on the i3 and the dyno car they are "
          "**cross-vehicle tests**, not validations. Equations without a fixed mass use each "
          "data set's mass (vehicle file, plus added load per i3 trip); `epa_prius3`, "
          "`moves_passenger_car` and `epa_prius2` carry their own fixed mass (ETW / source mass). "
          "On the dyno the target is battery power (losses and auxiliaries included), which no "
          "wheel-power equation contains. Evaluated on: i3 — the held-out test trips; Prius — "
          "the test trip; JLU — all tests (the calibrated dyno model is in sample).", ""]
    for key, d in s["all_equations"].items():
        L += [f"### {key} ({d['n']} samples, target {d['target']}, mean mass {d['mass_kg_mean']:.0f} kg)", ""]
        L += _metrics_table(d["equations"])
        L.append("")
    return "\n".join(L) + "\n"


def _speed_table(evs: dict, what: str) -> list[str]:
    """Mean error per 10 km/h speed bin, one column per equation [kW]."""
    names = list(evs)
    bins = evs[names[0]]
    out = [f"Mean error against speed, {what} [kW] (cf. paper Fig. 8):", "",
           "| speed [km/h] | n | " + " | ".join(names) + " |", "|---|---|" + "---|" * len(names)]
    for k, b in enumerate(bins):
        if b["n"]:
            out.append(f"| {b['lo_kmh']:.0f}–{b['hi_kmh']:.0f} | {b['n']} | "
                       + " | ".join(_n(evs[nm][k]["mean_w"], 2, _KW) for nm in names) + " |")
    return out + [""]


def _prius_reading(pr: dict) -> list[str]:
    """Plain-language reading of the Prius bands, chosen from the computed numbers."""
    out = []
    worst = _worst_band(pr["bands"]["speed_kmh_traction"])
    if worst:
        verb = "over" if worst["mean_error_w"] > 0 else "under"
        out.append(f"- In traction the largest mean gap is at {worst['band']}: the EPA road load "
                   f"{verb}states P_PTdrv by {_n(abs(worst['mean_error_w']), 2, _KW)} kW on average "
                   f"(measured {_n(worst['mean_measured_w'], 2, _KW)} kW).")
    worst = _worst_band(pr["bands"]["accel_mps2"])
    if worst:
        out.append(f"- By acceleration the largest gap is at {worst['band']} "
                   f"(mean error {_n(worst['mean_error_w'], 2, _KW)} kW): hard braking is friction "
                   "braking outside P_PTdrv; hard acceleration errors mix the mass (ETW vs the real car), "
                   "the ≈1.4 Hz OBD timing and the acceleration derived from OBD speed.")
    worst = _worst_band(pr["bands"]["grade_pct"])
    if worst:
        out.append(f"- By grade the largest gap is at {worst['band']} (mean error "
                   f"{_n(worst['mean_error_w'], 2, _KW)} kW): grade comes from GPS altitude smoothed "
                   "over 100 m, so steep short sections are blurred, and downhill the road load asks "
                   "for negative power that the car partly takes by friction brakes.")
    bl = pr["best_lag"]
    zero = next(r for r in pr["lag_scan"] if r["lag_samples"] == 0)
    if bl["lag_samples"] != 0:
        out.append(f"- Timing: the correlation rises from {_n(zero['r'], 3)} to {_n(bl['r'], 3)} when "
                   f"P_PTdrv at sample i is paired with the road load at sample i {'+' if bl['lag_samples'] > 0 else '−'} "
                   f"{abs(bl['lag_samples'])} (≈ {_n(abs(bl['lag_samples']) * pr['median_dt_s'], 1)} s at "
                   f"the median {_n(pr['median_dt_s'], 2)} s step): the OBD speed, and so the derived "
                   "acceleration, lags the MG1/MG2 signals. This is why mild deceleration shows measured "
                   "power well above the road load and mild acceleration below it.")
    trips = list(pr["per_trip"].values())
    if trips:
        rs = [t["traction_ratio_epa_over_measured"] for t in trips]
        out.append(f"- Traction energy EPA/measured per trip: {', '.join(_n(r, 3) for r in rs)}.")
    return out


def _jlu_reading(jl: dict) -> list[str]:
    """Plain-language reading of the per-cycle table, chosen from the computed numbers."""
    rows = sorted(jl["per_cycle"], key=lambda r: -r["relative_rmse"])
    spread = jl.get("constant_speed_repeat_spread", {})
    out = ["Reading (the three cycles with the largest RMSE relative to their RMS power):"]
    for r in rows[:3]:
        why = []
        if r["rms_accel_mps2"] < 0.25:
            sign = "more" if r["bias_w"] < 0 else "less"
            why.append(f"a steady cruise: the battery draws {sign} than a constant η plus a constant "
                       "P_aux predict at this part load (losses that do not scale with wheel power, "
                       "e.g. motor iron and inverter switching losses, and auxiliaries)")
            if r["cycle"] in spread:
                why.append(f"repeats of this test differ by {_n(100 * spread[r['cycle']], 1)} % in "
                           "steady battery power (test-day conditions: auxiliaries, battery "
                           "temperature), which no road-load model can explain")
        if r["rms_accel_mps2"] > 0.5:
            why.append("frequent hard accelerations and decelerations, where a constant η and the "
                       "acceleration derived from the roller speed fit worst and regeneration is "
                       "blended with friction braking")
        if r["mean_speed_kmh"] < 35 and r["rms_accel_mps2"] >= 0.25:
            why.append("low speed, so the constant auxiliary draw and low-load inverter losses "
                       "dominate a small measured power")
        if not why:
            why.append("no single cause stands out in speed or acceleration")
        out.append(f"- **{r['cycle']}**: RMSE {_n(r['rmse_w'], 2, _KW)} kW, bias "
                   f"{_n(r['bias_w'], 2, _KW)} kW, net energy pred/meas {_n(r['net_energy_ratio'], 3)} "
                   f"(mean speed {r['mean_speed_kmh']:.0f} km/h, RMS acceleration "
                   f"{_n(r['rms_accel_mps2'], 2)} m/s²): " + "; ".join(why) + ".")
    steady = [r for r in jl["per_cycle"] if r["rms_accel_mps2"] < 0.25]
    dyn = [r for r in jl["per_cycle"] if r["rms_accel_mps2"] >= 0.25]
    if steady and dyn:
        bs, bd = (float(np.mean([r["bias_w"] for r in steady])),
                  float(np.mean([r["bias_w"] for r in dyn])))
        verdict = ("one constant efficiency serves both within a few hundred watts"
                   if abs(bs - bd) < 300.0 else
                   "one constant efficiency does not serve both")
        out.append(f"- Mean bias of the steady (constant-speed) tests: {_n(bs, 2, _KW)} kW; of the "
                   f"driving cycles: {_n(bd, 2, _KW)} kW: {verdict}.")
    return out
