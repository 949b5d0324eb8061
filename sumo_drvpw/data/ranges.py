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
