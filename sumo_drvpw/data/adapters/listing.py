"""What a log file offers, to write a ``columns`` mapping from:
``sumo-drvpw import columns SRC... --list [--columns mapping.toml]``.

For an ASAM MDF file each channel's label, unit, samples and sampling rate (raw CAN frames
decoded first with the DBC files of the mapping's ``[options] dbc``,
:func:`sumo_drvpw.data.adapters.mdf.channels`); for a CSV or Parquet file each column's
label, the unit its label carries (``Speed (km/h)``, ``Speed [km/h]``), how many of the rows
read hold a value and how many of those read as numbers, and a first value. The mapping is
optional; only its ``[options]`` are read (separator, encoding, lines before the header,
DBC files), so its ``[columns]`` may still be unwritten.

Each listing ends with a mapping sketch (:func:`sketch`): the canonical names guessed from
the labels and their units (a speed named speed, velocity, … in a speed unit; a battery's
voltage and current, not a cell's; the ambient temperature; elevation; a motor's torque and
speed), to check and complete.
"""

from __future__ import annotations

import codecs
import math
import os
import re
from pathlib import Path

import pandas as pd

from sumo_drvpw.errors import UserError
from sumo_drvpw.data.adapters._common import expand_paths, is_number, lookup_unit, split_header

#: rows of a CSV read for the listing (the header and a first stretch of the log)
ROWS_READ = 5000


def list_sources(paths, mapping=None) -> list[dict]:
    """Per file: {"file", "kind", "rows": [{label, unit, samples, …}], "notes", "sketch"}."""
    from sumo_drvpw.data.adapters import mdf
    from sumo_drvpw.data.adapters.columns import SUFFIXES, default_options, load_options

    m = load_options(mapping) if mapping is not None else None
    out = []
    for f in expand_paths(paths, SUFFIXES + mdf.SUFFIXES, "CSV/Parquet/MDF"):
        notes: list[str] = []
        if mdf.is_mdf(f):
            rows, notes = mdf.channels(f, m or default_options())
            kind = "ASAM MDF" + (f", decoded with {', '.join(d.name for d in m['dbc'])}" if m and m["dbc"] else "")
            opts = {} if not m else {k: v for k, v in (
                ("dbc", [os.path.relpath(d, m["path"].parent) for d in m["dbc"]]),
                ("isotp_layout", m["isotp_layout"])) if v and v != "css"}
        else:
            used = m or _sniffed(f, notes)
            rows, kind = _table_columns(f, used), "table"
            opts = {k: used[k] for k, default in (("sep", ","), ("encoding", "utf-8"), ("decimal", ".")) if used[k] != default}
        out.append({"file": f, "kind": kind, "rows": rows, "notes": notes,
                    "sketch": sketch(rows, mdf.is_mdf(f), opts)})
    return out


def _sniffed(path: Path, notes: list) -> dict:
    """Options to read a CSV without a mapping: UTF-8 (else Latin-1) and the separator the
    header line shows (Python's csv.Sniffer; else ','), said in ``notes``."""
    import csv

    from sumo_drvpw.data.adapters.columns import default_options

    m = default_options()
    if path.suffix.lower() in (".parquet", ".pq"):
        return m
    head = path.read_bytes()[:65536]
    try:  # a character cut at the 64-KiB end is not a decoding error
        text = codecs.getincrementaldecoder("utf-8")().decode(head, final=False)
    except UnicodeDecodeError:
        text, m["encoding"] = head.decode("latin-1"), "latin-1"
    try:
        m["sep"] = csv.Sniffer().sniff(text.splitlines()[0] if text else "", delimiters=",;\t|").delimiter
    except csv.Error:
        pass
    notes.append(f"no mapping: read as {m['encoding']}, {m['sep']!r}-separated (sniffed); a mapping's "
                 "[options] sep and encoding say so when it differs")
    return m


def _missing(x) -> bool:
    """A missing cell (NaN, None, NaT; a list cell is not)."""
    try:
        return bool(pd.isna(x))
    except (TypeError, ValueError):
        return False


def _table_columns(path: Path, m: dict) -> list[dict]:
    from sumo_drvpw.data.adapters.columns import _read_table

    if path.suffix.lower() in (".parquet", ".pq"):
        import pyarrow.parquet as pq

        try:
            pf = pq.ParquetFile(path)
            df = next(pf.iter_batches(batch_size=ROWS_READ)).to_pandas() if pf.metadata.num_rows else None
        except Exception as e:  # pyarrow raises several kinds on a file that is not Parquet
            raise UserError(f"{path}: cannot be read as Parquet: {str(e).splitlines()[0]}") from None
    else:
        df = _read_table(path, {**m, "nrows": ROWS_READ})
    rows = []
    for c in ([] if df is None else df.columns):
        # (a missing value: NaN or None, whatever the dtype; pandas' str dtype keeps NaN a float)
        vals = [v for v in (str(x).strip() for x in df[c] if not _missing(x)) if v not in ("", "nan", "None", "-")]
        unit = split_header(str(c))[1]
        nums = [float(v) for v in vals if is_number(v)]
        rows.append({"label": str(c), "unit": unit, "samples": len(vals), "numbers": len(nums),
                     "negatives": sum(x < 0 for x in nums), "first": vals[0] if vals else ""})
    return rows


#: canonical name → (dimension of its unit, label pattern, labels it must not match): the
#: guesses of the mapping sketch
GUESSES = {
    "time_s": ("time", r"time\b|zeit|timestamp|^t$|epoch|unix", r"trip|duration|since"),
    "speed_mps": ("speed", r"speed|velocity|geschw|vitesse|\bspd|\bvel\b",
                  r"wheel ?speed|motor|engine|fan|(?<![a-z])wind|air ?speed|accuracy|max|limit|set"),
    "elevation_m": ("length", r"elev|(?<![a-z])elv(?![a-z])|altitude|(?<![a-z])alt(?![a-z])|höhe|hoehe|height",
                    r"accuracy|valid"),
    "ambient_c": ("temperature", r"ambient|amb\b|outside|outdoor|außen|aussen|environment", None),
    "battery_voltage_v": ("voltage", r"batt|\bhv\b|pack|traction|reess", r"cell|min|max|12 ?v|aux"),
    "battery_current_a": ("current", r"batt|\bhv\b|pack|traction|reess", r"cell|min|max|12 ?v|aux|limit"),
    "motor_torque_nm": ("torque", r"motor|\bmg2\b|drive", r"request|limit|max"),
    "motor_speed_rpm": ("rotational_speed", r"motor|\bmg2\b", r"fan|pump|max"),
    # a BMS's cumulative energy counters (Hyundai/Kia CED, CEC): the battery target without V·I
    "battery_discharge_energy_j": ("energy", r"discharg|\bced\b|tot_?disc", r"cell|max|limit|power"),
    "battery_charge_energy_j": ("energy", r"(?<!dis)charg|\bcec\b|tot_?char", r"cell|max|limit|power|discharg"),
    # an EV's state of charge: with options.soc_capacity_kwh, the battery's energy (an estimate)
    "soc_pct": ("percent", r"(?<![a-z])soc(?![a-z])|state ?of ?charge|ladezustand",
                r"display|min|max|target|limit|health|(?<![a-z])soh(?![a-z])"),
    # a petrol engine's fuel target without a fuel-flow sensor (OBD PID 0x10), and a fuel flow
    "maf_gps": ("mass_flow", r"air ?flow|(?<![a-z])maf(?![a-z])|mass air", r"temp|pressure|volt"),
    "fuel_rate_lph": ("volume_flow", r"fuel", r"avg|average|trip|total|used|level|pressure|temp|trim|remaining"),
    # a fuel mass flow (a PEMS's carbon balance, a truck's ECU): the fuel target in g/s, not an air flow
    "fuel_rate_gps": ("mass_flow", r"fuel", r"avg|average|trip|total|used|level|pressure|temp|trim|remaining|air"),
    # an electric drive's power (+ driving, − recuperating): the driving power at its output
    "power_w": ("power", r"(motor|drive|traction|wheel|e-?machine|\bmg2\b).*(power|pwr)|(power|pwr).*(motor|drive|traction|wheel)",
                r"aux|heat|hvac|a/?c\b|climate|limit|max|avail|request|charg"),
}
#: a time column's first value as a clock time or a timestamp → its [options] time_format
CLOCK_FORMATS = ((re.compile(r"^\d{1,2}:\d{2}:\d{2}\.\d+$"), "%H:%M:%S.%f"),
                 (re.compile(r"^\d{1,2}:\d{2}:\d{2}$"), "%H:%M:%S"),
                 (re.compile(r"^\d{4}-\d{2}-\d{2}[ T]\d{1,2}:\d{2}:\d{2}\.\d+$"), "%Y-%m-%d %H:%M:%S.%f"),
                 (re.compile(r"^\d{4}-\d{2}-\d{2}[ T]\d{1,2}:\d{2}:\d{2}$"), "%Y-%m-%d %H:%M:%S"))
#: a label without a unit is offered for a name only when it also names the quantity
UNITLESS_WORDS = {"percent": r"soc|state of charge", "time": r"time|zeit", "speed": r"speed|veloc|geschw|spd",
                  "length": r"elev|(?<![a-z])elv(?![a-z])|alti|(?<![a-z])alt(?![a-z])|height|höhe",
                  "temperature": r"temp|amb", "voltage": r"volt", "current": r"curr|amp",
                  "torque": r"torq|trq", "rotational_speed": r"rpm|speed|drehz", "energy": r"energy|ced|cec|tot_",
                  "mass_flow": r"maf|air ?flow", "volume_flow": r"fuel (rate|flow)", "power": r"power|pwr"}


def sketch(rows: list[dict], mdf: bool, options: dict) -> str:
    """A mapping TOML to start from: each canonical name of :data:`GUESSES` on the first label
    whose name matches and whose unit has the name's dimension (the others that would fit in
    a comment); ``options``: the [options] to write (sep, encoding, dbc). MDF files need no
    time and take units from the file; a CSV's unit is written from its label."""
    lines = ["# a mapping to start from — guessed from the labels and units above: check each, "
             "add what else to keep (docs/adapters.md)"]
    clock = None if mdf else _clock_time(rows)  # (label, its time_format): a clock-time column
    if clock:
        options = {**options, "time_unit": "datetime", "time_format": clock[1]}
    if options:
        lines.append("[options]")
        lines += [f"{k} = {_toml(v)}" for k, v in options.items()]
    for name, (dim, pat, bad) in GUESSES.items():
        if mdf and name == "time_s":
            continue
        hits, unitless = [], []
        for r in rows:
            label, unit = r["label"], r.get("unit", "")
            u = lookup_unit(unit) if unit else None
            text = split_header(label)[0] if not mdf else label
            if not re.search(pat, text, re.I) or (bad and re.search(bad, text, re.I)):
                continue
            if u and u[0] == dim:
                hits.append((label, unit, r))
            elif u is None and re.search(UNITLESS_WORDS[dim], text, re.I):  # no unit, or "(CED)": none known
                unitless.append(label)
        if name == "power_w":  # a table's power none of whose values read is negative: traction only
            traction = [h for h in hits if h[2].get("negatives", 1) == 0 and h[2].get("numbers", 0)]
            hits = [h for h in hits if h not in traction]
            if not hits and traction:
                lines.append(f"# {name}: perhaps {traction[0][0]} (never negative in the {traction[0][2]['numbers']} "
                             "values read: traction only, which no driving-power equation fits; map it if it "
                             "does go negative)")
                continue
        if not hits and name == "time_s" and (unix := _unix_time(unitless, rows)):
            lines += [f"[columns.{_toml(unix[0])}]", f'name = "time_s"  # Unix time [{unix[1]}]', f'unit = "{unix[1]}"']
            continue
        if not hits and name == "time_s" and clock:
            lines += [f"[columns.{_toml(clock[0])}]", 'name = "time_s"  # clock times: [options] time_format']
            continue
        if not hits:
            if unitless:
                lines.append(f"# {name}: perhaps {', '.join(unitless[:3])} (no unit recognised in the file: "
                             "give its unit)" + (_percent_scale(unitless[0], rows) if dim == "percent" else ""))
            elif name in ("time_s", "speed_mps"):
                lines.append(f"# no label recognised as {name} (required): map one"
                             + ("; rows at a fixed rate without a time column: [options] time_step_s = "
                                "<seconds between rows>" if name == "time_s" and not mdf else ""))
            continue
        # the vehicle's own first; among those the best covered: an MDF channel's mean rate over
        # its group's span (a bursty one reads low), a table column's values
        hits.sort(key=lambda h: (not re.search(r"vehicle|veh", h[0], re.I), -_coverage(h[2])))
        label, unit = hits[0][:2]
        lines.append(f"[columns.{_toml(label)}]")
        lines.append(f'name = "{name}"' + (f"  # also fits: {', '.join(h[0] for h in hits[1:4])}" if len(hits) > 1 else ""))
        if not mdf:
            lines.append(f"unit = {_toml(unit)}")
        if name == "battery_current_a":
            lines.append("# + while discharging; scale = -1 if this log counts charging positive")
        if name == "soc_pct":
            lines.append("# without battery V·I or energy counters, [options] soc_capacity_kwh = <the energy "
                         "its 0–100 % spans> makes it the battery's energy (an estimate; docs/adapters.md)")
        if name == "power_w":
            lines.append("# the drive's power out (+ driving, − recuperating); one never negative logs traction "
                         "only, which no driving-power equation fits")
    odd = [(r["label"], r["unit"]) for r in rows if r.get("unit") and lookup_unit(r["unit"]) is None]
    if odd and not mdf:
        lines.append("# units not recognised (a mapping gives unit and scale, e.g. '100w': unit = \"W\", "
                     "scale = 100): " + ", ".join(f"{lb} [{u}]" for lb, u in odd[:6]) + (" …" if len(odd) > 6 else ""))
    return "\n".join(lines)


def _unix_time(labels: list[str], rows: list[dict]) -> tuple[str, str] | None:
    """The first of ``labels`` (time-like, without a unit) whose first value is a Unix time —
    seconds (1e8 … 1e10: 1973–2286) or milliseconds (1e11 … 1e13) since 1970 —, with that
    unit; else None. Preferred to a clock-time column: a phone app's clock may keep whole
    seconds or minutes (LeafSpy's `Date/Time` in some exports) where its `epoch time` keeps
    milliseconds."""
    first = {r["label"]: r.get("first", "") for r in rows}
    for label in labels:
        v = str(first.get(label, "")).strip()
        if not is_number(v):
            continue
        x = float(v)
        if 1e8 <= x < 1e10:
            return label, "s"
        if 1e11 <= x < 1e13:
            return label, "ms"
    return None


def _percent_scale(label: str, rows: list[dict]) -> str:
    """For a per-cent column offered without a unit: where its first value is beyond 100, the
    power of ten that reads it as a per cent (LeafSpy's `SOC` 869720 counts 1/10000 %:
    scale = 0.0001 → 86.972 %), said in the sketch's comment; else ''."""
    v = str(next((r.get("first", "") for r in rows if r["label"] == label), "")).strip()
    if not is_number(v) or not abs(float(v)) > 100:
        return ""
    x = abs(float(v))
    k = math.ceil(math.log10(x / 100.0))
    return (f"; its first value {v} is no per cent: scale = {10.0 ** -k:g} reads it as "
            f"{x * 10.0 ** -k:g} %, check it against the app's display")


def _clock_time(rows: list[dict]) -> tuple[str, str] | None:
    """The first time-like label whose first value is a clock time or a timestamp
    (:data:`CLOCK_FORMATS`), with its format; else None."""
    pat, bad = GUESSES["time_s"][1:]
    for r in rows:
        text = split_header(r["label"])[0]
        if not re.search(pat, text, re.I) or (bad and re.search(bad, text, re.I)):
            continue
        for rx, fmt in CLOCK_FORMATS:
            if rx.match(str(r.get("first", "")).strip()):
                return r["label"], fmt
    return None


def _coverage(row: dict) -> float:
    """How well a listed channel covers its log: an MDF channel's mean rate [Hz], a table
    column's values (rows of neither: 0; the sort is stable, so they keep their order)."""
    x = row.get("mean_rate_hz", row.get("samples", 0))
    return float(x) if x == x and x is not None else 0.0


def _toml(v) -> str:
    if isinstance(v, list):
        return "[" + ", ".join(_toml(x) for x in v) + "]"
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'
