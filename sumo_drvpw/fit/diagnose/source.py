"""The tracer's samples in bounded memory: batches of whole trips, prepared once, read per pass.

The streamed tracer (:mod:`sumo_drvpw.fit.diagnose.streamed`) never holds the samples of
all logs at once. The logs are read in batches of whole trips
(:func:`sumo_drvpw.data.stream.whole_trips`, each batch through the reader's own path
:func:`~sumo_drvpw.data.log.from_frame` and :func:`~sumo_drvpw.data.measured.measure`),
reduced to the arrays the tracer needs (model inputs with the equation's mass, measured
power, declared term values, offered signals, the rows' power and trip for the lag
search) and kept as :class:`Batches`: in memory up to ``cache_mb``, beyond that in a
temporary folder (NumPy files, deleted at the end). Every later pass of the tracer reads
these prepared arrays, not the logs.

A first look at the data — column screening, which columns are two-valued, the sample
interval of the lag search, the calibration on the spot (without a declared equation),
the quantiles of the recuperation regimes — is made on a *sample*: the first
``sample_rows`` rows (whole trips) in reading order. With fewer rows than that, the sample
is all data and the streamed tracer equals the in-memory one (test).
"""

from __future__ import annotations

import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.data.stream import BATCH_ROWS, plan, whole_trips
from sumo_drvpw.model.terms import Inputs, parse_term

#: rows of the first-look sample (screening, two-valued columns, quantiles)
SAMPLE_ROWS = 1_000_000
#: prepared batches kept in memory up to this size [MB]; beyond, in a temporary folder
CACHE_MB = 768
INPUT_FIELDS = ("v", "a", "theta", "wind", "mass", "rho")


def read_batches(paths, vehicle=None, options=None, target: str = "wheel", rows: int = BATCH_ROWS):
    """:class:`~sumo_drvpw.data.measured.Measured` per batch of whole trips of every log, in
    reading order (the per-batch loader of the tracer; ``target`` as for ``load_measured``)."""
    from sumo_drvpw.data.log import from_frame
    from sumo_drvpw.data.measured import measure

    for part in plan(paths):
        stem = Path(part.path).stem
        for df, off in whole_trips(part, rows):
            name = part.path if off == 0 else f"{part.path} (batch from row {off})"
            if "trip_id" not in df:
                df.insert(0, "trip_id", stem)
            log = from_frame(df, vehicle, options, name=name)
            log.files = [part.path]
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
    """Prepared batches (dicts of arrays), in memory up to ``cache_mb``, else on disk."""

    def __init__(self, cache_mb: float = CACHE_MB):
        self.cache_bytes = cache_mb * 1e6
        self.nbytes = 0
        self._items: list = []
        self._dir: Path | None = None

    def append(self, d: dict) -> None:
        size = sum(v.nbytes for v in d.values() if isinstance(v, np.ndarray))
        self.nbytes += size
        if self.nbytes <= self.cache_bytes:
            self._items.append(d)
            return
        if self._dir is None:
            self._dir = Path(tempfile.mkdtemp(prefix="sumo_drvpw_diagnose_"))
        f = self._dir / f"b{len(self._items):06d}.npz"
        np.savez(f, **{k: v for k, v in d.items() if isinstance(v, np.ndarray)})
        self._items.append((f, {k: v for k, v in d.items() if not isinstance(v, np.ndarray)}))

    def __len__(self):
        return len(self._items)

    def __iter__(self):
        for it in self._items:
            if isinstance(it, dict):
                yield it
            else:
                with np.load(it[0]) as z:
                    d = {k: z[k] for k in z.files}
                d.update(it[1])
                yield d

    @property
    def on_disk(self) -> bool:
        return self._dir is not None

    def close(self) -> None:
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None
        self._items = []


@dataclass
class View:
    """The analysis samples of one batch as the tracer sees them in a pass."""

    x: Inputs                 # model inputs with the equation's mass
    y: np.ndarray             # measured power [W] (lag applied)
    dt: np.ndarray
    t: np.ndarray
    trip: np.ndarray          # global trip code
    decl: np.ndarray          # declared term values (n × q0)
    signals: dict             # offered signals and derived structural signals
    block: np.ndarray | None = None   # global block index
    extra: dict = field(default_factory=dict)

    @property
    def n(self):
        return len(self.y)


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
