"""A run's battery and fuel accounts as rows: per vehicle, per edge and per class, in kWh, L
and kg with their per-km values (the tables :mod:`sumo_drvpw.sim.chain_outputs` writes), read
from a :class:`~sumo_drvpw.sim.chain.ChainLedger`'s totals and distances. Class totals are sums
of the vehicle totals (with the vehicles already flushed out of memory), so vehicle, edge and
class rows agree by construction."""

from __future__ import annotations

import numpy as np

KWH = 3.6e6


class ChainTables:
    """:class:`~sumo_drvpw.sim.chain.ChainLedger`'s rows (a base class: it reads the ledger's
    ``active``, ``names``, ``chains``, totals and distances)."""

    def class_totals(self, classes: list[str]) -> dict[str, np.ndarray]:
        """Totals per class label (one label per vehicle index), {class: (E, Q)}, and the
        distances under ``"<class>/distance_m"`` style keys in :meth:`table`."""
        n = len(classes)
        tot = self.vehicle_totals(n)
        labels = np.asarray(classes, dtype=object)
        return {c: tot[labels == c].sum(axis=0) for c in dict.fromkeys(classes)}

    def table(self, totals: np.ndarray, dist_m: np.ndarray, keys: list[str]) -> list[dict]:
        """Rows {key, equation, distance_km, traction_kwh, …, fuel_l, co2_kg, per-km values}
        for every key and every equation with a chain that booked something there
        (``dist_m``: (keys, active equations), the distance each booked)."""
        rows = []
        dist_m = np.asarray(dist_m, float).reshape(-1, self.A)[:len(keys)]
        booked = np.asarray(totals)[:len(keys)][:, list(self.active)].any(axis=-1)  # (one pass, not one per row)
        for i, k in enumerate(keys):
            for j, e in enumerate(self.active):
                t = totals[i, e]
                km = float(dist_m[i, j]) / 1000.0
                if km == 0 and not booked[i, j]:
                    continue  # the equation does not book this vehicle (or none on this edge)
                r = {"key": k, "equation": self.names[e], "distance_km": km}
                if self.chains[e].predicts == "fuel":
                    r.update(fuel_l=t[5], co2_kg=t[6], fuel_kwh=t[4] / KWH)
                    if self.cold_start_on:
                        r["cold_start_l"] = t[7]
                    r["fuel_l_per_100km"] = 100.0 * t[5] / km if km > 0 else np.nan
                    r["co2_g_per_km"] = 1000.0 * t[6] / km if km > 0 else np.nan
                if self.chains[e].predicts != "fuel" or self.plug_in(e):
                    r.update(traction_kwh=t[0] / KWH, recuperated_kwh=t[1] / KWH,
                             auxiliary_kwh=t[2] / KWH, net_kwh=t[3] / KWH)
                    r["net_kwh_per_km"] = t[3] / KWH / km if km > 0 else np.nan
                rows.append(r)
        return rows

    def columns(self) -> list[str]:
        """The columns of :meth:`table`'s rows (the header of a table without rows)."""
        fuel = ["fuel_l", "co2_kg", "fuel_kwh", *(["cold_start_l"] if self.cold_start_on else []),
                "fuel_l_per_100km", "co2_g_per_km"]
        battery = ["traction_kwh", "recuperated_kwh", "auxiliary_kwh", "net_kwh", "net_kwh_per_km"]
        cols = ["key", "equation", "distance_km"]
        for e in self.active:
            cols += (fuel if self.chains[e].predicts == "fuel" else []) + (
                battery if self.chains[e].predicts != "fuel" or self.plug_in(e) else [])
        return list(dict.fromkeys(cols))

    def report(self, veh_ids: list[str], veh_classes: list[str], edge_ids: list[str],
               class_order=None) -> dict:
        """Per-vehicle, per-edge and per-class rows (see :meth:`table`); the vehicles held in
        memory, the classes with the flushed vehicles' totals added, by class name."""
        n = len(veh_ids)
        cls = self.class_totals(veh_classes)
        labels = np.asarray(veh_classes, dtype=object)
        vdist = self.vehicle_dist(n)
        cdist = np.array([vdist[labels == c].sum(axis=0) for c in cls]).reshape(len(cls), self.A)
        if self.flushed_class:
            dist = dict(zip(cls, cdist))
            for c, (q, m) in self.flushed_class.items():
                cls[c] = cls[c] + q if c in cls else q.copy()
                dist[c] = dist.get(c, 0.0) + m
            order = [c for c in (class_order or ()) if c in cls]
            order += [c for c in cls if c not in order]
            cls = {c: cls[c] for c in order}
            cdist = np.array([dist[c] for c in order]).reshape(len(order), self.A)
        if cls:  # by class name: the same rows live, replayed and on Dask (vehicles come in other orders)
            k = np.argsort(np.array(list(cls), dtype=object))
            cls, cdist = {c: cls[c] for c in np.array(list(cls), dtype=object)[k]}, cdist[k]
        return {"vehicles": self.table(self.vehicle_totals(n), vdist, list(veh_ids)),
                "edges": self.table(self.edge, self.edge_dist, list(edge_ids)),
                "classes": self.table(np.stack(list(cls.values())) if cls else np.zeros((0, self.E, self.Q)),
                                      cdist, list(cls))}
