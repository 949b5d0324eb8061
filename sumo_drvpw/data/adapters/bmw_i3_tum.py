"""Adapter for the TUM BMW i3 real-driving trips (``bmw-i3-tum``).

Source: Steinstraeter et al., "Battery and Heating Data in Real Driving Cycles", TUM,
IEEE DataPort. One ``TripXNN.csv`` per trip (';'-separated, latin-1, 10 Hz, labels
'Name [unit]'), plus ``overview.csv`` (one row per trip: date, route, weather, …).

Mapping (everything else is kept as ``snake_name_<unit suffix>`` in SI):

- Time [s] → ``time_s``; Velocity [km/h] → ``speed_mps``; Elevation [m] → ``elevation_m``
  (whole metres: the log reader smooths grade over distance).
- Motor Torque [Nm] → ``motor_torque_nm``; ``motor_speed_rpm`` = v / r_wheel · i_gear
  (``sumo_drvpw/model/builtin/vehicles/bmw_i3.toml``), since the files hold no motor speed.
- Longitudinal Acceleration [m/s^2] → ``imu_accel_mps2`` (accelerometer: includes
  g·sin θ, so it is not ``accel_mps2``; the reader derives dv/dt from speed).
- Battery Current [A] → ``battery_current_a`` with the sign flipped (logged negative when
  discharging; canonical: positive when discharging, as declared in bmw_i3.toml).
- Heating Power CAN [kW] → ``heater_power_w``; AirCon Power [kW] → ``aircon_power_w``;
  ``heater_electric_w`` = Heater Voltage × Heater Current (the heater's electrical power at
  the battery; NaN in files without them, e.g. TripA03–A21);
  Ambient Temperature [°C] → ``ambient_c``; Cabin Temperature Sensor → ``cabin_temp_c``.
- overview.csv joined per trip: ``route``, ``weather``, ``season`` (summer/winter),
  ``winter`` (bool), ``cabin_setpoint_c``, ``added_mass_kg`` (from notes like '+70 kg'),
  and ``mass_kg`` = vehicle mass + added mass.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.model.constants import KMH, RPM
from sumo_drvpw.errors import UserError
from sumo_drvpw.data.adapters._common import extra_values, generic_name, new_report, numeric, read_csv_strict, snake, split_header
from sumo_drvpw.data.adapters._common import DIMENSIONS, clean_time_and_speed, lookup_unit, unique_names

FORMAT = "bmw-i3-tum"
SUFFIXES = (".csv",)
VEHICLE = "bmw_i3"

#: label without unit (case-insensitive) → (canonical or extra name, factor to SI)
NAMES = {
    "time": ("time_s", 1.0),
    "velocity": ("speed_mps", KMH),
    "elevation": ("elevation_m", 1.0),
    "throttle": ("throttle_pct", 1.0),
    "motor torque": ("motor_torque_nm", 1.0),
    "longitudinal acceleration": ("imu_accel_mps2", 1.0),
    "regenerative braking signal": ("regen_braking_signal", 1.0),
    "battery voltage": ("battery_voltage_v", 1.0),
    "battery current": ("battery_current_a", -1.0),
    "battery temperature": ("battery_temp_c", 1.0),
    "max. battery temperature": ("battery_temp_max_c", 1.0),
    "soc": ("soc_pct", 1.0),
    "displayed soc": ("soc_displayed_pct", 1.0),
    "min. soc": ("soc_min_pct", 1.0),
    "max. soc": ("soc_max_pct", 1.0),
    "heating power can": ("heater_power_w", 1000.0),
    "heating power lin": ("heater_power_lin_w", 1.0),
    "requested heating power": ("heater_power_requested_w", 1.0),
    "aircon power": ("aircon_power_w", 1000.0),
    "heater signal": ("heater_signal", 1.0),
    "heater voltage": ("heater_voltage_v", 1.0),
    "heater current": ("heater_current_a", 1.0),
    "ambient temperature": ("ambient_c", 1.0),
    "ambient temperature sensor": ("ambient_sensor_c", 1.0),
    "cabin temperature sensor": ("cabin_temp_c", 1.0),
}
REQUIRED = ("time", "velocity", "motor torque", "battery voltage", "battery current")
#: roles of the columns this adapter writes (drive-log spec "Roles"; stored with the log)
ROLES = {
    "throttle_pct": "response", "regen_braking_signal": "response", "battery_temp_c": "response",
    "battery_temp_max_c": "response", "soc_pct": "response", "soc_displayed_pct": "response",
    "soc_min_pct": "response", "soc_max_pct": "response", "heater_power_w": "load",
    "heater_electric_w": "load",
    "heater_power_lin_w": "load", "heater_power_requested_w": "load", "aircon_power_w": "load",
    "heater_voltage_v": "response", "heater_current_a": "response", "heater_signal": "response",
    "ambient_c": "condition", "ambient_sensor_c": "condition", "cabin_temp_c": "condition",
    "winter": "condition", "weather": "condition", "season": "condition", "route": "condition",
    "cabin_setpoint_c": "condition", "added_mass_kg": "condition", "fan": "condition",
    "trip_ambient_start_c": "condition", "trip_battery_temp_start_c": "condition",
    "trip_soc_start_pct": "condition", "trip_battery_temp_end_c": "response",
    "trip_soc_end_pct": "response", "trip_distance_m": "response", "trip_duration_s": "response",
}
WINTER_MONTHS = (11, 12, 1, 2, 3)
#: how many folders above a trip are searched for overview.csv when none is beside it
OVERVIEW_LEVELS_UP = 3


def _header_unit(label: str, name: str, factor: float, path) -> tuple[float, float]:
    """(factor, offset) of a known column from the unit its header writes (the TUM files'
    own: km/h, kW, …; another unit of the same quantity converts as written, e.g. a speed in
    [m/s]); no unit, or one this reader does not know: the TUM unit. A unit of another
    quantity (a speed in [kW]) is refused, naming the file and column."""
    unit = split_header(label)[1]
    u = lookup_unit(unit) if unit else None
    dim = next((d for d, suf in DIMENSIONS.items() if suf and name.endswith("_" + suf)), None)
    if u is None or dim is None or (dim == "percent" and u[0] == "dimensionless"):
        return factor, 0.0
    if u[0] != dim:
        raise UserError(f"{path}: column '{label}': unit '{unit}' is not a {dim.replace('_', ' ')} "
                        f"(this reader writes it as {name})")
    return (-u[1] if factor < 0 else u[1]), u[2]


def read_file(path: Path, overview: pd.DataFrame | None, vehicle) -> tuple[pd.DataFrame, dict]:
    """One TUM trip CSV → canonical frame and its report (trip_id = file stem)."""
    trip = path.stem
    raw = read_csv_strict(path, sep=";", encoding="latin-1")
    rep = new_report(path, trip, len(raw))
    labels = [str(c).replace("Â°", "°").strip() for c in raw.columns]
    keys = [split_header(c)[0].lower() for c in labels]
    if _decimal_comma(raw, keys):  # re-saved by a German-locale spreadsheet: '12,5'
        raw = read_csv_strict(path, sep=";", encoding="latin-1", decimal=",")
        rep["notes"].append("decimal comma (time and speed written like '0,1'): read with ',' as the "
                            "decimal mark")
    missing = [k for k in REQUIRED if k not in keys]
    if missing:
        sep_hint = (" (only one column: not ';'-separated?)" if raw.shape[1] == 1 else "")
        raise UserError(f"{path}: missing column '{missing[0]}'{sep_hint}; found "
                        f"{', '.join(labels[:6])}{' …' if len(labels) > 6 else ''}")
    names, cols = [], []
    for label, key, src in zip(labels, keys, raw.columns):
        if key in NAMES:
            name, factor = NAMES[key]
            factor, offset = _header_unit(label, name, factor, path)
            col = numeric(raw[src], path, label) * factor + offset
        else:  # not a TUM column: numeric where it reads so, else kept as text
            name, factor, offset = generic_name(label, rep["notes"])
            col = extra_values(raw[src], path, label, rep["notes"], factor, offset)
        names.append(name)
        cols.append(col)
    names = unique_names(names)
    df = pd.DataFrame(dict(zip(names, cols)), index=raw.index)
    df = clean_time_and_speed(df, path, rep)
    # no motor-speed column in these files: single-speed gear and wheel radius from the vehicle file
    if "motor_speed_rpm" not in df.columns:
        ratio = vehicle.need("powertrain", "gear_ratio")
        radius = vehicle.need("powertrain", "wheel_radius_m")
        df["motor_speed_rpm"] = df["speed_mps"] / radius * ratio / RPM
        rep["notes"].append(f"motor_speed_rpm from speed: gear {ratio}, wheel radius {radius} m "
                            f"({vehicle.path})")
    # the heater's own electrical power, a battery-side load (`calibrate --target battery
    # --load heater_electric_w`); unknown (NaN) where the file lacks heater voltage or current:
    # an unknown load is not a zero load (the chain fit leaves such samples out)
    if {"heater_voltage_v", "heater_current_a"} <= set(df.columns):
        df["heater_electric_w"] = df["heater_voltage_v"] * df["heater_current_a"]
    else:
        df["heater_electric_w"] = np.nan
        rep["notes"].append("no heater voltage and current: heater_electric_w unknown (NaN)")
    df.insert(0, "trip_id", trip)
    df = _join_overview(df, trip, overview, vehicle, rep)
    return df.reset_index(drop=True), rep


def _decimal_comma(raw: pd.DataFrame, keys: list[str]) -> bool:
    """True when the time and speed columns are text whose every value is a number written
    with a decimal comma (the TUM files use ';' between columns, so a ',' is no separator)."""
    cols = [raw.iloc[:, keys.index(k)] for k in ("time", "velocity") if k in keys]
    if len(cols) < 2 or any(pd.api.types.is_numeric_dtype(c) for c in cols):
        return False
    text = pd.concat(cols).dropna().astype(str).str.strip()
    return bool(len(text)) and text.str.fullmatch(r"-?\d+(,\d+)?").all() and text.str.contains(",").any()


def read_overview(folder: Path) -> pd.DataFrame | None:
    """overview.csv of the data set (one row per trip), or None when the folder lacks it."""
    p = folder / "overview.csv"
    if not p.is_file():
        return None
    raw = None
    for enc in ("utf-8", "latin-1"):
        try:
            raw = read_csv_strict(p, sep=",", encoding=enc)
            break
        except UserError:
            if enc == "latin-1":
                raise
    cols = {snake(c): c for c in raw.columns}

    def col(prefix):
        for k, c in cols.items():
            if k.startswith(prefix):
                return raw[c]
        return pd.Series([np.nan] * len(raw), index=raw.index)

    if "trip" not in cols:
        raise UserError(f"{p}: missing column 'Trip'")
    date = col("date").astype(str)
    ymd = date.str.extract(r"(\d{4})[-_](\d{2})[-_](\d{2})[-_ ](\d{2})-(\d{2})-(\d{2})")
    stamp = pd.to_datetime(ymd[0] + "-" + ymd[1] + "-" + ymd[2] + " " + ymd[3] + ":" + ymd[4]
                           + ":" + ymd[5], errors="coerce")
    note = col("note").astype(object).fillna("").astype(str)
    added = note.str.extract(r"\+\s*(\d+(?:\.\d+)?)\s*kg", flags=re.I)[0].astype(float).fillna(0.0)
    month = stamp.dt.month
    trip = raw[cols["trip"]].astype(str).str.strip()
    winter = month.isin(WINTER_MONTHS).where(month.notna(), trip.str.startswith("TripB"))
    out = pd.DataFrame({
        "trip_id": trip,
        "trip_start": stamp.dt.strftime("%Y-%m-%dT%H:%M:%S"),
        "route": col("route").astype(str).str.strip(),
        "weather": col("weather").astype(str).str.strip(),
        "season": np.where(winter.astype(bool), "winter", "summer"),
        "winter": winter.astype(bool),
        "trip_battery_temp_start_c": numeric(col("battery_temperature_start"), p, "Battery Temperature (Start)"),
        "trip_battery_temp_end_c": numeric(col("battery_temperature_end"), p, "Battery Temperature (End)"),
        "trip_soc_start_pct": 100.0 * numeric(col("battery_state_of_charge_start"), p, "Battery State of Charge (Start)"),
        "trip_soc_end_pct": 100.0 * numeric(col("battery_state_of_charge_end"), p, "Battery State of Charge (End)"),
        "trip_ambient_start_c": numeric(col("ambient_temperature_start"), p, "Ambient Temperature (Start)"),
        "cabin_setpoint_c": numeric(col("target_cabin_temperature"), p, "Target Cabin Temperature"),
        "trip_distance_m": 1000.0 * numeric(col("distance_km"), p, "Distance [km]"),
        "trip_duration_s": 60.0 * numeric(col("duration_min"), p, "Duration [min]"),
        "fan": col("fan").astype(object).fillna("").astype(str).str.strip(),
        "note": note.str.strip(),
        "added_mass_kg": added,
    })
    out = out.drop_duplicates()  # a row copied twice says the same twice
    again = out["trip_id"].duplicated(keep=False)
    if again.any():  # two rows of one trip that disagree: which one holds is not for the reader to guess
        rows = out.index[again & (out["trip_id"] == out.loc[again, "trip_id"].iloc[0])]
        differ = [c for c in out.columns if out.loc[rows, c].astype(str).nunique() > 1]
        raise UserError(f"{p}: trip {out.loc[rows[0], 'trip_id']} is listed in data rows "
                        f"{', '.join(map(str, rows))} with different values ({', '.join(differ)}): keep one row")
    return out.set_index("trip_id")


def _join_overview(df, trip, overview, vehicle, rep):
    """Add the overview row of this trip as constant columns, and mass_kg = vehicle + added load."""
    if overview is None:
        rep["notes"].append(f"no overview.csv beside the trip or up to {OVERVIEW_LEVELS_UP} folders above it: "
                            "no trip metadata joined")
        return df
    if trip not in overview.index:
        rep["notes"].append(f"trip {trip} not in overview.csv: no trip metadata joined")
        return df
    row = overview.loc[trip]
    for k, v in row.items():
        df[k] = v
    df["mass_kg"] = vehicle.mass_kg + float(row["added_mass_kg"])
    return df


def read(paths) -> tuple[list[pd.DataFrame], list[dict], list[str]]:
    """Read TUM trip files (overview.csv in the same folder is joined, never read as a trip)."""
    from sumo_drvpw.model.vehicles import load_vehicle
    from sumo_drvpw.data.adapters._common import expand_paths, read_each

    vehicle = load_vehicle(VEHICLE)
    files = [f for f in expand_paths(paths, SUFFIXES, "TUM trip CSV") if f.name != "overview.csv"]
    if not files:
        from sumo_drvpw.data.paths import subfolder_hint

        folders = [Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths) if Path(p).is_dir()]
        raise UserError(f"{FORMAT}: no trip file among {paths} (overview.csv alone is not a trip)"
                        + "".join(subfolder_hint(d, SUFFIXES) for d in folders[:1]))
    overviews: dict[Path, pd.DataFrame | None] = {}

    def read_one(f: Path):
        # overview.csv beside the trip, else in a folder above it (trips sorted into
        # sub-folders by month or route, the data set's overview at the top)
        # (one above is taken only when it lists this trip: an unrelated overview.csv is not)
        folder = f.parent.resolve()
        for d in [folder, *folder.parents][:OVERVIEW_LEVELS_UP + 1]:
            if d not in overviews:
                try:
                    overviews[d] = read_overview(d)
                except UserError:  # an overview.csv above that is not the TUM one: not this trip's
                    if d == folder:
                        raise
                    overviews[d] = None
            if overviews[d] is not None and (d == folder or f.stem in overviews[d].index):
                break
        else:
            d = folder
        df, rep = read_file(f, overviews[d], vehicle)
        if d != folder and overviews[d] is not None and "trip_start" in df:
            rep["notes"].append(f"trip metadata from {d / 'overview.csv'} (a folder above the trip)")
        return df, rep

    frames, reports = read_each(files, read_one)
    return frames, reports, [f"vehicle file {vehicle.path}"]
