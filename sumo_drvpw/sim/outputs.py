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

from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import write_figure, write_json, write_parquet, write_text
from sumo_drvpw.sim import dynamics, teleport
from sumo_drvpw.sim.ledger import LEDGER_CATEGORIES, Ledger
from sumo_drvpw.sim.network import Network
from sumo_drvpw.sim.table_text import arrow_array, columns_csv, table_csv
from sumo_drvpw.sim.vtypes import SUMO_DEFAULT_VTYPES

UNITS = {"_j": "J", "_m": "m", "_s": "s", "_kg": "kg", "_w": "W", "_mps": "m/s",
         "_mps2": "m/s2", "_rad": "rad", "share": "1", "_whpkm": "Wh/km", "_kwh": "kWh",
         "_wh": "Wh", "_mg": "mg"}


def _unit(name: str) -> str | None:
    for suf, u in UNITS.items():
        if name.endswith(suf):
            return u
    return None


def table_with_units(cols: dict[str, object]) -> pa.Table:
    """A pyarrow table whose numeric fields carry ``unit`` metadata from their name suffix
    (its arrays made without pandas: :func:`~sumo_drvpw.sim.table_text.arrow_array`)."""
    arrays, fields = [], []
    for name, val in cols.items():
        arr = arrow_array(val)
        u = _unit(name)
        fields.append(pa.field(name, arr.type, metadata={"unit": u} if u else None))
        arrays.append(arr)
    return pa.Table.from_arrays(arrays, schema=pa.schema(fields))


def _energy_cols(prefix: str, x: np.ndarray) -> dict[str, np.ndarray]:
    out = {f"{prefix}_{c}_j": x[:, k] for k, c in enumerate(LEDGER_CATEGORIES)}
    out[f"{prefix}_total_j"] = x.sum(axis=1)
    return out


def _whpkm(energy_j: np.ndarray, dist_m: np.ndarray) -> np.ndarray:
    """Energy per distance [Wh/km] (NaN where nothing was driven): J/m ÷ 3.6."""
    e = np.asarray(energy_j, float)
    d = np.asarray(dist_m, float)
    return np.divide(e, d * 3.6, out=np.full_like(e, np.nan), where=d > 0)


def vehicles_table(ledger: Ledger, names: list[str],
                   predicts: list[str] | None = None, slots=None) -> pa.Table:
    """Per vehicle × equation (only accounted vehicles and equations applied to them): the
    vehicles held in memory, or only those of ``slots`` (ascending)."""
    n = ledger.n_veh
    sel = np.arange(n) if slots is None else np.asarray(slots, np.int64)
    keep = ledger.veh_keep[sel]
    # (every equation that applied at some time of the trip: a vType changed in it books on
    # by its new equations, each row its own distance and time)
    si, ei = np.nonzero(keep[:, None] & ledger.veh_app_seen[sel])
    vi = sel[si]
    tr = ledger.veh_trac[vi, ei]
    rc = ledger.veh_recup[vi, ei]
    cols = {"vehicle": [ledger.veh_ids[i] for i in vi],
            "vtype": [ledger.veh_type[i] for i in vi],
            "vclass": [ledger.veh_class[i] if i < len(ledger.veh_class) else "" for i in vi],
            "equation": [names[e] for e in ei],
            "predicts": [(predicts or ["wheel"] * len(names))[e] for e in ei],
            "mass_kg": ledger.booked_mass(vi, ei), "distance_m": ledger.veh_dist_eq[vi, ei],
            "time_s": ledger.veh_time_eq[vi, ei], "on_road_at_begin": ledger.veh_joined[vi], "on_road_at_end": ledger.on_road_at_end(vi)}
    cols.update(_energy_cols("traction", tr))
    cols.update(_energy_cols("recup", rc))
    cols["net_total_j"] = cols["traction_total_j"] + cols["recup_total_j"]
    cols["traction_whpkm"] = _whpkm(cols["traction_total_j"], cols["distance_m"])
    cols["net_whpkm"] = _whpkm(cols["net_total_j"], cols["distance_m"])
    cols.update(teleport.columns(ledger.veh_teleports[vi], ledger.veh_tele[vi, ei]))
    return table_with_units(cols)


def edges_table(ledger: Ledger, net: Network, names: list[str]) -> pa.Table:
    """Per edge × equation: class, length, vehicle count, energy per category."""
    nE, E = ledger.n_edges, ledger.E
    ed = np.repeat(np.arange(nE), E)
    eq = np.tile(np.arange(E), nE)
    obj = lambda x: np.fromiter(x, object)  # noqa: E731  (taken by index arrays: no per-row Python)
    cols = {"edge": obj(net.edge_ids)[ed], "equation": obj(names)[eq],
            "class": obj(map(str, net.edge_class))[ed], "type": obj(net.edge_type)[ed],
            "length_m": net.edge_length[ed], "speed_limit_mps": net.edge_speed[ed],
            "vehicles": ledger.edge_count[ed, eq], "distance_m": ledger.edge_dist_eq[ed, eq]}
    cols.update(_energy_cols("traction", ledger.edge_trac[ed, eq]))
    cols.update(_energy_cols("recup", ledger.edge_recup[ed, eq]))
    cols["net_total_j"] = cols["traction_total_j"] + cols["recup_total_j"]
    cols["traction_whpkm"] = _whpkm(cols["traction_total_j"], cols["distance_m"])
    cols["net_whpkm"] = _whpkm(cols["net_total_j"], cols["distance_m"])
    cols.update(teleport.columns(ledger.edge_teleports[ed, eq], ledger.edge_tele[ed, eq]))
    return table_with_units(cols)


def class_energy(ledger: Ledger, net: Network) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Energies by road class: (classes, traction (K, E, C), recup (K, E, C)) [J]."""
    classes = list(net.classes)
    k = np.array([classes.index(c) for c in net.edge_class], np.int64)
    ec = ledger.E * ledger.C
    tr, rc = np.zeros((len(classes), ledger.E, ledger.C)), np.zeros((len(classes), ledger.E, ledger.C))
    for out, x in ((tr.reshape(len(classes), ec), ledger.edge_trac), (rc.reshape(len(classes), ec), ledger.edge_recup)):
        x = x.reshape(len(k), ec)  # per class the sum over its edges in their order, as np.add.at
        for j in range(x.shape[1]):  # adds, by a bincount per (equation, category): faster over many edges
            out[:, j] = np.bincount(k, x[:, j], minlength=len(classes))
    return classes, tr, rc


def classes_table(ledger: Ledger, net: Network, names: list[str]) -> pa.Table:
    """Per road class × equation × category: traction energy, its share, recuperable
    energy, and per distance driven in the class [Wh/km]."""
    classes, tr, rc = class_energy(ledger, net)
    k = np.array([classes.index(c) for c in net.edge_class], np.int64)
    cdist = np.zeros((len(classes), ledger.E))
    for e in range(ledger.E):
        cdist[:, e] = np.bincount(k, weights=ledger.edge_dist_eq[:, e], minlength=len(classes))
    rows = {"class": [], "equation": [], "term": [], "traction_energy_j": [], "share": [],
            "recup_energy_j": [], "distance_m": [], "traction_whpkm": []}
    tcount, tenergy = teleport.by_class(ledger, net, classes)  # per class × equation, each term row
    rows.update({c: [] for c in teleport.COLUMNS})
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
                rows["distance_m"].append(cdist[ki, e])
                rows["traction_whpkm"].append(
                    tr[ki, e, ci] / (cdist[ki, e] * 3.6) if cdist[ki, e] > 0 else np.nan)
                for col, x in teleport.columns(tcount[ki, e], tenergy[ki, e]).items():
                    rows[col].append(float(x))
    return table_with_units(rows)


def edgedata_xml(ledger: Ledger, net: Network, names: list[str], begin: float,
                 end: float) -> str:
    """SUMO edgeData XML (``<meandata><interval begin end id><edge .../>``), one interval per
    boundary kept with :meth:`Ledger.snapshot` (else the whole run), edges driven on only.

    Per edge: ``sampledSeconds`` (vehicle-seconds [s]), ``entered`` (accounted vehicles
    that entered), and per equation ``<eq>_<term>_j`` (traction energy per term [J]),
    ``<eq>_recup_j`` (recuperable energy, ≤ 0 [J]), ``<eq>_total_j`` (traction [J]),
    ``<eq>_total_perVeh_j`` (per vehicle driving the whole edge: total × length / distance
    driven [J], as SUMO's MSMeanData_Emissions scales its ``_perVeh``) and ``<eq>_total_normed_jpm``
    (per metre driven [J/m]), in the manner of SUMO's ``CO2_abs``/``_perVeh``/``_normed``.
    Equation names are restricted to ``NAME_PATTERN`` (valid XML names); ids are escaped.
    Equations with an energy chain add ``<eq>_battery_{traction,recuperated,auxiliary,net}_kwh``
    or ``<eq>_fuel_l`` and ``<eq>_co2_kg`` (:meth:`sumo_drvpw.sim.chain.ChainLedger.edge_attrs`).
    Where teleports ended on an edge in the interval: ``<eq>_teleports``,
    ``<eq>_teleport_kinetic_j``, ``<eq>_teleport_potential_j`` (apart from the driving energy).
    An equation none of whose vehicles was on an edge in an interval has no attributes on
    it, as SUMO leaves out what it did not measure: a 0 would read as a free edge to a
    router taking it as a weight. One whose vehicles were there but drove none of it (they
    stood: a queue, a stop) has its sums — ``_<term>_j``, ``_recup_j``, ``_total_j`` (0 but
    for a standing constant such as ``v^0``) and its chain's — and no ``_total_perVeh_j`` or
    ``_total_normed_jpm``, which scale by the distance driven there: none, as SUMO's traffic
    edgeData leaves out ``traveltime`` on an edge whose vehicles did not move (a router then
    takes its default there, as on an edge without vehicles; a 0 would be a free edge).
    """
    from xml.sax.saxutils import quoteattr

    energy_, _, etime_, dist_eq_, time_eq_ = ledger._edges()
    cur = (float(end), energy_, dist_eq_, etime_, ledger.edge_count, ledger.edge_entered,
           ledger.edge_teleports, ledger.edge_tele, time_eq_)
    bounds = [s for s in ledger.snapshots if begin < s[0] < end] + [cur]
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             "<!-- sumo-drvpw: driving energy per edge, equation and term (traction [J], "
             "recuperable [J], per vehicle [J], per metre [J/m]) -->",
             # no XSD reference: SUMO validates declared schemas, and ours adds attributes
             "<meandata>"]
    prev = (float(begin),) + tuple(np.zeros_like(x) for x in cur[1:])
    cats = [c for c in LEDGER_CATEGORIES]
    chain = getattr(ledger, "chain", None)  # battery/fuel per edge (sim/chain.py, #12)
    if chain is not None:
        chain_at = dict(chain.snapshots)
        chain_at[float(end)] = chain.edge
        chain_prev = np.zeros_like(chain.edge)
    for b in bounds:
        t0, t1 = prev[0], b[0]
        energy, dist, etime, count, entered, tcount, tenergy, time_eq = (b[k] - prev[k] for k in range(1, 9))
        lines.append(f'    <interval begin="{t0:.2f}" end="{t1:.2f}" id="drvpw">')
        for i in np.flatnonzero((etime > 0) | (tcount > 0).any(axis=1)):
            attrs = [f'sampledSeconds="{etime[i]:.2f}"', f'entered="{entered[i]:.0f}"']
            # per equation: its vehicles were there (standing ones too), or booked there
            booked = (time_eq[i] > 1e-9) | (dist[i] > 0) | energy[i].any(axis=(0, 2)) | (tcount[i] > 0)
            for e, name in enumerate(names):
                tr = energy[i, 0, e]
                if not booked[e]:
                    continue  # none of its vehicles here: no attributes (a 0 reads as a free edge in routing)
                tot = float(tr.sum())
                for ci, cat in enumerate(cats):
                    attrs.append(f'{name}_{cat}_j="{tr[ci]:.3f}"')
                attrs.append(f'{name}_recup_j="{energy[i, 1, e].sum():.3f}"')
                attrs.append(f'{name}_total_j="{tot:.3f}"')
                if dist[i, e] > 0:  # (none driven, they stood: no per-vehicle figure, no free edge)
                    # SUMO's _perVeh: per vehicle driving the whole edge, the total × length / distance
                    # (per vehicle that entered in the interval gave 0 where one drove on across its start)
                    attrs.append(f'{name}_total_perVeh_j="{tot * float(net.edge_length[i]) / dist[i, e]:.3f}"')
                    attrs.append(f'{name}_total_normed_jpm="{tot / dist[i, e]:.6f}"')
                attrs += teleport.edge_attrs(name, tcount[i, e], tenergy[i, e])
            if chain is not None:
                attrs += chain.edge_attrs(chain_at[b[0]][i] - chain_prev[i], booked)
            lines.append(f"        <edge id={quoteattr(net.edge_ids[i])} {' '.join(attrs)}/>")
        lines.append("    </interval>")
        if chain is not None:
            chain_prev = chain_at[b[0]]
        prev = b
    lines += ["</meandata>", ""]
    return "\n".join(lines)


def summary_dict(ledger: Ledger, net: Network, names: list[str], uses_other: bool,
                 extra: dict, vtypes: dict | None = None) -> dict:
    """The summary.json document (see the issue's contract); ``vtypes``: the route files'
    vTypes (:func:`~sumo_drvpw.sim.vtypes.read_vtypes`), whose car-following attributes the
    driving dynamics list."""
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
           "vehicles": ledger.vehicles_total if hasattr(ledger, "vehicles_total")
           else int(np.count_nonzero(ledger.veh_keep[:ledger.n_veh])),
           "samples": int(ledger.samples),
           "slope_corrected_samples": int(ledger.corrected),
           "slope_clipped_samples": int(ledger.clipped),
           "position_reads": int(ledger.position_reads),
           "position_mismatches": int(ledger.position_mismatches),
           "hard_brakes": {"samples": int(getattr(ledger, "hard_brakes", 0)),
                           "max_decel_mps2": float(getattr(ledger, "hard_brake_max_mps2", 0.0))},
           "transportables": {"samples": int(getattr(ledger, "load_samples", 0)),
                              "max_kg": float(getattr(ledger, "load_max_kg", 0.0))},
           "internal_edges": "energy on internal junction lanes is booked on the edge "
                             "they lead to",
           "energy_definition": "energy_j: Σ term power × Δt over vehicle-steps with total "
                                "power > 0 (traction); recuperable_energy_j: over the others",
           "classes": classes,
           "equations": eqs}
    out.update(extra)
    net_j = {n: sum(eqs[n]["energy_j"][c]["total"] + eqs[n]["recuperable_energy_j"][c]["total"]
                    for c in classes) for n in names}
    out["teleports"], per_eq, warn = teleport.summary(ledger, net, names, classes, net_j)
    for n in names:
        eqs[n]["teleports"] = per_eq[n]
    dyn = getattr(ledger, "dynamics", None)
    if dyn is not None:
        out["driving_dynamics"] = {"source": dynamics.SOURCE, "vclasses": dyn.summary()}
        for lab, doc in out["driving_dynamics"]["vclasses"].items():  # where to look: its vTypes
            doc["vtypes"] = sorted(ledger.class_vtypes.get(lab, ()))
            doc["vtype_driving"] = {vt: _driving_of(vtypes or {}, vt) for vt in doc["vtypes"]}
        warn = list(warn) + dynamics.warnings(out["driving_dynamics"]["vclasses"])
    if warn:
        out["warnings"] = list(out.get("warnings", [])) + warn
    return out


def _driving_of(vtypes: dict, vt: str) -> dict | None:
    """:func:`dynamics.vtype_driving` of a vType the files declare, or one of SUMO's own
    (DEFAULT_VEHTYPE, …) no file redeclares; None for one made at run time (a TraCI
    script's ``vehicletype.copy``): the files cannot say how it drives."""
    info = vtypes.get(vt)
    if info is not None:
        return dynamics.vtype_driving(info.driving, info.vclass or "passenger")
    if vt in SUMO_DEFAULT_VTYPES:
        return dynamics.vtype_driving(None, SUMO_DEFAULT_VTYPES[vt])
    return None


TERM_COLOURS = {"acc": "#1f77b4", "grade": "#8c564b", "aero": "#2ca02c", "roll": "#ff7f0e",
                "other": "#7f7f7f"}


def share_figure(classes_tbl: pa.Table, path: Path, predicts: dict | None = None) -> None:
    """Stacked bars: traction energy [kWh] by term for each road class and equation, with
    the energy per distance [Wh/km] above each bar and, under it, what the equation
    predicts (wheel or powertrain output, ``predicts``: equation → label)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    df = classes_tbl.to_pandas()
    df = df[df["term"].isin(LEDGER_CATEGORIES)]
    kwh = df.pivot_table(index=["class", "equation"], columns="term",
                         values="traction_energy_j", sort=False).fillna(0.0) / 3.6e6
    kwh = kwh[[c for c in LEDGER_CATEGORIES if c in kwh.columns and kwh[c].abs().sum() > 0]]
    kwh = kwh[kwh.sum(axis=1) > 0]
    whpkm = df.groupby(["class", "equation"], sort=False)["traction_whpkm"].sum()
    fig, ax = plt.subplots(figsize=(max(6, 0.9 * len(kwh) + 2), 4.5))
    if len(kwh):
        kwh.plot.bar(stacked=True, ax=ax, width=0.75,
                     color=[TERM_COLOURS[c] for c in kwh.columns])
        what = predicts or {}  # (the bars are the terms' driving energy, a chain's equation too)
        label = {"battery": "driving; chain: battery", "fuel": "driving; chain: fuel"}
        many = len(kwh) > 12  # (upright labels would overlap)
        ax.set_xticklabels([f"{c}\n{e}\n({label.get(what.get(e, 'wheel'), what.get(e, 'wheel').replace('_', ' '))})"
                            for c, e in kwh.index], rotation=90 if many else 0, fontsize=6 if many else 7)
        tot = kwh.sum(axis=1).to_numpy()
        for k, (idx, t) in enumerate(zip(kwh.index, tot)):
            w = whpkm.get(idx, np.nan)
            ax.annotate(f"{t:.2f} kWh\n{w:.0f} Wh/km" if np.isfinite(w) else f"{t:.2f} kWh",
                        (k, t), ha="center", va="bottom", fontsize=7)
        ax.set_ylim(0, 1.18 * float(tot.max()))
    ax.set_ylabel("traction energy [kWh]")
    ax.set_xlabel("")
    ax.set_title("Traction energy by term, per road class and equation")
    if len(kwh):
        ax.legend(title="term", loc="center left", bbox_to_anchor=(1.0, 0.5))
    write_figure(path, fig)


def difference_table(ledger: Ledger, net: Network, names: list[str], pair: list[str]):
    """Per edge driven by either of two equations' vehicles: each one's traction energy [J] and
    distance [m], and their difference per km of the lesser distance [Wh/km] (the map's);
    and a warning when the two booked different vehicles (their distances apart by more than
    1 %: a bus equation beside a car's), whose difference is then no comparison of models.
    The table: column name → values (``pd.DataFrame(table)``; difference.csv its
    :func:`~sumo_drvpw.sim.table_text.columns_csv`)."""
    a, b = names.index(pair[0]), names.index(pair[1])
    ta, tb = ledger.edge_trac[:, a].sum(1), ledger.edge_trac[:, b].sum(1)
    da, db = ledger.edge_dist_eq[:, a], ledger.edge_dist_eq[:, b]
    k = np.flatnonzero((da > 0) | (db > 0))
    table = {"edge": [net.edge_ids[i] for i in k], "class": [str(net.edge_class[i]) for i in k],
                          f"{pair[0]}_traction_j": ta[k], f"{pair[1]}_traction_j": tb[k],
                          f"{pair[0]}_distance_m": da[k], f"{pair[1]}_distance_m": db[k],
                          "difference_whpkm": _whpkm(ta[k] - tb[k], np.minimum(da[k], db[k]))}
    sa, sb = float(da.sum()), float(db.sum())
    note = None
    if max(sa, sb) > 0 and abs(sa - sb) > 0.01 * max(sa, sb):
        note = (f"difference {pair[0]} − {pair[1]}: the two booked different vehicles ({sa / 1000:,.1f} and "
                f"{sb / 1000:,.1f} km): the map and difference.csv compare them where both drove, per km of "
                "the lesser distance — no comparison of two models of the same vehicles ([outputs] difference)")
    return table, note


def difference_map(ledger: Ledger, net: Network, names: list[str], pair: list[str],
                   path: Path) -> None:
    """Network map coloured by the per-edge traction-energy difference of two equations,
    per kilometre driven [Wh/km] (sumolib geometry). Long thin networks get a stretched
    cross axis (equal aspect only when the extent is within 1:8)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection

    a, b = names.index(pair[0]), names.index(pair[1])
    diff = ledger.edge_trac[:, a].sum(1) - ledger.edge_trac[:, b].sum(1)
    both = np.minimum(ledger.edge_dist_eq[:, a], ledger.edge_dist_eq[:, b])
    per_km = _whpkm(diff, both)
    fig, ax = plt.subplots(figsize=(7, 6))
    used = np.isfinite(per_km)
    ax.add_collection(LineCollection([s for s, u in zip(net.edge_shapes, used) if not u],
                                     colors="0.85", linewidths=0.8))
    lim = float(np.nanmax(np.abs(per_km))) if used.any() else 1.0
    lc = LineCollection([s for s, u in zip(net.edge_shapes, used) if u], cmap="coolwarm",
                        linewidths=2.5)
    lc.set_array(per_km[used])
    lc.set_clim(-lim or -1.0, lim or 1.0)
    ax.add_collection(lc)
    fig.colorbar(lc, ax=ax, label=f"{pair[0]} − {pair[1]} traction energy [Wh/km]")
    ax.autoscale()
    pts = np.concatenate(net.edge_shapes) if net.edge_shapes else np.zeros((1, 2))
    span = np.ptp(pts, axis=0)
    if span.min() > 0 and span.max() / span.min() <= 8:
        ax.set_aspect("equal")
    else:  # a strip (e.g. a 6 km × 40 m motorway): pad the short axis to stay readable
        k = int(np.argmin(span))
        mid = pts[:, k].mean()
        half = max(span.max() / 16, 1.0)
        (ax.set_ylim if k == 1 else ax.set_xlim)(mid - half, mid + half)
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(f"Per-edge difference {pair[0]} − {pair[1]}")
    write_figure(path, fig)


class RunResult:
    """What a run booked: tables as DataFrames, the summary, and :meth:`write`.

    ``result["steps"]`` reads ``result.summary["steps"]`` (the summary dict as before).
    """

    def __init__(self, ledger: Ledger, net: Network, names: list[str], predicts: list[str],
                 summary: dict, begin: float, end: float, edgedata: bool = True,
                 figures: bool = True, difference: list[str] | None = None,
                 period: float | None = None):
        self.ledger, self.net, self.names, self.predicts = ledger, net, names, predicts
        self.summary, self.begin, self.end = summary, begin, end
        self.edgedata, self.figures, self.difference, self.period = \
            edgedata, figures, difference, period
        #: SUMO's emissions-device totals per vehicle (outputs.sumo_device), or None
        self.sumo_device = None
        #: equation → the vTypes of the files that are its export (sim/sumo_outputs.exported_vtypes)
        self.exported_vtypes: dict = {}
        #: vType → (SUMO's Energy-model default mass, ours) [kg] (sim/sumo_outputs.energy_default_masses)
        self.energy_masses: dict = {}
        self._steps = getattr(ledger, "steps", None)  # what the summary was taken at

    def _check_current(self) -> None:
        """UserError when the run stepped on after this result was taken (an Accountant in
        a user's loop): the tables read the ledger, which has moved, the summary not."""
        if self._steps is not None and self.ledger.steps != self._steps:
            raise UserError(f"this result was taken after {self._steps} steps (t = {self.end:g} s) "
                            f"and the run has booked {self.ledger.steps - self._steps} more since: "
                            "its tables would not match its summary; take Accountant.result() again")

    def __getitem__(self, key):
        return self.summary[key]

    def get(self, key, default=None):
        return self.summary.get(key, default)

    def __contains__(self, key) -> bool:
        return key in self.summary

    @property
    def _spill(self):
        spill = getattr(self.ledger, "spill", None)
        return spill if spill is not None and spill.has_rows else None

    def _vehicles_all(self) -> pa.Table:
        """Every vehicle's rows: those flushed during the run, then those held in memory."""
        self._check_current()
        t = vehicles_table(self.ledger, self.names, self.predicts)
        return t if self._spill is None else self._spill.vehicles(t)

    def vehicles_arrow(self) -> pa.Table:
        t = self._vehicles_all()
        if self.sumo_device is None:
            return t
        df = t.to_pandas().merge(self.sumo_device, on="vehicle", how="left")
        cols = {c: df[c].to_numpy() if df[c].dtype != object else df[c].tolist()
                for c in df.columns}
        return table_with_units(cols)

    def chain_vehicles(self):
        """Every vehicle's energy-chain rows (battery kWh or fuel L per equation; those
        flushed during the run, then those held in memory) as a DataFrame, or None."""
        import pandas as pd

        self._check_current()
        ch = getattr(self.ledger, "chain", None)
        if ch is None:
            return None
        n = self.ledger.n_veh
        df = pd.DataFrame(ch.table(ch.vehicle_totals(n), ch.vehicle_dist(n),
                                   list(self.ledger.veh_ids[:n])))
        spill = getattr(self.ledger, "spill", None)
        if spill is not None and spill.chain_parts:
            parts = [pd.read_csv(p, header=None, names=spill.chain_columns,
                                 dtype={"key": str}) for p in spill.chain_parts]
            df = pd.concat([*parts, df], ignore_index=True)
        return df.rename(columns={"key": "vehicle"})

    def sumo_device_comparison(self):
        """Per equation, over the vehicles SUMO's emissions device reports for, what the
        plug-in books beside what SUMO's own model books (``sumo_outputs.device_comparison``:
        battery kWh, litres or net driving energy against SUMO's electricity or fuel; a
        battery chain's ratio split into its auxiliary part and the rest)."""
        from sumo_drvpw.sim.sumo_outputs import device_comparison

        if self.sumo_device is None:
            return device_comparison(None, None, None, {})
        v = self._vehicles_all().to_pandas()[["vehicle", "equation", "net_total_j", "vtype", "vclass"]]
        ch = getattr(self.ledger, "chain", None)
        chains = {} if ch is None else {ch.names[i]: ch.chains[i] for i in ch.active}
        return device_comparison(v, self.sumo_device, self.chain_vehicles(), chains, self.exported_vtypes,
                                 self.energy_masses)

    def edges_arrow(self) -> pa.Table:
        self._check_current()
        return edges_table(self.ledger, self.net, self.names)

    def classes_arrow(self) -> pa.Table:
        self._check_current()
        return classes_table(self.ledger, self.net, self.names)

    @property
    def vehicles(self):
        """Per vehicle × equation (pandas DataFrame; columns as in vehicles.parquet)."""
        return self.vehicles_arrow().to_pandas()

    @property
    def edges(self):
        """Per edge × equation (pandas DataFrame; columns as in edges.parquet)."""
        return self.edges_arrow().to_pandas()

    @property
    def classes(self):
        """Per road class × equation × term (pandas DataFrame; classes.parquet)."""
        return self.classes_arrow().to_pandas()

    def edgedata_xml(self) -> str:
        self._check_current()
        return edgedata_xml(self.ledger, self.net, self.names, self.begin, self.end)

    def write(self, out_dir, force: bool = False) -> dict[str, str]:
        """Write every table, figure and summary.json into ``out_dir`` as one output set
        with its manifest.json (an earlier set's files there that are not written again
        removed once it is written; a folder holding other files refused unless ``force``,
        which keeps them)."""
        from sumo_drvpw.fileio import (check_earlier_set, earlier_stamps, in_output_set, remove_stale,
                                       write_manifest)

        if in_output_set(out_dir):  # (a command's set, written whole by it)
            return write_outputs(Path(out_dir), self)
        listed, kept = check_earlier_set(out_dir, force)
        stamps = earlier_stamps(out_dir, listed)
        files = write_outputs(Path(out_dir), self)
        remove_stale(out_dir, stamps)
        write_manifest(Path(out_dir), command=["RunResult.write"], kept=kept)
        return files


def write_outputs(out_dir: Path, result: RunResult) -> dict[str, str]:
    """Write every table/figure atomically into ``out_dir``; returns name → path."""
    result._check_current()
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise UserError(f"{out_dir}: is a file; give a folder to write the run's outputs into")
    out_dir.mkdir(parents=True, exist_ok=True)
    summary = result.summary
    files = {}
    spill = result._spill
    if spill is not None and result.sumo_device is None:  # row groups streamed, bounded memory
        spill.write_vehicles(out_dir / "vehicles.parquet",
                             vehicles_table(result.ledger, result.names, result.predicts))
    else:
        write_parquet(out_dir / "vehicles.parquet", result.vehicles_arrow())
    write_parquet(out_dir / "edges.parquet", result.edges_arrow())
    ct = result.classes_arrow()
    write_parquet(out_dir / "classes.parquet", ct)
    write_text(out_dir / "shares.csv", table_csv(ct))
    files.update({k: str(out_dir / f) for k, f in (
        ("vehicles", "vehicles.parquet"), ("edges", "edges.parquet"),
        ("classes", "classes.parquet"), ("shares", "shares.csv"))})
    if result.sumo_device is not None:
        write_text(out_dir / "sumo_device.csv", result.sumo_device_comparison().to_csv(index=False))
        files["sumo_device"] = str(out_dir / "sumo_device.csv")
    if result.edgedata:
        write_text(out_dir / "edgedata.xml", result.edgedata_xml())
        files["edgedata"] = str(out_dir / "edgedata.xml")
    names = result.names
    pair = (result.difference or names[:2]) if len(names) >= 2 else None
    if pair is not None:  # the per-edge difference of two equations, as a table (and a map)
        table, note = difference_table(result.ledger, result.net, names, pair)
        write_text(out_dir / "difference.csv", columns_csv(table))
        files["difference"] = str(out_dir / "difference.csv")
        if note and note not in summary.setdefault("warnings", []):
            summary["warnings"].append(note)
    if result.figures:
        share_figure(ct, out_dir / "shares.png", dict(zip(names, result.predicts)))
        files["shares_figure"] = str(out_dir / "shares.png")
        if pair is not None:
            difference_map(result.ledger, result.net, names, pair,
                           out_dir / "difference_map.png")
            files["difference_map"] = str(out_dir / "difference_map.png")
    if getattr(result.ledger, "chain", None) is not None:  # battery/fuel accounts (#12)
        from sumo_drvpw.sim.chain_outputs import write_chain_outputs

        files.update(write_chain_outputs(out_dir, result))
    summary.setdefault("files", {}).update({k: os.path.basename(v) for k, v in files.items()})
    write_json(out_dir / "summary.json", summary)
    return files
