"""Outputs of a run: Parquet tables (units in field metadata), edgeData XML, figures, summary.

Column naming: ``traction_<cat>_j`` is the energy [J] of category ``<cat>`` (acc, grade,
aero, roll, other) over the vehicle-steps where the equation's total power is positive;
``recup_<cat>_j`` over the others (P ≤ 0; mostly negative: recuperable). Their sums
``traction_total_j``/``recup_total_j`` and ``net_total_j`` close the balance.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from sumo_drvpw.fileio import atomic_path, write_figure, write_json, write_parquet, write_text
from sumo_drvpw.sim.ledger import LEDGER_CATEGORIES, Ledger
from sumo_drvpw.sim.network import Network

UNITS = {"_j": "J", "_m": "m", "_s": "s", "_kg": "kg", "_w": "W", "_mps": "m/s",
         "_mps2": "m/s2", "_rad": "rad", "share": "1"}


def _unit(name: str) -> str | None:
    for suf, u in UNITS.items():
        if name.endswith(suf):
            return u
    return None


def table_with_units(cols: dict[str, object]) -> pa.Table:
    """A pyarrow table whose numeric fields carry ``unit`` metadata from their name suffix."""
    arrays, fields = [], []
    for name, val in cols.items():
        arr = pa.array(val)
        u = _unit(name)
        fields.append(pa.field(name, arr.type, metadata={"unit": u} if u else None))
        arrays.append(arr)
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))


def _energy_cols(prefix: str, x: np.ndarray) -> dict[str, np.ndarray]:
    out = {f"{prefix}_{c}_j": x[:, k] for k, c in enumerate(LEDGER_CATEGORIES)}
    out[f"{prefix}_total_j"] = x.sum(axis=1)
    return out


def vehicles_table(ledger: Ledger, names: list[str]) -> pa.Table:
    """Per vehicle × equation (only accounted vehicles and equations applied to them)."""
    n = ledger.n_veh
    keep = ledger.veh_keep[:n]
    vi, ei = np.nonzero(keep[:, None] & (ledger.veh_app[:n] > 0))
    tr = ledger.veh_trac[vi, ei]
    rc = ledger.veh_recup[vi, ei]
    cols = {"vehicle": [ledger.veh_ids[i] for i in vi],
            "vtype": [ledger.veh_type[i] for i in vi],
            "equation": [names[e] for e in ei],
            "mass_kg": ledger.veh_mass[vi], "distance_m": ledger.veh_dist[vi],
            "time_s": ledger.veh_time[vi]}
    cols.update(_energy_cols("traction", tr))
    cols.update(_energy_cols("recup", rc))
    cols["net_total_j"] = cols["traction_total_j"] + cols["recup_total_j"]
    return table_with_units(cols)


def edges_table(ledger: Ledger, net: Network, names: list[str]) -> pa.Table:
    """Per edge × equation: class, length, vehicle count, energy per category."""
    nE, E = ledger.n_edges, ledger.E
    ed = np.repeat(np.arange(nE), E)
    eq = np.tile(np.arange(E), nE)
    cols = {"edge": [net.edge_ids[i] for i in ed], "equation": [names[e] for e in eq],
            "class": [str(net.edge_class[i]) for i in ed], "type": [net.edge_type[i] for i in ed],
            "length_m": net.edge_length[ed], "speed_limit_mps": net.edge_speed[ed],
            "vehicles": ledger.edge_count[ed, eq], "distance_m": ledger.edge_dist[ed]}
    cols.update(_energy_cols("traction", ledger.edge_trac[ed, eq]))
    cols.update(_energy_cols("recup", ledger.edge_recup[ed, eq]))
    cols["net_total_j"] = cols["traction_total_j"] + cols["recup_total_j"]
    return table_with_units(cols)


def class_energy(ledger: Ledger, net: Network) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Energies by road class: (classes, traction (K, E, C), recup (K, E, C)) [J]."""
    classes = list(net.classes)
    k = np.array([classes.index(c) for c in net.edge_class], np.int64)
    tr = np.zeros((len(classes), ledger.E, ledger.C))
    rc = np.zeros_like(tr)
    np.add.at(tr, k, ledger.edge_trac)
    np.add.at(rc, k, ledger.edge_recup)
    return classes, tr, rc


def classes_table(ledger: Ledger, net: Network, names: list[str]) -> pa.Table:
    """Per road class × equation × category: traction energy, its share, recuperable energy."""
    classes, tr, rc = class_energy(ledger, net)
    rows = {"class": [], "equation": [], "term": [], "traction_energy_j": [], "share": [],
            "recup_energy_j": []}
    for ki, c in enumerate(classes):
        for e, name in enumerate(names):
            tot = tr[ki, e].sum()
            for ci, cat in enumerate(LEDGER_CATEGORIES):
                rows["class"].append(c)
                rows["equation"].append(name)
                rows["term"].append(cat)
                rows["traction_energy_j"].append(tr[ki, e, ci])
                rows["share"].append(tr[ki, e, ci] / tot if tot > 0 else np.nan)
                rows["recup_energy_j"].append(rc[ki, e, ci])
    return table_with_units(rows)


def edgedata_xml(ledger: Ledger, net: Network, names: list[str], begin: float,
                 end: float) -> str:
    """SUMO edgeData-style XML: per edge, traction energy [J] per equation and category
    (attributes ``drvpw_<eq>_<cat>_j`` and ``drvpw_<eq>_total_j``)."""
    from xml.sax.saxutils import quoteattr

    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             "<!-- sumo-drvpw: traction energy [J] per edge, equation and term -->",
             "<meandata>", f'    <interval begin="{begin:g}" end="{end:g}" id="drvpw">']
    for i, eid in enumerate(net.edge_ids):
        attrs = []
        for e, name in enumerate(names):
            for ci, cat in enumerate(LEDGER_CATEGORIES):
                attrs.append(f'drvpw_{name}_{cat}_j="{ledger.edge_trac[i, e, ci]:.3f}"')
            attrs.append(f'drvpw_{name}_total_j="{ledger.edge_trac[i, e].sum():.3f}"')
        lines.append(f"        <edge id={quoteattr(eid)} {' '.join(attrs)}/>")
    lines += ["    </interval>", "</meandata>", ""]
    return "\n".join(lines)


def summary_dict(ledger: Ledger, net: Network, names: list[str], uses_other: bool,
                 extra: dict) -> dict:
    """The summary.json document (see the issue's contract)."""
    classes, tr, rc = class_energy(ledger, net)
    cats = list(LEDGER_CATEGORIES) if uses_other else list(LEDGER_CATEGORIES[:4])
    eqs = {}
    for e, name in enumerate(names):
        ej, rj = {}, {}
        for ki, c in enumerate(classes):
            ej[c] = {cat: float(tr[ki, e, LEDGER_CATEGORIES.index(cat)]) for cat in cats}
            ej[c]["total"] = float(tr[ki, e].sum())
            rj[c] = {cat: float(rc[ki, e, LEDGER_CATEGORIES.index(cat)]) for cat in cats}
            rj[c]["total"] = float(rc[ki, e].sum())
        eqs[name] = {"energy_j": ej, "recuperable_energy_j": rj}
    out = {"steps": int(ledger.steps),
           "vehicles": int(np.count_nonzero(ledger.veh_keep[:ledger.n_veh])),
           "samples": int(ledger.samples),
           "slope_corrected_samples": int(ledger.corrected),
           "slope_clipped_samples": int(ledger.clipped),
           "position_reads": int(ledger.position_reads),
           "position_mismatches": int(ledger.position_mismatches),
           "internal_edges": "energy on internal junction lanes is booked on the edge "
                             "they lead to",
           "energy_definition": "energy_j: Σ term power × Δt over vehicle-steps with total "
                                "power > 0 (traction); recuperable_energy_j: over the others",
           "classes": classes,
           "equations": eqs}
    out.update(extra)
    return out


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
                         "wind": wind, "pc": pc.copy()})
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
        app = self.ledger.veh_app[vidx, eq] > 0
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


def share_figure(classes_tbl: pa.Table, path: Path) -> None:
    """Bar chart: traction-energy share by term for each road class and equation."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    df = classes_tbl.to_pandas()
    df = df[df["term"].isin(LEDGER_CATEGORIES)]
    piv = df.pivot_table(index=["class", "equation"], columns="term", values="share",
                         sort=False).fillna(0.0)
    piv = piv[[c for c in LEDGER_CATEGORIES if c in piv.columns and piv[c].abs().sum() > 0]]
    tot = df.groupby(["class", "equation"], sort=False)["traction_energy_j"].sum()
    piv = piv[tot.reindex(piv.index).to_numpy() > 0]
    fig, ax = plt.subplots(figsize=(max(6, 0.9 * len(piv) + 2), 4))
    if len(piv):
        piv.plot.bar(stacked=True, ax=ax, width=0.75)
        ax.set_xticklabels([f"{c}\n{e}" for c, e in piv.index], rotation=0, fontsize=7)
    ax.set_ylabel("share of traction energy [-]")
    ax.set_xlabel("")
    ax.set_title("Traction energy by term, per road class and equation")
    ax.legend(loc="center left", bbox_to_anchor=(1.0, 0.5))
    write_figure(path, fig)


def difference_map(ledger: Ledger, net: Network, names: list[str], pair: list[str],
                   path: Path) -> None:
    """Network map coloured by the per-edge traction-energy difference of two equations,
    per metre driven [J/m] (sumolib geometry)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    a, b = names.index(pair[0]), names.index(pair[1])
    diff = ledger.edge_trac[:, a].sum(1) - ledger.edge_trac[:, b].sum(1)
    per_m = np.divide(diff, ledger.edge_dist, out=np.full_like(diff, np.nan),
                      where=ledger.edge_dist > 0)
    fig, ax = plt.subplots(figsize=(7, 6))
    used = np.isfinite(per_m)
    ax.add_collection(LineCollection([s for s, u in zip(net.edge_shapes, used) if not u],
                                     colors="0.85", linewidths=0.8))
    lim = float(np.nanmax(np.abs(per_m))) if used.any() else 1.0
    lc = LineCollection([s for s, u in zip(net.edge_shapes, used) if u], cmap="coolwarm",
                        linewidths=2.5)
    lc.set_array(per_m[used])
    lc.set_clim(-lim or -1.0, lim or 1.0)
    ax.add_collection(lc)
    fig.colorbar(lc, ax=ax, label=f"{pair[0]} − {pair[1]} traction energy per metre [J/m]")
    ax.autoscale()
    ax.set_aspect("equal")
    ax.set_title(f"Per-edge difference {pair[0]} − {pair[1]}")
    write_figure(path, fig)


def write_outputs(out_dir: Path, ledger: Ledger, net: Network, names: list[str],
                  summary: dict, begin: float, end: float, edgedata: bool, figures: bool,
                  difference: list[str] | None) -> dict[str, str]:
    """Write every table/figure atomically into ``out_dir``; returns name → path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    files = {}
    write_parquet(out_dir / "vehicles.parquet", vehicles_table(ledger, names))
    write_parquet(out_dir / "edges.parquet", edges_table(ledger, net, names))
    ct = classes_table(ledger, net, names)
    write_parquet(out_dir / "classes.parquet", ct)
    write_text(out_dir / "shares.csv", ct.to_pandas().to_csv(index=False))
    files.update({k: str(out_dir / f) for k, f in (
        ("vehicles", "vehicles.parquet"), ("edges", "edges.parquet"),
        ("classes", "classes.parquet"), ("shares", "shares.csv"))})
    if edgedata:
        write_text(out_dir / "edgedata.xml", edgedata_xml(ledger, net, names, begin, end))
        files["edgedata"] = str(out_dir / "edgedata.xml")
    if figures:
        share_figure(ct, out_dir / "shares.png")
        files["shares_figure"] = str(out_dir / "shares.png")
        if len(names) >= 2:
            pair = difference or names[:2]
            difference_map(ledger, net, names, pair, out_dir / "difference_map.png")
            files["difference_map"] = str(out_dir / "difference_map.png")
    summary.setdefault("files", {}).update({k: os.path.basename(v) for k, v in files.items()})
    write_json(out_dir / "summary.json", summary)
    return files
