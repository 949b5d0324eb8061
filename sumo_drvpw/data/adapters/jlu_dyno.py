"""Adapter for the JLU chassis-dynamometer tests of a BEV (``jlu-dyno``).

Source: Yuan et al., Patterns 5(4) 2024, repository MOTIVES-LAB/generalized-energy-
consumption-evaluation-for-ev (xlsx converted to Parquet, values unchanged). One Parquet
file per test, 20 Hz; columns Time (timestamp), PhaseTime [s], DAScheduleSpeed and
DAActualSpeed [km/h], REESSCurrent/REESSCurrent2 [A], REESSVoltage/REESSVoltage2 [V].

Mapping: PhaseTime → ``time_s``; DAActualSpeed → ``speed_mps``; DAScheduleSpeed →
``schedule_speed_mps``; REESSVoltage → ``battery_voltage_v``; REESSCurrent →
``battery_current_a`` with the sign flipped (logged negative when discharging; canonical
positive when discharging, as declared in ``sumo_drvpw/model/builtin/vehicles/jlu_bev.toml``);
REESSCurrent2/REESSVoltage2 (a second, unexplained channel) kept as ``reess_current2_a``
and ``reess_voltage2_v`` as logged; Time → ``clock_s`` (Unix seconds). A dynamometer has
no slope: ``grade_rad`` = 0; ``mass_kg`` = the test mass of jlu_bev.toml (1919 kg).
trip_id = file stem; ``cycle`` = the test's cycle name (UDDS, CS_110, Artemis_rural, …).

PhaseTime stops at the schedule's end while the logger runs on: those tail samples are
dropped as 'time going backwards' / 'duplicate timestamp'.
"""

from __future__ import annotations

import re
from pathlib import Path

import pandas as pd

from sumo_drvpw.model.constants import KMH
from sumo_drvpw.errors import UserError
from sumo_drvpw.data.adapters._common import (clean_time_and_speed, extra_values, generic_name, new_report, numeric,
                                              unique_names)

FORMAT = "jlu-dyno"
SUFFIXES = (".parquet",)
VEHICLE = "jlu_bev"

#: vendor column → (name, factor)
NAMES = {
    "PhaseTime": ("time_s", 1.0),
    "DAActualSpeed": ("speed_mps", KMH),
    "DAScheduleSpeed": ("schedule_speed_mps", KMH),
    "REESSVoltage": ("battery_voltage_v", 1.0),
    "REESSCurrent": ("battery_current_a", -1.0),
    "REESSVoltage2": ("reess_voltage2_v", 1.0),
    "REESSCurrent2": ("reess_current2_a", 1.0),
}
REQUIRED = ("PhaseTime", "DAActualSpeed", "REESSVoltage", "REESSCurrent")
#: roles of the columns this adapter writes (drive-log spec "Roles"; stored with the log)
ROLES = {"reess_voltage2_v": "response", "reess_current2_a": "response", "cycle": "condition",
         "clock_s": "response", "schedule_speed_mps": "condition", "ambient_c": "condition",
         "gear": "response", "battery_discharge_energy_j": "response", "battery_charge_energy_j": "response",
         "latitude_deg": "condition", "longitude_deg": "condition"}


def cycle_name(stem: str) -> str:
    """Cycle of a test from its file name: 'WLTC_CADC_JC08_CSS__07_Artemis_rural_1' → 'Artemis_rural'."""
    tail = stem.split("__", 1)[-1]
    tail = re.sub(r"^\d+_", "", tail)
    return re.sub(r"_0?[1-9]$", "", tail) or stem  # repetition index _1, _01, _2 …


#: road logs (``jlu-road``): the dyno columns plus these
ROAD_NAMES = {
    "tempAmb": ("ambient_c", 1.0),
    "elevation": ("elevation_m", 1.0),
    "lat": ("latitude_deg", 1.0),
    "long": ("longitude_deg", 1.0),
    "gear": ("gear", 1.0),
    "tot_disc": ("battery_discharge_energy_j", 3.6e6),  # the BMS's counters, kWh
    "tot_char": ("battery_charge_energy_j", 3.6e6),
}
#: constant zero on the road (no schedule, no second channel): not written
ROAD_DROP = ("DAScheduleSpeed", "REESSCurrent2", "REESSVoltage2")
#: columns only a road log has (GPS position and elevation): no dynamometer test logs them
ROAD_ONLY = ("elevation", "lat", "long")


def refuse_other_kind(raw: pd.DataFrame, path: Path, road: bool) -> None:
    """UserError for a file of the other kind than the one asked for (a folder that holds
    dynamometer tests and road trips alike): a road trip read as a test would get grade 0 on
    a hilly road, a test read as a road trip loses its schedule and passes for a flat road.
    A road log logs elevation or GPS position; a test follows a speed schedule and logs
    neither."""
    road_cols = [c for c in ROAD_ONLY if c in raw.columns]
    if not road and road_cols:
        raise UserError(f"{path}: a road trip, not a dynamometer test (it logs {', '.join(road_cols)}; a "
                        "test is read with grade 0): read it as format 'jlu-road', the tests apart")
    if road and not road_cols and "DAScheduleSpeed" in raw.columns:
        top = float(pd.to_numeric(raw["DAScheduleSpeed"], errors="coerce").abs().max())
        if top > 0:
            raise UserError(f"{path}: a dynamometer test, not a road trip (it follows a speed schedule, "
                            f"DAScheduleSpeed up to {top:g} km/h, and logs no elevation or position): read it "
                            "as format 'jlu-dyno', the road trips apart")


def _clock_s(s: pd.Series, path: Path) -> pd.Series:
    """Wall-clock timestamps (datetime or text) → Unix seconds."""
    if not pd.api.types.is_datetime64_any_dtype(s):
        t = pd.to_datetime(s, errors="coerce", format="ISO8601")
        bad = t.isna() & s.notna()
        if bad.any():
            i = int(bad.to_numpy().nonzero()[0][0])
            raise UserError(f"{path}: column 'Time' has a value that is not a timestamp, "
                            f"{s.iloc[i]!r} at row {i}")
        s = t
    return (s - pd.Timestamp("1970-01-01")).dt.total_seconds()


def read_file(path: Path, vehicle, road: bool = False) -> tuple[pd.DataFrame, dict]:
    """One JLU Parquet file → canonical frame and report.

    road: a road log (``jlu-road``): elevation, ambient temperature, gear and the
    cumulative counters are mapped, the grade comes from the elevation (the log reader
    smooths it over distance), and the all-zero schedule/second-channel columns are left out.
    """
    try:
        raw = pd.read_parquet(path)
    except Exception as e:  # pyarrow raises several types for broken files
        raise UserError(f"{path}: cannot be read as Parquet: {str(e).splitlines()[0]}") from None
    trip = path.stem
    rep = new_report(path, trip, len(raw))
    if len(raw) == 0:
        raise UserError(f"{path}: no data rows")
    for k in REQUIRED:
        if k not in raw.columns:
            raise UserError(f"{path}: missing column '{k}'; found {', '.join(map(str, raw.columns))}")
    refuse_other_kind(raw, path, road)
    names, cols = [], []
    known = dict(NAMES, **ROAD_NAMES) if road else NAMES
    for c in raw.columns:
        s = raw[c]
        if road and c in ROAD_DROP:
            continue
        if c == "Time":
            names.append("clock_s")
            cols.append(_clock_s(s, path))
            continue
        name, f, o = (known[c] + (0.0,)) if c in known else generic_name(str(c), rep["notes"])
        names.append(name)
        cols.append(numeric(s, path, str(c)) * f + o if c in known
                    else extra_values(s, path, str(c), rep["notes"], f, o))
    df = pd.DataFrame(dict(zip(unique_names(names), cols)), index=raw.index)
    df = clean_time_and_speed(df, path, rep)
    if not road:
        df["grade_rad"] = 0.0
    df["mass_kg"] = vehicle.mass_kg
    df.insert(0, "trip_id", trip)
    if not road:
        df["cycle"] = cycle_name(trip)
    return df.reset_index(drop=True), rep


def read(paths):
    """Read JLU dynamometer tests (files or folders of .parquet)."""
    from sumo_drvpw.model.vehicles import load_vehicle
    from sumo_drvpw.data.adapters._common import expand_paths, read_each

    vehicle = load_vehicle(VEHICLE)
    frames, reports = read_each(expand_paths(paths, SUFFIXES, "dynamometer Parquet"),
                                lambda f: read_file(f, vehicle))
    return frames, reports, [f"vehicle file {vehicle.path}"]
