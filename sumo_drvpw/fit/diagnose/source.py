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
``sample_rows`` rows (whole trips) in reading order. With fewer rows than that, the sample
is all data and the streamed tracer equals the in-memory one (test).
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


def read_batches(paths, vehicle=None, options=None, target: str = "wheel", rows: int = BATCH_ROWS):
    """:class:`~sumo_drvpw.data.measured.Measured` per batch of whole trips of every log, in
    reading order (the per-batch loader of the tracer; ``target`` as for ``load_measured``)."""
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.data.measured import measure

    for part in plan(paths):
        stem = Path(part.path).stem
        logged = logged_flows(part.path, rows) if target != "wheel" else None  # once per file
        for df, off in whole_trips(part, rows):
            name = part.path if off == 0 else f"{part.path} (batch from row {off})"
            if "trip_id" not in df:
                df.insert(0, "trip_id", stem)
            log = from_frame(df, vehicle, options, name=name)
            log.files = [part.path]
            log.logged = logged
            del df
            yield measure(log, vehicle, target)


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


def concat_inputs(xs: list[Inputs]) -> Inputs:
    """One :class:`Inputs` of several (signals: those all have)."""
    keys = [k for k in xs[0].signals if all(k in x.signals for x in xs)]
    return Inputs(*(np.concatenate([getattr(x, f) for x in xs]) for f in INPUT_FIELDS),
                  {k: np.concatenate([np.asarray(x.signals[k]) for x in xs]) for k in keys})


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


def shift_rows(y: np.ndarray, trip: np.ndarray, lag: int) -> np.ndarray:
    """y(i + lag) where row i + lag is in the same trip, else NaN (rows of one batch)."""
    from sumo_drvpw.fit.diagnose.structural import shift_within_trips

    return shift_within_trips(y, trip, lag)


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
