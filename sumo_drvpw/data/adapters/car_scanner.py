"""Adapter for Car Scanner ELM OBD2 (phone OBD app) CSV exports (``car-scanner``).

Car Scanner polls one value at a time and writes it with its own timestamp, in either of
its two CSV layouts:

- **long**: ``"SECONDS";"PID";"VALUE";"UNITS";"LATITUDE";"LONGTITUDE";`` — one row per
  value, ``SECONDS`` the time of day in seconds, the phone's position on each row;
- **wide**: ``time,"Vehicle speed (km/h)","Battery DC Current (A)",…`` — one column per
  value (``PID (unit)``), ``time`` the time of day (``HH:MM:SS.fff``), and on each row
  only the value polled then (the other cells empty).

Either way the channels are asynchronous: each is kept as its own samples and put onto
the speed samples (:func:`sumo_drvpw.data.adapters.align.onto`: interpolated, or averaged
over each speed interval when polled faster than the speed, as ``align_channels`` does for
other asynchronous logs), and the import report says so.
A time of day that steps back by more than 12 h has passed midnight. trip_id = file stem.

Mapping (PID names as Car Scanner writes them; every other value is kept as
``snake_name_<unit suffix>`` in SI):

- ``Vehicle speed`` → ``speed_mps`` (the OBD wheel speed); without it ``Speed (GPS)``,
  which is otherwise kept as ``gps_speed_mps``. The import report names the source.
- ``Altitude (GPS)`` → ``elevation_m`` (the reader smooths it over distance for the grade);
  the position columns → ``latitude_deg``, ``longitude_deg``.
- The ambient temperature (one PID naming ambient/outside temperature) → ``ambient_c``.
- The BMS's cumulative energy counters (Hyundai's and Kia's "Cumulative Energy Discharged
  (CED)" and "... Charged (CEC)", kWh) → ``battery_discharge_energy_j``,
  ``battery_charge_energy_j``: the battery target of a log without V·I
  (:mod:`sumo_drvpw.data.counters`).
- The traction battery's current and voltage (one PID each naming the battery or HV and a
  current in A or a voltage in V; cell, minimum/maximum, 12 V and module values are not
  it) → ``battery_current_a``, ``battery_voltage_v``. Car Scanner keeps the sign the car's
  controller uses, which differs between makes; the canonical sign is positive when
  discharging, so the current is flipped when V·I is clearly negative while the car
  accelerates (median below −1 kW over at least 20 such samples), and the report says which
  sign was found. Where no single PID fits, the values stay extras and the report lists
  the candidates (the ``columns`` format then maps them by name).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.data.adapters._common import (carry_midnight, clean_time_and_speed, expand_paths, generic_name,
                                              lookup_unit, new_report, note_truncated, read_csv_strict,
                                              read_each, split_header, unique_names)
from sumo_drvpw.data.adapters.align import aligned_note, onto
from sumo_drvpw.errors import UserError

FORMAT = "car-scanner"
SUFFIXES = (".csv",)
LONG_HEADER = ("SECONDS", "PID", "VALUE", "UNITS")

#: roles of the fixed columns this adapter writes (drive-log spec "Roles")
ROLES = {"ambient_c": "condition", "latitude_deg": "condition", "longitude_deg": "condition",
         "gps_speed_mps": "response"}

_NOT_TRACTION = re.compile(r"cell|min|max|12 ?v|module|aux|obd|control|charg|capacity|isolation", re.I)


def _sep_of(path: Path) -> tuple[str, bool]:
    """(separator, long layout?) from the header line."""
    try:
        with open(path, encoding="utf-8-sig") as f:
            head = f.readline()
    except UnicodeDecodeError as e:
        raise UserError(f"{path}: not UTF-8 text: {e}") from None
    if not head.strip():
        raise UserError(f"{path}: file is empty")
    sep = ";" if head.count(";") > head.count(",") else ","
    first = [c.strip().strip('"').upper() for c in head.split(sep)[:4]]
    return sep, tuple(first) == LONG_HEADER


def _time_of_day(values: np.ndarray) -> np.ndarray:
    """Seconds since the first sample from times of day [s] in file order, the day carried
    on past midnight (:func:`carry_midnight`)."""
    t, _ = carry_midnight(values)
    return t - np.nanmin(t) if np.isfinite(t).any() else t


#: a channel: its own sample times [s since the first row] and values
Channel = tuple[np.ndarray, np.ndarray]


def _number(col: pd.Series) -> pd.Series:
    """Numbers of a long-layout column; a decimal comma (a phone set to such a language)
    reads as a point; anything else not a number is NaN."""
    if pd.api.types.is_numeric_dtype(col):
        return col.astype(float)
    return pd.to_numeric(col.astype("string").str.strip().str.replace(",", ".", regex=False), errors="coerce")


def _long(path: Path, sep: str, rep: dict) -> tuple[int, dict[str, Channel]]:
    """Long layout → (rows, {"PID (unit)": its own samples}); the position columns are
    channels of every row."""
    raw = read_csv_strict(path, sep=sep, keep_default_na=False, na_values=[""], encoding="utf-8-sig",
                          dtype={"PID": "category", "UNITS": "category"}, low_memory=False)
    raw.columns = [str(c).strip().strip('"').upper() for c in raw.columns]
    t = _number(raw["SECONDS"]).to_numpy(float)
    bad = ~np.isfinite(t)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise UserError(f"{path}: column 'SECONDS' data row {i} holds {raw['SECONDS'].iloc[i]!r}: not a number")
    t = _time_of_day(t)
    val = _number(raw["VALUE"]).to_numpy(float)
    codes, labels = _pid_labels(raw["PID"], raw["UNITS"])
    order = np.argsort(codes, kind="stable")
    bounds = np.concatenate([[0], np.cumsum(np.bincount(codes, minlength=len(labels)))])
    chans: dict[str, Channel] = {}
    text = []
    for k, lab in enumerate(labels):
        rows = order[bounds[k]:bounds[k + 1]]
        if not np.isfinite(val[rows]).any():
            text.append(str(lab))
            continue
        chans[str(lab)] = (t[rows], val[rows])
    if text:
        rep["notes"].append(f"{len(text)} PID(s) without a numeric value left out: {', '.join(text[:5])}"
                            + (" …" if len(text) > 5 else ""))
    for col, name in (("LATITUDE", "Latitude (deg)"), ("LONGTITUDE", "Longitude (deg)"),
                      ("LONGITUDE", "Longitude (deg)")):
        if col in raw:
            x = _number(raw[col]).to_numpy(float, copy=True)
            x[x == 0] = np.nan  # no fix is written as 0
            if np.isfinite(x).any():
                chans[name] = (t, x)
    return len(raw), chans


def _pid_labels(pid: pd.Series, unit: pd.Series) -> tuple[np.ndarray, list[str]]:
    """Per row the code of its "PID (unit)" label, and the labels in order of first
    appearance (stripped; no unit: the PID alone). Built from the categories' codes — a
    label per distinct (PID, unit) pair, not one string per row of a million-row log."""
    def parts(col: pd.Series) -> tuple[np.ndarray, list[str]]:
        col = col if isinstance(col.dtype, pd.CategoricalDtype) else col.astype("category")
        return (col.cat.codes.to_numpy(np.int64),
                [str(c).strip() for c in col.cat.categories] + [""])  # code −1: missing

    pc, pnames = parts(pid)
    uc, unames = parts(unit)
    pair, first = pd.factorize(pc * len(unames) + uc % len(unames))
    text = [pnames[k // len(unames)] + (f" ({u})" if (u := unames[k % len(unames)]) else "")
            for k in first]
    merged, labels = pd.factorize(np.asarray(text, dtype=object))  # equal after stripping
    return merged[pair], list(labels)


def _wide(path: Path, sep: str) -> tuple[int, dict[str, Channel]]:
    """Wide layout → (rows, {"PID (unit)": its own samples: the rows where it has a value})."""
    raw = read_csv_strict(path, sep=sep, dtype=str, keep_default_na=False, na_filter=False,
                          encoding="utf-8-sig")
    raw.columns = [str(c).strip() for c in raw.columns]
    tcol = raw.columns[0]
    if tcol.lower() not in ("time", "seconds"):
        raise UserError(f"{path}: first column is {tcol!r}, expected 'time' (Car Scanner's wide CSV) "
                        "or the long layout's \"SECONDS\";\"PID\";\"VALUE\";\"UNITS\" header")
    s = raw[tcol].str.strip()
    num = pd.to_numeric(s, errors="coerce")
    if num.notna().all():
        t = num.to_numpy(float)
    else:
        parsed = pd.to_datetime(s, format="%H:%M:%S.%f", errors="coerce")
        parsed = parsed.fillna(pd.to_datetime(s, format="%H:%M:%S", errors="coerce"))
        if parsed.isna().all():  # a date with the time ('2023-12-04 07:13:32.604')
            parsed = pd.to_datetime(s, format="ISO8601", errors="coerce", utc=True)  # offsets: one clock
            base = parsed.min()
        else:
            base = None
        bad = parsed.isna().to_numpy()
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise UserError(f"{path}: column {tcol!r} data row {i} holds {s.iloc[i]!r}, expected a time "
                            "of day like '07:13:32.604' (or a date and time)")
        t = ((parsed - (parsed.dt.normalize() if base is None else base)).dt.total_seconds()).to_numpy(float)
    t = _time_of_day(t)
    chans: dict[str, Channel] = {}
    for c in raw.columns[1:]:
        cells = raw[c].str.strip().str.replace(",", ".", regex=False) if sep != "," else raw[c].str.strip()
        if c.startswith("Unnamed: ") and not (cells != "").any():
            continue  # the trailing separator of every row
        x = pd.to_numeric(cells, errors="coerce")
        junk = x.isna() & (cells != "")
        if junk.any():
            i = int(np.flatnonzero(junk.to_numpy())[0])
            raise UserError(f"{path}: column {c!r} data row {i} holds {raw[c].iloc[i]!r}: not a number")
        x = x.to_numpy(float)
        own = np.isfinite(x)
        chans[c] = (t[own], x[own])
    return len(raw), chans


def _unit_dim(label: str) -> str | None:
    u = lookup_unit(split_header(label)[1])
    return u[0] if u else None


def _one(labels, pattern: str, dim: str, exclude=_NOT_TRACTION) -> tuple[str | None, list[str]]:
    """The one label whose PID matches ``pattern`` with a unit of dimension ``dim``."""
    hits = [lab for lab in labels if re.search(pattern, split_header(lab)[0], re.I)
            and _unit_dim(lab) == dim and not (exclude and exclude.search(split_header(lab)[0]))]
    return (hits[0] if len(hits) == 1 else None), hits


def read_file(path: Path) -> tuple[pd.DataFrame, dict]:
    """One Car Scanner CSV (long or wide layout) → canonical frame and report: one sample per
    speed value, every other channel interpolated onto it."""
    sep, long = _sep_of(path)
    rep = new_report(path, path.stem, 0)
    rows, chans = _long(path, sep, rep) if long else _wide(path, sep)
    rep["rows_read"] = int(rows)
    note_truncated(rep, path)  # the report began before the file was read
    labels = [lab for lab, (tc, _) in chans.items() if len(tc)]  # a PID with no value is not logged
    named: dict[str, str] = {}
    speed, _ = _one(labels, r"^vehicle speed$|^speed \(obd\)$", "speed", exclude=None)
    gps, _ = _one(labels, r"^speed \(gps\)$", "speed", exclude=None)
    if speed is None and gps is None:
        raise UserError(f"{path}: no speed: neither 'Vehicle speed' nor 'Speed (GPS)' is logged "
                        f"(found {', '.join(labels[:6])}{' …' if len(labels) > 6 else ''}); a speed "
                        "under another name (another app language): map it with the 'columns' format")
    named[speed or gps] = "speed_mps"
    rep["notes"].append(f"speed from {speed or gps!r}")
    if speed and gps:
        named[gps] = "gps_speed_mps"
    for pattern, dim, name in ((r"^altitude \(gps\)$|^gps altitude$", "length", "elevation_m"),
                               (r"ambient|outside|outdoor", "temperature", "ambient_c"),
                               # the BMS's cumulative energy counters (Hyundai/Kia CED, CEC)
                               (r"cumulative energy discharged|\bced\b", "energy", "battery_discharge_energy_j"),
                               (r"cumulative energy charged|\bcec\b", "energy", "battery_charge_energy_j")):
        lab, hits = _one(labels, pattern, dim, exclude=None)
        if lab:
            named[lab] = name
        elif len(hits) > 1:
            rep["notes"].append(f"{name}: {len(hits)} candidates ({', '.join(hits)}), none mapped")
    for pattern, dim, name in ((r"batt|hv|traction", "current", "battery_current_a"),
                               (r"batt|hv|traction", "voltage", "battery_voltage_v")):
        lab, hits = _one(labels, pattern, dim)
        if lab:
            named[lab] = name
        elif hits:
            rep["notes"].append(f"{name}: {len(hits)} candidates ({', '.join(hits)}), none mapped: "
                                "use the 'columns' format to name one")
    ts, vs = chans[speed or gps]
    _, f, o = generic_name(speed or gps)
    names, values, averaged = ["time_s", "speed_mps"], [ts, vs * f + o], []
    for lab, (tc, xc) in chans.items():
        if lab == (speed or gps) or lab not in labels:
            continue
        if lab in named:
            name = named[lab]
            _, f, o = generic_name(lab)
        elif lab in ("Latitude (deg)", "Longitude (deg)"):
            name, f, o = lab.split()[0].lower() + "_deg", 1.0, 0.0
        else:
            name, f, o = generic_name(lab, rep["notes"])
        names.append(name)
        x, mean = onto(ts, tc, xc)
        values.append(x * f + o)
        averaged += [len(names) - 1] if mean else []
    names = unique_names(names)
    df = pd.DataFrame(dict(zip(names, values)))
    if len(names) > 2:
        aligned_note(rows - len(ts), len(ts), dict(zip(names[2:], values[2:])), rep,
                     [names[i] for i in averaged])
    df = clean_time_and_speed(df, path, rep)
    df.insert(0, "trip_id", path.stem)
    return df.reset_index(drop=True), rep


def _pulling_power(df: pd.DataFrame) -> np.ndarray:
    """Battery V·I [W] on the samples where the car accelerates (> 0.5 m/s² above 3 m/s)."""
    v = df["speed_mps"].to_numpy(float)
    t = df["time_s"].to_numpy(float)
    a = np.gradient(v, t) if len(v) > 2 else np.zeros_like(v)
    p = (df["battery_voltage_v"] * df["battery_current_a"]).to_numpy(float)
    return p[(v > 3.0) & (a > 0.5) & np.isfinite(p)]


def _discharge_positive(df: pd.DataFrame, rep: dict, pooled: np.ndarray | None = None) -> None:
    """Flip the current when the battery clearly charges while the car accelerates; a file
    with too few such samples takes the sign the import's other files show (``pooled``: the
    accelerating V·I of those with enough), as one app logs one car's current one way."""
    own = _pulling_power(df)
    p, whose = own, "its"
    if len(own) < 20 and pooled is not None and len(pooled) >= 20:
        p, whose = pooled, f"the other files' (its own {len(own)})"
    if len(p) < 20:
        rep["notes"].append(f"battery current kept as logged: only {len(p)} samples accelerate "
                            "(> 0.5 m/s² above 3 m/s) to check its sign on")
        return
    med = float(np.median(p))
    if whose != "its":
        rep["notes"].append(f"battery current's sign from {whose} accelerating samples")
    if med < -1000.0:
        df["battery_current_a"] = -df["battery_current_a"]
        rep["notes"].append(f"battery current logged negative when discharging (median V·I {med / 1000:.1f} kW "
                            "while accelerating): sign flipped to the canonical positive-discharging")
    else:
        rep["notes"].append(f"battery current positive when discharging as logged (median V·I "
                            f"{med / 1000:.1f} kW while accelerating)")


def read(paths):
    """Read Car Scanner CSV exports (files or folders of .csv)."""
    frames, reports = read_each(expand_paths(paths, SUFFIXES, "Car Scanner CSV"), read_file)
    has = [i for i, df in enumerate(frames) if "battery_current_a" in df and "battery_voltage_v" in df]
    # the sign decided over the whole import: a file too short to tell takes the files' that can
    pool = [p for p in (_pulling_power(frames[i]) for i in has) if len(p) >= 20]
    pooled = np.concatenate(pool) if pool else None
    for i in has:
        _discharge_positive(frames[i], reports[i], pooled)
    return frames, reports, []
