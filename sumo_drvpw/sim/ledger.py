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
from ..terms import CATEGORIES, Inputs, parse_term

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
        C = len(LEDGER_CATEGORIES)
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
            # sparse map: (term number, output row e·C + c, coefficient); a handful of
            # vector axpys per step instead of a matmul (BLAS threads fight SUMO's)
            entries = []
            for i in members:
                for t, c in self.equations[i].terms.items():
                    cat = LEDGER_CATEGORIES.index(parse_term(t).category)
                    entries.append((terms.index(t), i * C + cat, float(c)))
            self.groups.append((mass, [parse_term(t) for t in terms], entries))
        self.uses_other = any(parse_term(t).category == "other"
                              for e in self.equations for t in e.term_names)

    def category_powers(self, x: Inputs, app: np.ndarray | None = None) -> np.ndarray:
        """Power [W] per sample, equation and category, shape (n, E, C).

        Parameters
        ----------
        x : inputs of n samples
        app : optional (n, E) weights (1: the equation applies to the vehicle, 0: not)

        The result is a view of an (E, C, n) array (what :meth:`Ledger.book` uses).
        """
        E, C, n = len(self.equations), len(LEDGER_CATEGORIES), len(x)
        out = np.zeros((E * C, n))
        for mass, terms, entries in self.groups:
            xm = x.with_mass(mass)
            vals = [t.evaluate(xm) for t in terms]
            for u, row, c in entries:
                out[row] += c * vals[u]
        out = out.reshape(E, C, n)
        if app is not None:
            out *= np.asarray(app, float).T[:, None, :]
        return out.transpose(2, 0, 1)


class Ledger:
    """Accumulators of a run (energies [J], distances [m], times [s]).

    Parameters
    ----------
    n_edges : number of (non-internal) edges
    n_equations : number of equations
    """

    def __init__(self, n_edges: int, n_equations: int, capacity: int = 1024):
        self.E, self.C, self.n_edges = n_equations, len(LEDGER_CATEGORIES), n_edges
        # edge energies as (2, E·C, edges): [traction, recuperable] rows for bincount adds
        self._edge_energy = np.zeros((2, self.E * self.C, n_edges))
        self._rows = None
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

    @property
    def edge_trac(self) -> np.ndarray:
        """Traction energy per edge, equation, category [J], (edges, E, C)."""
        return self._edge_energy[0].reshape(self.E, self.C, self.n_edges).transpose(2, 0, 1)

    @property
    def edge_recup(self) -> np.ndarray:
        """Recuperable energy per edge, equation, category [J], (edges, E, C)."""
        return self._edge_energy[1].reshape(self.E, self.C, self.n_edges).transpose(2, 0, 1)

    @property
    def veh_trac(self) -> np.ndarray:
        """Traction energy per vehicle, equation, category [J], (capacity, E, C)."""
        return self._veh_energy[:, 0]

    @property
    def veh_recup(self) -> np.ndarray:
        """Recuperable energy per vehicle, equation, category [J], (capacity, E, C)."""
        return self._veh_energy[:, 1]

    def _alloc(self, cap: int) -> None:
        def grow(name, shape, dtype=float, fill=0):
            old = getattr(self, name, None)
            new = np.full(shape, fill, dtype=dtype)
            if old is not None:
                new[:len(old)] = old
            setattr(self, name, new)
        E, C = self.E, self.C
        grow("_veh_energy", (cap, 2, E, C))
        grow("veh_dist", (cap,))
        grow("veh_time", (cap,))
        grow("veh_mass", (cap,), float, np.nan)
        grow("veh_app", (cap, E))
        grow("veh_keep", (cap,), bool, False)
        grow("veh_prev_edge", (cap,), np.int64, -1)
        grow("veh_prev_speed", (cap,), float, np.nan)
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
        EC, n = E * C, len(vidx)
        pct = pc.transpose(1, 2, 0)  # (E, C, n): contiguous when pc is from EquationSet
        split = np.empty((2, E, C, n))  # [traction, recuperable] energies of the step
        energy = np.multiply(pct, dt, out=split[1])
        pos = energy.sum(axis=1) > 0.0
        np.multiply(energy, pos[:, None, :], out=split[0])
        split[1] -= split[0]
        # one scatter-add per vehicle row and one bincount for the edges: the per-call
        # overhead, not the arithmetic, dominates at a few thousand vehicles
        self._veh_energy[vidx] += split.transpose(3, 0, 1, 2)
        d = v * dt
        self.veh_dist[vidx] += d
        self.veh_time[vidx] += dt
        if self._rows is None:
            self._rows = (np.arange(2 * EC) * self.n_edges)[:, None]
        flat = (self._rows + eidx).ravel()
        self._edge_energy += np.bincount(flat, split.ravel(), 2 * EC * self.n_edges
                                         ).reshape(self._edge_energy.shape)
        self.edge_dist += np.bincount(eidx, d, self.n_edges)
        enter = eidx != self.veh_prev_edge[vidx]
        if enter.any():
            self.veh_prev_edge[vidx[enter]] = eidx[enter]
            np.add.at(self.edge_count, eidx[enter], self.veh_app[vidx[enter]])
        self.samples += n
        return split[0].transpose(2, 0, 1), split[1].transpose(2, 0, 1)
