"""Stream canonical drive logs in bounded memory, one batch of whole trips at a time.

The unit of streaming is the trip: every derivation that needs neighbours (acceleration,
grade from elevation over distance, shaft accelerations of measured power) is per trip
already, so a batch of *whole* trips goes through exactly the reader's own path
(:func:`sumo_drvpw.data.log.from_frame`, then :func:`sumo_drvpw.data.measured.measure`) and
sees the same samples as :func:`~sumo_drvpw.data.measured.load_measured`.

Files are read in chunks of ``rows`` (Parquet record batches via pyarrow, CSV chunks via
pandas). The last trip of a chunk may continue in the next one; its rows are carried over
until the trip ends (or the file does), so a trip is never cut. Memory is therefore
O(``rows`` + the longest trip); a trip longer than ``max_trip_rows`` is refused with a
``UserError`` (split it into trips: ``trip_id``). A file without ``trip_id`` is one trip.

A :class:`Part` is a piece of the input that holds whole trips (a file, or a run of
Parquet row groups that starts and ends at trip boundaries): the unit of work of the
engines in :mod:`sumo_drvpw.fit.engine`.

Difference from the in-memory reader, on purpose: the moving-average width of the derived
acceleration is ``accel_window_s`` over the *batch's* median sample interval (the
in-memory reader takes the median over all logs). Both agree whenever trips are sampled at
one rate; with mixed rates the per-batch width is the closer one to each trip's own rate.
Row numbers in error messages count from the start of the batch named in the message.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Iterator

import numpy as np
import pandas as pd

from sumo_drvpw.data.log import ReadOptions, expand_paths, from_frame
from sumo_drvpw.errors import UserError

#: Rows read per chunk [-]: the memory bound besides the longest trip.
BATCH_ROWS = 1_000_000
#: Longest trip streamed [rows] (about 29 days at 8 Hz); longer ones must be split.
MAX_TRIP_ROWS = 20_000_000
#: Rows a Part of a Parquet file aims at when a file is split for parallel engines.
PART_ROWS = 4_000_000


@dataclass(frozen=True)
class Part:
    """Whole trips of one file: all of it, or the Parquet row groups ``row_groups``."""

    path: str
    row_groups: tuple[int, ...] | None = None
    rows: int = 0

    def describe(self) -> str:
        if self.row_groups is None:
            return self.path
        return f"{self.path} [row groups {self.row_groups[0]}–{self.row_groups[-1]}]"


def _is_parquet(p: Path) -> bool:
    return p.suffix.lower() == ".parquet"


def _parquet_file(p: Path):
    import pyarrow.parquet as pq

    try:
        return pq.ParquetFile(p)
    except (OSError, ValueError) as e:
        raise UserError(f"{p}: cannot read as parquet: {e}") from None


def plan(paths, part_rows: int = PART_ROWS) -> list[Part]:
    """The input as Parts of whole trips, in reading order.

    Parameters
    ----------
    paths : files or folders (Parquet, CSV), as for :func:`sumo_drvpw.data.log.read_log`
    part_rows : Parquet files with several row groups are split into runs of about this
        many rows [-], cut only where a row group starts a new trip (the ``trip_id`` of its
        first row differs from the last row of the group before); CSV files are one Part.
    """
    parts: list[Part] = []
    for p in expand_paths(paths):
        if not _is_parquet(p):
            parts.append(Part(str(p), None, 0))
            continue
        f = _parquet_file(p)
        md = f.metadata
        if md.num_row_groups <= 1 or "trip_id" not in f.schema_arrow.names:
            parts.append(Part(str(p), None, md.num_rows))
            continue
        run: list[int] = []
        rows = 0
        prev_last = None
        for i in range(md.num_row_groups):
            tid = f.read_row_group(i, columns=["trip_id"]).column(0)
            n = len(tid)
            first = None if n == 0 else str(tid[0].as_py())
            if run and rows >= part_rows and first != prev_last:
                parts.append(Part(str(p), tuple(run), rows))
                run, rows = [], 0
            run.append(i)
            rows += n
            if n:
                prev_last = str(tid[n - 1].as_py())
        if run:
            parts.append(Part(str(p), tuple(run), rows))
    return parts


def _chunks(part: Part, rows: int) -> Iterator[pd.DataFrame]:
    p = Path(part.path)
    try:
        if _is_parquet(p):
            f = _parquet_file(p)
            groups = list(part.row_groups) if part.row_groups is not None else None
            for b in f.iter_batches(batch_size=rows, row_groups=groups):
                yield b.to_pandas()
        else:
            for df in pd.read_csv(p, chunksize=rows, low_memory=False):
                yield df
    except pd.errors.EmptyDataError:
        raise UserError(f"{p}: empty file (no header, no rows)") from None
    except (OSError, pd.errors.ParserError) as e:
        raise UserError(f"{p}: cannot read as {p.suffix[1:]}: {e}") from None


def whole_trips(part: Part, rows: int = BATCH_ROWS,
                max_trip_rows: int = MAX_TRIP_ROWS) -> Iterator[tuple[pd.DataFrame, int]]:
    """Raw frames of whole trips of a Part, each with the offset of its first row.

    The rows of the last trip of a chunk are carried into the next chunk until a new
    trip starts; a trip longer than ``max_trip_rows`` raises :class:`UserError`.
    """
    carry: pd.DataFrame | None = None
    offset = 0
    seen_rows = 0
    for df in _chunks(part, rows):
        seen_rows += len(df)
        if carry is not None and len(carry):
            df = pd.concat([carry, df], ignore_index=True)
        if "trip_id" in df:
            tid = df["trip_id"].astype(str).to_numpy()
            other = np.flatnonzero(tid != tid[-1]) if len(tid) else np.zeros(0, int)
            cut = int(other[-1]) + 1 if len(other) else 0
        else:
            cut = 0
        if cut > 0:
            yield df.iloc[:cut].reset_index(drop=True), offset
            offset += cut
            carry = df.iloc[cut:].reset_index(drop=True)
        else:
            carry = df
        if len(carry) > max_trip_rows:
            trip = carry["trip_id"].iloc[0] if "trip_id" in carry else Path(part.path).stem
            raise UserError(f"{part.describe()}: trip '{trip}' has more than {max_trip_rows} rows "
                            f"(from row {offset}); split it into trips (column 'trip_id') to "
                            "stream it")
    if seen_rows == 0:
        raise UserError(f"{part.path}: empty table (header only, no samples)")
    if carry is not None and len(carry):
        yield carry, offset


def iter_measured(part: Part, vehicle=None, options: ReadOptions | None = None,
                  rows: int = BATCH_ROWS, max_trip_rows: int = MAX_TRIP_ROWS):
    """:class:`~sumo_drvpw.data.measured.Measured` per batch of whole trips of a Part.

    Parameters
    ----------
    part : a :class:`Part` (see :func:`plan`)
    vehicle : a :class:`~sumo_drvpw.model.vehicles.Vehicle` or None
    options : :class:`~sumo_drvpw.data.log.ReadOptions`
    rows : rows per chunk read [-]
    """
    from sumo_drvpw.data.measured import measure

    stem = Path(part.path).stem
    for df, off in whole_trips(part, rows, max_trip_rows):
        name = part.path if off == 0 and part.row_groups in (None, ()) or off == 0 and \
            part.row_groups and part.row_groups[0] == 0 else f"{part.path} (batch from row {off})"
        if "trip_id" not in df:
            df.insert(0, "trip_id", stem)
        log = from_frame(df, vehicle, options, name=name)
        log.files = [part.path]
        yield measure(log, vehicle)
