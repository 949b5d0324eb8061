"""SUMO FCD files read in time-ordered blocks of rows (bounded memory), or whole.

``iter_fcd_blocks(path, chunk_rows)`` yields :class:`Block` objects: the timesteps the
block covers (every ``<timestep>`` of an XML file, vehicles or not; the distinct row
times of a tabular file) and its rows as NumPy columns (time, id, type, speed, lane, pos,
and angle, slope, accel, x, y, signals when the file has them), checked and converted as
:func:`read_fcd` always did. Memory is one block: XML is parsed with ``iterparse`` and cut
after a ``</timestep>`` once ``chunk_rows`` rows are collected; Parquet is read record
batch by record batch (only the FCD columns), the parts of a partitioned FCD one after
the other in the order of their first time; CSV ``chunk_rows`` lines at a time. A tabular
block may end inside a timestep: the replay (:mod:`sumo_drvpw.sim.fcd`) joins the rows of
a timestep before it books it. Rows must come in time order (SUMO writes them so); a
time earlier than the one before is a UserError naming the file and the row; so are a
vehicle without type or lane, a speed not finite or above ``SPEED_MAX_MPS`` (the drive
logs' bound), a number column of dates or time spans, and a file that cannot be read
(a truncated ``.gz``). Rows are counted in the file read (a part of a partitioned FCD).

``read_fcd(path)`` is every block joined: one DataFrame (the in-memory path).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
import zlib
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.data.log import SPEED_MAX_MPS
from sumo_drvpw.data.paths import folders_in_order
from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import open_maybe_gzip
from sumo_drvpw.sim.scenario_values import sumo_seconds
from sumo_drvpw.sim.scenario_paths import sumo_file_list

#: our name → SUMO's tabular FCD column (``<element>_<attribute>``)
FCD_COLUMNS = {"time": "timestep_time", "id": "vehicle_id", "type": "vehicle_type",
               "speed": "vehicle_speed", "lane": "vehicle_lane", "pos": "vehicle_pos",
               "angle": "vehicle_angle", "slope": "vehicle_slope",
               "accel": "vehicle_acceleration", "x": "vehicle_x", "y": "vehicle_y", "signals": "vehicle_signals"}
_REQUIRED = ("time", "id", "type", "speed", "lane", "pos")
#: optional columns; x, y tell a parked vehicle (beside its lane) from a standing one, and
#: signals (--fcd-output.signals) one idling in its space, blinker on (sim/fcd_idle.py)
_OPTIONAL = ("angle", "slope", "accel", "x", "y", "signals")
_XML_ATTRS = {"id": "id", "type": "type", "speed": "speed", "lane": "lane", "pos": "pos", "angle": "angle",
              "slope": "slope", "accel": "acceleration", "x": "x", "y": "y", "signals": "signals"}
#: what a row missing one of the replay's attributes tells the user to do
ATTRIBUTES_HINT = ("; an FCD recorded with --fcd-output.attributes needs speed, lane, pos and type "
                   "among them (and x, y to tell parked vehicles)")
#: our name → what the messages call it in an XML / a tabular file
_XML_NAMES = {k: f"attribute {a}" for k, a in _XML_ATTRS.items()}
_TABULAR_NAMES = {k: f"column {c}" for k, c in FCD_COLUMNS.items()}
#: rows per block of the streamed replay (about 15 MB of columns; larger blocks read no
#: faster: the replay's per-timestep work dominates)
CHUNK_ROWS = 50_000
#: bytes read at a time from a Parquet column chunk (SUMO writes one row group: without
#: it the whole compressed column chunks are held while they are decoded)
PARQUET_BUFFER = 1 << 20


@dataclass
class Block:
    """Rows of consecutive timesteps. ``times``: the timesteps the block covers, ascending
    (XML: also those without vehicles); ``cols``: name → array of the rows (``id``,
    ``type``, ``lane`` object arrays of str; the rest float; optional ones absent when the
    file lacks them); ``first_row``: the number of rows before this block."""

    times: np.ndarray
    cols: dict
    first_row: int

    def __len__(self) -> int:
        return len(self.cols["time"])


def fcd_parts(spec) -> list[Path]:
    """The Parquet files of a partitioned FCD: a folder (its ``*.parquet``, recursively) or
    a glob pattern (``fcd/part-*.parquet``), sorted by name; [] when ``spec`` is neither."""
    import glob

    p = Path(spec)
    if p.is_dir():
        files = sorted(f for f in p.rglob("*.parquet") if f.is_file())
        if not files:
            raise UserError(f"FCD folder {p}: no .parquet files in it")
        return files
    if any(c in str(spec) for c in "*?[") and not p.exists():
        files = sorted(Path(f) for f in glob.glob(str(spec), recursive=True) if Path(f).is_file())
        if not files:
            raise UserError(f"FCD pattern {spec}: matches no file")
        bad = [f for f in files if not f.name.lower().endswith(".parquet")]
        if bad:
            raise UserError(f"FCD pattern {spec}: {bad[0]} is not a .parquet file (a pattern "
                            "reads partitioned Parquet FCD only)")
        return files
    return []


LANE_MAX_M = 1.0e6  #: the longest lane a position may lie on [m] (SUMO's longest edges: tens of km)


def _normalise(df: pd.DataFrame, label, first_row: int, names: dict | None = None) -> dict:
    """Checked columns of raw rows (our names): rows without an id dropped, numbers
    parsed (UserError naming the column and the row, counted over the whole file; a
    missing type or lane of a vehicle, a speed not finite or above ``SPEED_MAX_MPS``).
    ``names``: our name → the file's (XML attribute, tabular column), for the messages."""
    names = {k: f"column {k}" for k in FCD_COLUMNS} | (names or {})
    has_id = (df["id"].notna() & (df["id"].astype(str) != "")).to_numpy()
    rows = np.flatnonzero(has_id)  # the kept rows' positions in the block

    def row(i: int) -> int:  # the file's row of kept row i
        return first_row + int(rows[i]) + 1

    df = df[has_id]
    out = {}
    for k in ("time", "speed", "pos", *_OPTIONAL):
        if k not in df.columns:
            continue
        vals = pd.to_numeric(df[k], errors="coerce")
        bad = vals.isna() & df[k].notna()
        if bad.any():
            i = int(np.flatnonzero(bad.to_numpy())[0])
            raise UserError(f"FCD file {label}: {names[k]}: not a number at vehicle row "
                            f"{row(i)}: {df[k].iloc[i]!r}")
        out[k] = vals.to_numpy(float)
    person = (df["person"].to_numpy(bool) if "person" in df.columns
              else np.zeros(len(df), bool))
    for k in ("speed", "pos"):
        miss = np.isnan(out[k]) & ~person  # a person's row may lack them: it rides nowhere
        if miss.any():
            i = int(np.flatnonzero(miss)[0])
            raise UserError(f"FCD file {label}: column {k} missing at vehicle row "
                            f"{row(i)} (vehicle {df['id'].iloc[i]!r}){ATTRIBUTES_HINT}")
    v = out["speed"]
    # NaN: a person's missing speed (checked above); SUMO writes no negative speed (a
    # rounded −0.00 aside)
    bad = np.isinf(v) | (v > SPEED_MAX_MPS) | (v < -0.01)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise UserError(f"FCD file {label}: {names['speed']} is {v[i]:g} at vehicle "
                        f"row {row(i)} (vehicle {df['id'].iloc[i]!r}): not a speed (finite, 0 to "
                        f"{SPEED_MAX_MPS:g} m/s)")
    pos = out["pos"]  # a position on its lane: SUMO writes none below 0 or beyond any lane (a rounded −0.00 aside)
    bad = ~person & (np.isinf(pos) | (pos < -0.01) | (pos > LANE_MAX_M))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise UserError(f"FCD file {label}: {names['pos']} is {pos[i]:g} at vehicle row {row(i)} "
                        f"(vehicle {df['id'].iloc[i]!r}): not a position on a lane (0 to {LANE_MAX_M:g} m)")
    for k in ("type", "lane"):  # SUMO writes both for every vehicle (a person has no lane)
        miss = df[k].isna().to_numpy() & ~person
        if miss.any():
            i = int(np.flatnonzero(miss)[0])
            meso = (" of a microscopic simulation (a mesoscopic one writes the edge: it "
                    "moves vehicles queue by queue, without lanes or accelerations, so no "
                    "driving power follows from its FCD)") if k == "lane" else ""
            raise UserError(f"FCD file {label}: {names[k]} missing at vehicle row {row(i)} "
                            f"(vehicle {df['id'].iloc[i]!r}); SUMO writes it for every "
                            f"vehicle{meso}{ATTRIBUTES_HINT}")
    miss = np.isnan(out["time"])  # a row of the tabular FCD without its timestep's time
    if miss.any():
        i = int(np.flatnonzero(miss)[0])
        raise UserError(f"FCD file {label}: {names['time']} missing at row {row(i)} "
                        f"({'person' if person[i] else 'vehicle'} {df['id'].iloc[i]!r})")
    for k in ("id", "type", "lane"):
        out[k] = df[k].astype(str).to_numpy(object)
    twice = pd.DataFrame({"t": out["time"], "id": out["id"]})[~person].duplicated().to_numpy()
    if twice.any():  # SUMO writes a vehicle once per timestep
        i = int(np.flatnonzero(~person)[np.flatnonzero(twice)[0]])
        raise UserError(f"FCD file {label}: vehicle {out['id'][i]!r} appears twice at time "
                        f"{out['time'][i]:g} (vehicle row {row(i)}); SUMO writes each vehicle "
                        "once per timestep")
    out["lane"][person] = ""  # persons walk on edges, not lanes (and ride in vehicles)
    out["person"] = person
    return out


def _temporal(dtype) -> bool:
    """A date, time span or truth column (pandas' numbers, but not SUMO's)."""
    return (pd.api.types.is_datetime64_any_dtype(dtype) or pd.api.types.is_timedelta64_dtype(dtype)
            or pd.api.types.is_bool_dtype(dtype))


def _xml_blocks(path: Path, chunk_rows: int):
    keys = ("time", "person", *_XML_ATTRS)
    present = dict.fromkeys(_OPTIONAL, False)

    def block(cols, times, first):
        for k in _OPTIONAL:
            present[k] = present[k] or any(x is not None for x in cols[k])
        df = pd.DataFrame({k: v for k, v in cols.items()
                           if k in _REQUIRED or k == "person" or present[k]})
        return Block(np.asarray(times, float), _normalise(df, path, first, _XML_NAMES), first)

    cols: dict[str, list] = {k: [] for k in keys}
    times: list[float] = []
    done = 0
    try:
        with open_maybe_gzip(path) as fh:
            t = None
            for ev, el in ET.iterparse(fh, events=("start", "end")):
                tag = el.tag
                if ev == "start":
                    if tag == "timestep":
                        t = _seconds(el.attrib["time"])
                        times.append(t)
                    continue
                if tag in ("vehicle", "person", "container") and t is not None:  # (a container: as a person
                    a = el.attrib  # of a container type, as SUMO's tabular FCD writes it: fcd_conn)
                    cols["time"].append(t)
                    cols["person"].append(tag != "vehicle")
                    for k, xk in _XML_ATTRS.items():
                        cols[k].append(a.get(xk))
                    el.clear()
                elif tag == "timestep":
                    el.clear()
                    if len(cols["time"]) >= chunk_rows:
                        b = block(cols, times, done)
                        done += len(cols["time"])
                        cols, times = {k: [] for k in keys}, []
                        yield b
    except ET.ParseError as e:
        raise UserError(f"FCD file {path}: not valid XML: {e}") from None
    except (KeyError, ValueError) as e:
        raise UserError(f"FCD file {path}: a <timestep> without a valid time: {e}") from None
    except (EOFError, OSError, zlib.error) as e:  # gzip.BadGzipFile is an OSError
        raise UserError(f"FCD file {path}: cannot read it (truncated or corrupt?): {e}") from None
    if times or cols["time"]:
        yield block(cols, times, done)


def _tabular_block(raw: pd.DataFrame, label, first: int, row0: int | None = None) -> Block:
    """A block of a tabular file's rows; ``first``: rows before it (of every part read),
    ``row0``: rows before it in the file ``label`` (default ``first``), for the messages."""
    missing = [FCD_COLUMNS[k] for k in _REQUIRED if FCD_COLUMNS[k] not in raw.columns]
    if missing:
        raise UserError(f"FCD file {label}: no column {missing[0]} (SUMO's tabular FCD "
                        f"has {', '.join(FCD_COLUMNS[k] for k in _REQUIRED)})")
    _check_types({c: raw[c].dtype for c in raw.columns}, label, _temporal)
    raw = raw.assign(**{FCD_COLUMNS["time"]: _time_column(raw[FCD_COLUMNS["time"]])})
    times = np.unique(pd.to_numeric(raw[FCD_COLUMNS["time"]], errors="coerce").dropna())
    df = pd.DataFrame({k: raw[c] for k, c in FCD_COLUMNS.items() if c in raw.columns})
    # SUMO's tabular FCD writes persons in the vehicles' columns, with an edge and no lane
    # (a row with neither is a damaged vehicle row: refused below, not read as a person)
    def empty(c):
        return (c.isna() | (c.astype(str) == "")).to_numpy()
    person = empty(raw[FCD_COLUMNS["lane"]])
    if "vehicle_edge" in raw.columns:
        person = person & ~empty(raw["vehicle_edge"])
    df["person"] = person
    return Block(times.astype(float),
                 _normalise(df, label, first if row0 is None else row0, _TABULAR_NAMES), first)


def _check_types(types: dict, label, wrong) -> None:
    """UserError for a numeric column of a tabular FCD (column name → its pandas dtype or
    Arrow type) whose type is ``wrong`` (dates, time spans, truth values: SUMO writes
    seconds, metres, m/s)."""
    for k in ("time", "speed", "pos", *_OPTIONAL):
        c = FCD_COLUMNS[k]
        if c in types and wrong(types[c]):
            raise UserError(f"FCD file {label}: column {c} holds {types[c]} values, not "
                            "numbers (SUMO writes times in seconds, speeds in m/s, positions "
                            "in m)")


def _first_time(f: Path) -> float:
    """The first row's time of a Parquet part (its statistics, else its first batch)."""
    import pyarrow.parquet as pq

    pf = pq.ParquetFile(f)
    names = pf.schema_arrow.names
    col = FCD_COLUMNS["time"]
    if col not in names or pf.metadata.num_rows == 0:
        return float("inf")
    _check_arrow_types(pf.schema_arrow, f)
    rg = pf.metadata.row_group(0).column(names.index(col)).statistics
    if rg is not None and rg.has_min_max and not isinstance(rg.min, (str, bytes)):
        return float(rg.min)
    # no statistics, or clock-time strings (their minimum sorts as text: the first row)
    batch = next(pf.iter_batches(batch_size=1, columns=[col]))
    return _seconds(str(batch.column(0)[0].as_py()))


def _seconds(text: str) -> float:
    """A time attribute of SUMO's output: seconds, or "h:m:s" / "d:h:m:s" when the run
    had --human-readable-time; ValueError otherwise."""
    try:
        return float(text)
    except ValueError:
        t = sumo_seconds(text)
        if t is None:
            raise ValueError(f"not a time in seconds or h:m:s: {text!r}") from None
        return t


def _time_column(col: pd.Series) -> pd.Series:
    """A tabular FCD's time column in seconds (clock-time strings of --human-readable-time
    converted once per distinct value; anything else left for the number check)."""
    if pd.api.types.is_numeric_dtype(col):
        return col
    text = col.astype("string")
    clock = text.str.contains(":", na=False)
    if not clock.any():
        return col
    values = {u: sumo_seconds(u) for u in text[clock].unique()}
    return col.where(~clock, text[clock].map(lambda u: values[u] if values[u] is not None else u))


def _check_arrow_types(schema, label) -> None:
    """:func:`_check_types` on a Parquet file's schema (dates, times of day, time spans,
    truth values in a numeric column)."""
    import pyarrow as pa

    _check_types({f.name: f.type for f in schema}, label,
                 lambda t: pa.types.is_temporal(t) or pa.types.is_boolean(t))


def _parquet_blocks(files: list[Path], label, chunk_rows: int):
    import pyarrow.parquet as pq

    wanted = set(FCD_COLUMNS.values())
    if len(files) > 1:  # the parts in time order (names sort part-10 before part-2)
        try:
            files = sorted(files, key=lambda f: (_first_time(f), str(f)))
        except UserError:
            raise
        except Exception as e:  # pyarrow raises several error types for bad files
            raise UserError(f"FCD {label}: cannot read Parquet: {e}") from None
    first, schema = 0, None
    for f in files:
        try:
            pf = pq.ParquetFile(f, buffer_size=PARQUET_BUFFER, pre_buffer=False)
            names = [c for c in pf.schema_arrow.names if c in wanted]
            types = {c: pf.schema_arrow.field(c).type for c in names}
        except Exception as e:
            raise UserError(f"FCD file {f}: cannot read Parquet: {e}") from None
        _check_arrow_types(pf.schema_arrow, f)
        if schema is None:
            schema = types
        bad = [c for c in names if c in schema and types[c] != schema[c]
               and not (pd.api.types.is_numeric_dtype(types[c].to_pandas_dtype())
                        and pd.api.types.is_numeric_dtype(schema[c].to_pandas_dtype()))]
        if bad:
            raise UserError(f"FCD {label}: the parts' columns do not agree: {bad[0]} is "
                            f"{schema[bad[0]]} in the first part, {types[bad[0]]} in {f}")
        try:
            batches = pf.iter_batches(batch_size=chunk_rows, columns=names)
            row0 = 0  # rows before the batch in this part
            for rb in batches:
                b = _tabular_block(rb.to_pandas(), f, first, row0)
                first += rb.num_rows
                row0 += rb.num_rows
                yield b
        except UserError:
            raise
        except Exception as e:
            raise UserError(f"FCD file {f}: cannot read Parquet: {e}") from None


def _csv_blocks(path: Path, chunk_rows: int):
    first = 0
    text = {FCD_COLUMNS[k]: str for k in ("id", "type", "lane")}
    try:
        reader = pd.read_csv(path, sep=None, engine="python", chunksize=chunk_rows, dtype=text,
                             encoding="utf-8-sig")  # a byte-order mark (Excel) is no header
        for raw in reader:
            b = _tabular_block(raw, path, first)
            first += len(raw)
            yield b
    except UserError:
        raise
    except Exception as e:
        raise UserError(f"FCD file {path}: cannot read CSV: {e}") from None


def header_options(path) -> dict[str, str] | None:
    """The options SUMO wrote into the comment at the head of an XML FCD output (those of
    the run that recorded it which differ from SUMO's defaults: option → value); None when
    the file has no such header (Parquet, CSV, a folder or pattern of parts, or XML written
    by another tool)."""
    import re

    p = Path(path)
    name = p.name.lower()
    if fcd_parts(path) or not p.is_file() or name.endswith((".parquet", ".csv", ".csv.gz")):
        return None
    try:
        with open_maybe_gzip(p) as fh:
            head = fh.read(65536).decode("utf-8", "replace")
    except (EOFError, OSError, zlib.error):
        return None  # the reader says what is wrong with the file
    m = re.search(r"<!--\s*generated on.*?by Eclipse SUMO(.*?)-->", head, re.S)
    if m is None:
        return None
    return dict(re.findall(r"<([\w.:-]+) value=\"([^\"]*)\"\s*/>", m.group(1)))


#: the input options of a SUMO run whose files a replay takes from an FCD's header
RECORDED_INPUTS = ("net-file", "route-files", "additional-files")
#: folders named by the header's paths but not by where the FCD is now, searched at most
#: this deep and this many (the run's folder beside the FCD's: ``scenario/`` of ``out/``)
_SEARCH_DEPTH, _SEARCH_DIRS = 2, 2000
#: the name standing for a folder of the run the FCD's path does not name
_MARK = "\u2039run folder\u203a"


def recorded_inputs(path, head: dict[str, str] | None = None, cwd=None) -> dict | None:
    """The network, route and additional files of the run that recorded an XML FCD, as its
    header names them (:func:`header_options`), found on this machine: ``{"net": Path |
    None, "files": [route files, then additional files], "missing": [(option, path as
    written) not found], "looked_in": [folders tried]}``; None without a header or when it
    names no input.

    SUMO writes each path as given, relative to the folder of its config (``-c``) or to
    the working folder of the run — a folder the header does not name. The header's own
    ``fcd-output`` path leads from that folder to the FCD, so a path is found from where the
    FCD is now, wherever the run was started. Where it climbs out of the FCD's folders (a
    config in ``scenario/`` writing ``../out/fcd.xml`` and reading ``net.net.xml``), the
    run's folder is the folder that deep beside them holding the most of the header's
    files; where several hold as many, a file is taken only where they all put the same one
    (a folder's name the paths leave open: each folder's copy differs, none is guessed). Else — the FCD renamed or moved on its own — the folder of the FCD,
    its parent and ``cwd`` (default: the working folder) are tried in that order. A path
    SUMO wrote absolute is taken as it is."""
    import posixpath

    head = header_options(path) if head is None else head
    if not head or not any(head.get(k, "").strip() for k in RECORDED_INPUTS):
        return None
    fcd = Path(path).resolve()
    fallbacks = list(dict.fromkeys([fcd.parent, fcd.parent.parent, Path(cwd or Path.cwd()).resolve()]))
    # a stand-in for the run's folder, deep enough that no ".." of a real path climbs out
    marks = [f"{_MARK}{i}" for i in range(32)]
    root = "/" + "/".join(marks)
    out_rel = head.get("fcd-output", "").strip().replace("\\", "/")
    start = (posixpath.dirname(posixpath.normpath(posixpath.join(root, out_rel)))
             if out_rel and not posixpath.isabs(out_rel) else None)
    values = [(k, v.replace("\\", "/")) for k in RECORDED_INPUTS for v in sumo_file_list(head.get(k))]

    def from_fcd(v: str) -> str | None:  # the path from the FCD's folder (marks: unknown names)
        if start is None or posixpath.isabs(v):
            return None
        return posixpath.relpath(posixpath.normpath(posixpath.join(root, v)), start)

    # the run's folders the paths name and the FCD's does not: the candidates beside them
    # that hold the most of the files; a file is taken where they all put the same one
    hidden = {v: r for _, v in values if (r := from_fcd(v)) is not None and _MARK in r}
    chosen: dict[str, Path] = {}
    if hidden:
        def known(r: str) -> str:  # the part of a path before its first unnamed folder
            parts = r.split("/")
            return "/".join(parts[:next(i for i, p in enumerate(parts) if p in marks)])

        def named(r: str, sub: dict) -> Path:
            return fcd.parent / "/".join(sub.get(p, p) for p in r.split("/"))

        # the unnamed folders, outermost first (each path names a leading run of them)
        chain = max(([p for p in r.split("/") if p in marks] for r in hidden.values()), key=len)
        depth = len(chain)
        up = known(next(iter(hidden.values())))  # "": the run's folder is below the FCD's
        if depth <= _SEARCH_DEPTH and all(known(r) == up for r in hidden.values()):
            best: list[tuple[int, dict]] = []
            for cand in folders_in_order((fcd.parent / up).resolve(), depth, _SEARCH_DIRS):
                sub = dict(zip(chain, cand.parts[-depth:]))
                hits = sum(named(r, sub).is_file() for r in hidden.values())
                if hits:
                    best.append((hits, sub))
            top = [sub for h, sub in best if h == max(h for h, _ in best)] if best else []
            for v, r in hidden.items():
                found = {named(r, sub).resolve() for sub in top if named(r, sub).is_file()}
                if len(found) == 1 and len(top) == len([1 for sub in top if named(r, sub).is_file()]):
                    chosen[v] = found.pop()

    def find(v: str) -> Path | None:
        if posixpath.isabs(v) or Path(v).is_absolute():
            return Path(v).resolve() if Path(v).is_file() else None
        tries = [chosen[v]] if v in chosen else []
        r = from_fcd(v)
        if r is not None and _MARK not in r:
            tries.append(fcd.parent / r)
        tries += [d / v for d in fallbacks]
        return next((t.resolve() for t in tries if t.is_file()), None)

    from sumo_drvpw.sim.sumo_outputs import original_of_copy

    got = [(key, v, find(v)) for key, v in values]
    # an FCD that ``sumo-drvpw run`` recorded names its temporary copies of the additional
    # files that declare outputs (gone after the run): the originals, where its others are
    homes = list(dict.fromkeys(p.parent for _, _, p in got if p is not None))
    net, files, missing = None, [], []
    for key, v, p in got:
        name = original_of_copy(v) if p is None else None
        names = (name, name + ".gz") if name else ()  # (the copy of x.add.xml.gz is N.x.add.xml)
        p = p or next(((d / n).resolve() for d in homes for n in names if (d / n).is_file()), None)
        if p is None:
            missing.append((key, v))
        elif key == "net-file":
            net = p
        elif p not in files:
            files.append(p)
    return {"net": net, "files": files, "missing": missing, "looked_in": [str(d) for d in fallbacks]}


#: SUMO configs looked at for the one that wrote a header-less FCD (beside it and one up)
CONFIGS_LOOKED_AT = 50


def configs_beside(path) -> list[Path]:
    """The SUMO configs (``*.sumocfg``) in an FCD's folder and the one above it, at most
    :data:`CONFIGS_LOOKED_AT`."""
    fcd = Path(path).resolve()
    return [*sorted(fcd.parent.glob("*.sumocfg")), *sorted(fcd.parent.parent.glob("*.sumocfg"))][:CONFIGS_LOOKED_AT]


def configs_writing(path) -> list[tuple[Path, Path, list[Path]]]:
    """The SUMO configs beside an FCD file (:func:`configs_beside`) whose ``fcd-output`` is
    this file, each as (config, its network, its route and additional files)."""
    from sumo_drvpw.sim.scenario_paths import config_files

    p = Path(path)
    if fcd_parts(path) or not p.is_file():
        return []
    fcd = p.resolve()
    found = []
    for cfg in configs_beside(fcd):
        try:
            net, files, vals = config_files(cfg)
        except UserError:
            continue
        out = vals.get("fcd-output", "").strip()
        if out and (cfg.parent / out).resolve() == fcd:
            found.append((cfg, net, files))
    return found


def configured_inputs(path) -> dict | None:
    """For an FCD without SUMO's header (Parquet, CSV, or XML another tool wrote): the
    network, route and additional files of the one SUMO config (``*.sumocfg`` in the FCD's
    folder or the one above it) whose ``fcd-output`` is this file, as
    :func:`recorded_inputs` returns them (plus ``"config"``); None when no config, or more
    than one, names it (a run given ``--fcd-output`` on its command line names it nowhere)."""
    found = configs_writing(path)
    if len(found) != 1:
        return None
    cfg, net, files = found[0]
    have = [f for f in files if f.is_file()]
    return {"net": net if net.is_file() else None, "files": have, "config": cfg,
            "missing": ([("net-file", str(net))] if not net.is_file() else [])
            + [("route-files", str(f)) for f in files if not f.is_file()],
            "looked_in": [str(cfg.parent)]}


def run_inputs(path) -> dict | None:
    """The files of the run that wrote an FCD: those its header names
    (:func:`recorded_inputs`), else those of the SUMO config beside it that writes it
    (:func:`configured_inputs`, with ``"config"``); None when neither names any."""
    return recorded_inputs(path) or configured_inputs(path)


def iter_fcd_blocks(path, chunk_rows: int = CHUNK_ROWS):
    """Blocks of about ``chunk_rows`` rows of an FCD file (XML, ``.xml.gz``, Parquet, CSV)
    or of partitioned Parquet FCD (a folder or a glob pattern), in time order."""
    if chunk_rows < 1:
        raise UserError(f"FCD: chunk_rows must be ≥ 1, got {chunk_rows}")
    parts = fcd_parts(path)
    p = Path(path)
    if not parts and not p.is_file():
        raise UserError(f"FCD file not found: {p}")
    name = p.name.lower()
    if parts or name.endswith(".parquet"):
        return _parquet_blocks(parts or [p], p, chunk_rows)
    if name.endswith(".csv") or name.endswith(".csv.gz"):
        return _csv_blocks(p, chunk_rows)
    return _xml_blocks(p, chunk_rows)


def read_fcd(path, chunk_rows: int = CHUNK_ROWS) -> pd.DataFrame:
    """FCD rows (time, id, type, speed, lane, pos, person, [angle, slope, accel, x, y]) sorted
    by time (``person``: a person's row, SUMO's ``<person>``; its lane "");
    ``df.attrs["times"]``: every timestep of the file, vehicles or not. UserError names
    the file and the missing column. ``path``: a file, or partitioned Parquet FCD (a folder
    or a glob pattern of ``.parquet`` files, read as one, only the FCD columns). Holds the
    whole file: for long files replay it streamed (:func:`sumo_drvpw.sim.fcd.process_fcd`)."""
    blocks = list(iter_fcd_blocks(path, chunk_rows))
    keys = [k for k in FCD_COLUMNS if k in _REQUIRED or any(k in b.cols for b in blocks)]
    df = pd.DataFrame({k: np.concatenate([b.cols[k] if k in b.cols else
                                          np.full(len(b), np.nan) for b in blocks])
                       if blocks else np.zeros(0) for k in keys})
    df["person"] = (np.concatenate([b.cols["person"] for b in blocks]) if blocks
                    else np.zeros(0, bool))
    for k in ("id", "type", "lane"):
        df[k] = df[k].astype(str).astype(object)
    times = np.unique(np.concatenate([b.times for b in blocks])) if blocks else np.zeros(0)
    df = df.sort_values("time", kind="stable").reset_index(drop=True)
    df.attrs["times"] = times
    return df
