"""The per vehicle-step trace of a run (``outputs.trace``): every step's powers per term and
equation, streamed to ``trace.parquet`` in row groups (:class:`TraceWriter`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from sumo_drvpw.fileio import atomic_path
from sumo_drvpw.sim.ledger import LEDGER_CATEGORIES, Ledger
from sumo_drvpw.sim.outputs import table_with_units


class TraceWriter:
    """Streams per vehicle-step × equation powers to ``trace.parquet`` in row groups.

    Written to a temporary file and renamed on :meth:`close`, which the runner calls in a
    ``finally`` block, so the file is complete (up to the last step) even after Ctrl-C.
    """

    def __init__(self, path: Path, ledger: Ledger, names: list[str], edge_ids: list[str],
                 rows_per_group: int = 200_000):
        self.path = Path(path)
        self.edges = edge_ids
        self.ledger, self.names = ledger, names
        self.rows_per_group = rows_per_group
        self._cm = atomic_path(self.path)
        self.tmp = self._cm.__enter__()
        self.buf: list[dict] = []
        self.nbuf = 0
        self.writer = None
        self.schema = None

    def write(self, t, vidx, eidx, v, a, theta, wind, pc) -> None:
        n, E, _ = pc.shape
        self.buf.append({"t": t, "vidx": vidx, "eidx": eidx, "v": v, "a": a, "theta": theta,
                         "wind": wind, "pc": pc.copy(), "app": self.ledger.veh_app[vidx] > 0})  # (as it booked)
        self.nbuf += n * E
        if self.nbuf >= self.rows_per_group:
            self.flush()

    def flush(self) -> None:
        if not self.buf:
            return
        b = self.buf
        E = b[0]["pc"].shape[1]
        cat = lambda k: np.concatenate([np.repeat(x[k], E) for x in b])  # noqa: E731
        time = np.concatenate([np.full(len(x["vidx"]) * E, x["t"]) for x in b])
        vidx = cat("vidx")
        eidx = cat("eidx")
        pc = np.concatenate([x["pc"].reshape(-1, x["pc"].shape[2]) for x in b])
        eq = np.concatenate([np.tile(np.arange(E), len(x["vidx"])) for x in b])
        app = np.concatenate([x["app"].reshape(-1) for x in b])
        ids = np.asarray(self.ledger.veh_ids, dtype=object)
        cols = {"time_s": time[app],
                "vehicle": pa.array(ids[vidx[app]].astype(str)).dictionary_encode(),
                "edge": pa.array(np.asarray(self.edges, dtype=object)[eidx[app]].astype(str)
                                 ).dictionary_encode(),
                "equation": pa.array(np.asarray(self.names, dtype=object)[eq[app]].astype(str)
                                     ).dictionary_encode(),
                "speed_mps": cat("v")[app], "accel_mps2": cat("a")[app],
                "theta_rad": cat("theta")[app], "wind_mps": cat("wind")[app]}
        for k, c in enumerate(LEDGER_CATEGORIES):
            cols[f"p_{c}_w"] = pc[app, k]
        cols["p_total_w"] = pc[app].sum(axis=1)
        table = table_with_units(cols)
        if self.writer is None:
            self.schema = table.schema
            self.writer = pq.ParquetWriter(self.tmp, self.schema)
        self.writer.write_table(table.cast(self.schema))
        self.buf, self.nbuf = [], 0

    def close(self) -> None:
        """Flush and publish the file (atomic rename)."""
        try:
            self.flush()
            if self.writer is None:
                empty = {"time_s": [], "vehicle": [], "edge": [], "equation": []}
                pq.write_table(pa.table({k: pa.array(v, pa.float64() if k == "time_s"
                                                      else pa.string())
                                         for k, v in empty.items()}), self.tmp)
            else:
                self.writer.close()
            self._cm.__exit__(None, None, None)
        except BaseException as e:
            self._cm.__exit__(type(e), e, None)
            raise


#: One colour per term category in every figure (matplotlib's tab10 entries).
