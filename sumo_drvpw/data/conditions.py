"""The road and the air a drive log was driven in: grade, wind and air density, derived
where the log omits them (:func:`sumo_drvpw.data.log.read_log`'s derivations).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sumo_drvpw.data.trips import grade_from_elevation, trips_without as _trips_without
from sumo_drvpw.model.air import air_density
from sumo_drvpw.model.constants import P_STD_KPA, RHO_DEFAULT


def derive_conditions(df: pd.DataFrame, t: np.ndarray, v: np.ndarray, trip_codes: np.ndarray,
                      start: np.ndarray, opt, counts: dict) -> None:
    """``grade_rad``, ``wind_mps`` and ``air_density_kgm3`` of a validated table (``df``
    changed in place; their sources and fills in ``counts``).

    Parameters
    ----------
    df : the concatenated, validated table; t, v : its time [s] and speed [m/s]
    trip_codes : contiguous trip code per row (0, 1, … in order); start : a trip's first row
    opt : the reading options (:class:`sumo_drvpw.data.log.ReadOptions`)
    """
    def elevation_grade():
        step = v * np.r_[0.0, np.diff(t)]
        step[start] = 0.0
        dist = pd.Series(step).groupby(trip_codes, sort=False).cumsum().to_numpy()
        return grade_from_elevation(df["elevation_m"].to_numpy(float), dist, trip_codes, opt.grade_window_m)

    has_z = "elevation_m" in df and np.isfinite(df["elevation_m"].to_numpy(float)).any()
    lacking = None
    if "grade_rad" in df:
        counts["grade_source"] = "grade_rad column"
        lacking = _trips_without(df["grade_rad"], trip_codes)
    elif "grade_pct" in df:
        df["grade_rad"] = np.arctan(df["grade_pct"].to_numpy(float) / 100.0)
        counts["grade_source"] = "grade_pct column"
        lacking = _trips_without(df["grade_pct"], trip_codes)
    elif has_z:
        z = df["elevation_m"].to_numpy(float)
        df["grade_rad"] = elevation_grade()
        counts["grade_source"] = (f"elevation_m over distance: 1 m grid, {opt.grade_window_m:g} m "
                                  "moving average, gradient")
        # a trip without elevation is read flat, a stretch without it (no GPS fix) is bridged
        # or held: both said (no grade energy there)
        n_fin = pd.Series(np.isfinite(z)).groupby(trip_codes).transform("sum").to_numpy()
        flat = df["trip_id"].to_numpy()[start & (n_fin < 2)]
        if len(flat):
            counts["grade_flat_trips"] = [str(x) for x in flat]
        counts["elevation_missing_samples"] = int((~np.isfinite(z) & (n_fin >= 2)).sum())
    else:
        df["grade_rad"] = 0.0
        counts["grade_source"] = ("none (elevation_m holds no value: flat road assumed)" if "elevation_m" in df
                                  else "none (flat road assumed)")
        counts["grade_flat_trips"] = [str(x) for x in df["trip_id"].to_numpy()[start]]
    if lacking is not None and lacking.any():  # a file of a folder without the column: its
        # trips' grade from their elevation, else flat, as the file read alone (NaN: left out)
        fill = np.nan_to_num(elevation_grade()) if has_z else np.zeros(len(df))
        df["grade_rad"] = np.where(lacking, fill, df["grade_rad"].to_numpy(float))
        counts["grade_filled_rows"] = int(lacking.sum())
        zs = df["elevation_m"].to_numpy(float) if has_z else np.full(len(df), np.nan)
        no_z = np.bincount(trip_codes, weights=np.isfinite(zs).astype(float)) < 2
        flat = df["trip_id"].to_numpy()[start & lacking & no_z[trip_codes]]
        if len(flat):
            counts["grade_flat_trips"] = [str(x) for x in flat]

    if "wind_mps" in df:
        counts["wind_source"] = "wind_mps column"
    elif "airspeed_mps" in df:
        df["wind_mps"] = v - df["airspeed_mps"].to_numpy(float)
        counts["wind_source"] = "speed − airspeed_mps"
    else:
        df["wind_mps"] = 0.0
        counts["wind_source"] = "none (still air assumed)"

    if "air_density_kgm3" in df:
        counts["air_density_source"] = "air_density_kgm3 column"
    elif "ambient_c" in df:
        p_kpa = df["pressure_kpa"].to_numpy(float) if "pressure_kpa" in df else np.full(len(df), P_STD_KPA)
        p_kpa = np.where(np.isnan(p_kpa), P_STD_KPA, p_kpa)  # missing pressure: standard
        rho = air_density(df["ambient_c"].to_numpy(float), p_kpa)
        missing = np.isnan(rho)  # no temperature logged in that sample: the default density
        df["air_density_kgm3"] = np.where(missing, RHO_DEFAULT, rho)
        counts["air_density_source"] = "ideal gas from ambient_c and pressure_kpa"
        counts["air_density_default_samples"] = int(missing.sum())
    else:
        df["air_density_kgm3"] = RHO_DEFAULT
        counts["air_density_source"] = f"default {RHO_DEFAULT} kg/m³"
