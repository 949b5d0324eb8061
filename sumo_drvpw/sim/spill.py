"""Finished vehicles out of memory: per-vehicle rows streamed to Parquet row groups on disk.

A long run (a city's day: hundreds of thousands of trips) must not keep every vehicle it
ever saw. :meth:`sumo_drvpw.sim.ledger.Ledger.flush` hands the rows of vehicles that left
the simulation to a :class:`VehicleSpill`, which writes them as one Parquet file per flush
(one row group of ``vehicles.parquet``; the energy chain's rows as one CSV part) into its
folder. The run's outputs join the parts and the rows of the vehicles still held in memory:
``vehicles.parquet`` is written row group by row group (bounded memory), and
``chain_vehicles.csv`` part by part. Rows come in flush order (vehicles finished first,
first), then the vehicles running at the end; within a flush in order of first appearance.
"""

from __future__ import annotations

import shutil
import tempfile
import weakref
from pathlib import Path

import pyarrow as pa
import pyarrow.parquet as pq

from sumo_drvpw.fileio import atomic_path
from sumo_drvpw.sim.outputs import vehicles_table, write_outputs

#: Name of the spill folder a run makes inside its output folder (removed after writing).
SPILL_DIR = ".drvpw-spill"


class VehicleSpill:
    """Parquet (and chain CSV) parts of the vehicles flushed out of a ledger.

    Parameters
    ----------
    names : equation names (the ledger's order)
    predicts : what each equation predicts (the ``predicts`` column)
    directory : folder for the parts (created at the first flush; removed by
        :meth:`cleanup`); None: a temporary folder of the system's
    """

    def __init__(self, names: list[str], predicts: list[str], directory=None):
        self.names, self.predicts = list(names), list(predicts)
        self.directory = Path(directory) if directory is not None else None
        self._made = None
        self.parts: list[Path] = []
        self.chain_parts: list[Path] = []
        self.chain_columns: list[str] | None = None
        self.rows = 0
        #: a finished file holding every row (after :meth:`publish`): read instead of parts
        self.published: Path | None = None
        self.published_chain: Path | None = None
        self._finalizer = None

    # ------------------------------------------------------------------ writing parts
    def _dir(self) -> Path:
        if self._made is None:
            if self.directory is None:
                self._made = Path(tempfile.mkdtemp(prefix="drvpw-vehicles-"))
            else:
                self.directory.mkdir(parents=True, exist_ok=True)
                self._made = Path(tempfile.mkdtemp(prefix="part-", dir=self.directory))
            self._finalizer = weakref.finalize(self, shutil.rmtree, str(self._made), True)
        return self._made

    def write(self, ledger, slots) -> None:
        """Rows of the ledger's vehicles ``slots`` (ascending) as one more part."""
        t = vehicles_table(ledger, self.names, self.predicts, slots=slots)
        if t.num_rows == 0:
            return
        path = self._dir() / f"vehicles-{len(self.parts):06d}.parquet"
        pq.write_table(t, path)
        self.parts.append(path)
        self.rows += t.num_rows

    def write_chain(self, rows: list[dict], columns: list[str] | None = None) -> None:
        """Energy-chain rows (:meth:`sumo_drvpw.sim.chain.ChainLedger.table`) as a CSV part.
        ``columns``: those of every chain of the run (``ChainLedger.columns``), fixed at the
        first part: a part whose vehicles had only some of the chains (petrol cars first,
        electric ones later) keeps the others' columns, and every Dask bucket writes the
        same (default: the first part's rows' own columns)."""
        from sumo_drvpw.sim.table_text import rows_csv

        if not rows:
            return
        if self.chain_columns is None:
            self.chain_columns = list(columns) if columns is not None else list(dict.fromkeys(k for r in rows for k in r))
        path = self._dir() / f"chain-{len(self.chain_parts):06d}.csv"
        with open(path, "w", encoding="utf-8", newline="") as f:  # (pd.DataFrame(rows).reindex(columns=…)'s text)
            f.write(rows_csv(rows, self.chain_columns, header=False))
        self.chain_parts.append(path)

    @property
    def has_rows(self) -> bool:
        return bool(self.parts) or self.published is not None

    @property
    def has_chain_rows(self) -> bool:
        return bool(self.chain_parts) or self.published_chain is not None

    # ------------------------------------------------------------------ reading, outputs
    def _schema(self) -> pa.Schema:
        return pq.read_schema(self.parts[0])

    def vehicles(self, tail: pa.Table) -> pa.Table:
        """Every row: the parts, then ``tail`` (the vehicles held in memory)."""
        if self.published is not None:
            return pq.read_table(self.published)
        tables = [pq.read_table(p) for p in self.parts]
        if tail.num_rows:
            tables.append(tail.cast(tables[0].schema))
        return pa.concat_tables(tables)

    def write_vehicles(self, path, tail: pa.Table) -> None:
        """``vehicles.parquet`` at ``path`` (atomically): each part one row group, then the
        vehicles held in memory; memory holds one part at a time."""
        if self.published is not None:
            with atomic_path(path) as tmp:
                shutil.copyfile(self.published, tmp)
            return
        schema = self._schema()
        with atomic_path(path) as tmp:
            with pq.ParquetWriter(tmp, schema) as w:
                for p in self.parts:
                    w.write_table(pq.read_table(p))
                if tail.num_rows:
                    w.write_table(tail.cast(schema))

    def write_chain_csv(self, path, tail_rows: list[dict]) -> None:
        """``chain_vehicles.csv`` at ``path``: header, the parts, then ``tail_rows``; the same
        text as one ``DataFrame(rows).to_csv(index=False)`` of every row."""
        from sumo_drvpw.sim.table_text import columns_csv, rows_csv

        if self.published_chain is not None:
            with atomic_path(path) as tmp:
                shutil.copyfile(self.published_chain, tmp)
            return
        cols = self.chain_columns
        with atomic_path(path) as tmp:
            with open(tmp, "w", encoding="utf-8", newline="") as out:
                out.write(columns_csv({c: [] for c in cols}))  # (the header)
                for p in self.chain_parts:
                    with open(p, encoding="utf-8", newline="") as f:
                        shutil.copyfileobj(f, out)
                if tail_rows:
                    out.write(rows_csv(tail_rows, cols, header=False))

    def publish(self, vehicles_file, chain_file=None) -> None:
        """The complete files were written (``vehicles.parquet``, ``chain_vehicles.csv``):
        read them from now on and remove the parts."""
        self.published = Path(vehicles_file) if self.parts else self.published
        if chain_file is not None and self.chain_parts:
            self.published_chain = Path(chain_file)
        self.cleanup()

    def cleanup(self) -> None:
        """Remove the parts and their folder."""
        if self._finalizer is not None:
            self._finalizer()
        if self.directory is not None and self.directory.is_dir():
            try:
                self.directory.rmdir()  # only when no other run's parts are in it
            except OSError:
                pass
        self._made, self.parts, self.chain_parts = None, [], []


def write_published(result, out_dir) -> None:
    """The result's tables written into ``out_dir`` (the run's own folder: its caller makes it
    an output set); then the result's spilled rows are read from the written
    ``vehicles.parquet`` (and ``chain_vehicles.csv``) and the parts are removed."""
    out_dir = Path(out_dir)
    write_outputs(out_dir, result)
    spill = getattr(result.ledger, "spill", None)
    if spill is not None and spill.has_rows:
        chain = out_dir / "chain_vehicles.csv"
        spill.publish(out_dir / "vehicles.parquet", chain if chain.is_file() else None)


def discard_parts(ledger) -> None:
    """Remove a ledger's spill parts unless they were published (a failed run's leftovers)."""
    spill = getattr(ledger, "spill", None)
    if spill is not None and spill.published is None:
        spill.cleanup()
