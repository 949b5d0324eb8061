"""Plausible ranges of a drive log's physical columns, checked as a log is read: a value
outside its column's range is no measurement of a road vehicle (a unit mistaken, a logger's
glitch or 'no reading' value) and is refused, naming the file, the column, the row and the
value (beside the per-value rules of :mod:`sumo_drvpw.data.log`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import MASS_MAX_KG

#: The fastest a shaft of a road vehicle's powertrain turns, either way [rpm]: engines stay
#: below about 10,000 rpm (a road car's redline; a heavy diesel's about 2,500), traction
#: motors below about 20,000 (the Prius 3's MG2 reaches about 13,500 rpm, ORNL's evaluation
#: of the 2010 Prius; the BMW i3's motor 11,400; the shared logs: Prius Gen 2 MG1 7,700,
#: MG2 4,500, engine 3,900, i3 motor 11,200). 30,000 leaves room for faster motors and
#: still refuses a logger's garbage or a value scaled wrongly by far (1e6 'rpm'); speeds in
#: rad/s taken for rpm read 9.5 times too slow and are not caught here.
SHAFT_SPEED_MAX_RPM = 30_000.0
#: The largest torque of a road vehicle's engine or traction motor shaft, either way [N·m]:
#: the largest truck engines give about 3.7 kN·m (Scania's 770-hp V8: 3,700 N·m), the
#: direct-drive traction motors of buses and trucks are of that order, a car's far less
#: (Prius 3 MG2 207 N·m; the shared logs: Prius Gen 2 MG2 267, MG1 45, i3 motor 250).
#: 20 kN·m is five times the largest and still refuses a logger's garbage (1e7 N·m) or a
#: torque in N·cm of any sizeable machine.
SHAFT_TORQUE_MAX_NM = 20_000.0
#: The largest power of a road vehicle, either way [W]: 100 t (MASS_MAX_KG) at the reader's
#: top speed of 100 m/s climbing or braking at 1 g would be 98 MW; the most powerful road cars
#: give about 1.5 MW and the largest truck engines about 0.6 MW. Catches a logger's garbage
#: (1e12 W), not a power in kW (the calibration's acc coefficient tells that, 1000x off).
POWER_MAX_W = 100e6
#: A traction battery's terminal voltage [V]: never below 0; the highest packs are about
#: 1,000 V (800-V platforms run to about 900 V), and 1,500 V DC is the top of the voltage
#: class B that the vehicle standards cover (ISO 6469-3, UN ECE R100). Catches a voltage in mV
#: (350 V: 350,000) or a logger's negative 'no reading' value.
BATTERY_VOLTAGE_MAX_V = 1_500.0
#: A traction battery's current, either way [A]: the megawatt charging system (MCS) is rated
#: up to 3,000 A, and a 1.5-MW pack at 400 V draws under 4 kA (the shared logs reach 404 A).
#: 10 kA catches a current in mA of any sizeable one (100 A: 100,000).
BATTERY_CURRENT_MAX_A = 10_000.0
_RPM_HINT = ("a shaft speed in rpm (revolutions per minute): no road vehicle's engine or traction motor turns "
             f"faster than {SHAFT_SPEED_MAX_RPM:,.0f} rpm")
_NM_HINT = ("a shaft torque in N·m: no road vehicle's engine or traction motor gives more than "
            f"{SHAFT_TORQUE_MAX_NM:,.0f} N·m (in N·cm? divide by 100)")
#: Plausible ranges of optional physical columns: (low, high, unit, hint when outside).
RANGES = {
    "mass_kg": (1.0, MASS_MAX_KG, "kg", "a vehicle mass is > 0 and at most 100 t"),
    "pressure_kpa": (10.0, 200.0, "kPa", "ambient pressure in kPa (101.3 at sea level; in Pa? divide by 1000)"),
    "ambient_c": (-90.0, 80.0, "°C", "ambient temperature in °C (in K? subtract 273.15)"),
    "air_density_kgm3": (0.1, 2.0, "kg/m³", "air density is about 1.2 kg/m³"),
    "wind_mps": (-100.0, 100.0, "m/s", "wind along the direction of travel, in m/s"),
    "airspeed_mps": (-50.0, 150.0, "m/s", "air speed in m/s"),
    "yaw_rate_rps": (-10.0, 10.0, "rad/s", "yaw rate in rad/s (in deg/s? multiply by π/180)"),
    "elevation_m": (-500.0, 9000.0, "m", "elevation above sea level in m (in feet? multiply by 0.3048)"),
    # the power-split (engine, MG1, MG2) and single-motor columns of the measured power
    **{c: (-SHAFT_SPEED_MAX_RPM, SHAFT_SPEED_MAX_RPM, "rpm", _RPM_HINT)
       for c in ("ice_speed_rpm", "mg1_speed_rpm", "mg2_speed_rpm", "motor_speed_rpm")},
    **{c: (-SHAFT_TORQUE_MAX_NM, SHAFT_TORQUE_MAX_NM, "N·m", _NM_HINT)
       for c in ("mg1_torque_nm", "mg2_torque_nm", "motor_torque_nm")},
    "power_w": (-POWER_MAX_W, POWER_MAX_W, "W", f"a driving power in W: no road vehicle's exceeds {POWER_MAX_W:.0e} W"),
    "battery_voltage_v": (0.0, BATTERY_VOLTAGE_MAX_V, "V",
                          "a traction battery's terminal voltage in V: never negative, at most about 1,000 V "
                          "(in mV? divide by 1000)"),
    "battery_current_a": (-BATTERY_CURRENT_MAX_A, BATTERY_CURRENT_MAX_A, "A",
                          "a traction battery's current in A (in mA? divide by 1000)"),
}


def check_ranges(df: pd.DataFrame, p: Path) -> None:
    """UserError for the first value of a :data:`RANGES` column outside its range, naming
    the file ``p``, the column, the row and the value (a few such values among many good
    ones: said as a logger's glitch or 'no reading' value, to be read as missing)."""
    for c, (lo, hi, unit, hint) in RANGES.items():
        if c in df:
            _check_range(df[c].to_numpy(float, na_value=np.nan), p, c, lo, hi, unit, hint)
    from sumo_drvpw.data.conditions import gps_speed_columns

    for c in gps_speed_columns(df.columns):  # (read beside the speed, data/conditions.speed_against_gps)
        _check_range(_numbers(df[c], p, c), p, c, 0.0, GPS_SPEED_MAX_MPS, "m/s", _GPS_HINT)


#: A GPS speed [m/s], as the log's speed_mps: never negative, no road vehicle's above 100 m/s
GPS_SPEED_MAX_MPS = 100.0
_GPS_HINT = "a GPS speed in m/s: never negative, no road vehicle's above 100 m/s (in km/h? divide by 3.6)"


def _numbers(s: pd.Series, p, c: str) -> np.ndarray:
    """The numbers of column ``c`` (empty cells NaN); text refused naming the row and the value."""
    x = pd.to_numeric(s, errors="coerce").to_numpy(float, na_value=np.nan)
    text = np.isnan(x) & s.notna().to_numpy() & (s.astype(str).str.strip() != "").to_numpy()
    if text.any():
        i = int(np.flatnonzero(text)[0])
        raise UserError(f"{p}: column '{c}' has a non-numeric value {s.iloc[i]!r} at row {i}")
    return x


def _check_range(x: np.ndarray, p, c: str, lo: float, hi: float, unit: str, hint: str) -> None:
    """UserError for the first value of ``x`` (column ``c`` of ``p``) outside [lo, hi] [unit]."""
    bad = (x < lo) | (x > hi)
    if bad.any():
        i, ok = int(np.flatnonzero(bad)[0]), np.isfinite(x) & ~bad
        few = ok.any() and bad.sum() <= 0.01 * ok.sum()  # a few glitches among good values
        raise UserError(f"{p}: column '{c}' is {x[i]:g} at row {i}, outside [{lo:g}, {hi:g}] {unit}: "
                        + (f"of the {int(bad.sum() + ok.sum())} values read with it, {int(bad.sum())} are outside ({', '.join(f'{u:g}' for u in np.unique(x[bad])[:4])}"
                           f"), the rest in [{x[ok].min():g}, {x[ok].max():g}]: a logger's glitch or 'no reading' "
                           "value? read them as missing (the import columns mapping's na_values)" if few else hint))


#: A fuel mass flow [g/s]: a 570-kW truck engine (Scania's 770-hp V8) at full load and about
#: 42 % efficiency burns about 32 g/s of diesel; 200 g/s is six times that.
FUEL_RATE_MAX_GPS = 200.0
#: A fuel volume flow [L/h]: the same engine's 32 g/s is about 140 L/h of diesel; 1,000 L/h is
#: seven times that.
FUEL_RATE_MAX_LPH = 1_000.0
#: An engine's mass air flow [g/s]: OBD's MAF reading (PID 0x10) ends at 655.35 g/s, and a 16-L
#: truck diesel at full load breathes about 0.8 kg/s; 2 kg/s is more than twice that.
AIR_FLOW_MAX_GPS = 2_000.0
#: Of the flows a fuel power is measured with, found by name (:func:`sumo_drvpw.data.powertrain.flow_columns`):
#: (low, high, unit, hint when outside). A fuel trim's OBD PIDs (0x06–0x09) read −100 … 99.2 %.
FLOW_RANGES = {
    "fuel_rate_gps": (0.0, FUEL_RATE_MAX_GPS, "g/s", "a fuel mass flow in g/s: never negative (in mg/s? divide by 1000)"),
    "fuel_lph": (0.0, FUEL_RATE_MAX_LPH, "L/h", "a fuel volume flow in L/h: never negative (in mL/h? divide by 1000)"),
    "air_gps": (0.0, AIR_FLOW_MAX_GPS, "g/s", "an engine's mass air flow in g/s: never negative (in mg/s? divide by 1000)"),
    "trim_pct": (-100.0, 100.0, "%", "a fuel trim in % (−100 … 99.2 as OBD reads it; a fraction? multiply by 100)"),
}


def flow_values(log, col: str, kind: str) -> np.ndarray:
    """The numbers of the flow column ``col`` of a read log (``kind``: a :data:`FLOW_RANGES`
    key; empty cells NaN), refused in one line naming the log, the column, the row and the
    value where one is text, infinite or outside its range (these columns are found by name
    and checked where a fuel power is measured from them, in memory and streamed alike)."""
    s = log.df[col]
    if pd.api.types.is_numeric_dtype(s) or pd.api.types.is_bool_dtype(s):
        x = s.to_numpy(float, na_value=np.nan)
    else:
        x = pd.to_numeric(s, errors="coerce").to_numpy(float)
        text = np.isnan(x) & s.notna().to_numpy() & (s.astype(str).str.strip() != "").to_numpy()
        if text.any():
            i = int(np.flatnonzero(text)[0])
            raise UserError(f"{log.describe()}: column '{col}' has a non-numeric value {s.iloc[i]!r} at row {i}")
    inf = np.isinf(x)
    if inf.any():
        i = int(np.flatnonzero(inf)[0])
        raise UserError(f"{log.describe()}: column '{col}' is {x[i]:g} at row {i}; values must be finite")
    _check_range(x, log.describe(), col, *FLOW_RANGES[kind])
    return x
