"""Measured driving power from powertrain signals: power-split hybrid, single motor, battery.

Sign conventions (all machines)
-------------------------------
* Speeds are positive in the forward-driving direction of rotation [rad/s].
* A machine's torque is positive when it drives its shaft forward (motoring MG2,
  engine firing); MG1 reacting the engine while generating has τ_MG1 < 0 at ω_MG1 > 0.
* Mechanical power of a machine τ·ω > 0 means it delivers power to the gear set.
* Driving power P_PTdrv > 0: the powertrain pushes the car; < 0: it brakes the car
  (regeneration). Friction braking is not in it (the log's ``brake`` flag marks it).

Power-split gear (Toyota Hybrid System, seed paper Eq. 5–12)
------------------------------------------------------------
Planetary set: engine on the carrier (C), MG1 on the sun (S teeth), ring (R teeth) on
the output. Willis: S·ω_MG1 + R·ω_R = (R + S)·ω_ice. The ring drives the wheels through
the counter gear and final drive; MG2 drives the ring through its reduction gear.
Ratios here are conventional (> 1 slows the wheel): ω_R = ω_MG2/k_r,
ω_wh = ω_R/(k_c·k_f). The paper writes G_r = 1/k_r, G_c = 1/k_c, G_f = 1/k_f.

Engine torque from MG1 (Eq. 5–8):
    τ_ice = ω̇_ice(I_ice + I_C) + ((R+S)/S)·[ω̇_MG1(I_MG1 + I_S) − τ_MG1]
Torque the carrier passes into the gear set (engine torque less what accelerates the
engine and carrier), and its ring share:
    τ_C = τ_ice − ω̇_ice(I_ice + I_C) = ((R+S)/S)·[ω̇_MG1(I_MG1 + I_S) − τ_MG1]
    τ_R,ice = (R/(R+S))·τ_C
Wheel torque (Eq. 9–11), each inertia at its own shaft's acceleration:
    τ_PTdrv = k_r·k_c·k_f·τ_MG2 + k_c·k_f·τ_R,ice
              − ω̇_wh·[I_R·(k_c·k_f)² + I_MG2·(k_r·k_c·k_f)² + I_wh]
    P_PTdrv = τ_PTdrv·ω_wh                                           (Eq. 12)

Differences from the paper's printed form, on purpose: the ring receives R/(R+S) of the
carrier's *net* torque τ_C (the printed form applies it to τ_ice, which would pass the
engine's own inertia torque to the wheels), and reflected inertias scale with the square
of the ratio (the printed form has single powers, which is not dimensionally a reflected
inertia). Both agree with the printed form at steady state.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from sumo_drvpw.data.ranges import flow_values
from sumo_drvpw.model.constants import RPM
from sumo_drvpw.data.counters import COUNTERS
from sumo_drvpw.errors import NoDrivingPower, UserError


def planetary_mg1_speed(ice_rad_s, ring_rad_s, sun_teeth: float, ring_teeth: float):
    """MG1 (sun) speed from engine (carrier) and ring speeds, Willis equation [rad/s]."""
    s, r = float(sun_teeth), float(ring_teeth)
    return ((r + s) * np.asarray(ice_rad_s) - r * np.asarray(ring_rad_s)) / s


def power_split_power(ice_w, ice_dw, mg1_w, mg1_dw, mg1_tq, mg2_w, mg2_tq, wh_dw, *,
                      sun_teeth, ring_teeth, mg2_reduction, counter_ratio, final_drive,
                      inertia: dict) -> dict:
    """Driving power of a power-split hybrid at the wheels (seed paper Eq. 5–12).

    Parameters
    ----------
    ice_w, ice_dw : engine speed [rad/s] and its time derivative [rad/s²]
    mg1_w, mg1_dw, mg1_tq : MG1 speed [rad/s], acceleration [rad/s²], torque [N·m]
    mg2_w, mg2_tq : MG2 speed [rad/s] and torque [N·m]
    wh_dw : wheel angular acceleration [rad/s²]
    sun_teeth, ring_teeth : planetary tooth counts [-]
    mg2_reduction, counter_ratio, final_drive : conventional ratios k_r, k_c, k_f [-]
    inertia : kg·m² for keys ice, carrier, mg1, sun, ring, mg2, wheels (missing = 0)

    Returns a dict of arrays: ``ice_torque_nm`` (τ_ice), ``wheel_speed`` ω_wh [rad/s],
    ``wheel_torque_nm`` τ_PTdrv, ``power_w`` P_PTdrv [W].
    """
    s, r = float(sun_teeth), float(ring_teeth)
    kr, kc, kf = float(mg2_reduction), float(counter_ratio), float(final_drive)
    inn = {k: float(inertia.get(k, 0.0)) for k in ("ice", "carrier", "mg1", "sun", "ring", "mg2", "wheels")}
    tau_c = ((r + s) / s) * (np.asarray(mg1_dw) * (inn["mg1"] + inn["sun"]) - np.asarray(mg1_tq))
    tau_ice = np.asarray(ice_dw) * (inn["ice"] + inn["carrier"]) + tau_c
    tau_ring = (r / (r + s)) * tau_c
    j_wheel = inn["ring"] * (kc * kf) ** 2 + inn["mg2"] * (kr * kc * kf) ** 2 + inn["wheels"]
    tau_wh = kr * kc * kf * np.asarray(mg2_tq) + kc * kf * tau_ring - np.asarray(wh_dw) * j_wheel
    w_wh = np.asarray(mg2_w) / (kr * kc * kf)
    return {"ice_torque_nm": tau_ice, "wheel_speed": w_wh, "wheel_torque_nm": tau_wh,
            "power_w": tau_wh * w_wh}


def single_motor_power(torque_nm, speed_rad_s):
    """Mechanical motor shaft power τ·ω [W] (positive when driving)."""
    return np.asarray(torque_nm, float) * np.asarray(speed_rad_s, float)


def battery_power(voltage_v, current_a, current_positive: str = "discharge"):
    """Electrical battery power [W], positive when the battery delivers power.

    Parameters
    ----------
    voltage_v : terminal voltage [V]; current_a : current [A]
    current_positive : "discharge" if the logged current is positive when discharging,
        "charge" if it is positive when charging
    """
    p = np.asarray(voltage_v, float) * np.asarray(current_a, float)
    if current_positive == "discharge":
        return p
    if current_positive == "charge":
        return -p
    raise UserError(f"battery.current_positive must be 'discharge' or 'charge', got {current_positive!r}")


POWER_SPLIT_COLUMNS = ("ice_speed_rpm", "mg1_speed_rpm", "mg1_torque_nm", "mg2_speed_rpm", "mg2_torque_nm")


#: the measured driving power's sources in the spec's order: the columns a trip must hold
POWER_SOURCES = (("power_w",), POWER_SPLIT_COLUMNS, ("motor_torque_nm", "motor_speed_rpm"),
                 ("motor_torque_nm",), ("battery_voltage_v", "battery_current_a"))


def terms_predict_of(source: str) -> str:
    """What an equation calibrated on the measured power of ``source`` (:func:`measured_power`'s
    text) predicts: the powertrain output for a power-split's P_PTdrv or a motor's shaft power
    (the drivetrain's losses behind it are not in it), else the wheel."""
    return "powertrain_output" if str(source).startswith(("power-split", "single motor")) else "wheel"


def measured_power(log, vehicle=None, window_s: float | None = None) -> tuple[np.ndarray, str]:
    """The measured driving power of a :class:`~sumo_drvpw.data.log.DriveLog` [W] and its source.

    Shaft accelerations use the same smoothed derivative as the log's acceleration
    (:meth:`~sumo_drvpw.data.log.DriveLog.derivative`: each trip's window, never across a
    logging gap; ``window_s`` [s]: one width instead).

    Each trip uses exactly one source, the first in the spec's order that holds a value in
    it: ``power_w``; the power-split signals (needs a ``power_split`` vehicle); motor torque
    and speed (speed from vehicle speed, gear ratio and wheel radius when ``motor_speed_rpm``
    is absent); battery V·I. So a file of a folder is read as it is alone; a trip that holds
    none takes the first the table has (its power NaN: left out), and a file of a folder
    that has none of the columns is refused, named, as read alone. The rows of each source go
    to ``log.counts["power_rows"]``; the text says each (:func:`sumo_drvpw.data.conditions.source_counts`).
    """
    from sumo_drvpw.data.conditions import said
    from sumo_drvpw.data.trips import trip_codes_of

    df = log.df
    present = [all(c in df for c in cols) for cols in POWER_SOURCES]
    for f, cols in _each_file(log, df):  # a file that has none is refused, as read alone
        if not any(all(c in cols for c in s) for s in POWER_SOURCES):
            flows = [c for c in flow_columns(sorted(_header_of(f) | cols)) if not c.endswith("_pct")]
            counters = all(c in (_header_of(f) | cols) for c in COUNTERS)
            raise NoDrivingPower(
                f"{f}: no measured power: the log needs 'power_w', or the power-split columns "
                f"({', '.join(POWER_SPLIT_COLUMNS)}), or 'motor_torque_nm', or "
                "'battery_voltage_v' and 'battery_current_a'"
                + (f"; it holds {', '.join(flows[:3])}, the engine's fuel or air flow: a fuel-chain target, "
                   "calibrated on a road-load equation" if flows else "")
                + (f"; it holds {' and '.join(COUNTERS)}, the battery's energy counters: a battery-chain "
                   "target, calibrated on a road-load equation" if counters else ""),
                targets=(("fuel",) if flows else ()) + (("battery",) if counters else ()))
    codes = trip_codes_of(df["trip_id"])
    n = int(codes.max()) + 1
    pick = np.full(n, -1)
    for i in range(len(POWER_SOURCES) - 1, -1, -1):
        if present[i]:
            held = np.ones(n, bool)
            for c in POWER_SOURCES[i]:
                held &= np.bincount(codes, weights=np.isfinite(df[c].to_numpy(float)), minlength=n) > 0
            pick[held] = i
    pick[pick < 0] = present.index(True)
    row = pick[codes]
    p, rows = np.full(len(df), np.nan), {}
    for i in np.unique(pick):
        q, text = _power_of(int(i), log, vehicle, window_s)
        sel = row == i
        p = q if len(rows) == 0 and sel.all() else np.where(sel, q, p)
        rows[text] = int(sel.sum())
    log.counts["power_rows"] = rows
    return p, said(rows)


def _power_of(kind: int, log, vehicle, window_s) -> tuple[np.ndarray, str]:
    """The power of every row from source ``kind`` (:data:`POWER_SOURCES`) and its text."""
    df = log.df
    where = log.describe()
    if kind == 0:
        return df["power_w"].to_numpy(float), "direct (power_w)"
    if kind == 1:
        if vehicle is None or vehicle.powertrain_type != "power_split":
            raise UserError(f"{where}: the log has power-split signals ({', '.join(POWER_SPLIT_COLUMNS)}); "
                            "give a vehicle with a power_split powertrain (e.g. prius3, prius2)")
        pt = vehicle.powertrain
        kr = float(pt.get("mg2_reduction", 1.0))
        kc = float(pt.get("counter_ratio", 1.0))
        kf = vehicle.need("powertrain", "final_drive")
        ice = df["ice_speed_rpm"].to_numpy(float) * RPM
        mg1 = df["mg1_speed_rpm"].to_numpy(float) * RPM
        mg2 = df["mg2_speed_rpm"].to_numpy(float) * RPM
        wh = mg2 / (kr * kc * kf)
        out = power_split_power(
            ice, log.derivative(ice, window_s), mg1, log.derivative(mg1, window_s),
            df["mg1_torque_nm"].to_numpy(float), mg2, df["mg2_torque_nm"].to_numpy(float),
            log.derivative(wh, window_s),
            sun_teeth=vehicle.need("powertrain", "sun_teeth"),
            ring_teeth=vehicle.need("powertrain", "ring_teeth"),
            mg2_reduction=kr, counter_ratio=kc, final_drive=kf,
            inertia=pt.get("inertia_kgm2", {}))
        return out["power_w"], "power-split (MG1, MG2, engine; Eq. 5-12)"
    if kind in (2, 3):
        if kind == 2:
            w = df["motor_speed_rpm"].to_numpy(float) * RPM
            how = "motor torque × motor speed"
        else:
            if vehicle is None:
                raise UserError(f"{where}: 'motor_torque_nm' without 'motor_speed_rpm' needs a vehicle "
                                "(its gear_ratio and wheel_radius_m)")
            w = (df["speed_mps"].to_numpy(float) / vehicle.need("powertrain", "wheel_radius_m")
                 * vehicle.need("powertrain", "gear_ratio"))
            how = "motor torque × (speed / wheel radius × gear ratio)"
        return single_motor_power(df["motor_torque_nm"].to_numpy(float), w), f"single motor ({how})"
    conv = (vehicle.battery.get("current_positive", "discharge") if vehicle is not None
            else "discharge")
    return (battery_power(df["battery_voltage_v"], df["battery_current_a"], conv),
            f"battery V·I (current positive = {conv})")


def _header_of(f) -> frozenset:
    """The column names of the file ``f`` (a streamed batch reads only the columns it uses:
    what else the file holds is in its header), or none when ``f`` is no readable file."""
    from pathlib import Path

    from sumo_drvpw.data.stream import column_names

    return frozenset(column_names(f) or ()) if Path(str(f)).is_file() else frozenset()


def _each_file(log, df) -> list[tuple[str, frozenset]]:
    """(file, its columns) of each file of a folder read in memory (``log.file_columns``);
    else the log's description and the table's columns: a measured power is refused for a
    file that cannot give it, named, as the file read alone (or streamed) is."""
    if getattr(log, "file_columns", None):
        return list(log.file_columns.items())
    return [(log.describe(), frozenset(map(str, df.columns)))]


def measured_battery_power(log, vehicle=None) -> tuple[np.ndarray, str]:
    """Battery power of a drive log [W], positive when discharging, and its source: V·I, or,
    for a trip without them, the rate of the BMS's energy counters
    (:mod:`sumo_drvpw.data.counters`); see :func:`battery_power_and_view`."""
    return battery_power_and_view(log, vehicle, count=False)[:2]


def battery_power_and_view(log, vehicle=None, count: bool = True) -> tuple[np.ndarray, str, object]:
    """Battery power of a drive log [W], positive when discharging, its source, and the
    counters' view of the log (:class:`~sumo_drvpw.data.counters.CounterView`; None when
    every trip logs V·I).

    V·I takes the vehicle file's sign convention ``battery.current_positive`` (default
    ``discharge``, the spec's canonical sign). Each trip uses V·I where it holds them, else
    the counters. A file of a folder with neither pair is refused, named, as read alone (not
    read as NaN). With ``count`` (the battery target's reading; not a hybrid's fuel target's
    correction), the rows of each source go to ``log.counts["power_rows"]``.
    """
    from sumo_drvpw.data.conditions import said
    from sumo_drvpw.data.counters import COUNTER_SOURCE, COUNTERS, CounterView
    from sumo_drvpw.data.trips import trip_codes_of

    vi = ("battery_voltage_v", "battery_current_a")
    df = log.df
    for f, cols in _each_file(log, df):  # a file without them is refused, as read alone
        if all(c in cols for c in COUNTERS):
            continue
        missing = [c for c in vi if c not in cols]
        if missing:
            raise UserError(f"{f}: the battery target needs the column '{missing[0]}' "
                            "(battery_voltage_v and battery_current_a; or the BMS's energy counters "
                            "battery_discharge_energy_j and battery_charge_energy_j)")
    conv = vehicle.battery.get("current_positive", "discharge") if vehicle is not None else "discharge"
    has_vi, has_ctr = all(c in df for c in vi), all(c in df for c in COUNTERS)
    p = battery_power(df["battery_voltage_v"], df["battery_current_a"], conv) if has_vi else None
    text = f"battery V·I (current positive = {conv})"
    counts = log.counts if count else {}
    counts["power_rows"] = {text: len(df)}
    if not has_ctr:
        return p, text, None
    codes = trip_codes_of(df["trip_id"])
    use = np.ones(len(df), bool)
    if has_vi:  # a trip that holds V·I keeps them
        n = int(codes.max()) + 1
        held = np.bincount(codes, weights=np.isfinite(p), minlength=n) > 0
        use = ~held[codes]
    if not use.any():
        return p, text, None
    view = CounterView(df["time_s"].to_numpy(float), df["dt_s"].to_numpy(float), codes,
                       *(df[k].to_numpy(float, na_value=np.nan) for k in COUNTERS), rows=use)
    q = view.power()
    if not has_vi or use.all():
        counts["power_rows"] = {COUNTER_SOURCE: len(df)}
        return q, COUNTER_SOURCE, view
    rows = {text: int((~use).sum()), COUNTER_SOURCE: int(use.sum())}
    counts["power_rows"] = rows
    return np.where(use, q, p), said(rows), view


#: fuel-flow columns in the order they are used: mass flow [g/s], or volume flow [L/h]
FUEL_COLUMNS = ("fuel_rate_gps", "fuel_rate_lph")


def fuel_flow_candidates(df, logged=None) -> list[str]:
    """Extra columns that read as a fuel volume flow: named with 'fuel', ending in ``_lph``
    (what adapters make of a vendor's L/h or gal/h flow: Torque's 'Fuel flow rate/hour',
    Car Scanner's 'Calculated instant fuel rate'), with at least one value (``logged``: as
    for :func:`fuel_column`)."""
    return [str(c) for c in df.columns if str(c).endswith("_lph") and "fuel" in str(c) and _logged(df, c, logged)]


def _logged(df, col, logged=None) -> bool:
    """Whether column ``col`` holds any value (a file's column for a PID the car never
    answered is empty: no fuel flow, not a fuel flow of NaN): in ``df``, or when ``logged``
    is given (the columns that hold a value in the whole file, :func:`flow_columns`), there."""
    return col in logged if logged is not None else bool(df[col].notna().any())


def flow_columns(names) -> list[str]:
    """Of the column ``names``, those whose choice depends on whether they hold a value: the
    fuel flows, air flows and fuel trims found by name. A streamed file's batch chooses
    among them by the whole file's values (``DriveLog.logged``), so a batch in which the
    chosen flow is empty is missing samples (left out and counted), not another source."""
    return [str(n) for n in names if str(n) in FUEL_COLUMNS or (str(n).endswith("_lph") and "fuel" in str(n))
            or (str(n).endswith("_gps") and ("air" in str(n) or str(n).startswith("maf")))
            or (str(n).endswith("_pct") and _TRIM.search(str(n)))]


def fuel_column(df, logged=None) -> str | None:
    """The fuel-flow column of a log: ``fuel_rate_gps``, ``fuel_rate_lph``, else the one
    fuel volume flow among the extras (:func:`fuel_flow_candidates`; of several, the one
    whose name starts with 'fuel'); None when there is none or no single one. ``logged``:
    the columns that hold a value in the whole file, when ``df`` is a batch of it (None:
    judged on ``df``)."""
    for c in FUEL_COLUMNS:
        if c in df and _logged(df, c, logged):
            return c
    cands = fuel_flow_candidates(df, logged)
    if len(cands) > 1:
        cands = [c for c in cands if c.startswith("fuel")]
    return cands[0] if len(cands) == 1 else None


def measured_fuel(vehicle=None, chains_fuel: str | None = None) -> tuple[str, str]:
    """The fuel a log's fuel flow is read as (:func:`measured_fuel_power`: its LHV and
    density) and where that comes from: the vehicle file's ``powertrain.fuel``, else
    ``chains_fuel`` (the one fuel the compared equations' chains burn:
    :attr:`~sumo_drvpw.data.log.ReadOptions.fuel`), else gasoline."""
    if vehicle is not None and vehicle.powertrain.get("fuel"):
        return str(vehicle.powertrain["fuel"]), f"vehicle {vehicle.name}'s powertrain.fuel"
    if chains_fuel:
        return str(chains_fuel), "the fuel the equations' chains burn: no vehicle file names a fuel"
    return "gasoline", "the default: no vehicle file names a fuel"


def measured_fuel_power(log, vehicle=None, fuel: str | None = None) -> tuple[np.ndarray, str]:
    """Fuel power of a drive log [W] (mass flow × lower heating value) and its source.

    P_fuel = ṁ·LHV with ṁ [kg/s] from ``fuel_rate_gps`` / 1000, or from a volume flow [L/h]
    × density / 3600. The fuel is ``fuel`` if given, else the vehicle file's
    ``powertrain.fuel``, else the log's reading options' ``fuel`` (the compared chains'),
    else gasoline; its LHV and density are in
    :data:`sumo_drvpw.model.constants.FUELS`. A petrol car's log without a fuel flow but
    with its mass air flow (:func:`air_flow_column`) gives an estimate: ṁ = MAF / AFR_st
    × (1 + fuel trims) / commanded λ (:func:`fuel_from_air_flow`).

    A flow (or fuel trim) that is text, infinite or outside its plausible range is refused,
    naming the column, the row and the value (:func:`sumo_drvpw.data.ranges.flow_values`).
    Each file of a folder read in memory takes its own flow, as read alone or streamed (a
    file without one is refused, named); the rows of each source go to
    ``log.counts["power_rows"]`` and the text says each.
    """
    from sumo_drvpw.model.constants import FUELS

    import dataclasses

    from sumo_drvpw.data.conditions import merge_rows, said

    name = fuel or measured_fuel(vehicle, getattr(getattr(log, "options", None), "fuel", None))[0]
    if name not in FUELS:
        raise UserError(f"fuel '{name}' is not one of {', '.join(FUELS)}")
    fp = FUELS[name]
    groups = _files_by_flows(log)
    if groups is None:  # one table, or a streamed batch (its whole file's choice: ``log.logged``)
        p, text = _fuel_of(log, getattr(log, "logged", None), name, fp)
        log.counts["power_rows"] = {text: len(p)}
        return p, text
    # a folder read in memory: each file's flow as the file read alone, its rows said
    p, rows = np.full(len(log.df), np.nan), {}
    for files, logged, sel in groups:
        q, text = _fuel_of(dataclasses.replace(log, files=files, logged=logged), logged, name, fp)
        p = np.where(sel, q, p)
        rows[text] = rows.get(text, 0) + int(sel.sum())
    rows = merge_rows(rows, {}, "power_rows")  # in the sources' order, as batches merge
    log.counts["power_rows"] = rows
    return p, said(rows)


def _files_by_flows(log):
    """A folder read in memory (``log.file_logged``): (its files, their fuel and air flows
    that hold a value, their rows) per distinct set of flows; else None."""
    if not getattr(log, "file_logged", None) or len(set(log.file_logged.values())) < 2:
        return None
    by: dict = {}
    for f, logged in log.file_logged.items():
        by.setdefault(logged, []).append(f)
    trip = log.df["trip_id"].astype(str)
    return [(files, logged, trip.isin([t for f in files for t in log.file_trips[f]]).to_numpy())
            for logged, files in by.items()]


def _fuel_of(log, logged, name: str, fp: dict) -> tuple[np.ndarray, str]:
    """The fuel power of every row of ``log`` from the flow chosen by ``logged`` and its text."""
    df = log.df
    col = fuel_column(df, logged)
    if col is None:
        air = air_flow_column(df, logged)
        if air is not None and name == "gasoline":
            kgps, how = fuel_from_air_flow(log, air)
            return kgps * fp["lhv_j_per_kg"], how
        several = fuel_flow_candidates(df, logged)
        airs = air_flow_candidates(df, logged)
        raise UserError(f"{log.describe()}: the fuel target needs a fuel-flow column "
                        f"({', '.join(FUEL_COLUMNS)}, or one '…fuel…_lph' column"
                        + (", or for a petrol engine its mass air flow '…air…_gps'" if air is None else "")
                        + ")"
                        + (f"; several air flows: {', '.join(airs)} — map the one to use as maf_gps "
                           "and leave the others out" if len(airs) > 1 else "")
                        + (f"; several could be: {', '.join(several)} — name the one to use "
                           "fuel_rate_lph (import columns mapping)" if len(several) > 1 else "")
                        + (f"; '{air}' is an air flow, and a {name} engine's fuel is not its air "
                           "over a fixed ratio (a diesel runs lean)" if air is not None else ""))
    x = flow_values(log, col, "fuel_rate_gps" if col == "fuel_rate_gps" else "fuel_lph")
    kgps = x / 1000.0 if col == "fuel_rate_gps" else x * fp["density_kg_per_l"] / 3600.0
    return kgps * fp["lhv_j_per_kg"], f"fuel flow {col} × LHV of {name}"


def air_flow_candidates(df, logged=None) -> list[str]:
    """Logged extras that read as an engine's mass air flow [g/s]: ending in ``_gps``, named
    for air or MAF (what the adapters make of OBD PID 0x10, e.g. Torque's 'Mass Air Flow
    Rate(g/s)', VED's 'MAF[g/sec]'); ``logged`` as for :func:`fuel_column`."""
    return [str(n) for n in df.columns if str(n).endswith("_gps") and str(n) != "fuel_rate_gps"
            and ("air" in str(n) or str(n).startswith("maf")) and _logged(df, n, logged)]


def air_flow_column(df, logged=None) -> str | None:
    """The one mass air flow of a log (:func:`air_flow_candidates`), or None."""
    c = air_flow_candidates(df, logged)
    return c[0] if len(c) == 1 else None


#: a bank's fuel trims: '…fuel_trim…bank_N…' in %, short and long term
_TRIM = re.compile(r"(?=.*fuel_trim)(?=.*(short|long))(?=.*bank_?(\d))")


def fuel_from_air_flow(log, air: str) -> tuple[np.ndarray, str]:
    """A petrol engine's fuel mass flow [kg/s] from its mass air flow ``air`` [g/s], and
    how: ṁ_f = ṁ_air / AFR_st × (1 + mean over banks of (short + long term fuel trim) / 100)
    / λ_cmd, with AFR_st of petrol (:data:`~sumo_drvpw.model.constants.AFR_STOICH_GASOLINE`),
    the fuel-trim columns ('…fuel_trim…short|long…bank_N…_pct'; a missing value counts 0)
    and the commanded equivalence ratio λ_cmd ('…commanded…equivalence_ratio…' or
    '…commanded…lambda…', used where in [0.5, 1.5], else 1) when logged. An estimate: exact
    in closed loop; in deceleration fuel cut the injectors are off while air still flows,
    which this books as fuel unless the log's λ_cmd says so."""
    from sumo_drvpw.model.constants import AFR_STOICH_GASOLINE

    df = log.df
    x = flow_values(log, air, "air_gps")
    count_throttling(log, x)
    banks: dict[str, np.ndarray] = {}
    trims = []
    for c in df.columns:
        m = _TRIM.search(str(c))
        if m and str(c).endswith("_pct") and _logged(df, c, getattr(log, "logged", None)):  # an inline engine has one bank
            t = np.nan_to_num(flow_values(log, c, "trim_pct"))
            banks[m.group(2)] = banks.get(m.group(2), 0.0) + t
            trims.append(str(c))
    factor = 1.0 + (np.mean(list(banks.values()), axis=0) / 100.0 if banks else 0.0)
    lam = [str(c) for c in df.columns if "command" in str(c)
           and ("equivalence_ratio" in str(c) or "lambda" in str(c))]
    how = f"ESTIMATE: fuel from the mass air flow {air} / {AFR_STOICH_GASOLINE:.2f} (stoichiometric petrol)"
    if trims:
        how += f" × (1 + fuel trims {', '.join(sorted(trims))})"
    if len(lam) == 1:
        lv = pd.to_numeric(df[lam[0]], errors="coerce").to_numpy(float)  # text: not a λ, as out of range
        lv = np.where(np.isfinite(lv) & (lv >= 0.5) & (lv <= 1.5), lv, 1.0)
        factor = factor / lv
        how += f" / commanded λ {lam[0]}"
    how += " × LHV of gasoline (deceleration fuel cut reads as air: an overestimate there)"
    return x / 1000.0 / AFR_STOICH_GASOLINE * factor, how



#: a manifold pressure [kPa] below which an engine is throttled: a petrol engine's idling and
#: coasting (20–40 kPa; a rehearsal's petrol Toyota: below it on 85 % of its running rows); a
#: diesel's stays near the air outside or above it (KIT's Seat Leon: on 0.1 %)
THROTTLED_KPA = 50.0
#: the rows a throttle is judged on: the engine running at no load — standing (idling: speed
#: below this [m/s]) or on the overrun (decelerating at least :data:`OVERRUN_MPS2`), where a
#: petrol engine's throttle is closed and its manifold at 20–40 kPa while a diesel's stays
#: near the air outside. Under load a throttled engine's manifold pressure rises with the load
#: it carries (a downsized turbo petrol cruising on a highway: above 50 kPa on all but its
#: lift-offs), so the other rows say nothing of a throttle.
IDLING_MPS = 0.5
#: the deceleration [m/s²] (negative) at or below which a moving car is on the overrun
OVERRUN_MPS2 = -0.5
#: the fewest idling or overrun rows the throttle is judged on
THROTTLE_ROWS_MIN = 100


def manifold_pressure_column(df) -> str | None:
    """The one intake manifold absolute pressure of a log [kPa] (OBD PID 0x0B: 'Intake
    Manifold Absolute Pressure [kPa]', Torque's 'Intake Manifold Pressure(psi)' as the
    adapters name them), not a boost or vacuum gauge's relative one; else None."""
    c = [str(n) for n in df.columns if str(n).endswith("_kpa") and ("manifold" in str(n) or str(n).startswith("map_"))
         and not any(w in str(n) for w in ("boost", "vacuum", "gauge", "relative"))]
    return c[0] if len(c) == 1 else None


def count_throttling(log, air_gps: np.ndarray) -> None:
    """Into ``log.counts``: the rows with the engine running (air flowing) at no load —
    idling or on the overrun (:data:`IDLING_MPS`, :data:`OVERRUN_MPS2`) — and a manifold
    pressure (``throttle_rows``), and those of them below :data:`THROTTLED_KPA`
    (``throttled_rows``) — the fuel chain's check reads them (:func:`unthrottled_note`)."""
    col = manifold_pressure_column(log.df)
    counts = getattr(log, "counts", None)
    if col is None or counts is None:
        return
    df = log.df
    kpa = pd.to_numeric(df[col], errors="coerce").to_numpy(float)
    v = df["speed_mps"].to_numpy(float)
    a = df["accel_mps2"].to_numpy(float) if "accel_mps2" in df else np.full(len(df), np.nan)
    no_load = (v < IDLING_MPS) | (a <= OVERRUN_MPS2)
    run = np.isfinite(kpa) & (np.nan_to_num(air_gps) > 0) & no_load
    counts["throttle_rows"], counts["throttled_rows"] = int(run.sum()), int((run & (kpa < THROTTLED_KPA)).sum())
    counts["throttle_column"] = col


def unthrottled_note(counts: dict | None) -> str:
    """A fuel target from the air flow of an engine whose manifold pressure hardly ever falls
    below :data:`THROTTLED_KPA` where it idles or runs on the overrun (under 5 % of at least
    :data:`THROTTLE_ROWS_MIN` such rows; a log with fewer — a highway cruise — is not judged):
    a reading's clause."""
    n, k = int((counts or {}).get("throttle_rows", 0) or 0), int((counts or {}).get("throttled_rows", 0) or 0)
    if n < THROTTLE_ROWS_MIN or k >= 0.05 * n:
        return ""
    return (f"; CHECK THE TARGET: the fuel is read from the mass air flow, yet the intake manifold pressure "
            f"({counts.get('throttle_column')}) is below {THROTTLED_KPA:g} kPa on {k} of {n} rows with the engine "
            "running idle or on the overrun ({:.1%}; a throttled petrol engine's falls to 20–40 kPa there): an unthrottled "
            "engine — a diesel, whose air flow says nothing of its fuel (declare powertrain.fuel = \"diesel\"), "
            "or a petrol engine with valve-lift control".format(k / n))
