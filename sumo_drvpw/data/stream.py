"""Stream canonical drive logs in bounded memory, one batch of whole trips at a time.

The unit of streaming is the trip: every derivation that needs neighbours (acceleration,
grade from elevation over distance, shaft accelerations of measured power) is per trip
already, so a batch of *whole* trips goes through exactly the reader's own path
(:func:`sumo_drvpw.data.log.from_frame`, then :func:`sumo_drvpw.data.measured.measure`) and
sees the same samples as :func:`~sumo_drvpw.data.measured.load_measured`.

Files are read in chunks of ``rows`` (Parquet record batches via pyarrow, CSV chunks via
pandas); :func:`iter_measured` reads fewer rows of a wide file, at most :data:`BATCH_VALUES`
values of the columns it reads. The last trip of a chunk may continue in the next one; its
rows are carried over until the trip ends (or the file does), so a trip is never cut.
Memory is therefore O(``rows`` + the longest trip); a trip longer than ``max_trip_rows`` is refused with a
``UserError`` (split it into trips: ``trip_id``). A file without ``trip_id`` is one trip.

A :class:`Part` is a piece of the input that holds whole trips (a file, or a range of
rows of a Parquet file that starts and ends at trip boundaries): the unit of work of the
engines in :mod:`sumo_drvpw.fit.engine`.

The derived acceleration and the time weights of a trip are its own (its median step, the
resolution of its speed, its logging gaps: :func:`sumo_drvpw.data.log.read_log`), so a
batch gives the same numbers as the in-memory reader, whatever trips share the batch.
Row numbers in error messages count from the start of the batch named in the message.
"""

from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
import pandas as pd

from sumo_drvpw.data.log import DERIVED, ReadOptions, _validate, from_frame
from sumo_drvpw.data.log_files import FLAGS, NUMERIC, REQUIRED, expand_paths, read_error
from sumo_drvpw.data.plausible import check_header
from sumo_drvpw.data.truncated import complete_bytes, open_complete, refuse_if_too_short
from sumo_drvpw.errors import UserError

#: Columns the reader and measured power use; calibrate and compare read these plus the
#: signals their terms name (extra columns are for the tracer, not read here).
CANONICAL = frozenset(NUMERIC) | frozenset(FLAGS) | frozenset(DERIVED)
#: Rows read per chunk at most [-] (a narrow log's bound; a wide one's is :data:`BATCH_VALUES`).
BATCH_ROWS = 500_000
#: Values (rows × (columns read + :data:`DERIVED_VALUES`)) a batch holds at most: the
#: streamed reader's peak is its working set of one batch (the Arrow batch, its frame, the
#: validated copy, the derived inputs and extra signals, what the statistics compute on it,
#: the next batch read meanwhile: about 40 bytes per value), so a wide log is read in fewer
#: rows (:func:`rows_for`) and the peak does not grow with its width
BATCH_VALUES = 2_000_000
#: Values per row counted besides the columns read, for the inputs, measured power, masks,
#: weights and trip codes derived from them: a narrow log is read in about 100,000 rows a
#: batch, not 500,000 (calibrate of benchmarks/scale.py's 10 M-row log of 8 columns: peak RSS
#: ~315 against ~520 MB, the same CPU time; batches of 50,000 rows took 20–100 % more CPU)
DERIVED_VALUES = 10
#: ... but at least this many rows per chunk (the per-batch overhead)
MIN_BATCH_ROWS = 10_000
#: Longest trip streamed [rows] (about 29 days at 8 Hz); longer ones must be split.
MAX_TRIP_ROWS = 20_000_000
#: Rows a Part of a Parquet file has at least when a file is cut for parallel engines.
PART_ROWS = 4_000_000


@dataclass(frozen=True)
class Part:
    """Whole trips of one file: all of it, or its rows ``start`` to ``stop`` (Parquet)."""

    path: str
    start: int | None = None
    stop: int | None = None
    rows: int = 0

    def describe(self) -> str:
        if self.start is None:
            return self.path
        return f"{self.path} [rows {self.start}–{self.stop - 1}]"


def _is_parquet(p: Path) -> bool:
    return p.suffix.lower() == ".parquet"


def _parquet_file(p: Path, **kw):
    import pyarrow.parquet as pq

    try:
        return pq.ParquetFile(p, **kw)
    except (OSError, ValueError) as e:
        raise UserError(f"{p}: cannot read as parquet: {e}") from None


def trip_starts(p: Path) -> np.ndarray:
    """Row numbers where a new trip starts in a Parquet file with ``trip_id`` (row 0 first).

    Reads only the ``trip_id`` column, one row group at a time, dictionary-encoded (the
    comparison is on integer codes within a row group)."""
    f = _parquet_file(p, read_dictionary=["trip_id"])
    out, offset, prev = [np.zeros(1, np.int64)], 0, None
    for i in range(f.metadata.num_row_groups):
        col = f.read_row_group(i, columns=["trip_id"]).column(0).combine_chunks()
        n = len(col)
        if n == 0:
            continue
        if hasattr(col, "indices"):
            codes = col.indices.to_numpy(zero_copy_only=False)
            first, last = col.dictionary[codes[0]].as_py(), col.dictionary[codes[-1]].as_py()
        else:
            codes = pd.factorize(col.to_numpy(zero_copy_only=False))[0]
            first, last = col[0].as_py(), col[n - 1].as_py()
        new = np.flatnonzero(codes[1:] != codes[:-1]) + 1 + offset
        if prev is not None and str(first) != str(prev) and offset > 0:
            out.append(np.array([offset]))
        out.append(new)
        prev = last
        offset += n
    return np.concatenate(out)


def plan(paths, part_rows: int | None = None) -> list[Part]:
    """The input as Parts of whole trips, in reading order.

    Parameters
    ----------
    paths : files or folders (Parquet, CSV), as for :func:`sumo_drvpw.data.log.read_log`
    part_rows : when given, a Parquet file with ``trip_id`` is cut into Parts of at least
        this many rows [-], each cut at the start of a trip (for parallel engines); CSV
        files and files without ``trip_id`` are one Part each. None: one Part per file.
    """
    parts: list[Part] = []
    for p in expand_paths(paths):
        if not _is_parquet(p):
            parts.append(Part(str(p)))
            continue
        f = _parquet_file(p)
        n = f.metadata.num_rows
        if part_rows is None or n <= part_rows or "trip_id" not in f.schema_arrow.names:
            parts.append(Part(str(p), rows=n))
            continue
        starts = trip_starts(p)
        cuts = [0]
        for s0 in starts:
            if s0 - cuts[-1] >= part_rows:
                cuts.append(int(s0))
        cuts.append(n)
        parts += [Part(str(p), a, b, b - a) for a, b in zip(cuts[:-1], cuts[1:]) if b > a]
    return parts


def _text_trip_id(p: Path) -> list[str]:
    """``["trip_id"]`` when a Parquet file stores it as text (read dictionary-encoded: a
    pandas categorical, integer codes instead of one Python string per row), else []."""
    import pyarrow as pa

    f = _parquet_file(p)
    names = f.schema_arrow.names
    if "trip_id" not in names:
        return []
    typ = f.schema_arrow.field("trip_id").type
    return ["trip_id"] if pa.types.is_string(typ) or pa.types.is_large_string(typ) else []


def _chunks(part: Part, rows: int, columns=None, categorical: bool = False) -> Iterator[pd.DataFrame]:
    p = Path(part.path)
    try:
        check_header(p)  # a column named twice, a CSV not separated by commas
        if _is_parquet(p):
            f = _parquet_file(p, read_dictionary=_text_trip_id(p) if categorical else None)
            cols = None if columns is None else [c for c in f.schema_arrow.names if c in columns]
            groups, at = None, 0
            if part.start is not None:
                sizes = [f.metadata.row_group(i).num_rows for i in range(f.metadata.num_row_groups)]
                ends = np.cumsum(sizes)
                groups = [i for i in range(len(sizes))
                          if ends[i] > part.start and ends[i] - sizes[i] < part.stop]
                at = int(ends[groups[0]] - sizes[groups[0]]) if groups else 0
            for b in f.iter_batches(batch_size=rows, row_groups=groups, columns=cols):
                lo, hi = at, at + b.num_rows
                at = hi
                if part.start is not None:
                    if hi <= part.start or lo >= part.stop:
                        continue
                    b = b.slice(max(part.start - lo, 0), min(hi, part.stop) - max(lo, part.start))
                yield b.to_pandas()
                del b
        else:
            # every column read, then the wanted kept: with usecols, pandas drops the extra
            # fields of a row longer than the header silently (the memory engine refuses it);
            # a file cut inside its last row is read up to it (data/truncated.py)
            size = complete_bytes(p)
            with (nullcontext(p) if size is None else open_complete(p, size)) as src:
                for df in pd.read_csv(src, chunksize=rows, low_memory=False):
                    yield df if columns is None else df[[c for c in df.columns if c in columns]]
    except pd.errors.EmptyDataError:
        raise UserError(f"{p}: empty file (no header, no rows)") from None
    except (OSError, ValueError, pd.errors.ParserError) as e:
        raise read_error(p, e) from None


def check_required(path) -> None:
    """A drive log without a required column is refused before its batches are read, as
    the whole-file reader refuses it, naming the file's own columns (a batch holds only the
    columns a run reads: the message listed those). An unreadable header is left to the
    reading."""
    p = Path(path)
    check_header(p)  # a column named twice, a CSV not separated by commas: said as such
    try:
        names = (_parquet_file(p).schema_arrow.names if _is_parquet(p)
                 else list(pd.read_csv(p, nrows=0).columns))
    except (UserError, OSError, ValueError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return
    if any(c not in names for c in REQUIRED):
        _validate(pd.DataFrame(columns=names), p)


def column_names(path) -> list[str] | None:
    """The column names of a drive log file (a Parquet file's schema, a CSV file's header),
    without reading its rows; None when the header cannot be read (reading the file then
    says why)."""
    p = Path(path)
    try:
        return list(_parquet_file(p).schema_arrow.names if _is_parquet(p)
                    else map(str, pd.read_csv(p, nrows=0).columns))
    except (UserError, OSError, ValueError, UnicodeDecodeError, pd.errors.ParserError,
            pd.errors.EmptyDataError):
        return None


def rows_for(width: int, rows: int = BATCH_ROWS) -> int:
    """Rows per chunk of a file read ``width`` columns wide: :data:`BATCH_VALUES` over the
    width plus :data:`DERIVED_VALUES`, within [:data:`MIN_BATCH_ROWS`, ``rows``] (``rows``
    below that minimum is kept)."""
    return int(min(rows, max(MIN_BATCH_ROWS, BATCH_VALUES // (max(int(width), 0) + DERIVED_VALUES))))


def read_width(path, columns=None) -> int:
    """Columns a chunk of the file ``path`` holds when ``columns`` are wanted (None: all): a
    Parquet file reads only those it has; a CSV chunk is parsed whole, then cut (:func:`_chunks`).
    A header that cannot be read counts as none (its reading says why)."""
    names = column_names(path) or ()
    if columns is None or not _is_parquet(Path(path)):
        return len(names)
    return sum(c in columns for c in names)


def logged_flows(path, rows: int = BATCH_ROWS) -> frozenset | None:
    """The fuel flows, air flows and fuel trims (:func:`sumo_drvpw.data.powertrain.flow_columns`)
    that hold a value anywhere in a whole file: what its batches choose their fuel flow by,
    as the in-memory reader chooses on the whole file (``DriveLog.logged``). Reads only those
    columns. None when the file cannot be read so (its reading then says why)."""
    from sumo_drvpw.data.powertrain import flow_columns

    p = Path(path)
    names = column_names(p)
    if names is None:
        return None
    try:
        want = [c for c in dict.fromkeys(flow_columns(names))]
        found: set[str] = set()
        if not want:
            return frozenset()
        size = None if _is_parquet(p) else complete_bytes(p)  # a cut last row: not read
        with (nullcontext(p) if size is None else open_complete(p, size)) as src:
            chunks = (_parquet_file(p).iter_batches(batch_size=rows, columns=want) if _is_parquet(p)
                      else pd.read_csv(src, usecols=want, chunksize=rows, low_memory=False))
            for b in chunks:
                df = b.to_pandas() if hasattr(b, "to_pandas") else b
                found |= {c for c in want if c not in found and bool(df[c].notna().any())}
                if len(found) == len(want):
                    break
        return frozenset(found)
    except (UserError, OSError, ValueError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return None


def _concat(a: pd.DataFrame, b: pd.DataFrame) -> pd.DataFrame:
    """Rows of ``a`` then ``b``; categorical trip ids stay categorical (union of categories)."""
    ta, tb = a.get("trip_id"), b.get("trip_id")
    if ta is None or tb is None or not (isinstance(ta.dtype, pd.CategoricalDtype)
                                        and isinstance(tb.dtype, pd.CategoricalDtype)):
        return pd.concat([a, b], ignore_index=True)
    trip = pd.api.types.union_categoricals([ta, tb], ignore_order=True)
    out = pd.concat([a.drop(columns="trip_id"), b.drop(columns="trip_id")], ignore_index=True)
    out.insert(list(a.columns).index("trip_id"), "trip_id", trip)
    return out


def whole_trips(part: Part, rows: int = BATCH_ROWS, max_trip_rows: int = MAX_TRIP_ROWS,
                columns=None, categorical: bool = False,
                truncated: dict | None = None) -> Iterator[tuple[pd.DataFrame, int]]:
    """Raw frames of whole trips of a Part, each with the offset of its first row
    (``columns``: read only these, when present; None: all).

    The rows of the last trip of a chunk are carried into the next chunk until a new
    trip starts; a trip longer than ``max_trip_rows`` raises :class:`UserError`.
    ``categorical``: a text ``trip_id`` of a Parquet file comes as a pandas categorical
    (dictionary-encoded, no Python string per row; the reader keeps it so); False: as read.
    ``truncated``: when given, a CSV file cut inside its last row (left out, never read:
    :mod:`sumo_drvpw.data.truncated`) puts ``truncated[path] = that row's number`` there before
    the last frame is yielded; fewer than 2 complete rows before it are refused.
    """
    from sumo_drvpw.data.trips import trip_codes_of

    carry: pd.DataFrame | None = None
    offset = 0
    seen_rows = 0
    for df in _chunks(part, rows, columns, categorical):
        seen_rows += len(df)
        if carry is not None and len(carry):
            df = _concat(carry, df)
        if "trip_id" in df and len(df):
            # integer codes, not Python strings (the costly part of a text column)
            tid = df["trip_id"]
            codes = trip_codes_of(tid if isinstance(tid.dtype, pd.CategoricalDtype) else tid.astype(str))
            other = np.flatnonzero(codes != codes[-1])
            cut = int(other[-1]) + 1 if len(other) else 0
        else:
            cut = 0
        if cut > 0:
            # the unfinished trip is copied out first, so the chunk is freed once the
            # batch is used (slices would keep the whole chunk alive: two chunks in memory)
            carry = df.iloc[cut:].copy().reset_index(drop=True)
            out = [(df.iloc[:cut].reset_index(drop=True), offset)]
            del df
            yield out.pop()  # this frame keeps no reference to the batch while it is used
            offset += cut
        else:
            carry = df
            del df
        if len(carry) > max_trip_rows:
            trip = carry["trip_id"].iloc[0] if "trip_id" in carry else Path(part.path).stem
            raise UserError(f"{part.describe()}: trip '{trip}' has more than {max_trip_rows} rows "
                            f"(from row {offset}); split it into trips (column 'trip_id') to "
                            "stream it")
    if not _is_parquet(Path(part.path)) and complete_bytes(part.path) is not None:
        refuse_if_too_short(part.path, seen_rows)
        if truncated is not None:
            truncated[part.path] = seen_rows
    if seen_rows == 0:
        raise UserError(f"{part.path}: empty table (header only, no samples)")
    if carry is not None and len(carry):
        out = [(carry, offset)]
        del carry
        yield out.pop()


def iter_measured(part: Part, vehicle=None, options: ReadOptions | None = None,
                  rows: int = BATCH_ROWS, max_trip_rows: int = MAX_TRIP_ROWS, columns=None,
                  target: str = "wheel"):
    """:class:`~sumo_drvpw.data.measured.Measured` per batch of whole trips of a Part.

    Parameters
    ----------
    part : a :class:`Part` (see :func:`plan`)
    vehicle : a :class:`~sumo_drvpw.model.vehicles.Vehicle` or None
    options : :class:`~sumo_drvpw.data.log.ReadOptions`
    rows : rows per chunk read [-]
    columns : read only these columns (e.g. :data:`CANONICAL` and the signals the terms
        name); None: all
    target : what the measured power is (``wheel``, ``battery``, ``fuel``: as for
        :func:`~sumo_drvpw.data.measured.load_measured`); a battery target's sign test is
        left to the caller, on all batches (``Measured.sign_test``,
        :func:`~sumo_drvpw.data.measured.check_sign_sums`)

    Each chunk holds at most ``rows`` rows and :data:`BATCH_VALUES` values of the columns
    read (:func:`rows_for` of the Part's :func:`read_width`): a wide log in fewer rows.
    """
    from sumo_drvpw.data.measured import measure

    if columns is not None and options is not None and options.measurement is not None:
        from sumo_drvpw.data.corrections import needed_columns

        columns = set(columns) | needed_columns(options.measurement)
    if columns is not None:  # a GPS speed beside the speed: compared with it (data/conditions.py)
        from sumo_drvpw.data.conditions import gps_speed_columns

        columns = set(columns) | set(gps_speed_columns(column_names(part.path) or ()))
    stem = Path(part.path).stem
    check_required(part.path)
    rows = rows_for(read_width(part.path, columns), rows)  # a wide log in fewer rows
    # the fuel flow chosen once for the file, not per batch (a battery target: is there an engine)
    logged = logged_flows(part.path, rows) if target != "wheel" else None
    cut: dict = {}
    for df, off in whole_trips(part, rows, max_trip_rows, columns, categorical=True, truncated=cut):
        first = off + (part.start or 0)
        name = part.path if first == 0 else f"{part.path} (batch from row {first})"
        if "trip_id" not in df:
            df.insert(0, "trip_id", stem)
        log = from_frame(df, vehicle, options, name=name)
        log.files = [part.path]
        log.logged = logged
        if cut:  # the last batch of a file cut inside its last row: said as the reader says it
            log.counts["truncated_rows"] = dict(cut)
        del df
        m = measure(log, vehicle, target, sign_check=False)
        del log
        yield m
        del m  # before the next chunk is read: one batch in memory at a time
