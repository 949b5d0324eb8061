"""Energy ledger: vehicle × equation × category and edge × equation × category accumulators.

Every equation's terms are evaluated for all vehicles of a step in one pass: one term
matrix per distinct equation mass (the union of the terms of the equations sharing it)
times a coefficient matrix that maps terms to (equation, category) columns. Energies are
power × Δt, split by the sign of each equation's total power: traction (P > 0) and
recuperable (P ≤ 0) energy are kept apart per category. Accumulation uses fancy-index
adds for vehicles (unique within a step) and ``np.bincount`` for edges.
"""

from __future__ import annotations

import numpy as np

from ..equations import Equation
from ..terms import CATEGORIES, Inputs, parse_term, term_matrix

#: Reporting categories of the ledger: the four physical ones and "other".
LEDGER_CATEGORIES = CATEGORIES + ("other",)


class EquationSet:
    """Several equations evaluated at once into per-category powers.

    Parameters
    ----------
    equations : the equations, in output order
    """

    def __init__(self, equations: list[Equation]):
        self.equations = list(equations)
        self.names = [e.name for e in self.equations]
        E, C = len(self.equations), len(LEDGER_CATEGORIES)
        groups: dict[float | None, list[int]] = {}
        for i, e in enumerate(self.equations):
            groups.setdefault(e.mass_kg, []).append(i)
        self.groups = []
        for mass, members in groups.items():
            terms: list[str] = []
            for i in members:
                for t in self.equations[i].term_names:
                    if t not in terms:
                        terms.append(t)
            W = np.zeros((len(terms), E * C))
            for i in members:
                eq = self.equations[i]
                for t, c in eq.terms.items():
                    cat = LEDGER_CATEGORIES.index(parse_term(t).category)
                    W[terms.index(t), i * C + cat] += c
            self.groups.append((mass, terms, W))
        self.uses_other = any(parse_term(t).category == "other"
                              for e in self.equations for t in e.term_names)

    def category_powers(self, x: Inputs) -> np.ndarray:
        """Power [W] per sample, equation and category, shape (n, E, C)."""
        out = None
        for mass, terms, W in self.groups:
            part = term_matrix(terms, x.with_mass(mass)) @ W
            out = part if out is None else out + part
        return out.reshape(len(x), len(self.equations), len(LEDGER_CATEGORIES))


class Ledger:
    """Accumulators of a run (energies [J], distances [m], times [s]).

    Parameters
    ----------
    n_edges : number of (non-internal) edges
    n_equations : number of equations
    """

    def __init__(self, n_edges: int, n_equations: int, capacity: int = 1024):
        self.E, self.C, self.n_edges = n_equations, len(LEDGER_CATEGORIES), n_edges
        shape = (n_edges, self.E, self.C)
        self.edge_trac = np.zeros(shape)
        self.edge_recup = np.zeros(shape)
        self.edge_count = np.zeros((n_edges, self.E))
        self.edge_dist = np.zeros(n_edges)
        self.n_veh = 0
        self._alloc(capacity)
        self.veh_ids: list[str] = []
        self.veh_type: list[str] = []
        self.steps = 0
        self.samples = 0
        self.corrected = 0
        self.clipped = 0

    def _alloc(self, cap: int) -> None:
        def grow(name, shape, dtype=float, fill=0):
            old = getattr(self, name, None)
            new = np.full(shape, fill, dtype=dtype)
            if old is not None:
                new[:len(old)] = old
            setattr(self, name, new)
        E, C = self.E, self.C
        grow("veh_trac", (cap, E, C))
        grow("veh_recup", (cap, E, C))
        grow("veh_dist", (cap,))
        grow("veh_time", (cap,))
        grow("veh_mass", (cap,), float, np.nan)
        grow("veh_app", (cap, E))
        grow("veh_keep", (cap,), bool, False)
        grow("veh_prev_edge", (cap,), np.int64, -1)
        self.capacity = cap

    def add_vehicle(self, vid: str, vtype: str, mass: float, app: np.ndarray,
                    keep: bool) -> int:
        """Register a vehicle; returns its index."""
        if self.n_veh >= self.capacity:
            self._alloc(2 * self.capacity)
        i = self.n_veh
        self.veh_ids.append(vid)
        self.veh_type.append(vtype)
        self.veh_mass[i] = mass
        self.veh_app[i] = app
        self.veh_keep[i] = keep
        self.n_veh += 1
        return i

    def book(self, vidx: np.ndarray, eidx: np.ndarray, v: np.ndarray, dt: float,
             pc: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Book one step for vehicles ``vidx`` on edges ``eidx``.

        Parameters
        ----------
        vidx, eidx : vehicle and edge numbers (each vehicle once)
        v : speed [m/s]
        dt : step length [s]
        pc : power per vehicle, equation, category [W], (n, E, C), already zero where an
             equation does not apply to a vehicle

        Returns traction and recuperable energies [J] of the step, (n, E, C) each.
        """
        E, C = self.E, self.C
        pos = pc.sum(axis=2) > 0.0
        energy = pc * dt
        trac = energy * pos[:, :, None]
        recup = energy - trac
        self.veh_trac[vidx] += trac
        self.veh_recup[vidx] += recup
        d = v * dt
        self.veh_dist[vidx] += d
        self.veh_time[vidx] += dt
        EC = E * C
        flat = (eidx[:, None] * EC + np.arange(EC)).ravel()
        size = self.n_edges * EC
        self.edge_trac += np.bincount(flat, trac.ravel(), size).reshape(self.edge_trac.shape)
        self.edge_recup += np.bincount(flat, recup.ravel(), size).reshape(self.edge_trac.shape)
        self.edge_dist += np.bincount(eidx, d, self.n_edges)
        enter = eidx != self.veh_prev_edge[vidx]
        if enter.any():
            self.veh_prev_edge[vidx[enter]] = eidx[enter]
            np.add.at(self.edge_count, eidx[enter], self.veh_app[vidx[enter]])
        self.samples += len(vidx)
        return trac, recup
