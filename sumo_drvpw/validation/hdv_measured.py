"""What explains the per-trip error of ``moves_combination_truck_diesel`` on two measured class-8 trucks.

Run by ``scripts/hdv_measured.py`` (docs/hdv-fuel.md, 'Measured'): UC Riverside's PEMS logs of
two 1997–2001 tractors with the MERL trailer (github.com/Torreskai0722/FEAD,
``VT-Dataset/veh002_all.csv``, ``veh003_all.csv``: 1 Hz, speed in mph, the ECU's fuel rate
in g/s, engine speed, elevation, the PEMS's CO₂, CO, HC in g/s, test phase; no licence stated:
read where they lie, nothing of them is kept). The logs are imported as the report's commands
do (:data:`MAPPING`, :data:`VEHICLE`, 28,000 kg), the built-in books each trip, and each
hypothesis for its per-trip error is scored on trips it was not fitted on:

* the fuel signal: the ECU's fuel rate against the fuel the PEMS's exhaust carbon balance
  gives (:func:`carbon_balance_gps`), and the lag between fuel and driving power;
* the mass: per trip, the mass at which the chain books what the trip burnt
  (:func:`implied_mass_t`) — one truck and trailer cannot change mass between phases —, and
  one mass fitted on one truck, scored on the other;
* the grade: the elevation smoothed over 30, 300, 1000 m instead of 100 m, and no grade;
* the chain's form, from published engine physics and **not fitted** (every trip is held
  out): the zero-output fuel of a 12.7-L diesel at the logged engine speed (:data:`S60_RPM`,
  :data:`S60_ZERO_OUTPUT_W`), the rated output's cap (:data:`S60_MAX_W`), the rotating inertia
  of engine and wheels at the logged gear (:func:`rotating_mass_factor`) and the air's
  density at the logged height.

The engine speed is logged on these trucks, not in SUMO: a form that needs it says what
physics is missing, it is not a chain a SUMO run can book.
"""

from __future__ import annotations

import dataclasses
import tempfile
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import FUELS, KELVIN, P_STD_KPA, R_DRY_AIR, RHO_DEFAULT, RPM, STANDSTILL_MPS, T_REF_C

EQUATION = "moves_combination_truck_diesel"
FILES = ("veh002_all.csv", "veh003_all.csv")
#: the column mapping of docs/hdv-fuel.md (``sumo-drvpw import columns … --columns``)
MAPPING = """[options]
time_step_s = 1
trip_gap_s = 60
[columns."vel (mph)"]
name = "speed_mps"
unit = "mph"
[columns."elevation (m)"]
name = "elevation_m"
unit = "m"
[columns."fuel (g/s)"]
name = "fuel_rate_gps"
unit = "g/s"
[columns."phase_num"]
name = "trip_id"
"""
#: tractor 7.6 t + MERL trailer 20.4 t (ESTIMATE, docs/hdv-fuel.md)
MASS_KG = 28000.0
VEHICLE = f"""[vehicle]
name = "vt_truck"
mass_kg = {MASS_KG:.0f}
[powertrain]
type = "direct"
fuel = "diesel"
displacement_l = 12.7
"""
#: trips that burnt less are left out of the per-trip errors [L]
MIN_TRIP_L = 0.1
#: a trip's |error| that moves by less is neither helped nor hurt [percentage points]
CHANGE_PP = 1.0
#: block lengths the moving engine's line is fitted on [s] (:func:`block_line`)
BLOCKS_S = (1, 10, 30, 60)
#: the masses the implied mass is searched on [kg]
MASS_GRID_KG = np.arange(2000.0, 120001.0, 500.0)
#: Detroit Diesel Series 60 12.7 L (docs/sources.md [DDC-S60]): the zero-output intercept of
#: its fuel map's Willans line per engine speed [rpm → W of fuel]; below 1,200 rpm the idle's
S60_RPM = np.array([1200.0, 1400.0, 1600.0, 1800.0])
S60_ZERO_OUTPUT_W = np.array([16.6e3, 28.3e3, 39.8e3, 53.1e3])
#: its rated output [W] (docs/sources.md [DDC-S60])
S60_MAX_W = 332e3
#: rolling radius of a tractor-trailer's drive tyre (275/80R22.5) [m]: ADVISOR's
#: WH_TractorTrailer_midRR.m ([ADVISOR], hdv_fuel.SOURCES); the trucks' own tyres are not stated
TYRE_RADIUS_M = 0.501
#: the rotating inertia of a 12.7-L diesel's engine [kg·m²]: ADVISOR's FC_CI330.m (the S60) —
#: its mass (4.2 kg per kW of its 332 kW) × (1/3 + 2/9) × (0.075 m)², the Bosch handbook's
#: correlation as the file writes it
ENGINE_INERTIA_KGM2 = 4.2 * S60_MAX_W / 1e3 * (1.0 / 3.0 + 2.0 / 9.0) * 0.075**2
#: the 18 wheels and tyres of a tractor-trailer [kg·m²]: ADVISOR's 80 kg per tyre and wheel
#: (WH_TractorTrailer_midRR.m, after SAE 2000-01-3432) as solid cylinders of the tyre's radius.
#: ESTIMATE: axles, brake drums and the gearbox are left out
WHEELS_INERTIA_KGM2 = 18 * 80.0 * TYRE_RADIUS_M**2 / 2.0
#: a class-8 truck's 10-speed gearbox's efficiency: ADVISOR's TX_RTLO12610B.m (Eaton Fuller
#: RTLO-12610B, 0.92 in every gear; its final drive's loss unknown, left 0) [ADVISOR]
ADVISOR_GEARBOX = 0.92
#: [GILLESPIE] (hdv_fuel.SOURCES), Fundamentals of Vehicle Dynamics (SAE 1992): a passenger car's
#: mass factor, 1 + 0.04 + 0.0025·N² at overall gear ratio N (engine to wheel) — used here only
#: as the contrast to a truck's own inertias
GILLESPIE = (1.04, 0.0025)
#: the standard atmosphere's pressure at height h: P_STD·(1 − ISA_LAPSE·h)^ISA_EXPONENT ([ISA], hdv_fuel.SOURCES)
ISA_LAPSE, ISA_EXPONENT = 2.25577e-5, 5.25588
#: CO's carbon as CO₂ [kg CO₂ per kg CO]: molar masses 44.0095 and 28.0101 g/mol
CO_AS_CO2 = 44.0095 / 28.0101


def read_trucks(folder, grade_window_m: float = 100.0, flat_road: bool = False):
    """The two FEAD logs of ``folder`` imported with :data:`MAPPING` and read with
    :data:`VEHICLE` (a :class:`~sumo_drvpw.data.log.DriveLog`); UserError naming a file absent."""
    from sumo_drvpw.data.adapters import read
    from sumo_drvpw.data.log import ReadOptions, read_log

    paths = [Path(folder) / f for f in FILES]
    missing = [str(p) for p in paths if not p.is_file()]
    if missing:
        raise UserError(f"{missing[0]}: not found (the FEAD repository's VT-Dataset folder holds {', '.join(FILES)})")
    with tempfile.TemporaryDirectory() as td:
        (Path(td) / "map.toml").write_text(MAPPING, encoding="utf-8")
        (Path(td) / "veh.toml").write_text(VEHICLE, encoding="utf-8")
        df, _ = read("columns", [str(p) for p in paths], columns=str(Path(td) / "map.toml"))
        df.to_parquet(Path(td) / "vt.parquet", index=False)
        return read_log([Path(td) / "vt.parquet"], Path(td) / "veh.toml",
                        ReadOptions(grade_window_m=grade_window_m, flat_road=flat_road))


def carbon_balance_gps(co2_gps, co_gps, hc_gps, fuel: str = "diesel") -> np.ndarray:
    """Fuel [g/s] from the exhaust's carbon: CO₂ and CO's carbon as CO₂ over the fuel's kg CO₂ per
    kg (``FUELS``), the unburnt hydrocarbons as fuel (their carbon share taken as the fuel's)."""
    co2 = np.asarray(co2_gps, float) + CO_AS_CO2 * np.asarray(co_gps, float)
    return co2 / FUELS[fuel]["co2_kg_per_kg"] + np.asarray(hc_gps, float)


def mass_factor(n, v_mps, mass_kg: float, engine_kgm2: float = ENGINE_INERTIA_KGM2,
                wheels_kgm2: float = WHEELS_INERTIA_KGM2, radius_m: float = TYRE_RADIUS_M) -> np.ndarray:
    """The rotating parts' mass factor at overall gear ratio ``n``: 1 + (I_wheels + I_engine·n²)/(m·r²)
    (their kinetic energy ½·I·ω² over the vehicle's ½·m·v²); 1 where the truck stands or creeps
    (v < 2 m/s: the clutch slips)."""
    v = np.asarray(v_mps, float)
    extra = (wheels_kgm2 + engine_kgm2 * np.asarray(n, float) ** 2) / (float(mass_kg) * radius_m**2)
    return np.where(v >= 2.0, 1.0 + extra, 1.0)


def gear_ratio(rpm, v_mps, radius_m: float = TYRE_RADIUS_M) -> np.ndarray:
    """Overall ratio engine ÷ wheel speed from the logged engine and road speeds (0 below 2 m/s)."""
    v = np.asarray(v_mps, float)
    return np.where(v >= 2.0, np.asarray(rpm, float) * RPM * radius_m / np.maximum(v, 2.0), 0.0)


def rotating_mass_factor(rpm, v_mps, mass_kg: float = MASS_KG, car: bool = False) -> np.ndarray:
    """The mass factor at the gear the logged engine and road speeds give: the truck's own
    inertias (:data:`ENGINE_INERTIA_KGM2`, :data:`WHEELS_INERTIA_KGM2`), or with ``car``
    Gillespie's passenger-car shares (0.04 and 0.0025 of m·r²)."""
    n = gear_ratio(rpm, v_mps)
    if car:
        r2 = float(mass_kg) * TYRE_RADIUS_M**2
        return mass_factor(n, v_mps, mass_kg, GILLESPIE[1] * r2, (GILLESPIE[0] - 1.0) * r2)
    return mass_factor(n, v_mps, mass_kg)


def speed_gear_factor(v_mps, engine_rpm: float, top: float, first: float, mass_kg: float = MASS_KG) -> np.ndarray:
    """The truck's mass factor from the road speed alone (what a SUMO run has): the driver keeps
    the engine near ``engine_rpm`` by shifting, between the ``first`` and ``top`` gears' overall
    ratios; 1 below 2 m/s."""
    v = np.asarray(v_mps, float)
    n = np.clip(engine_rpm * RPM * TYRE_RADIUS_M / np.maximum(v, 2.0), top, first)
    return mass_factor(n, v, mass_kg)


def s60_zero_output_w(rpm, idle_w: float) -> np.ndarray:
    """The S60 map's zero-output fuel at ``rpm`` [W], never below the idle's ``idle_w``."""
    return np.maximum(np.interp(np.asarray(rpm, float), S60_RPM, S60_ZERO_OUTPUT_W), idle_w)


def booked_l(eq, x, dt, chain=None, rpm=None, factor=None, rho=None, smooth=None) -> np.ndarray:
    """Litres per sample the equation's chain (or ``chain``) books on inputs ``x``; with
    ``factor`` the acceleration term times the rotating-mass factor, with ``rpm`` the moving
    fuelled engine's zero-output fuel the S60's at that speed, with ``rho`` [kg/m³] the
    equation's drag term (``v3``, a coefficient at RHO_DEFAULT) at that air density, with
    ``smooth`` = (samples, trip per sample) the driving power averaged over that many samples
    (centred, within each trip) before the chain cuts the fuel below 0."""
    ch = chain or eq.chain
    p = eq.power(x)
    if factor is not None:
        p = p + (factor - 1.0) * x.mass * x.v * x.a
    if rho is not None:
        p = p + (np.asarray(rho, float) / RHO_DEFAULT - 1.0) * eq.terms.get("v3", 0.0) * x.v**3
    if smooth is not None:
        p = pd.Series(p).groupby(np.asarray(smooth[1])).transform(
            lambda q: q.rolling(smooth[0], center=True, min_periods=1).mean()).to_numpy()
    r = ch.evaluate(p, x.v, dt_s=dt)
    litres = r["fuel_l"]
    if rpm is not None:
        moving = ch.engine_on(p, x.v) & (x.v > STANDSTILL_MPS)
        more = np.where(moving, s60_zero_output_w(rpm, ch.idle_fuel_power_w) - ch.idle_fuel_power_w, 0.0)
        litres = litres + more * dt / ch.fuel_props["lhv_j_per_kg"] / ch.fuel_props["density_kg_per_l"]
    return litres


def at_mass(x, mass_kg):
    """Inputs ``x`` at one mass [kg] (the log's vehicle mass replaced)."""
    return dataclasses.replace(x, mass=np.full(len(x.v), float(mass_kg)))


def implied_mass_t(eq, x, dt, trips, measured_l: pd.Series) -> pd.Series:
    """Per trip of ``measured_l``, the mass [t] at which the chain books what it burnt
    (interpolated on :data:`MASS_GRID_KG`); NaN where even the lightest books more, inf where
    the heaviest books less."""
    grid = np.array([pd.Series(booked_l(eq, at_mass(x, m), dt)).groupby(trips).sum()[measured_l.index]
                     for m in MASS_GRID_KG])
    out = {}
    for j, t in enumerate(measured_l.index):
        y, m = grid[:, j], measured_l[t]
        out[t] = (np.nan if m < y[0] else np.inf) if not y[0] <= m <= y[-1] else np.interp(m, y, MASS_GRID_KG) / 1e3
    return pd.Series(out)


def _score(name: str, litres, base, measured: pd.Series, trips, truck: pd.Series, kmh: pd.Series,
           fitted_on=None) -> dict:
    """A hypothesis's per-trip errors against the built-in's (``base`` [%]): mean |error| per
    truck and all, the trips whose |error| fell (``helped``) or rose (``hurt``) by more than
    :data:`CHANGE_PP` points, the mean signed error of the slow (10–45 km/h) and fast
    (> 45 km/h mean) trips, the total's error."""
    got = pd.Series(litres).groupby(trips).sum()[measured.index]
    err, err0 = 100.0 * (got / measured - 1.0), base[measured.index]
    d = err.abs() - err0.abs()
    slow, fast = (kmh[measured.index] > 10) & (kmh[measured.index] <= 45), kmh[measured.index] > 45
    row = {"hypothesis": name, "fitted_on": fitted_on, "mean_abs_pct": round(float(err.abs().mean()), 1),
           "helped": int((d < -CHANGE_PP).sum()), "hurt": int((d > CHANGE_PP).sum()), "trips": int(err.size),
           "slow_pct": round(float(err[slow].mean()), 1), "fast_pct": round(float(err[fast].mean()), 1),
           "total_pct": round(float(100.0 * (got.sum() / measured.sum() - 1.0)), 1)}
    for t in sorted(truck.unique()):
        row[t] = round(float(err[truck.index[truck == t]].abs().mean()), 1)
    return row


def block_line(fuel_w, p_w, v, trips, block_s: int, eta_d: float) -> tuple[float, float]:
    """The moving engine's Willans line fitted on blocks of ``block_s`` samples within each trip
    (moving and fuelled throughout: v > STANDSTILL_MPS, P ≥ 0): its zero-output fuel [W] and its
    slope η (fuel → engine output, the engine output max(P, 0)/``eta_d``) by least squares of
    the blocks' mean fuel on their mean output. Noise in a 1-Hz driving power (derived
    acceleration, grade) and fuel running a few seconds apart from it flatten a per-sample
    line (errors in the regressor); longer blocks average them out."""
    blk = pd.Series(np.arange(len(trips)) // block_s).astype(str).to_numpy() + np.asarray(trips, str)
    g = pd.DataFrame({"f": fuel_w, "e": np.maximum(p_w, 0.0) / eta_d,
                      "ok": ((np.asarray(v) > STANDSTILL_MPS) & (np.asarray(p_w) >= 0)) * 1.0}).groupby(blk).mean()
    g = g[g["ok"] == 1.0]
    if len(g) < 3:
        raise UserError(f"blocks of {block_s} s: {len(g)} moving fuelled block(s), too few for a line")
    slope, icpt = np.polyfit(g["e"].to_numpy(), g["f"].to_numpy(), 1)
    return float(icpt), float(1.0 / slope)


def study(folder) -> dict:
    """Every check of the module docstring on the logs of ``folder`` (a dict for the report)."""
    from sumo_drvpw.model.equations import load_equation

    eq = load_equation(EQUATION)
    log = read_trucks(folder)
    d = log.df
    trips, dt = d["trip_id"].to_numpy(str), d["dt_s"].to_numpy(float)
    x = at_mass(log.inputs(), MASS_KG)
    rho_l = FUELS["diesel"]["density_kg_per_l"] * 1e3  # g per L
    ecu = d["fuel_rate_gps"].to_numpy(float)
    cb = carbon_balance_gps(d["co2_gps"], d["co_gps"], d["hc_gps"])
    rpm = d["engine_rpm"].to_numpy(float)
    meas_all = pd.Series(ecu * dt / rho_l).groupby(trips).sum()
    keep = meas_all.index[meas_all >= MIN_TRIP_L]
    meas, meas_cb = meas_all[keep], pd.Series(cb * dt / rho_l).groupby(trips).sum()[keep]
    truck = pd.Series([t.split("-")[0].split("_")[0] for t in keep], index=keep)
    kmh = pd.Series(3.6 * x.v).groupby(trips).mean()
    b0 = booked_l(eq, x, dt)
    got0 = pd.Series(b0).groupby(trips).sum()[keep]
    base = 100.0 * (got0 / meas - 1.0)

    # the fuel signal: ECU against the carbon balance, per truck; lag of fuel behind driving power
    p0 = eq.power(x)
    sig = {}
    for t in sorted(truck.unique()):
        m = np.char.startswith(trips.astype(str), t)
        slope, icpt = np.polyfit(cb[m], ecu[m], 1)
        moving = m & (x.v > STANDSTILL_MPS)
        hi, lo = moving & (p0 > 200e3), moving & (p0 < 30e3)
        idle_on = m & (x.v <= STANDSTILL_MPS) & (rpm > 300.0)
        lags = {k: float(np.corrcoef(ecu[m][max(k, 0):m.sum() + min(k, 0)],
                                     np.maximum(p0[m], 0)[max(-k, 0):m.sum() - max(k, 0)])[0, 1]) for k in range(-5, 6)}
        sig[t] = {"ecu_l": round(float((ecu[m] * dt[m]).sum() / rho_l), 1),
                  "carbon_balance_l": round(float((cb[m] * dt[m]).sum() / rho_l), 1),
                  "line": [round(float(icpt), 3), round(float(slope), 3)],
                  "ratio_above_200kw": round(float(ecu[hi].sum() / cb[hi].sum()), 2),
                  "ratio_below_30kw": round(float(ecu[lo].sum() / cb[lo].sum()), 2),
                  "best_lag_s": max(lags, key=lags.get),
                  # standing with the engine running (its speed logged above 300 rpm) [L/h]
                  "standing_l_h": [round(float(f[idle_on].mean() * 3600.0 / rho_l), 2) for f in (ecu, cb)]}

    # the mass: per trip, and one mass per truck fitted on the other
    m_ecu, m_cb = implied_mass_t(eq, x, dt, trips, meas), implied_mass_t(eq, x, dt, trips, meas_cb)
    rows = []
    for t in keep:
        sel = trips == t
        rows.append({"trip": t, "measured_l": round(float(meas[t]), 2), "carbon_balance_l": round(float(meas_cb[t]), 2),
                     "booked_l": round(float(got0[t]), 2), "error_pct": round(float(base[t]), 1),
                     "mean_kmh": round(float(3.6 * x.v[sel].mean()), 1),
                     "climb_m": round(float(d["elevation_m"].to_numpy()[sel][-1] - d["elevation_m"].to_numpy()[sel][0]), 1),
                     "implied_mass_t": _mass(m_ecu[t]), "implied_mass_cb_t": _mass(m_cb[t])})
    hyps = [_score("the carbon balance's fuel as the measurement (no change to the chain)", b0, base, meas_cb,
                   trips, truck, kmh)]
    totals = np.array([pd.Series(booked_l(eq, at_mass(x, mk), dt)).groupby(trips).sum()[keep] for mk in MASS_GRID_KG])
    for t in sorted(truck.unique()):  # fit on t's trips' total, score on the other's
        on = (truck == t).to_numpy()
        mk = float(np.interp(meas[on].sum(), totals[:, on].sum(1), MASS_GRID_KG))
        other = truck.index[~on]
        hyps.append(_score(f"one mass, {mk / 1e3:.1f} t, fitted on {t}'s trips", booked_l(eq, at_mass(x, mk), dt),
                           base, meas[other], trips, truck[other], kmh, fitted_on=t))
    ratio = gear_ratio(rpm, x.v)
    for t in sorted(truck.unique()):  # the speed-only gear model: read from t's log, scored on the other's
        on_t = np.char.startswith(trips.astype(str), t)
        top = float(np.percentile(ratio[on_t & (x.v > 22.0)], 5))
        first = float(np.percentile(ratio[on_t & (x.v > 2.0) & (x.v < 5.0)], 95))
        fit = float(np.median(rpm[on_t & (x.v > 2.0)]))  # its engine's median moving speed (not fitted to fuel)
        other = truck.index[truck != t]
        hyps.append(_score(f"rotating inertia, gear from speed alone ({fit:.0f} rpm, ratios {top:.1f}–{first:.1f}), "
                           f"read from {t}'s log", booked_l(eq, x, dt, factor=speed_gear_factor(x.v, fit, top, first)),
                           base, meas[other], trips, truck[other], kmh, fitted_on=t))
    for w, flat in ((30.0, False), (300.0, False), (1000.0, False), (100.0, True)):
        lg = read_trucks(folder, w, flat)
        name = "no grade (flat road)" if flat else f"elevation smoothed over {w:.0f} m (not 100 m)"
        hyps.append(_score(name, booked_l(eq, at_mass(lg.inputs(), MASS_KG), dt), base, meas, trips, truck, kmh))
    f_rot, f_car = rotating_mass_factor(rpm, x.v), rotating_mass_factor(rpm, x.v, car=True)
    capped = dataclasses.replace(eq.chain, engine_max_w=S60_MAX_W)
    h = d["elevation_m"].to_numpy(float)
    rho = P_STD_KPA * 1e3 * (1.0 - ISA_LAPSE * h) ** ISA_EXPONENT / (R_DRY_AIR * (T_REF_C + KELVIN))
    for name, kw, xx in (
            ("the S60's zero-output fuel at the logged engine speed", {"rpm": rpm}, x),
            ("the S60's rated output caps the engine (332 kW)", {"chain": capped}, x),
            ("rotating inertia at the logged gear: the truck's (ADVISOR's engine and wheels)", {"factor": f_rot}, x),
            ("rotating inertia at the logged gear: a passenger car's share (Gillespie)", {"factor": f_car}, x),
            ("air density at the logged height ([ISA] pressure, 20 °C)", {"rho": rho}, x),
            ("driving power averaged over 5 s before the fuel cut-off (its 1-Hz noise)", {"smooth": (5, trips)}, x),
            ("driveline 0.92 (ADVISOR's Eaton 10-speed; FASTSim's 0.80 in the built-in)",
             {"chain": dataclasses.replace(eq.chain, traction_efficiency=ADVISOR_GEARBOX)}, x),
            ("zero-output fuel at the logged speed + rotating inertia", {"rpm": rpm, "factor": f_rot}, x),
            ("the S60's friction + the truck's inertia + the 332-kW cap + the air's density",
             {"rpm": rpm, "factor": f_rot, "chain": capped, "rho": rho}, x),
            ("driveline 0.92 + the truck's inertia + the S60's zero-output fuel at the logged speed",
             {"rpm": rpm, "factor": f_rot, "chain": dataclasses.replace(eq.chain, traction_efficiency=ADVISOR_GEARBOX)}, x)):
        hyps.append(_score(name, booked_l(eq, xx, dt, **kw), base, meas, trips, truck, kmh))
    lines = []  # the moving line fitted on one truck's blocks, its trips' errors on the other's
    for label, pp in (("MOVES road load", p0), ("with the truck's rotating inertia", p0 + (f_rot - 1.0) * x.mass * x.v * x.a)):
        for k in BLOCKS_S:
            for t in sorted(truck.unique()):
                on = np.char.startswith(trips.astype(str), t)
                z, eta = block_line(ecu[on] * FUELS["diesel"]["lhv_j_per_kg"] / 1e3, pp[on], x.v[on], trips[on], k,
                                    eq.chain.traction_efficiency)
                other = truck.index[truck != t]
                ch = dataclasses.replace(eq.chain, marginal_efficiency=eta, aux_power_w=0.0,
                                         idle_fuel_power_w=eq.chain.idle_fuel_power_w + eq.chain.aux_power_w
                                         / eq.chain.marginal_efficiency, moving_idle_fuel_power_w=max(
                                             z, eq.chain.idle_fuel_power_w + eq.chain.aux_power_w / eq.chain.marginal_efficiency))
                sc = _score("", booked_l(eq, x, dt, chain=ch, factor=None if label.startswith("MOVES") else f_rot),
                            base, meas[other], trips, truck[other], kmh)
                lines.append({"road_load": label, "block_s": k, "fitted_on": t, "zero_output_kw": round(z / 1e3, 1),
                              "eta": round(eta, 3), "held_out_mean_abs_pct": sc["mean_abs_pct"],
                              "built_in_mean_abs_pct": round(float(base[other].abs().mean()), 1)})
    # fuel → wheel on the fast trips: their positive wheel energy over the fuel beyond the chain's
    # zero-output fuel, with either measurement
    fast = np.isin(trips, kmh.index[(kmh > 45)].intersection(keep))
    fuelled = fast & eq.chain.engine_on(p0, x.v)
    zero = np.where(fuelled, eq.chain.idle_fuel_power_w + eq.chain.aux_power_w / eq.chain.marginal_efficiency, 0.0)
    wheel = float(np.sum(np.maximum(p0, 0.0)[fast] * dt[fast]))
    lhv = FUELS["diesel"]["lhv_j_per_kg"] / 1e3  # J per g
    to_wheel = {k: round(wheel / float(np.sum((f * lhv - zero)[fast] * dt[fast])), 3) for k, f in (("ecu", ecu), ("carbon_balance", cb))}
    slow = (x.v > 2.0) & (x.v < 12.0)
    n_slow, n_fast = float(np.median(ratio[slow])), float(np.median(ratio[x.v > 22.0]))
    inertia = {"engine_kgm2": round(ENGINE_INERTIA_KGM2, 2), "wheels_kgm2": round(WHEELS_INERTIA_KGM2, 1),
               "radius_m": TYRE_RADIUS_M, "factor_slow": round(float(mass_factor(n_slow, 10.0, MASS_KG)), 3),
               "factor_fast": round(float(mass_factor(n_fast, 10.0, MASS_KG)), 3),
               "car_factor_slow": round(GILLESPIE[0] + GILLESPIE[1] * n_slow**2, 3),
               "car_engine_kgm2": round(GILLESPIE[1] * MASS_KG * TYRE_RADIUS_M**2, 1)}
    return {"equation": EQUATION, "mass_t": MASS_KG / 1e3, "trips": int(keep.size),
            "mean_abs_pct": round(float(base.abs().mean()), 1), "signal": sig, "per_trip": rows,
            "moving_lines": lines, "fast_fuel_to_wheel": to_wheel, "hypotheses": [_score("the built-in", b0, base, meas, trips, truck, kmh)] + hyps, "inertia": inertia,
            "gear_ratio_median": {"below_43_kmh": round(n_slow, 1), "above_79_kmh": round(n_fast, 1)}}


def _mass(m: float):
    """An implied mass for the JSON: [t], or where the grid ends ('< 2': even 2 t books more)."""
    if np.isnan(m):
        return f"< {MASS_GRID_KG[0] / 1e3:.0f}"
    return f"> {MASS_GRID_KG[-1] / 1e3:.0f}" if np.isinf(m) else round(float(m), 1)
