"""The tracer's samples in bounded memory: batches of whole trips, prepared once, read per pass.

The streamed tracer (:mod:`sumo_drvpw.fit.diagnose.streamed`) never holds the samples of
all logs at once. The logs are read in batches of whole trips
(:func:`sumo_drvpw.data.stream.whole_trips`, each batch through the reader's own path
:func:`~sumo_drvpw.data.log.from_frame` and :func:`~sumo_drvpw.data.measured.measure`),
reduced to the arrays the tracer needs (model inputs with the equation's mass, measured
power, declared term values, offered signals, the rows' power and trip for the lag
search) and kept as :class:`Batches`: in memory up to ``cache_mb``, beyond that in a
temporary folder (NumPy files, deleted at the end). Every later pass of the tracer reads
these prepared arrays (those it uses), not the logs.

A first look at the data — column screening, which columns are two-valued, the sample
interval of the lag search, the calibration on the spot (without a declared equation),
the quantiles of the recuperation regimes — is made on a *sample*: the first
``sample_rows`` rows (whole trips: up to the end of the trip of row ``sample_rows`` − 1,
whatever the chunk size) in reading order. With fewer rows than that, the sample is all
data and the streamed tracer equals the in-memory one (test). The logs are read in chunks
of at most ``BATCH_VALUES`` values (data/stream.py ``rows_for``: a wide log in fewer rows),
every column for the sample, then only the columns the tracer reads.
"""

from __future__ import annotations

import shutil
import tempfile
from functools import cached_property
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.data.stream import BATCH_ROWS, logged_flows, plan, whole_trips
from sumo_drvpw.model.terms import Inputs, parse_term

#: rows of the first-look sample (screening, two-valued columns, quantiles)
SAMPLE_ROWS = 500_000
#: prepared batches kept in memory up to this size [MB]; beyond, in a temporary folder
CACHE_MB = 200
INPUT_FIELDS = ("v", "a", "theta", "wind", "mass", "rho")


def read_batches(paths, vehicle=None, options=None, target: str = "wheel", rows: int = BATCH_ROWS,
                 sample_rows: int | None = None, want: dict | None = None, sign_check: bool = True):
    """:class:`~sumo_drvpw.data.measured.Measured` per batch of whole trips of every log, in
    reading order (the per-batch loader of the tracer; ``target`` as for ``load_measured``).

    Parameters
    ----------
    rows : rows per chunk read at most [-]; a wide file is read in fewer, at most
        :data:`~sumo_drvpw.data.stream.BATCH_VALUES` values of the columns read
        (:func:`~sumo_drvpw.data.stream.rows_for`), so a batch's memory does not grow with
        the log's width
    sample_rows : when given, the batch that holds row ``sample_rows`` (counted over all
        files) is cut after the trip of row ``sample_rows − 1``: the first-look sample (the
        batches up to ``sample_rows`` rows) then ends at that trip's end, whatever the
        chunk size
    want : ``{"columns": set | None}``, the columns to read (None: all), looked up at each
        file and after each batch: narrowed, the rest of a Parquet file is read with only
        those columns from the next trip on (a CSV chunk is parsed whole, then cut)

    sign_check : test a battery target's sign on each batch; False: its sums are left in
        each batch's ``Measured.sign_test`` for the caller to test on all batches
        (``data.measured.check_sign_sums``), as the in-memory reader tests all samples

    The extra columns' signals are read from each batch's table when asked for
    (``measure(lazy_signals=True)``), not copied.
    """
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.data.measured import measure
    from sumo_drvpw.data.stream import Part, read_width, rows_for

    want = {"columns": None} if want is None else want
    seen = 0  # rows yielded before this batch, over all files
    todo = list(plan(paths))
    logged_of: dict = {}
    while todo:
        part = todo.pop(0)
        stem = Path(part.path).stem
        if part.path not in logged_of:  # the fuel flow chosen once per file, on all of it
            logged_of[part.path] = logged_flows(part.path, rows) if target != "wheel" else None
        cols = want["columns"]
        chunk = rows_for(read_width(part.path, cols), rows)  # a wide log in fewer rows
        cut: dict = {}
        for df, off in whole_trips(part, chunk, columns=cols, categorical=True, truncated=cut):
            first = off + (part.start or 0)
            pieces = [df]
            if sample_rows is not None and seen < sample_rows < seen + len(df):
                pieces = _cut_after_trip_of(df, sample_rows - seen - 1)
            del df
            at = first
            while pieces:
                piece = pieces.pop(0)
                name = part.path if at == 0 else f"{part.path} (batch from row {at})"
                if "trip_id" not in piece:
                    piece.insert(0, "trip_id", stem)
                log = from_frame(piece, vehicle, options, name=name)
                log.files = [part.path]
                log.logged = logged_of[part.path]
                if cut and not pieces:  # a file cut inside its last row: its last batch says so
                    log.counts["truncated_rows"] = dict(cut)
                n = len(piece)
                del piece
                seen += n
                at += n
                m = measure(log, vehicle, target, sign_check=sign_check, lazy_signals=True)
                del log
                yield m
                del m  # before the next chunk is read: one batch in memory at a time
            nxt = at  # the first row after this batch
            stop = part.stop if part.stop is not None else part.rows
            if want["columns"] != cols and part.path.lower().endswith(".parquet") and stop and nxt < stop:
                # narrowed: the rest of this file from the next trip on, only those columns
                todo.insert(0, Part(part.path, nxt, stop, stop - nxt))
                break


def _cut_after_trip_of(df: pd.DataFrame, i: int) -> list:
    """A frame of whole trips cut after the trip that row ``i`` is in (one piece when that
    trip is the last)."""
    if "trip_id" not in df:
        return [df]
    tid = df["trip_id"]
    codes = pd.factorize(tid if isinstance(tid.dtype, pd.CategoricalDtype) else tid.astype(str))[0]
    after = np.flatnonzero(codes[i:] != codes[i])
    if not len(after):
        return [df]
    end = i + int(after[0])
    return [df.iloc[:end].reset_index(drop=True), df.iloc[end:].reset_index(drop=True)]


def parquet_metadata(paths) -> dict:
    """The sumo_drvpw / drive_log.* key-value metadata of the Parquet logs (column roles)."""
    import pyarrow.parquet as pq

    meta = {}
    for part in plan(paths):
        if part.path.lower().endswith(".parquet"):
            for k, v in (pq.read_schema(part.path).metadata or {}).items():
                if k.startswith((b"sumo_drvpw", b"drive_log.")):
                    meta[k.decode()] = v.decode()
    return meta


def concat_inputs(ms: list) -> Inputs:
    """One :class:`Inputs` of the inputs of several batches (:class:`~sumo_drvpw.data.measured.Measured`;
    signals: those all have), each signal made once and filled batch by batch. Each batch is
    left holding its share as views of the whole (its own signals and the table's extra
    columns go: the table keeps what the tracer reads of it — trip, time, weights, elevation,
    the air's columns), so the batches are held once, not twice. Changed in place."""
    import dataclasses

    from sumo_drvpw.data.log import DERIVED

    keep = set(DERIVED) | {"elevation_m", "ambient_c", "pressure_kpa"}
    keys = [k for k in ms[0].inputs.signals if all(k in m.inputs.signals for m in ms)]
    sizes = [len(m.inputs.v) for m in ms]
    sig = {k: np.empty(sum(sizes)) for k in keys}
    lo = 0
    for m, n in zip(ms, sizes):
        for k in keys:
            sig[k][lo:lo + n] = np.asarray(m.inputs.signals[k], float)
        # the inputs copied too: v and mass may be views of the table's whole block
        m.inputs = dataclasses.replace(m.inputs, signals={k: v[lo:lo + n] for k, v in sig.items()},
                                       **{f: np.array(getattr(m.inputs, f), float) for f in INPUT_FIELDS})
        # a copy: a selection of columns is a view of the whole table's block (pandas ≥ 3)
        m.log.df = m.log.df[[c for c in m.log.df.columns if c in keep]].copy()
        lo += n
    return Inputs(*(np.concatenate([getattr(m.inputs, f) for m in ms]) for f in INPUT_FIELDS), sig)


class Batches:
    """Prepared batches (dicts of arrays), in memory up to ``cache_mb``, else on disk.

    A 1-D array holding one value (a fixed mass, air density, sample interval) is kept as
    that value and given back as a read-only broadcast view. On disk each array is a raw
    ``.npy`` file (no compression, no checksum: a pass reads at disk-cache speed)."""

    def __init__(self, cache_mb: float = CACHE_MB):
        self.cache_bytes = cache_mb * 1e6
        self.nbytes = 0
        self._items: list = []
        self._dir: Path | None = None

    @staticmethod
    def _pack(d: dict) -> dict:
        out = {}
        for k, v in d.items():
            if (isinstance(v, np.ndarray) and v.ndim == 1 and v.dtype.kind == "f" and len(v) > 1
                    and v[0] == v[-1] and np.all(v == v[0])):
                out[k] = ("const", float(v[0]), len(v))
            else:
                out[k] = v
        return out

    @staticmethod
    def _unpack(d: dict) -> dict:
        return {k: (np.broadcast_to(v[1], (v[2],)) if isinstance(v, tuple) and v and v[0] == "const" else v)
                for k, v in d.items()}

    def append(self, d: dict) -> None:
        d = self._pack(d)
        size = sum(v.nbytes for v in d.values() if isinstance(v, np.ndarray))
        self.nbytes += size
        if self.nbytes <= self.cache_bytes:
            self._items.append(d)
            return
        if self._dir is None:
            self._dir = Path(tempfile.mkdtemp(prefix="sumo_drvpw_diagnose_"))
        i = len(self._items)
        files, rest = {}, {}
        for k, v in d.items():
            if isinstance(v, np.ndarray):
                f = self._dir / f"b{i:06d}_{k}.npy"
                np.save(f, v, allow_pickle=False)
                files[k] = f
            else:
                rest[k] = v
        self._items.append((files, rest))

    def __len__(self):
        return len(self._items)

    def __iter__(self):
        for it in self._items:
            if isinstance(it, dict):
                yield self._unpack(it)
            else:
                files, rest = it
                yield _OnDisk(files, self._unpack(rest))

    @property
    def on_disk(self) -> bool:
        return self._dir is not None

    def close(self) -> None:
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None
        self._items = []


class _OnDisk(dict):
    """A prepared batch in the temporary folder: each array read when a pass first asks
    for it (a pass that needs three of a batch's arrays reads those three)."""

    def __init__(self, files: dict, rest: dict):
        super().__init__(rest)
        self._files = files

    def __missing__(self, key):
        if key not in self._files:
            raise KeyError(key)
        val = self[key] = np.load(self._files[key], allow_pickle=False)
        return val

    def __contains__(self, key):
        return dict.__contains__(self, key) or key in self._files


class View:
    """The analysis samples of one prepared batch as the tracer sees them in a pass: the
    arrays are selected (``sel``: the samples of the lag search) and shifted (``lag``)
    when first asked for, so a pass pays only for what it reads."""

    def __init__(self, d: dict, sel, lag: int, gmap: np.ndarray):
        self.d, self.sel, self.lag, self._gmap = d, sel, lag, gmap
        self.extra: dict = {}
        self.signals: dict = {}

    def _s(self, a):
        return a if self.sel is None else a[self.sel]

    @cached_property
    def n(self) -> int:
        return int(len(self.d["y"]) if self.sel is None else np.count_nonzero(self.sel))

    @cached_property
    def y(self) -> np.ndarray:
        """Measured power [W], read ``lag`` samples later within the trip."""
        d = self.d
        if self.lag == 0:
            return self._s(d["y"])
        # a shift is applied on the common samples only, where it stays in the trip
        y = np.full(len(d["idx"]), np.nan)
        y[d["common"]] = d["yrow"][d["idx"][d["common"]] + self.lag]
        return self._s(y)

    @cached_property
    def x(self) -> Inputs:
        """Model inputs with the equation's mass."""
        return Inputs(*(self._s(self.d[f]) for f in INPUT_FIELDS))

    @cached_property
    def dt(self) -> np.ndarray:
        return self._s(self.d["dt"])

    @cached_property
    def t(self) -> np.ndarray:
        return self._s(self.d["t"])

    @cached_property
    def trip(self) -> np.ndarray:
        """Global trip code per sample."""
        return self._gmap[self._s(self.d["tloc"])]

    @cached_property
    def decl(self) -> np.ndarray:
        """Declared term values (n × q0)."""
        return self._s(self.d["decl"])


def factor(view: View, f: str, declared: list) -> np.ndarray:
    """Value of one factor of a candidate term on a view (as ``BlockModel.factor``)."""
    if f.startswith("[") and f.endswith("]^2"):
        s = view.signals[f[1:-3]]
        return s * s
    if f.startswith("["):
        return np.asarray(view.signals[f[1:-1]], float)
    if f in declared:
        return view.decl[:, declared.index(f)]
    return np.asarray(parse_term(f).evaluate(view.x), dtype=float)


def cand_values(view: View, cand, declared: list, mass_terms: dict | None = None) -> np.ndarray:
    """Values of a candidate (or model column) on a view (as ``BlockModel.values``)."""
    if cand.kind == "trip_offset":
        return np.ones(view.n)
    if cand.kind == "trip_mass":
        out = np.zeros(view.n)
        for t, c in (mass_terms or {}).items():
            out += c * view.decl[:, declared.index(t)]
        return out
    if cand.kind == "declared":
        return view.decl[:, declared.index(cand.term)]
    if cand.kind in ("signal", "signal_sq", "structural") and "*" not in cand.term:
        return factor(view, cand.term, declared)
    parts = cand.term.split("*", 1) if cand.kind != "speed" else [cand.term]
    val = factor(view, parts[0], declared)
    for p in parts[1:]:
        val = val * factor(view, p, declared)
    return val


def first_appearance(names_in_order) -> list:
    """Names in order of first appearance."""
    return list(pd.unique(pd.Series(list(names_in_order), dtype=object)))
