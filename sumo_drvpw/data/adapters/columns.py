"""Generic adapter (``columns``): any CSV/Parquet log through a user's mapping TOML.

Mapping file::

    [options]                 # all optional
    sep = ";"                 # CSV separator (default ",")
    encoding = "latin-1"      # CSV encoding (default "utf-8")
    decimal = ","             # CSV decimal mark (default ".")
    time_unit = "ms"          # unit of the time column when its entry has none (default "s");
                              # "datetime" parses timestamps (time_format = "%Y-%m-%d %H:%M:%S")
    na_values = ["-", "N/A"]  # cells read as missing
    keep_unmapped = true      # keep other columns as snake_case extras (default true)
    skip_rows = 2             # CSV lines before the header (an app's title lines; default 0)
    time_step_s = 1.0         # a table without a time column: its rows follow at this step
                              # [s] (time_s = data row × step; then time_s is not mapped)
    trip_gap_s = 600          # a pause in logging longer than this [s] ends a trip: its parts
                              # are trips <trip>_1, <trip>_2, … (a day's log of an app)

    [columns."Speed"]         # source column label
    name = "speed_mps"        # canonical or extra name; the suffix must fit the unit
    unit = "km/h"             # converted to SI (see _common.UNITS)
    scale = -1                # optional extra factor (e.g. flip a current's sign)
    role = "response"         # optional: condition | load | response (drive-log spec)
    na_values = [-3.6]        # optional: this column's own 'no reading' values (numbers in
                              # the file's unit, or texts), read as missing and counted

    [columns."Trip"]
    name = "trip_id"          # text, in every row; without it trip_id = file stem

    [columns."Time (s)"]      # a column other loggers label differently (adapters/labels.py):
    name = "time_s"
    also = ["Zeit", "t [s]"]  # their labels, tried in order after the table's own; or another
    first_wins = true         # table of the same name (its own unit); a file holding two of a
                              # column's labels is refused, unless first_wins: the first listed

``time_s`` (or ``options.time_step_s``) and ``speed_mps`` must be mapped. Units: m/s km/h mph ft/s · m km ft mi ·
s ms min h · °C °F K · rpm rad/s · W kW hp · N kN lbf · Nm lbf·ft · kg t lb · m/s² g ·
kPa Pa hPa bar psi · V mV · A mA · % · rad deg · J kJ Wh kWh · l/h gal/h · g/s kg/h lb/min · "" (none).
Temperatures go to °C (``_c``), rotational speeds to rpm (``_rpm``), angles to rad
(``_rad``) unless the name ends in ``_deg``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import read_toml
from sumo_drvpw.data.adapters._common import (clean_time_and_speed,
                      expand_paths, generic_name, lookup_unit, new_report, numeric, read_csv_strict,
                      read_each, unique_names, UNITS)

from sumo_drvpw.data.adapters import labels as candidate_labels
from sumo_drvpw.data.adapters.cells import degrees_minutes
from sumo_drvpw.data.adapters.timestamps import _seconds, to_datetimes
from sumo_drvpw.data.adapters.trip_names import qualify_shared_trips
from sumo_drvpw.data.adapters.unit_names import _entry, _name_note
from sumo_drvpw.data.log import FLAGS
from sumo_drvpw.data.adapters.header_hints import close_label, header_cells, no_header_hint, skip_hint
from sumo_drvpw.data.adapters.isotp import LAYOUTS as ISOTP_LAYOUTS

FORMAT = "columns"
SUFFIXES = (".csv", ".txt", ".tsv", ".parquet", ".pq")
OPTIONS = {"sep", "encoding", "decimal", "time_unit", "time_format", "na_values", "keep_unmapped",
           "skip_rows", "dbc", "mdf_trips", "isotp_layout", "soc_capacity_kwh", "time_step_s", "trip_gap_s"}
#: the largest battery options.soc_capacity_kwh accepts [kWh] (a heavy truck's is about 1 MWh)
MAX_SOC_CAPACITY_KWH = 2000.0
ENTRY = {"name", "unit", "scale", "role", "na_values", "valid", *candidate_labels.KEYS}


def load_mapping(path, mdf: bool = False) -> dict:
    """Read and check a mapping TOML; every problem is a UserError naming the file and key.

    ``mdf``: the mapping is for ASAM MDF files (:mod:`~sumo_drvpw.data.adapters.mdf`):
    ``time_s`` is not required, and an entry without a unit takes its channel's unit from
    the file (its ``unit`` is then None until read)."""
    p = Path(path)
    doc = read_toml(p, "column mapping")
    out = _options(p, doc)
    opts = doc.get("options", {})

    cols = doc.get("columns")
    if not isinstance(cols, dict) or not cols:
        raise UserError(f"{p}: no [columns.\"<source label>\"] table")
    time_unit = str(opts.get("time_unit", "s"))
    if time_unit != "datetime" and (lookup_unit(time_unit) or ("",))[0] != "time":
        known = sorted(u for u, (d, _, _) in UNITS.items() if d == "time")
        raise UserError(f"{p}: options.time_unit {time_unit!r} is no time unit (known: {', '.join(known)}, datetime)")
    entries, wins, notes = {}, {}, []
    for label, e in cols.items():
        key = f"columns.{label!r}" if not label.isidentifier() else f"columns.{label}"
        if label.strip() != label:  # header labels are read stripped: a label copied with the
            label = label.strip()   # header's own leading space (' Speed (km/h)') names the same
            if label in cols or label in entries:
                raise UserError(f"{p}: {key} and columns.{label!r} name the same source column "
                                "(labels are read without their surrounding spaces)")
        if not isinstance(e, dict) or "name" not in e:
            raise UserError(f"{p}: {key} needs a table with 'name' (and 'unit')")
        for k in e:
            if k not in ENTRY:
                raise UserError(f"{p}: {key}.{k} is not one of {', '.join(sorted(ENTRY))}")
        for k in ("name", "unit", "role", "valid"):
            if k in e and not isinstance(e[k], str):
                raise UserError(f"{p}: {key}.{k} must be a text, got {e[k]!r}")
        name = e["name"]
        if name == "time_s" and "unit" in e and "time_unit" in opts and e["unit"] != time_unit:
            raise UserError(f"{p}: {key}.unit {e['unit']!r} and options.time_unit "
                            f"{time_unit!r} disagree on the time column's unit: give one")
        unit = str(e.get("unit", time_unit if name == "time_s" else ""))
        scale = e.get("scale", 1.0)
        if not isinstance(scale, (int, float)) or isinstance(scale, bool) or not math.isfinite(scale):
            raise UserError(f"{p}: {key}.scale must be a number, got {scale!r}")
        if mdf and "unit" not in e and name not in ("time_s", "trip_id"):
            # the channel's unit is read from the file (factor: the scale, for the check below)
            entries[label] = {"name": name, "kind": "number", "factor": float(scale), "offset": 0.0, "unit": None}
        else:
            entries[label] = {**_entry(p, key, name, unit, float(scale)), "unit": unit}
        entries[label].update(key=key, scale=float(scale))
        if entries[label]["kind"] == "number" and (note := _name_note(key, name, entries[label]["unit"])):
            notes.append(note)
        if "na_values" in e:
            own = e["na_values"] if isinstance(e["na_values"], list) else [e["na_values"]]
            if not own or any(isinstance(x, bool) or not isinstance(x, (str, int, float)) for x in own):
                raise UserError(f"{p}: {key}.na_values must be a number or text, or a list of them, "
                                f"got {e['na_values']!r}")
            entries[label]["na_text"] = tuple(str(x).strip() for x in own if isinstance(x, str))
            entries[label]["na_num"] = tuple(float(x) for x in own if not isinstance(x, str))
        if "valid" in e:  # a validity flag (a CAN signal's 'valid' bit): 0 marks a sample unread
            entries[label]["valid"] = e["valid"]
        if "role" in e:
            from sumo_drvpw.data.roles import check_role

            entries[label]["role"] = check_role(str(e["role"]), f"{p}: {key}.role")
        wins[key] = candidate_labels.first_wins(p, key, e)
        for other in candidate_labels.also_labels(p, key, label, e):  # other loggers' labels of the column
            tabled = any(other == c.strip() for c in cols)
            if tabled or other in entries:
                raise UserError(f"{p}: {key}.also lists {other!r}, which "
                                + ("has a table of its own" if tabled else f"{entries[other]['key']}.also lists too")
                                + " (a label names one column)")
            entries[other] = dict(entries[label])
    names = [e["name"] for e in entries.values()]
    if "time_format" in opts and not any(e["kind"] == "datetime" for e in entries.values()):
        raise UserError(f"{p}: options.time_format is for timestamps: it goes with a time "
                        "column read as dates (options.time_unit or its unit = \"datetime\")")
    step = out["time_step_s"]
    if step is not None and "time_s" in names:
        raise UserError(f"{p}: options.time_step_s gives a table without a time column its time "
                        "from the row number: map no column to 'time_s' beside it (or drop the option)")
    for need in ("speed_mps",) if mdf or step is not None else ("time_s", "speed_mps"):
        if need not in names:
            raise UserError(f"{p}: no source column is mapped to '{need}' (required"
                            + ("; a table whose rows follow at a fixed rate without a time column: "
                               "options.time_step_s = <seconds between rows>)" if need == "time_s" else ")"))
    groups, first = candidate_labels.candidates(p, entries, wins)  # a column's labels: the first a file holds is read
    _check_scales(p, entries)
    if out["soc_capacity_kwh"] is not None and "soc_pct" not in names:
        raise UserError(f"{p}: options.soc_capacity_kwh estimates the battery's energy from the state "
                        "of charge: map a source column to 'soc_pct' (in %)")
    return {**out, "columns": entries, "candidates": {n: g for n, g in groups.items() if len(g) > 1},
            "first_wins": first, "notes": notes}


def load_options(path) -> dict:
    """The ``[options]`` of a mapping TOML alone, checked — how to read a file and its DBC
    files — for listing what a file offers before its ``[columns]`` are written
    (``import columns SRC --list``); :func:`load_mapping` without the columns."""
    p = Path(path)
    return {**_options(p, read_toml(p, "column mapping")), "columns": {}}


def default_options(where: str = "(no mapping)") -> dict:
    """The options every mapping starts from (:func:`load_options` of an empty file)."""
    return {**_options(Path(where), {}), "columns": {}}


def _options(p: Path, doc: dict) -> dict:
    """A mapping's top-level keys and ``[options]`` checked, with their defaults."""
    for k in doc:
        if k not in ("options", "columns"):
            raise UserError(f"{p}: unknown key '{k}' (a mapping has [options] and "
                            "[columns.\"<source label>\"])")
    opts = doc.get("options", {})
    if not isinstance(opts, dict):
        raise UserError(f"{p}: [options] must be a table")
    for k in opts:
        if k not in OPTIONS:
            raise UserError(f"{p}: unknown option 'options.{k}' (known: {', '.join(sorted(OPTIONS))})")
    skip = opts.get("skip_rows", 0)
    if not isinstance(skip, int) or isinstance(skip, bool) or skip < 0:
        raise UserError(f"{p}: options.skip_rows must be a whole number ≥ 0 (lines before the "
                        f"header), got {skip!r}")
    if "keep_unmapped" in opts and not isinstance(opts["keep_unmapped"], bool):
        raise UserError(f"{p}: options.keep_unmapped must be true or false, got "
                        f"{opts['keep_unmapped']!r}")
    _check_text_options(p, opts)
    cap = opts.get("soc_capacity_kwh")
    if cap is not None and (isinstance(cap, bool) or not isinstance(cap, (int, float))
                            or not 0 < cap <= MAX_SOC_CAPACITY_KWH):
        raise UserError(f"{p}: options.soc_capacity_kwh must be the battery energy [kWh] that the "
                        f"logged SOC's 0–100 % spans (> 0, ≤ {MAX_SOC_CAPACITY_KWH:g}), got {cap!r}")
    from sumo_drvpw.data.plausible import MAX_MEDIAN_STEP_S

    step = opts.get("time_step_s")
    if step is not None and (isinstance(step, bool) or not isinstance(step, (int, float))
                             or not 0 < step <= MAX_MEDIAN_STEP_S):
        raise UserError(f"{p}: options.time_step_s must be the seconds between a table's rows (> 0, "
                        f"≤ {MAX_MEDIAN_STEP_S:g}: driving power needs samples seconds apart at most), "
                        f"got {step!r}")
    gap = opts.get("trip_gap_s")
    if gap is not None and (isinstance(gap, bool) or not isinstance(gap, (int, float)) or not 0 < gap < 1e9):
        raise UserError(f"{p}: options.trip_gap_s must be the seconds of a pause in logging that ends a "
                        f"trip (> 0; e.g. 600: a car parked between two drives), got {gap!r}")
    na = opts.get("na_values", ["-", ""])
    if isinstance(na, str):
        na = [na]
    return {"path": p, "sep": str(opts.get("sep", ",")), "encoding": str(opts.get("encoding", "utf-8")),
            "decimal": str(opts.get("decimal", ".")), "time_format": opts.get("time_format"),
            "na_values": [str(x) for x in na], "keep_unmapped": bool(opts.get("keep_unmapped", True)),
            "skip_rows": skip, "dbc": _dbc_files(p, opts.get("dbc", [])),
            "mdf_trips": _choice(p, opts, "mdf_trips", ("file", "folder")),
            "isotp_layout": _choice(p, opts, "isotp_layout", ISOTP_LAYOUTS),
            "soc_capacity_kwh": None if cap is None else float(cap),
            "time_step_s": None if step is None else float(step),
            "trip_gap_s": None if gap is None else float(gap)}


def _choice(p: Path, opts: dict, key: str, allowed: tuple[str, ...]) -> str:
    """An option that takes one of ``allowed`` texts (the first is its default)."""
    v = opts.get(key, allowed[0])
    if v not in allowed:
        raise UserError(f"{p}: options.{key} must be one of {', '.join(map(repr, allowed))}, got {v!r}")
    return v


def _dbc_files(p: Path, dbc) -> list[Path]:
    """options.dbc: DBC files (relative to the mapping file) that decode an MDF bus log."""
    items = [dbc] if isinstance(dbc, str) else dbc
    if not isinstance(items, list) or not all(isinstance(x, str) and x for x in items):
        raise UserError(f"{p}: options.dbc must be a file name or a list of them, got {dbc!r}")
    files = [(p.parent / x) for x in items]
    for f, x in zip(files, items):
        if not f.is_file():
            raise UserError(f"{p}: options.dbc: no file {x!r} (looked for {f})")
    return files


def _check_text_options(p, opts: dict) -> None:
    """options.encoding a known codec, sep/decimal distinct single characters."""
    import codecs

    enc = opts.get("encoding", "utf-8")
    try:
        if not isinstance(enc, str):
            raise LookupError
        codecs.lookup(enc)
    except LookupError:
        raise UserError(f"{p}: options.encoding {enc!r} is not a known text encoding "
                        "(e.g. utf-8, latin-1, cp1252, utf-16)") from None
    sep, dec = opts.get("sep", ","), opts.get("decimal", ".")
    for k, v in (("sep", sep), ("decimal", dec)):
        if not isinstance(v, str) or not v:
            raise UserError(f"{p}: options.{k} must be a non-empty text, got {v!r}")
    if sep == dec:
        raise UserError(f"{p}: options.decimal {dec!r} equals options.sep: numbers could not be told apart")


def _check_scales(p, entries: dict) -> None:
    """No mapped number is scaled by 0."""
    zero = [label for label, e in entries.items() if e.get("kind") == "number" and e["factor"] == 0]
    if zero:
        raise UserError(f"{p}: columns.{zero[0]!r}.scale is 0: every value would read as 0")


def mapping_roles(path) -> dict[str, str]:
    """Roles declared in a mapping TOML: canonical/extra column name → role."""
    if path is None:
        return {}
    return {e["name"]: e["role"] for e in load_mapping(path, mdf=True)["columns"].values() if "role" in e}


def _read_table(path: Path, m: dict) -> pd.DataFrame:
    if path.suffix.lower() in (".parquet", ".pq"):
        try:
            df = pd.read_parquet(path)
        except Exception as e:
            raise UserError(f"{path}: cannot be read as Parquet: {str(e).splitlines()[0]}") from None
        if len(df) == 0:
            raise UserError(f"{path}: no data rows")
        return df
    try:
        return read_csv_strict(path, sep=m["sep"], encoding=m["encoding"], decimal=m["decimal"],
                               dtype=str, keep_default_na=False, na_filter=False,
                               skiprows=m.get("skip_rows", 0) or None, nrows=m.get("nrows"))
    except UserError as e:  # title lines of another width above the header: say where it is
        hint = skip_hint(path, m)
        if hint:
            raise UserError(f"{e}{hint}") from None
        raise


def read_file(path: Path, m: dict) -> tuple[pd.DataFrame, dict]:
    """One CSV/Parquet file through the mapping → canonical frame and report."""
    raw = _read_table(path, m)
    raw.columns = [str(c).strip() for c in raw.columns]
    rep = new_report(path, path.stem, len(raw))
    labels = list(raw.columns)
    whole = m  # (every label of a column: where a missing one's hints look)
    m, notes, left_out = candidate_labels.for_file(m, labels.__contains__, path)  # each column's label here
    rep["notes"] += notes
    # (pandas reads a label written twice as 'v' and 'v.1': the header line itself is counted then)
    cells = header_cells(path, m) if any(c.rpartition(".")[2].isdigit() for c in labels) else []
    times = {c: max(labels.count(c), cells.count(c)) for c in m["columns"]}
    twice = [c for c in m["columns"] if times[c] > 1]
    if twice:  # (the i3 logs label two columns 'Temperature Vent right [°C]', one with a space)
        raise UserError(f"{path}: {times[twice[0]]} columns are labelled '{twice[0]}' (spaces around "
                        f"labels are not read), and {m['path']} maps that label: it cannot tell them apart")
    for label in m["columns"]:
        if label not in raw.columns:
            hint = (f" (only one column '{raw.columns[0][:40]}': wrong sep {m['sep']!r}?)"
                    if raw.shape[1] == 1 else "")
            near = (close_label(x, labels, m["encoding"]) for x in candidate_labels.all_labels(whole, label))
            hint = skip_hint(path, whole) or no_header_hint(raw) or next((h for h in near if h), "") or hint
            raise UserError(f"{path}: missing column '{label}' named in {m['path']}"
                            f"{candidate_labels.nor_others(m, label)}{hint}")
    na = tuple(m["na_values"])
    out: list[tuple[str, pd.Series]] = []  # (a list: two columns may read as one name)
    comma = m["decimal"] != "." and path.suffix.lower() not in (".parquet", ".pq")
    for j, label in enumerate(labels):
        s = cell = raw.iloc[:, j]  # (cell: as read, before the decimal mark is applied)
        if comma:  # CSV read as text (exact cells for error messages): apply the decimal mark here
            s = s.astype(str).str.replace(m["decimal"], ".", regex=False)
        e = m["columns"].get(label)
        if e is None:
            if not m["keep_unmapped"] or label in left_out:
                continue
            if label.startswith("Unnamed: ") and s.astype(str).str.strip().isin(na + ("",)).all():
                rep["notes"].append(f"column {label!r} has no header and no value (a trailing "
                                    "separator): left out")
                continue
            name, f, o = generic_name(label, rep["notes"])
            if name == "time_s" and m.get("time_step_s") is not None:  # kept, it would pass unread
                raise UserError(f"{path}: column '{label}' reads as a time (time_s), and {m['path']} takes the "
                                "time from the row number (options.time_step_s): map that column to "
                                "'time_s' and drop the option (or options.keep_unmapped = false)")
            try:
                out.append((name, numeric(s, path, label, na, bools=True) * f + o))  # (true/false: a flag)
            except UserError:
                out.append((name, cell.astype(str)))  # text extra (e.g. a date or a mode label)
            continue
        if e["kind"] == "text":
            out.append((e["name"], cell.astype(str).str.strip()))
            blank = (cell.isna() | out[-1][1].isin(na + ("",))).to_numpy() & (e["name"] == "trip_id")
            if blank.any():  # (was written as a trip of its own, named '', 'nan' or 'None')
                i = int(np.flatnonzero(blank)[0])
                raise UserError(f"{path}: column '{label}' (trip_id) data row {i} holds no trip id ({str(cell.iloc[i])!r}): "
                                f"give every row one, or map no trip column in {m['path']} (each file one trip, named by the file)")
        elif e["kind"] == "datetime":
            t = to_datetimes(s, m["time_format"])
            bad = t.isna() & ~s.astype(str).str.strip().isin(na)
            if bad.any():
                i = int(np.flatnonzero(bad.to_numpy())[0])
                raise UserError(f"{path}: column '{label}' data row {i} holds {s.iloc[i]!r}: "
                                "not a date/time")
            out.append(("time_s", _seconds(t, m["time_format"], rep)))
        else:
            if e.get("deg_min"):
                s = degrees_minutes(s, path, label, na)
            x = numeric(s, path, label, na + e.get("na_text", ()), bools=e["name"] in FLAGS)  # (a speed true: no 1)
            cells = cell.astype(str).str.strip()
            own = x.isin(e.get("na_num", ())) | (cells.isin(e.get("na_text", ())) & ~cells.isin(na))
            if own.any():
                rep["notes"].append(f"column '{label}': {int(own.sum())} cell(s) held its 'no reading' value "
                                    f"({', '.join(map(str, e.get('na_num', ()) + e.get('na_text', ())))}): "
                                    "read as missing")
                x = x.where(~own)
            if "valid" in e:
                x = x.where(_valid_flag(raw, e["valid"], path, label, m, na) != 0)
            out.append((e["name"], x * e["factor"] + e["offset"]))
    if m.get("time_step_s") is not None:  # no time column: the rows follow at a fixed step
        out.insert(0, ("time_s", pd.Series(np.arange(len(raw)) * m["time_step_s"], index=raw.index)))
        rep["notes"].append(f"time from the row number: options.time_step_s = {m['time_step_s']:g} s "
                            "between data rows (data row 0 at 0 s)")
    names = unique_names([n for n, _ in out])
    df = pd.DataFrame(dict(zip(names, (x for _, x in out))), index=raw.index)
    if "trip_id" in df:
        return _split_trips(df, path, rep, split_at_pauses=m["trip_gap_s"] is not None)
    df = clean_time_and_speed(df, path, rep)
    df.insert(0, "trip_id", path.stem)
    return df.reset_index(drop=True), rep


def _valid_flag(raw: pd.DataFrame, flag: str, path: Path, label: str, m: dict, na) -> pd.Series:
    """The validity column ``flag`` of a mapped column (0: the sample is no reading)."""
    if flag not in raw.columns:
        raise UserError(f"{path}: missing column '{flag}' (the validity flag of '{label}' in {m['path']})")
    return numeric(raw[flag], path, flag, na, bools=True).fillna(0)


def _split_trips(df, path, rep, split_at_pauses=False):
    """Clean time per trip when the file carries its own trip_id column; each trip's notes
    (why rows went: time going backwards, …) are the file's, named by trip. A trip whose rows
    resume after other trips' is noted, unless the mapping splits trips at their pauses."""
    parts, resumed = [], []
    for trip, g in df.groupby("trip_id", sort=False):
        sub = new_report(path, str(trip), len(g))
        parts.append(clean_time_and_speed(g, f"{path} (trip {trip})", sub))
        for k, n in sub["dropped"].items():
            rep["dropped"][k] = rep["dropped"].get(k, 0) + n
        rep["notes"] += [f"trip {trip}: {n}" + (_restart_hint(g) if n.startswith("time going backwards") else "")
                         for n in sub["notes"]]
        again = np.flatnonzero(np.diff(np.asarray(g.index)) > 1)  # its rows resume after other trips'
        if len(again):
            resumed.append(f"trip {trip} in {len(again) + 1} runs, again from data row {g.index[again[0] + 1]}")
    if resumed and not split_at_pauses:
        rep["notes"].append(f"{len(resumed)} trip id(s) whose rows resume after other trips' rows, each read as "
                            f"one trip ({'; '.join(resumed[:3])}{' …' if len(resumed) > 3 else ''}): a number "
                            "reused for another recording? give each its own id (options.trip_gap_s splits a "
                            "trip at its pauses)")
    out = pd.concat(parts)
    rep["kept"] = int(len(out))
    rep["trip_id"] = ",".join(map(str, out["trip_id"].unique()))
    return out.reset_index(drop=True), rep


def _restart_hint(g: pd.DataFrame) -> str:
    """'; …two recordings share this trip id…' when a trip's time starts over (steps back to
    its first time or before, after other rows: a trip number unique only per vehicle or per
    day, as VED's with its VehId), else ''."""
    t = g["time_s"].to_numpy(float)
    ok = np.isfinite(t)
    t = t[ok]
    if len(t) < 2:
        return ""
    i = np.flatnonzero((np.diff(t) < 0) & (t[1:] <= t[0]))
    if not len(i):
        return ""
    return (f"; its time starts over at data row {g.index[np.flatnonzero(ok)[i[0] + 1]]}: two recordings "
            "share this trip id (a trip number unique only per vehicle or day, as VED's Trip with its "
            "VehId) — give each recording a trip id of its own to keep both")


def read(paths, columns):
    """Read CSV/Parquet or ASAM MDF files through the mapping TOML ``columns``."""
    from sumo_drvpw.data.adapters import mdf

    if columns is None:
        raise UserError("format 'columns' needs a mapping file (mapping.toml)")
    named = {Path(p) for p in ([paths] if isinstance(paths, (str, Path)) else paths)}
    files = [f for f in expand_paths(paths, SUFFIXES + mdf.SUFFIXES, "CSV/Parquet/MDF")
             if f.suffix.lower() != ".dat" or f in named or mdf.is_mdf(f)]  # a folder's text .dat: not a log
    kinds = {mdf.is_mdf(f) for f in files}
    if len(kinds) > 1:
        first = next(f for f in files if mdf.is_mdf(f))
        raise UserError(f"{first}: an ASAM MDF file among CSV/Parquet files: import MDF files "
                        "on their own (their mapping takes the time and units from the file)")
    m = load_mapping(columns, mdf=kinds == {True})
    if kinds == {True} and m["time_step_s"] is not None:
        raise UserError(f"{m['path']}: options.time_step_s gives a table without a time column its "
                        "time: an MDF file carries its own (drop the option)")
    if kinds == {True}:
        groups = {f: None for f in files}  # each file a trip, or each folder's files one trip
        if m["mdf_trips"] == "folder":
            groups = {}
            for f in files:
                groups.setdefault(f.parent, []).append(f)
        frames, reports = read_each(groups, lambda p: mdf.read_file(p, m, groups[p]))
    else:
        frames, reports = read_each(files, lambda f: read_file(f, m))
        if any(e["name"] == "trip_id" for e in m["columns"].values()):
            frames = qualify_shared_trips(frames, reports)
    if m["trip_gap_s"] is not None:  # (before the SOC's energy: a pause's charging is no trip's)
        frames = [split_at_pauses(f, r, m["trip_gap_s"], m["path"]) for f, r in zip(frames, reports)]
    if m["soc_capacity_kwh"] is not None:  # the battery's energy estimated from its SOC
        from sumo_drvpw.data.counters import soc_counters

        frames = [soc_counters(f, r, m["soc_capacity_kwh"]) for f, r in zip(frames, reports)]
    return frames, reports, [f"mapping {m['path']}", *m["notes"]]


def split_at_pauses(df: pd.DataFrame, rep: dict, gap_s: float, mapping=None) -> pd.DataFrame:
    """A trip whose logging pauses longer than ``gap_s`` [s] (a day's log of an app that runs
    while the car is parked between drives) split there: its parts named ``<trip>_1``,
    ``<trip>_2``, … (``<trip>_part1``, … where another trip of the file has such a name; per-trip
    energies, held-out folds and trip signatures take a trip as one drive); said in the file's
    notes. Trips without such a pause keep their id. A ``gap_s`` not longer than the file's time
    step (the median within its trips) is a UserError naming the ``mapping`` and the file: it
    would make every sample a trip of its own (0.1 written for 0.1 h)."""
    if df.empty:
        return df
    trip = df["trip_id"].astype(str).to_numpy()
    t = df["time_s"].to_numpy(float)
    same = np.r_[False, trip[1:] == trip[:-1]]
    steps = np.diff(t)[same[1:]]
    step = float(np.median(steps[steps > 0])) if (steps > 0).any() else np.nan
    if gap_s <= step:
        raise UserError(f"{mapping or 'mapping'}: options.trip_gap_s = {gap_s:g} s is not longer than the time step of "
                        f"{rep['file']} ({step:g} s, its median): every sample would be a trip of its own (a pause "
                        "in logging that ends a trip, e.g. 600 s: a car parked between two drives)")
    pause = same & (np.r_[0.0, np.diff(t)] > gap_s)
    if not pause.any():
        return df
    part = pd.Series(pause.astype(int)).groupby(trip, sort=False).cumsum().to_numpy() + 1
    split = pd.Series(pause).groupby(trip, sort=False).transform("any").to_numpy()
    sep = "_part" if set(trip[~split]) & {f"{a}_{k}" for a, k in zip(trip[split], part[split])} else "_"
    df = df.copy()  # (a part named as another trip of the file would join it: then <trip>_part<k>)
    df["trip_id"] = np.where(split, pd.Series(trip).str.cat(part.astype(str), sep=sep).to_numpy(), trip)
    longest = float(np.max(np.diff(t)[pause[1:]]))
    rep["notes"].append(f"{int(pause.sum())} pause(s) in logging longer than options.trip_gap_s = {gap_s:g} s "
                        f"(the longest {longest:.0f} s) split {len(set(trip[split]))} trip(s) into "
                        f"{len(set(df['trip_id'][split]))}: each part a trip of its own")
    rep["trip_id"] = ",".join(map(str, pd.unique(df["trip_id"])))
    return df
