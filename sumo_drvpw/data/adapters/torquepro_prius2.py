"""Adapter for Torque Pro (phone OBD app) logs (``torquepro``; ``torquepro-prius2`` is the
same reader, named for the 2nd-generation Prius logs it was written for).

Source: repository denjiv/PETS (``From_CdA_Act.json``, ``To_CdA_Act.json``): a JSON list of
records, one per sample (≈1.4 Hz, irregular), numbers sometimes as strings, ``"-"`` while
the OBD link (or a PID) has no value. Also accepts the same columns as Torque's CSV export.

Mapping (everything else kept as ``snake_name_<unit suffix>`` in SI):

- Device Time (ms resolution) → ``time_s`` = seconds since the file's first sample.
- Speed (OBD)(mph) → ``speed_mps``; Speed (GPS)(mph) → ``gps_speed_mps``.
- GPS Altitude(ft) → ``elevation_m`` (the phone's 'Altitude' [m] fills its ``-`` gaps, and is
  the elevation of a log without the GPS Altitude PID, noted).
- Engine RPM → ``ice_speed_rpm``; MG1/MG2 Revolution(RPM) and Torque(Nm) →
  ``mg1_speed_rpm``, ``mg1_torque_nm``, ``mg2_speed_rpm``, ``mg2_torque_nm``.
- HV Battery Current(Amp) → ``battery_current_a`` (as logged: positive when discharging);
  Power Resource VB(Volt) → ``battery_voltage_v``.
- Ambient air temp(°F) → ``ambient_c``; G(x/y/z) are phone accelerometer axes in m/s²
  (``phone_ax_mps2`` …; include gravity), G(calibrated) and Acceleration Sensor(Total)(g)
  in g → m/s².

Torque writes each value in the unit its user chose: a label of the table above in another
unit (``Speed (OBD)(km/h)``, ``GPS Altitude(m)``, ``Ambient air temp(°C)``) maps to the same
column, converted from the unit in its brackets. A header row repeated inside a CSV (Torque
starts a new logging session in the same file) is dropped and counted.

Samples before the OBD link is up (any powertrain field ``-``) are dropped and counted as
'link not up (-)'; later ``-`` cells become NaN (counted per column in the notes). A
powertrain field that never answers in the whole log (an EV's engine speed, a PID the car
does not support) does not hold the link down: it stays NaN and is named in the notes.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.model.constants import FT, G, MPH
from sumo_drvpw.errors import UserError
from sumo_drvpw.data.adapters._common import (DIMENSIONS, clean_time_and_speed, drop, extra_values, generic_name,
                                              lookup_unit, new_report, numeric, split_header, unique_names)

FORMAT = "torquepro-prius2"
SUFFIXES = (".json", ".csv")
TIME = "Device Time"
TIME_FORMAT = "%d-%m-%Y %H:%M:%S.%f"  # its month, written in English (%b), as a number (MONTHS)
#: the English month abbreviations of 'Device Time' ('25-Mar-2017 …') → month numbers: read by
#: this table, not by %b, which pandas reads in the process's LC_TIME (an application or
#: notebook that set a German locale read no 'Mar', a Turkish one no 'Oct')
MONTHS = {m: f"{i:02d}" for i, m in enumerate(("jan", "feb", "mar", "apr", "may", "jun", "jul", "aug",
                                               "sep", "oct", "nov", "dec"), 1)}

#: vendor label → (name, factor, offset)
NAMES = {
    "Speed (OBD)(mph)": ("speed_mps", MPH, 0.0),
    "Speed (GPS)(mph)": ("gps_speed_mps", MPH, 0.0),
    "GPS Speed (Meters-second)": ("gps_speed_phone_mps", 1.0, 0.0),
    "GPS Altitude(ft)": ("elevation_m", FT, 0.0),
    "Altitude": ("altitude_phone_m", 1.0, 0.0),
    "Longitude": ("longitude_deg", 1.0, 0.0),
    "Latitude": ("latitude_deg", 1.0, 0.0),
    "Bearing": ("bearing_deg", 1.0, 0.0),
    "Horizontal Dilution of Precision": ("gps_hdop", 1.0, 0.0),
    "G(x)": ("phone_ax_mps2", 1.0, 0.0),
    "G(y)": ("phone_ay_mps2", 1.0, 0.0),
    "G(z)": ("phone_az_mps2", 1.0, 0.0),
    "G(calibrated)": ("phone_accel_calibrated_mps2", G, 0.0),
    "Acceleration Sensor(Total)(g)": ("phone_accel_total_mps2", G, 0.0),
    "Ambient air temp(°F)": ("ambient_c", 5.0 / 9.0, -32.0 * 5.0 / 9.0),
    "Battery power (kW)(kW)": ("battery_power_obd_w", 1000.0, 0.0),
    "Engine RPM(rpm)": ("ice_speed_rpm", 1.0, 0.0),
    "HV Battery Current(Amp)": ("battery_current_a", 1.0, 0.0),
    "Power Resource VB(Volt)": ("battery_voltage_v", 1.0, 0.0),
    "Power Resource IB(Amp)": ("battery_current_ib_a", 1.0, 0.0),
    "MG1 Revolution(RPM)": ("mg1_speed_rpm", 1.0, 0.0),
    "MG1 Torque(Nm)": ("mg1_torque_nm", 1.0, 0.0),
    "MG2 Revolution(RPM)": ("mg2_speed_rpm", 1.0, 0.0),
    "MG2 Torque(Nm)": ("mg2_torque_nm", 1.0, 0.0),
    "Motor (MG1) Torque Execute Value(Nm)": ("mg1_torque_exec_nm", 1.0, 0.0),
    "Motor (MG2) Torque Execute Value(Nm)": ("mg2_torque_exec_nm", 1.0, 0.0),
    "Regenerative Brake Torque(Nm)": ("regen_brake_torque_nm", 1.0, 0.0),
    "State Of Charge(%)": ("soc_pct", 1.0, 0.0),
    "Accelerator Pedal Angle(%)": ("accel_pedal_pct", 1.0, 0.0),
    "Engine Load(%)": ("engine_load_pct", 1.0, 0.0),
    "Engine Load(Absolute)(%)": ("engine_load_abs_pct", 1.0, 0.0),
    "GPS Latitude(°)": ("gps_latitude_deg", 1.0, 0.0),
    "GPS Longitude(°)": ("gps_longitude_deg", 1.0, 0.0),
}
TEXT = {"GPS Time": "gps_time"}
#: roles of the columns this adapter writes (drive-log spec "Roles"; stored with the log)
ROLES = {
    "ambient_c": "condition", "battery_power_obd_w": "response", "battery_current_ib_a": "response",
    "mg1_torque_exec_nm": "response", "mg2_torque_exec_nm": "response",
    "regen_brake_torque_nm": "response", "soc_pct": "response", "accel_pedal_pct": "response",
    "engine_load_pct": "response", "engine_load_abs_pct": "response",
    # the phone's accelerometer axes and the GPS speeds measure the car's motion, which
    # follows the power demand: the model's own inputs seen through another sensor
    "phone_ax_mps2": "response", "phone_ay_mps2": "response", "phone_az_mps2": "response",
    "phone_accel_calibrated_mps2": "response", "phone_accel_total_mps2": "response",
    "gps_speed_mps": "response", "gps_speed_phone_mps": "response",
    "bearing_deg": "condition", "latitude_deg": "condition", "longitude_deg": "condition",
    "gps_latitude_deg": "condition", "gps_longitude_deg": "condition",
    "altitude_phone_m": "condition",
}
SPEED = "Speed (OBD)(mph)"
#: what Torque writes for a value without a finite reading (its cost and economy PIDs at
#: standstill: per km of no distance): read as missing and counted
INFINITE = ("∞", "-∞", "Infinity", "-Infinity")


def _by_base() -> dict[str, str]:
    """Label without its unit → column name, for the labels whose bracket holds a unit."""
    out = {}
    for label, (name, _, _) in NAMES.items():
        base, unit = split_header(label)
        u = lookup_unit(unit)
        if unit and u is not None and name.endswith("_" + DIMENSIONS[u[0]]):
            out[base] = name
    return out


#: "Speed (OBD)" → speed_mps, … (the unit comes from the log's own label)
BY_BASE = _by_base()


def _mapping(label: str, notes: list) -> tuple[str, float, float]:
    """(name, factor, offset) of a Torque label: the table, the table's label in another
    unit, or a generic extra."""
    if label in NAMES:
        return NAMES[label]
    base, unit = split_header(label)
    name = BY_BASE.get(base)
    u = lookup_unit(unit) if name else None
    if u is not None and name.endswith("_" + DIMENSIONS[u[0]]):
        _, f, o = u
        return name, f, o
    return generic_name(label, notes)
#: the columns the table maps (a label in another unit included): strictly numeric
KNOWN = {name for name, _, _ in NAMES.values()}
#: powertrain fields whose first complete row marks the OBD link as up
LINK = ("Engine RPM(rpm)", "MG1 Revolution(RPM)", "MG1 Torque(Nm)", "MG2 Revolution(RPM)",
        "MG2 Torque(Nm)", "HV Battery Current(Amp)", "Power Resource VB(Volt)")


def _load(path: Path) -> pd.DataFrame:
    """The raw records of one Torque log (JSON list of objects, or Torque CSV) as strings/numbers."""
    if path.suffix.lower() == ".csv":
        from sumo_drvpw.data.adapters._common import read_csv_strict
        return read_csv_strict(path, sep=",", dtype=str, skipinitialspace=True)
    try:
        text = path.read_text(encoding="utf-8-sig")  # a byte-order mark is no JSON
    except UnicodeDecodeError as e:
        raise UserError(f"{path}: not UTF-8 text: {e}") from None
    if not text.strip():
        raise UserError(f"{path}: file is empty")
    try:
        doc = json.loads(text, object_pairs_hook=lambda pairs, n=[]: _record(pairs, path, n))
    except json.JSONDecodeError as e:
        raise UserError(f"{path}: not valid JSON: {e}") from None
    if not isinstance(doc, list) or not all(isinstance(r, dict) for r in doc):
        raise UserError(f"{path}: expected a JSON list of records (objects), got {type(doc).__name__}")
    if not doc:
        raise UserError(f"{path}: no data rows")
    return pd.DataFrame.from_records(doc)


def _record(pairs: list, path: Path, seen: list) -> dict:
    """A JSON object of a Torque log (``seen``: those read before it, one each); a key given twice
    (a damaged or hand-edited file: which value to read cannot be told) is a UserError naming it
    and the record (json keeps the last silently)."""
    seen.append(1)
    keys = [k for k, _ in pairs]
    if len(set(keys)) < len(keys):
        k = next(k for i, k in enumerate(keys) if k in keys[:i])
        raise UserError(f"{path}: data row {len(seen) - 1} holds '{k}' twice (a damaged or hand-edited file?): which value to read "
                        "cannot be told; keep one")
    return dict(pairs)


def read_file(path: Path) -> tuple[pd.DataFrame, dict]:
    """One Torque Pro log → canonical frame and report (trip_id = file stem)."""
    raw = _load(path)
    trip = path.stem
    rep = new_report(path, trip, len(raw))
    labels = [str(c).strip() for c in raw.columns]
    raw.columns = labels
    twice = next((m[1] for lab in labels if (m := re.fullmatch(r"(.+)\.\d+", lab)) and m[1] in labels), None)
    if path.suffix.lower() == ".csv" and twice is not None:  # (pandas names the second 'X.1')
        raise UserError(f"{path}: the header holds '{twice}' twice: which to read cannot be told; keep one")
    speed = [lab for lab in labels if lab != TIME and _mapping(lab, [])[0] == "speed_mps"]
    odd = [lab for lab in labels if split_header(lab)[0] == split_header(SPEED)[0]]
    if not speed and odd:  # 'Speed (OBD)(knots)': its unit named, not the column called missing
        raise UserError(f"{path}: column '{odd[0]}': unit '{split_header(odd[0])[1]}' is no speed this reader knows "
                        "(km/h, mph, m/s, ft/s)")
    for k, ok in ((TIME, TIME in labels), (SPEED, bool(speed))):
        if not ok:
            raise UserError(f"{path}: missing column '{k}' (or the OBD speed in another unit); "
                            f"found {', '.join(labels[:6])} …")
    again = raw[TIME].astype(str).str.strip() == TIME
    if again.any():  # a new logging session in the same CSV repeats the header
        raw = drop(raw, again.to_numpy(), "repeated header (a new logging session)", rep)
    t = pd.to_datetime(raw[TIME].astype(str).str.strip().str.replace(
        r"^(\d{1,2})-([A-Za-z]{3})-", lambda m: f"{m[1]}-{MONTHS.get(m[2].lower(), m[2])}-", regex=True),
        format=TIME_FORMAT, errors="coerce")
    bad = t.isna() & raw[TIME].notna()
    if bad.any():
        i = int(np.flatnonzero(bad.to_numpy())[0])
        raise UserError(f"{path}: column '{TIME}' data row {i} holds {raw[TIME].iloc[i]!r}, "
                        f"expected like '25-Mar-2017 11:46:29.523'")
    cols = {"time_s": (t - t.min()).dt.total_seconds()}
    dash, infinite, source = {}, {}, {}
    for label in labels:
        if label == TIME:
            continue
        if label in TEXT:
            cols[TEXT[label]] = raw[label].astype(str)
            continue
        name, f, o = _mapping(label, rep["notes"])
        if name in KNOWN and name in source:  # (one reading in two units: the later silently won)
            raise UserError(f"{path}: columns '{source[name]}' and '{label}' both give {name}: which to read cannot "
                            "be told; keep one")
        source[name] = label
        s = raw[label]
        n_dash = int(s.map(lambda x: isinstance(x, str) and x.strip() == "-").sum())
        if n_dash:
            dash[name] = n_dash
        n_inf = int(s.map(lambda x: isinstance(x, str) and x.strip() in INFINITE).sum())
        if n_inf:
            infinite[name] = n_inf
        if name in KNOWN:
            cols[name] = numeric(s, path, label, ("-", "") + INFINITE) * f + o
        else:  # a PID this reader does not know (a comment, a mode label: kept as text)
            cols[name] = extra_values(s, path, label, rep["notes"], f, o, ("-", "") + INFINITE)
    names = unique_names(list(cols))
    df = pd.DataFrame(dict(zip(names, cols.values())), index=raw.index)
    if "altitude_phone_m" in df and "elevation_m" in df:
        df["elevation_m"] = df["elevation_m"].fillna(df["altitude_phone_m"])
    elif "altitude_phone_m" in df and df["altitude_phone_m"].notna().any():
        df["elevation_m"] = df["altitude_phone_m"]  # the same GPS fix, without the PID
        rep["notes"].append("no 'GPS Altitude' column: elevation_m is the phone's 'Altitude' [m]")
    # samples before the OBD link is up: leading rows with any powertrain field '-'
    link = sorted({_mapping(k, [])[0] for k in labels} & {NAMES[k][0] for k in LINK})
    # (a field that never answers — no engine speed on an EV, a PID the car lacks — says
    # nothing of the link: it stays NaN and is named in the notes)
    silent = [k for k in link if df[k].isna().all()]
    if silent:
        rep["notes"].append("no value in the whole log (the car does not answer it): " + ", ".join(silent))
        link = [k for k in link if k not in silent]
    if link:
        complete = df[link].notna().all(axis=1).to_numpy()
        first = int(np.argmax(complete)) if complete.any() else len(df)
        df = drop(df, np.arange(len(df)) < first, "link not up (-)", rep)
    df = clean_time_and_speed(df, path, rep)
    if infinite:
        rep["notes"].append("'∞' cells (no finite reading) read as NaN: "
                            + ", ".join(f"{k} {n}" for k, n in infinite.items()))
    left = {k: int(df[k].isna().sum()) for k in dash if k in df and df[k].isna().any()}
    if left:
        rep["notes"].append("'-' cells kept as NaN after the link is up: "
                            + ", ".join(f"{k} {n}" for k, n in left.items()))
    df.insert(0, "trip_id", trip)
    return df.reset_index(drop=True), rep


def read(paths):
    """Read Torque Pro Prius logs (files or folders of .json/.csv)."""
    from sumo_drvpw.data.adapters._common import expand_paths, read_each

    frames, reports = read_each(expand_paths(paths, SUFFIXES, "Torque Pro log"), read_file)
    battery = any("battery_current_a" in f for f in frames)
    return frames, reports, ["battery_current_a as logged (positive when discharging)"] if battery else []
