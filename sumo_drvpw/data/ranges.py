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
}


def check_ranges(df: pd.DataFrame, p: Path) -> None:
    """UserError for the first value of a :data:`RANGES` column outside its range, naming
    the file ``p``, the column, the row and the value (a few such values among many good
    ones: said as a logger's glitch or 'no reading' value, to be read as missing)."""
    for c, (lo, hi, unit, hint) in RANGES.items():
        if c in df:
            x = df[c].to_numpy(float, na_value=np.nan)
            bad = (x < lo) | (x > hi)
            if bad.any():
                i, ok = int(np.flatnonzero(bad)[0]), np.isfinite(x) & ~bad
                few = ok.any() and bad.sum() <= 0.01 * ok.sum()  # a few glitches among good values
                raise UserError(f"{p}: column '{c}' is {x[i]:g} at row {i}, outside [{lo:g}, {hi:g}] {unit}: "
                                + (f"of the {int(bad.sum() + ok.sum())} values read with it, {int(bad.sum())} are outside ({', '.join(f'{u:g}' for u in np.unique(x[bad])[:4])}"
                                   f"), the rest in [{x[ok].min():g}, {x[ok].max():g}]: a logger's glitch or 'no reading' "
                                   "value? read them as missing (the import columns mapping's na_values)" if few else hint))
