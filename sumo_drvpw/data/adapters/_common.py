"""Shared helpers of the adapters: unit table, strict numeric parsing, time cleaning, reports.

Every adapter turns one vendor file into a canonical frame (SI, names of
../shared/spec/drive-log.md) and a per-file report of kept and dropped samples.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.data.counters import COUNTERS, describe
from sumo_drvpw.data.adapters.align import align_channels
from sumo_drvpw.data.adapters import cells
from sumo_drvpw.data.adapters.trip_names import in_several, qualify_by_folder
from sumo_drvpw.data.log_files import FLAGS
from sumo_drvpw.data.paths import expand_paths  # noqa: F401  (re-exported for the adapters)
from sumo_drvpw.model.constants import FT, G_UNIT, GAL, HP, KELVIN, KMH, LB, LBF, MILE, MPH, RPM
from sumo_drvpw.errors import UserError

numeric, is_number, extra_values = cells.numeric, cells.is_number, cells.extra_values  # (for the adapters)

#: Canonical columns in the order of the spec; everything else is an extra column.
CANONICAL = (
    "trip_id", "time_s", "speed_mps", "accel_mps2", "grade_rad", "grade_pct", "elevation_m",
    "wind_mps", "airspeed_mps", "air_density_kgm3", "ambient_c", "pressure_kpa", "mass_kg",
    "brake", "reverse", "power_w", "motor_torque_nm", "motor_speed_rpm", "battery_voltage_v",
    "battery_current_a", "ice_speed_rpm", "mg1_speed_rpm", "mg1_torque_nm", "mg2_speed_rpm",
    "mg2_torque_nm", "battery_discharge_energy_j", "battery_charge_energy_j",
)

#: dimension → suffix of the column name that holds it in the canonical unit
DIMENSIONS = {
    "speed": "mps", "length": "m", "time": "s", "temperature": "c", "rotational_speed": "rpm",
    "power": "w", "force": "n", "torque": "nm", "mass": "kg", "acceleration": "mps2",
    "pressure": "kpa", "voltage": "v", "current": "a", "percent": "pct", "angle": "rad",
    "energy": "j", "volume_flow": "lph", "density": "kgm3", "mass_flow": "gps", "dimensionless": "",
}

#: unit spelling → (dimension, factor, offset): value_canonical = value · factor + offset.
#: Canonical units: m/s, m, s, °C, rpm, W, N, N·m, kg, m/s², kPa, V, A, %, rad, J, l/h, kg/m³, g/s.
UNITS: dict[str, tuple[str, float, float]] = {}


def _u(dimension: str, factor: float, offset: float, *names: str) -> None:
    for n in names:
        UNITS[n.lower()] = (dimension, factor, offset)


_u("speed", 1.0, 0.0, "m/s", "mps", "meters-second", "meters/second", "m s-1")
_u("speed", KMH, 0.0, "km/h", "kmh", "kph", "km/hr")
_u("speed", MPH, 0.0, "mph", "mi/h")
_u("speed", FT, 0.0, "ft/s", "fps")
_u("length", 1.0, 0.0, "m", "meter", "metre", "meters", "metres")
_u("length", 1000.0, 0.0, "km")
_u("length", FT, 0.0, "ft", "feet")
_u("length", MILE, 0.0, "mi", "mile", "miles")
_u("time", 1.0, 0.0, "s", "sec", "secs", "seconds")
_u("time", 1e-3, 0.0, "ms")
_u("time", 1e-6, 0.0, "us")
_u("time", 60.0, 0.0, "min")
_u("time", 3600.0, 0.0, "h", "hr")
_u("temperature", 1.0, 0.0, "°c", "\u2103", "degc", "c", "celsius")  # U+2103 ℃: Car Scanner's spelling
_u("temperature", 5.0 / 9.0, -32.0 * 5.0 / 9.0, "°f", "\u2109", "degf", "f", "fahrenheit")
_u("temperature", 1.0, -KELVIN, "k", "kelvin")
_u("rotational_speed", 1.0, 0.0, "rpm", "1/min", "min-1")
_u("rotational_speed", 1.0 / RPM, 0.0, "rad/s")
_u("power", 1.0, 0.0, "w", "watt", "watts")
_u("power", 1000.0, 0.0, "kw")
_u("power", HP, 0.0, "hp")
_u("force", 1.0, 0.0, "n")
_u("force", 1000.0, 0.0, "kn")
_u("force", LBF, 0.0, "lbf")
_u("torque", 1.0, 0.0, "nm", "n·m", "n.m", "n m")
_u("torque", LBF * FT, 0.0, "lbf·ft", "lbf.ft", "lbf ft", "lb-ft", "ft-lb", "ft·lbf")
_u("mass", 1.0, 0.0, "kg")
_u("mass", 1000.0, 0.0, "t")
_u("mass", LB, 0.0, "lb", "lbs")
_u("acceleration", 1.0, 0.0, "m/s^2", "m/s²", "m/s2", "mps2")
_u("acceleration", G_UNIT, 0.0, "g")  # a sensor in g: 9.80665 by definition
_u("pressure", 1.0, 0.0, "kpa")
_u("pressure", 1e-3, 0.0, "pa")
_u("pressure", 0.1, 0.0, "hpa", "mbar")
_u("pressure", 100.0, 0.0, "bar")
_u("pressure", LBF / (FT / 12.0) ** 2 / 1000.0, 0.0, "psi")
_u("voltage", 1.0, 0.0, "v", "volt", "volts")
_u("voltage", 1e-3, 0.0, "mv")
_u("current", 1.0, 0.0, "a", "amp", "amps", "ampere", "amperes")
_u("current", 1e-3, 0.0, "ma")
_u("percent", 1.0, 0.0, "%", "pct", "percent")
_u("angle", 1.0, 0.0, "rad")
_u("angle", math.pi / 180.0, 0.0, "deg", "°", "degree", "degrees")
#: degrees and decimal minutes as text, "34 11.28809" (LeafSpy's Lat/Long): read by cells.degrees_minutes
DEG_MIN = ("deg min", "° '", "°'")
_u("angle", math.pi / 180.0, 0.0, *DEG_MIN)
_u("energy", 1.0, 0.0, "j")
_u("energy", 1000.0, 0.0, "kj")
_u("energy", 3600.0, 0.0, "wh")
_u("energy", 3.6e6, 0.0, "kwh")
_u("volume_flow", 1.0, 0.0, "l/h", "lph", "l/hr", "l-hr")
_u("volume_flow", GAL * 1000.0, 0.0, "gal/h", "gal-hr", "gal/hr", "gph")
_u("volume_flow", 3.6, 0.0, "cc/s", "ccps", "ml/s", "cm3/s", "cm³/s")  # a dynamometer's flow meter (Argonne D3: Eng_FuelFlow_Direct[ccps])
_u("density", 1.0, 0.0, "kg/m3", "kg/m^3", "kg/m³")
_u("mass_flow", 1.0, 0.0, "g/s", "g/sec", "gps", "gm/s")  # a mass air flow (OBD PID 0x10 MAF, g/s; gm/s: Torque's Nissan PIDs)
_u("mass_flow", 1000.0, 0.0, "kg/s")
_u("mass_flow", 1000.0 / 3600.0, 0.0, "kg/h", "kg/hr")
_u("mass_flow", LB * 1000.0 / 60.0, 0.0, "lb/min")
_u("dimensionless", 1.0, 0.0, "", "-", "1", "bool", "text", ":1", "lambda", "λ")  # ratios (Torque's AFR, λ)


def lookup_unit(unit: str):
    """(dimension, factor, offset) of a unit spelling, or None when unknown ('Â°C', a degree
    sign encoded twice, reads as '°C': the 'Â' is dropped before the spelling is lowered).

    A unit whose '/' a file-name-safe export wrote as '_' or '-' ('gal_hr', 'Meters_second',
    'km-h': Torque logs re-saved by their users) reads as the unit with '/' when the spelling
    itself is unknown."""
    key = unit.replace("Â", "").strip().lower()
    if key in UNITS:
        return UNITS[key]
    for sep in ("_", "-"):
        if key.count(sep) == 1 and "/" not in key:
            u = UNITS.get(key.replace(sep, "/"))
            if u is not None:
                return u
    return None


def snake(name: str) -> str:
    """A clean snake_case identifier from a vendor label ('Heating Power CAN' → 'heating_power_can')."""
    s = re.sub(r"[^0-9a-zA-Z]+", "_", name.replace("Â", "")).strip("_").lower()
    return s or "column"


_HEADER = re.compile(r"^(?P<name>.*?)\s*[\[(](?P<unit>[^\[\]()]*)[\])]\s*$")


def split_header(label: str) -> tuple[str, str]:
    """Split 'Velocity [km/h]' or 'Engine RPM(rpm)' into ('Velocity', 'km/h'); no unit → ''."""
    m = _HEADER.match(label.strip())
    if not m:
        return label.strip(), ""
    return m.group("name").strip(), m.group("unit").strip()


def generic_name(label: str, notes: list | None = None) -> tuple[str, float, float]:
    """Extra-column name with canonical unit suffix, and the (factor, offset) to convert to it."""
    name, unit = split_header(label)
    u = lookup_unit(unit)
    if u is None:
        if notes is not None:
            notes.append(f"column '{label}': unit '{unit}' unknown, kept unconverted")
        plain = re.sub(r"[^0-9a-zA-Z]+", "", unit)  # 'λ', '$': no name suffix to make of them
        return (f"{snake(name)}_{snake(unit)}" if plain else snake(name)), 1.0, 0.0
    dim, f, o = u
    suffix = DIMENSIONS[dim]
    if dim == "angle":  # angles from loggers are positions (lat/lon, bearing): keep degrees
        return f"{snake(name)}_deg", f * 180.0 / math.pi, 0.0
    return (f"{snake(name)}_{suffix}" if suffix else snake(name)), f, o


def unique_names(names: list[str]) -> list[str]:
    """Make names unique by appending _2, _3, … to repeats (vendor files repeat labels)."""
    seen: dict[str, int] = {}
    out = []
    for n in names:
        k = seen.get(n, 0) + 1
        seen[n] = k
        out.append(n if k == 1 else f"{n}_{k}")
    return out


def read_csv_strict(path: Path, **kw) -> pd.DataFrame:
    """pandas.read_csv with empty or undecodable files turned into a UserError naming the file.
    No column becomes the index: a logger that ends every data row with a separator, but not
    its header line, leaves an empty last field, which pandas would otherwise read as a
    shift of every column by one (the first taken as the index, silently)."""
    import warnings

    kw.setdefault("index_col", False)
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always", pd.errors.ParserWarning)
            df = pd.read_csv(path, **kw)
        if (any(issubclass(w.category, pd.errors.ParserWarning) for w in caught)  # (pandas ≥ 3 warns;
                or _wider_first_row(Path(path), kw)):                               #  2.x not with dtype=str)
            WIDER_ROWS.add(str(path))
    except pd.errors.EmptyDataError:
        raise UserError(f"{path}: file is empty") from None
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError) as e:
        raise UserError(f"{path}: cannot be read as CSV ({kw.get('sep', ',')!r}-separated, "
                        f"{kw.get('encoding', 'utf-8')}): {str(e).splitlines()[0]}") from None
    if len(df) == 0:
        raise UserError(f"{path}: no data rows")
    if len(df.columns) and isinstance(df.columns[0], str):
        first = df.columns[0]  # a UTF-8 byte-order mark (Excel writes one), as any encoding read it
        for bom in ("\ufeff", "\xef\xbb\xbf"):
            first = first.removeprefix(bom)
        if first != df.columns[0]:  # relabelled in place: a rename would copy the table
            df.columns = [first, *df.columns[1:]]
    if _cut_mid_row(Path(path), kw.get("sep", ","), str(kw.get("encoding") or "utf-8")):
        df = df.iloc[:-1]
        if len(df) < 2:
            raise UserError(f"{path}: file is cut short (truncated mid-row) and holds {len(df)} complete "
                            "data row(s): nothing sensible to import")
        TRUNCATED[str(path)] = 1
    return df


#: files whose last row was cut mid-row (path → rows dropped), read by :func:`new_report`
TRUNCATED: dict[str, int] = {}
#: files whose data rows hold more fields than their header line, read by :func:`new_report`
WIDER_ROWS: set[str] = set()


def _wider_first_row(path: Path, kw: dict) -> bool:
    """True when the first data row holds more fields than the header line (a logger that
    ends every data row with a separator), told from the file, whatever pandas warns of.
    Single-character separators, a header on the first line, plain encodings only."""
    import csv
    import io

    sep, enc = kw.get("sep", ","), str(kw.get("encoding") or "utf-8")
    if (not isinstance(sep, str) or len(sep) != 1 or kw.get("header", "infer") not in ("infer", 0)
            or kw.get("skiprows") or enc.lower().replace("-", "").startswith(("utf16", "utf32"))):
        return False
    with open(path, "rb") as f:
        text = f.read(65536).decode(enc, errors="replace")
    try:  # (newline="": rows end at \r, \n or \r\n, as loggers write them)
        rows = [r for _, r in zip(range(3), csv.reader(io.StringIO(text, newline=""), delimiter=sep)) if r][:2]
    except csv.Error:  # not CSV as the csv module reads it: pandas has read it already
        return False
    return len(rows) == 2 and len(rows[1]) > len(rows[0])


def _cut_mid_row(path: Path, sep: str, encoding: str) -> bool:
    """True when the file ends inside a row: no final newline (loggers end every row with
    one; a cut inside the last field leaves the field count whole), as the canonical reader
    tells it (:func:`sumo_drvpw.data.truncated.complete_bytes`: blanks after the last line
    break, which the CSV reader skips, are no cut row)."""
    from sumo_drvpw.data.truncated import complete_bytes

    return len(sep) == 1 and complete_bytes(path, encoding) is not None


def new_report(path: Path, trip_id: str, rows: int) -> dict:
    """Per-file report: rows read, kept, dropped per reason, notes (a cut-short file says so)."""
    rep = {"file": str(path), "trip_id": trip_id, "rows_read": int(rows), "kept": 0,
           "dropped": {}, "notes": []}
    return note_truncated(rep, path)


def note_truncated(rep: dict, path: Path) -> dict:
    """Put into a file's report that :func:`read_csv_strict` dropped its cut last row (an
    adapter that starts its report before it reads the file calls this after reading)."""
    cut = TRUNCATED.pop(str(path), 0)
    if cut:
        rep["rows_read"] += cut
        rep["dropped"]["truncated last row"] = cut
        rep["notes"].append("file is cut short (truncated): it ends inside its last row, which is dropped")
    if str(path) in WIDER_ROWS:
        WIDER_ROWS.discard(str(path))
        rep["notes"].append("data rows hold more fields than the header line (a separator at the end of "
                            "each row): the fields beyond the header's are not read")
    return rep


def drop(df: pd.DataFrame, mask, reason: str, report: dict) -> pd.DataFrame:
    """Remove rows where mask is True and count them under reason."""
    mask = np.asarray(mask, dtype=bool)
    n = int(mask.sum())
    if n:
        report["dropped"][reason] = report["dropped"].get(reason, 0) + n
        df = df.loc[~mask]
    return df


def carry_midnight(seconds) -> tuple[np.ndarray, int]:
    """Times of day [s] in file order with the day carried on where they step back by more
    than 12 h (past midnight; a log of time of day only, as phone OBD apps write it), and
    how many times that happened. NaN stays NaN."""
    t = np.asarray(seconds, float)
    ok = np.isfinite(t)
    back = np.concatenate([[False], np.diff(t[ok]) < -43200.0])
    days = np.zeros(len(t))
    days[ok] = 86400.0 * np.cumsum(back)
    return t + days, int(back.sum())


#: the share of a file's rows dropped as duplicate timestamps beyond which the import says why
DUPLICATE_NOTE_SHARE = 0.2


def clean_time_and_speed(df: pd.DataFrame, path, report: dict) -> pd.DataFrame:
    """Drop NaN time/speed and samples whose time does not increase; check speed is plausible.

    An asynchronous log's channels are first put onto its speed samples
    (:func:`~sumo_drvpw.data.adapters.align.align_channels`), so dropping the rows without
    speed loses no channel.
    A sample whose time equals the latest kept time is a 'duplicate timestamp' (the first
    one is kept); one whose time is earlier is 'time going backwards'. Speed must be in
    [0, 100] m/s after conversion, else a UserError names file and row (wrong unit), except a
    signed speed backing up (:func:`_reversing`): its magnitude, flagged ``reverse``, noted.
    """
    df = align_channels(df, report)
    df = drop(df, df["time_s"].isna(), "NaN time", report)
    df = drop(df, df["speed_mps"].isna(), "NaN speed", report)
    t = df["time_s"].to_numpy(float)
    prev_max = np.concatenate([[-np.inf], np.maximum.accumulate(t)[:-1]])
    dup = t == prev_max
    if dup.sum() > DUPLICATE_NOTE_SHARE * len(t):  # more rows than the clock tells apart: say why
        kept = t[~dup]
        step = float(np.median(np.diff(kept))) if len(kept) > 1 else float("nan")
        report["notes"].append(
            f"{int(dup.sum())} of {len(t)} rows share their time with the row before (the time column steps "
            f"by {step:g} s, the rows come {len(t) / max(len(kept), 1):.1f} per step): the first row of each "
            "time is kept; a time column of finer resolution (or the logger's own timestamp) keeps them all")
    df = drop(df, dup, "duplicate timestamp", report)
    t = df["time_s"].to_numpy(float)
    prev_max = np.concatenate([[-np.inf], np.maximum.accumulate(t)[:-1]])
    back = t < prev_max
    if back.any():
        report["notes"].append(_backwards_note(t, prev_max, back, df.index))
    df = drop(df, back, "time going backwards", report)
    v = df["speed_mps"].to_numpy(float)
    back_up = _reversing(v)
    bad = ((v < -0.01) & ~back_up) | (v > 100.0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        same = int((v == v[i]).sum())
        raise UserError(f"{path}: speed {v[i]:.3g} m/s at data row {df.index[i]} is outside "
                        "[0, 100] m/s: wrong unit or sign?"
                        + (f" (or a logger's 'no reading' value: every negative speed, {same} sample(s), "
                           "holds exactly it; give it as the speed column's na_values)"
                           if v[i] < 0 and same >= 3 and same == int((v < -0.01).sum()) else ""))
    df = df.copy()
    if back_up.any():  # a signed speed (CAN, LeafSpy): backing up is driving, in reverse
        rev = df["reverse"].astype("boolean").fillna(False).to_numpy(bool) if "reverse" in df else False
        df["reverse"] = back_up | rev
        report["notes"].append(f"{int(back_up.sum())} sample(s) with a negative speed (down to {v.min():.3g} m/s) "
                               "read as reversing: speed taken as its magnitude, flag 'reverse' set (left out "
                               "of calibration)")
        v = np.abs(v)
    df["speed_mps"] = np.clip(v, 0.0, None)
    if all(c in df for c in COUNTERS):  # how finely they resolve the battery's power
        report["notes"].append(describe(df["time_s"].to_numpy(float), np.zeros(len(df), int),
                                        *(df[c].to_numpy(float, na_value=np.nan) for c in COUNTERS)))
    report["kept"] = int(len(df))
    if len(df) == 0:
        raise UserError(f"{path}: no sample left after dropping {report['dropped']}")
    return df


#: a step back in time at least this long [s] is a logging session of its own, not a clock
#: glitch: the note on 'time going backwards' says how to keep it
SESSION_BACK_S = 600.0


def _backwards_note(t: np.ndarray, prev_max: np.ndarray, back: np.ndarray, index) -> str:
    """Where and by how much a file's time first steps back, for the 'time going backwards'
    drops: a jump back by minutes or hours (logging sessions written out of order into one
    file) loses every row up to where the time passes its latest value again."""
    i = int(np.flatnonzero(back)[0])
    jump = float(prev_max[i] - t[i])
    worst = float(np.max(prev_max[back] - t[back]))
    def span(x: float) -> str:
        return f"{x:.4g} s" if x < SESSION_BACK_S else f"{x:.0f} s ({x / 3600:.1f} h)"

    text = (f"time going backwards: {int(back.sum())} row(s) dropped; it first steps back by {span(jump)} "
            f"at data row {index[i]}" + ("" if worst == jump else f" (by up to {span(worst)})"))
    if worst >= SESSION_BACK_S:
        text += ("; a step back by minutes or hours is an earlier logging session written after a later one: "
                 "put each session into a file of its own (one trip each) to keep its rows")
    return text


#: fastest backing up read as reversing [m/s] (36 km/h: above a car's top speed in reverse)
REVERSE_MAX_MPS = 10.0
#: largest share of the moving samples a signed speed may have below zero to read as
#: reversing (more: the speed's sign is wrong, the whole log is refused)
REVERSE_MAX_SHARE = 0.1


def _reversing(v: np.ndarray) -> np.ndarray:
    """Samples of a signed speed that are backing up: below −0.01 m/s, no faster than
    :data:`REVERSE_MAX_MPS`, in a log that mostly drives forward (at most
    :data:`REVERSE_MAX_SHARE` of its moving samples below zero), and not all one value (a
    logger's 'no reading' value repeated, as LeafSpy's −3.6 km/h while the car regenerates
    at speed); else none."""
    neg = v < -0.01
    moving = np.abs(v) > 0.01
    if not neg.any() or neg.sum() > REVERSE_MAX_SHARE * moving.sum() or np.nanmin(v) < -REVERSE_MAX_MPS \
            or (neg.sum() >= 3 and np.unique(v[neg]).size == 1):  # one value, repeated: a sentinel
        return np.zeros(len(v), bool)
    return neg


def order_columns(df: pd.DataFrame) -> pd.DataFrame:
    """Canonical columns first in spec order, extras after in vendor order."""
    first = [c for c in CANONICAL if c in df.columns]
    return df[first + [c for c in df.columns if c not in first]]


_UNKNOWN_UNIT = re.compile(r"^column '(?P<col>.*)': unit '(?P<unit>.*)' unknown, kept unconverted$")


def _fold_unit_notes(notes: list[str]) -> list[str]:
    """One note for all of a file's columns whose unit is unknown (a Torque log has dozens)."""
    hits = [m for m in map(_UNKNOWN_UNIT.match, notes) if m]
    if len(hits) < 2:
        return notes
    rest = [n for n in notes if not _UNKNOWN_UNIT.match(n)]
    return [f"{len(hits)} columns with a unit not known here, kept unconverted: "
            + ", ".join(m["col"] for m in hits)] + rest


def _refuse_non_flags(frame: pd.DataFrame, report: dict) -> None:
    """A flag column (``brake``, ``reverse``) holds 0/1 or true/false; anything else (a pedal
    position, a percentage) is refused naming the file, the column and its first such value."""
    for c in FLAGS:
        if c not in frame:
            continue
        x = frame[c]
        if pd.api.types.is_bool_dtype(x):
            continue
        num = pd.to_numeric(x, errors="coerce")
        bad = x.notna() & ~num.isin([0, 1])
        if bad.any():
            v = x[bad].iloc[0]
            v = repr(v) if isinstance(v, str) else f"{float(v):g}"
            raise UserError(f"{report['file']}: column '{c}' holds {v} "
                            f"(its first value not 0 or 1): '{c}' is a flag, 0 or 1 (map a pedal "
                            "position or a percentage to a column of its own name instead)")


def combine(fmt: str, frames: list[pd.DataFrame], reports: list[dict], notes=()) -> tuple:
    """Concatenate per-file frames and build the import report (totals + per file)."""
    if not frames:
        raise UserError(f"{fmt}: no input files")
    for r in reports:
        r["notes"] = _fold_unit_notes(r["notes"])
    ids = [set(map(str, pd.unique(f["trip_id"]))) if "trip_id" in f else {str(r["trip_id"])}
           for f, r in zip(frames, reports)]  # (a file's trip column may hold several)
    frames, ids = qualify_by_folder(frames, reports, ids)  # a/log.csv, b/log.csv
    dup = sorted(in_several(ids))
    if dup:
        held = [r["file"] for r, s in zip(reports, ids) if dup[0] in s]
        raise UserError(f"{fmt}: trip_id {dup[0]!r} comes from more than one file: " + ", ".join(held)
                        + ("; one file given twice (also in its folder?): give it once" if len({Path(f).resolve()
                           for f in held}) < len(held) else "; files of one name in one folder: rename one (its trips are "
                           "named after it)" if len({Path(f).stem for f in held}) == 1 else ""))
    copies = _copies(frames, reports)
    for f, r in zip(frames, reports):
        _refuse_infinite(f, r)
        _refuse_non_flags(f, r)
    df = pd.concat(frames, ignore_index=True, sort=False)
    df = order_columns(df)
    for c in FLAGS:  # a flag one file sets (a car backing up): not set in the others
        if c in df:
            df[c] = df[c].astype("boolean").fillna(False).astype(bool)
    mixed = _text_in_some_files(df, frames, reports)
    dropped: dict[str, int] = {}
    for r in reports:
        for k, n in r["dropped"].items():
            dropped[k] = dropped.get(k, 0) + n
    report = {"format": fmt, "files": reports, "rows_read": sum(r["rows_read"] for r in reports),
              "kept": int(len(df)), "dropped": dropped, "notes": list(notes) + mixed + copies,
              "columns": list(df.columns), "warnings": _coarse_steps(frames, reports)}
    return df, report


def _coarse_steps(frames: list[pd.DataFrame], reports: list[dict]) -> list[str]:
    """Per file whose samples lie more than MAX_MEDIAN_STEP_S apart (median step within a
    trip: a log kept one sample a minute, a time in the wrong unit), one warning naming it
    and the step: imported, but the commands that need driving power refuse such a log."""
    from sumo_drvpw.data.plausible import MAX_MEDIAN_STEP_S

    out = []
    for f, r in zip(frames, reports):
        t = f["time_s"].to_numpy(float)
        trip = f["trip_id"].to_numpy() if "trip_id" in f else np.zeros(len(f))
        same = trip[1:] == trip[:-1]
        if not same.any():
            continue
        step = float(np.median(np.diff(t)[same]))
        if step > MAX_MEDIAN_STEP_S:
            out.append(f"{r['file']}: samples {step:g} s apart (median within a trip), more than "
                       f"{MAX_MEDIAN_STEP_S:g} s: imported, but calibrate, compare and diagnose will refuse "
                       "it (driving power needs samples seconds apart); is the time column's unit right?")
    return out


def _text_in_some_files(df: pd.DataFrame, frames: list[pd.DataFrame], reports: list[dict]) -> list[str]:
    """An extra column that is text in some files and numbers in others (a logger's status
    field written 'none' in one file, 0 in another) is kept as text in all, the numbers
    written as text (a Parquet column holds one type); the note names it and its files."""
    notes = []
    for c in df.columns:
        if df[c].dtype != object:
            continue
        x = df[c]
        kinds = x[x.notna()].map(lambda v: isinstance(v, str))
        if kinds.all() or not kinds.any():
            continue
        df[c] = x.where(x.isna(), x.astype(str))
        text = [r["file"] for f, r in zip(frames, reports) if c in f and not pd.api.types.is_numeric_dtype(f[c])]
        notes.append(f"column '{c}' is text in {len(text)} file(s) ({', '.join(Path(t).name for t in text[:3])}"
                     f"{', …' if len(text) > 3 else ''}) and numbers in others: kept as text in all")
    return notes


def _copies(frames: list[pd.DataFrame], reports: list[dict]) -> list[str]:
    """Notes on files whose samples equal another's, time and speed sample for sample (a copy
    of one trip under another name, 'TripA01 - Copy.csv', or re-saved beside its original):
    imported, such a trip counts twice in every fit and mean. Files that never move are not
    compared (standing logs of one length may well agree)."""
    import hashlib

    seen: dict[str, str] = {}
    out = []
    for f, r in zip(frames, reports):
        v = f["speed_mps"].to_numpy(float)
        if not (v > 0).any():
            continue
        key = hashlib.sha1(np.ascontiguousarray(f["time_s"].to_numpy(float)).tobytes()
                           + np.ascontiguousarray(v).tobytes()).hexdigest()
        if key in seen:
            out.append(f"{r['file']} holds the same samples as {seen[key]} (time and speed equal, sample "
                       "for sample): one trip under two names, counted twice by every fit and mean; import one")
        else:
            seen[key] = r["file"]
    return out


def _refuse_infinite(df: pd.DataFrame, report: dict) -> None:
    """A vendor value read as ±inf (an overflowing "1e999", a logger's "inf") is no
    measurement, and downstream it would pass for one (a time of inf even reorders a trip):
    UserError naming the file, the column and the first such sample."""
    for c in df.columns:
        if not pd.api.types.is_float_dtype(df[c]):
            continue
        bad = np.isinf(df[c].to_numpy(float))
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise UserError(f"{report.get('file', report.get('trip_id'))}: column {c} is "
                            f"{df[c].iloc[i]} at sample {i + 1} of those kept: not a finite "
                            "number; fix or drop that value in the vendor file")


def read_each(files, read_one) -> tuple[list, list]:
    """Read every file with ``read_one(path) → (frame, report)``: (frames, reports)."""
    pairs = [read_one(f) for f in files]
    return [df for df, _ in pairs], [rep for _, rep in pairs]
