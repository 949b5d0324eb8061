"""JLU chassis dynamometer (BEV, 46 tests, target battery power V·I): the road load
recovered through a constant drivetrain efficiency.

Traction samples (a ≥ 0, v > 2 m/s: chosen by the kinematics only, never by the
answer) are fitted by OLS (:mod:`sumo_drvpw.fit.ols`)

    P_batt = (A·v + B·v² + C·v³ + m·a·v)/η + P_aux = c1·v + c2·v² + c3·v³ + c_acc·m·v·a + P_aux,

so η = 1/c_acc, A = c1·η, B = c2·η, C = c3·η, against the published dyno road load
(jlu_bev.toml [road_load], F = A + B·v + C·v² with B, C per km/h in the file). Where that
model's wheel power is negative (regeneration) the same five terms get a separate free fit
(the two-regime model of the per-cycle table).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from sumo_drvpw.fit.ols import ols
from sumo_drvpw.model.constants import KMH
from sumo_drvpw.validation.data import Dataset, StudyResult, vehicle_table

#: data-set folder read by this study
DATASET = "jlu_bev_dyno"
#: Traction samples: acceleration ≥ 0 and speed above this [m/s].
TRACTION_MIN_SPEED_MPS = 2.0
#: Speeds at which recovered and published road-load forces are tabulated [km/h].
FORCE_TABLE_KMH = (20, 50, 80, 110, 130)
#: Steady samples of a constant-speed test: |a| below [m/s²], v above [m/s], at least n.
STEADY_MAX_ACCEL_MPS2 = 0.05
STEADY_MIN_SPEED_MPS = 1.0
STEADY_MIN_SAMPLES = 200
#: Cycle-name prefixes of the constant-speed tests.
CONSTANT_SPEED_PREFIXES = ("CS_", "SPEED_")
#: The five columns of the battery-power model, in the term grammar (one = P_aux).
TERMS = ("v1", "v2", "v3", "acc", "one")


def published_road_load(vehicle) -> dict:
    """Published dyno road load of the vehicle file in SI: ``A_n`` [N], ``B_n_per_mps``
    [N/(m/s)], ``C_n_per_mps2`` [N/(m/s)²] (the file gives B, C per km/h)."""
    rl = vehicle_table(vehicle, "road_load")
    return {"A_n": float(rl["a_n"]), "B_n_per_mps": float(rl["b_n_per_kmh"]) / KMH,
            "C_n_per_mps2": float(rl["c_n_per_kmh2"]) / KMH ** 2}


def road_load_force(c: dict, v):
    """F = A + B·v + C·v² [N] of a road load ``c`` (keys as :func:`published_road_load`)
    at speed ``v`` [m/s]."""
    return c["A_n"] + c["B_n_per_mps"] * v + c["C_n_per_mps2"] * v * v


def _per_cycle(ds: Dataset, pred, cycle) -> list[dict]:
    """Speed, acceleration, energy and error statistics of the model ``pred`` per cycle."""
    from sumo_drvpw.fit.compare import metrics

    x, meas, u, dt = ds.inputs, ds.power_w, ds.usable, ds.dt
    rows = []
    for c in sorted(set(cycle[u])):
        m = u & (cycle == c)
        mt = metrics(pred[m], meas[m])
        e_meas = float((meas[m] * dt[m]).sum())
        e_pred = float((pred[m] * dt[m]).sum())
        dist = float((x.v[m] * dt[m]).sum())
        rows.append({
            "cycle": c, "tests": int(len(set(ds.trip[m]))), "n": int(m.sum()),
            "mean_speed_kmh": float(x.v[m].mean() / KMH), "max_speed_kmh": float(x.v[m].max() / KMH),
            "rms_accel_mps2": float(np.sqrt(np.mean(x.a[m] ** 2))),
            "mean_measured_w": float(meas[m].mean()), "rmse_w": mt["rmse_w"], "bias_w": mt["bias_w"],
            "r2": mt["r2"], "net_energy_ratio": e_pred / e_meas if e_meas > 0 else None,
            "measured_wh_per_km": e_meas / 3600.0 / (dist / 1000.0) if dist > 0 else None,
            "relative_rmse": mt["rmse_w"] / max(float(np.sqrt(np.mean(meas[m] ** 2))), 1.0)})
    return rows


def _constant_speed(ds: Dataset, pub: dict, cycle) -> list[dict]:
    """Mean battery power of the steady samples of each constant-speed test, with the
    published wheel power at that speed and their ratio (efficiency incl. auxiliaries)."""
    x, meas, u = ds.inputs, ds.power_w, ds.usable
    out = []
    for t in sorted(set(ds.trip[u])):
        m = u & (ds.trip == t)
        c = cycle[m][0]
        if not c.startswith(CONSTANT_SPEED_PREFIXES):
            continue
        steady = m & (np.abs(x.a) < STEADY_MAX_ACCEL_MPS2) & (x.v > STEADY_MIN_SPEED_MPS)
        if steady.sum() < STEADY_MIN_SAMPLES:
            continue
        v_mean = float(x.v[steady].mean())
        wheel = road_load_force(pub, v_mean) * v_mean
        battery = float(meas[steady].mean())
        out.append({"test": t, "cycle": c, "speed_kmh": v_mean / KMH, "battery_w": battery,
                    "published_wheel_w": wheel, "implied_eta_incl_aux": wheel / battery})
    return out


def study(ds: Dataset, out: Path) -> StudyResult:
    """Recover the dyno road load through a drivetrain efficiency; per-cycle errors."""
    from sumo_drvpw.fit.compare import metrics
    from sumo_drvpw.model.equations import Equation
    from sumo_drvpw.model.terms import term_matrix
    from sumo_drvpw.report import figures as plots

    x, meas, u = ds.inputs, ds.power_w, ds.usable
    pub = published_road_load(ds.vehicle)
    trac = u & (x.a >= 0) & (x.v > TRACTION_MIN_SPEED_MPS)
    X_all = term_matrix(TERMS, x)
    fit = ols(X_all[trac], meas[trac], TERMS)
    b, se = fit.beta, fit.se
    eta = 1.0 / b[3]
    # regeneration regime: where the traction model's own wheel power is negative
    wheel_model = X_all[:, :4] @ b[:4]
    regen = u & (wheel_model < 0)
    rec = {"A_n": b[0] * eta, "B_n_per_mps": b[1] * eta, "C_n_per_mps2": b[2] * eta,
           "eta": eta, "p_aux_w": b[4]}
    pub_eq = Equation(name="jlu_published_road_load",
                      terms={"v1": pub["A_n"], "v2": pub["B_n_per_mps"], "v3": pub["C_n_per_mps2"],
                             "acc": 1.0},
                      description="published dyno road load at the wheel (no losses)")
    # implied efficiency with the published road load held fixed: P = (F_pub·v + m·a·v)/η + P_aux
    wheel_pub = pub_eq.power(x)
    fixed_fit = ols(np.column_stack([wheel_pub[trac], np.ones(int(trac.sum()))]), meas[trac],
                    ("wheel", "one"))
    b2, se2 = fixed_fit.beta, fixed_fit.se
    fixed = {"eta": 1.0 / b2[0], "p_aux_w": b2[1], "eta_se": se2[0] / b2[0] ** 2}
    # regeneration: P_batt = η_r·(wheel power) + P_aux with the published road load
    b3 = ols(np.column_stack([wheel_pub[regen], np.ones(int(regen.sum()))]), meas[regen],
             ("wheel", "one")).beta
    # free fit on regen samples as well (all five terms)
    b4 = ols(X_all[regen], meas[regen], TERMS).beta
    two_regime = np.where(wheel_model >= 0, X_all @ b, X_all @ b4)
    cycle = ds.log.df["cycle"].astype(str).to_numpy()
    per_cycle = _per_cycle(ds, two_regime, cycle)
    cs = _constant_speed(ds, pub, cycle)
    by_cycle: dict[str, list[float]] = {}
    for c in cs:
        by_cycle.setdefault(c["cycle"], []).append(c["battery_w"])
    spread = {c: (max(v) - min(v)) / float(np.mean(v)) for c, v in by_cycle.items() if len(v) > 1}
    forces = []
    for kmh in FORCE_TABLE_KMH:
        fp, fr = road_load_force(pub, kmh * KMH), road_load_force(rec, kmh * KMH)
        forces.append({"speed_kmh": kmh, "published_n": fp, "recovered_n": fr, "ratio": fr / fp})
    eq = Equation(name="drvpw_jlu_traction", terms=fit.params, std_err=fit.std_err, mass_kg=None,
                  description="battery power of the JLU car on traction samples: "
                              "(A·v + B·v² + C·v³ + m·a·v)/η + P_aux")
    points = [{"speed_kmh": c["speed_kmh"],
               "force_n": fixed["eta"] * (c["battery_w"] - fixed["p_aux_w"]) / (c["speed_kmh"] * KMH)}
              for c in cs]
    plots.road_load_and_cycle_errors(pub, rec, eta, points, per_cycle, out / "jlu_road_load.png")
    summary = {
        **ds.provenance(),
        "vehicle": {"file": Path(ds.vehicle.path).name},
        "mass_kg": float(np.median(x.mass[u])),
        "model": "traction (a ≥ 0, v > 2 m/s): P_batt = c1·v + c2·v² + c3·v³ + c_acc·m·v·a + P_aux, "
                 "η = 1/c_acc, A = c1·η, B = c2·η, C = c3·η",
        "n_traction": int(trac.sum()), "n_regen": int(regen.sum()),
        "traction_fit": {"coef": fit.params, "std_err": fit.std_err},
        "published": {**pub, "B_n_per_kmh": pub["B_n_per_mps"] * KMH,
                      "C_n_per_kmh2": pub["C_n_per_mps2"] * KMH ** 2},
        "recovered": {**rec, "B_n_per_kmh": rec["B_n_per_mps"] * KMH,
                      "C_n_per_kmh2": rec["C_n_per_mps2"] * KMH ** 2,
                      "A_se_n": se[0] * eta, "B_se_n_per_kmh": se[1] * eta * KMH,
                      "C_se_n_per_kmh2": se[2] * eta * KMH ** 2},
        "forces": forces,
        "published_road_load_fixed": fixed,
        "regen_with_published_road_load": {"eta_regen": float(b3[0]), "p_aux_w": float(b3[1])},
        "two_regime_all": metrics(two_regime[u], meas[u]),
        "per_cycle": per_cycle,
        "constant_speed": cs,
        "steady_max_accel_mps2": STEADY_MAX_ACCEL_MPS2,
        "constant_speed_repeat_spread": spread,
    }
    return StudyResult(summary, u, [eq, pub_eq], ["jlu_road_load.png"],
                       settings={"jlu_traction": f"a >= 0 and v > {TRACTION_MIN_SPEED_MPS} m/s",
                                 "jlu_regen": "traction model's wheel power "
                                              "(A·v + B·v² + C·v³ + m·a·v)/η < 0"})
