"""Energy ledger: vehicle × equation × category and edge × equation × category accumulators.

Every equation's terms are evaluated for all vehicles of a step in one pass: one term
matrix per distinct equation mass (the union of the terms of the equations sharing it)
times a coefficient matrix that maps terms to (equation, category) columns. Energies are
power × Δt, split by the sign of each equation's total power: traction (P > 0) and
recuperable (P ≤ 0) energy are kept apart per category. Each step is added to the
vehicles' running totals (one fancy-index add; vehicles are unique within a step). Edges
are booked by differences of those running totals: when a vehicle enters an edge, the
energy and distance it accumulated since entering its previous edge are added to that
edge, and the segments still open are added when the edge totals are read. Per step only
the few vehicles that change edge touch the edge arrays, and the sums equal direct
per-step booking up to rounding.

Bounded memory: vehicles that left the simulation (:meth:`Ledger.retire`) keep their rows
until :attr:`Ledger.flush_vehicles` of them are finished; then :meth:`Ledger.flush` closes
their open edge segments, hands their rows to :attr:`Ledger.spill` (which streams them to
``vehicles.parquet`` row groups, :mod:`sumo_drvpw.sim.spill`) and compacts the running
vehicles to the front of the arrays. Memory then grows with the vehicles running at once,
not with the trips of the run; edge and class totals are sums kept per edge.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from sumo_drvpw.model.equations import Equation
from sumo_drvpw.model.terms import CATEGORIES, Inputs, parse_term
from sumo_drvpw.sim import sumo_inputs
from sumo_drvpw.sim.dynamics import Dynamics
from sumo_drvpw.sim.sumo_inputs import as_sumo, at_mean_speed

#: Reporting categories of the ledger: the four physical ones and "other".
LEDGER_CATEGORIES = CATEGORIES + ("other",)
#: SUMO's halting speed [m/s] (SUMO_const_haltingSpeed): below it a vehicle waits, and a
#: jammed one is teleported after --time-to-teleport of waiting
HALTING_SPEED_MPS = 0.1
#: SUMO's reading of a step (its home: :mod:`sumo_drvpw.sim.sumo_inputs`), where the tests import it from
as_sumo_inputs = sumo_inputs.as_sumo_inputs


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
        groups: dict[tuple, list[int]] = {}
        for i, e in enumerate(self.equations):
            groups.setdefault((e.mass_kg, at_mean_speed(e), as_sumo(e)), []).append(i)
        self.groups = []
        for (mass, mean, sumo), members in groups.items():
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
            self.groups.append((mass, [parse_term(t) for t in terms], entries, mean, sumo))
        self._live_cache: dict = {}  # equations booking a vehicle of a step → their groups
        self._app_cache: dict = {}  # a few vehicles' app (shape, dtype, bytes) → the same
        self.uses_other = any(parse_term(t).category == "other"
                              for e in self.equations for t in e.term_names)
        #: an equation has the ``radial`` factor: the loop passes the yaw rate
        self.uses_yaw = any("radial" in parse_term(t).factors
                            for e in self.equations for t in e.term_names)
        #: an equation is evaluated at the step's mean speed (:func:`at_mean_speed`)
        self.uses_mean = any(g[3] for g in self.groups)
        #: an equation books the grade at SUMO's own slope (:func:`as_sumo`): the loop passes
        #: getSlope as the signal ``sumo_slope_rad``
        self.uses_sumo_slope = any(g[4] and any(t.category == "grade" for t in g[1]) for g in self.groups)
        #: SUMO Energy-model equations at the vehicle's mass (vtype_energy): their acc coefficient
        #: 1 + m_rot/m holds the rotating mass m_rot of the vType's mass m, which neither riders
        #: nor a setMass change (HelpersEnergy: the total mass plus rotatingMass)
        self.rot_fixed = [(i, e.terms.get("acc", 1.0) - 1.0, float(e.provenance.get("rotating_mass_kg", 0.0)))
                          for i, e in enumerate(self.equations)
                          if e.mass_kg is None and e.provenance.get("rotating_mass_fixed")]

    def _live_groups(self, app) -> list:
        """The groups with only the equations that apply to a vehicle of the step (``app``
        (n, E) > 0; None: all) and the terms those read: an equation no vehicle of the step
        books is not evaluated (a bare SUMO config carries a built-in equation per vClass,
        most of them booking no vehicle most of the time); its rows stay 0. A few vehicles'
        ``app`` is looked up by its bytes first (the same vehicles mostly: no mask to derive)."""
        a = None if app is None else np.asarray(app)
        raw = None if a is None or len(a) > 64 else (a.shape, a.dtype.str, a.tobytes())
        if raw is not None and (got := self._app_cache.get(raw)) is not None:
            return got
        live = None if a is None else a != 0
        key = None if live is None else np.packbits(live.any(axis=0)).tobytes()
        got = self._live_cache.get(key)
        if got is None:
            C, on = len(LEDGER_CATEGORIES), None if live is None else live.any(axis=0)
            got = []
            for mass, terms, entries, mean, sumo in self.groups:
                kept = [e for e in entries if on is None or on[e[1] // C]]
                if kept:  # its entries (term row, output row, coefficient), and as arrays for np.add.at
                    need = sorted({u for u, _, _ in kept})
                    rows = [(need.index(u), r, c) for u, r, c in kept]
                    arrays = tuple(np.array(x) for x in zip(*[(u, r, [c]) for u, r, c in rows]))
                    got.append((mass, [terms[u] for u in need], rows, arrays, mean, sumo))
            self._live_cache[key] = got
        if raw is not None:
            self._app_cache = {**(self._app_cache if len(self._app_cache) < 64 else {}), raw: got}
        return got

    def category_powers(self, x: Inputs, app: np.ndarray | None = None, x_mean: Inputs | None = None) -> np.ndarray:
        """Power [W] per sample, equation and category, shape (n, E, C).

        Parameters
        ----------
        x : inputs of n samples
        app : optional (n, E) weights (1: the equation applies to the vehicle, 0: not)
        x_mean : the inputs at the step's mean speed, for equations evaluated there
            (:func:`at_mean_speed`; None: ``x``); its signal ``load_kg`` (riders' mass [kg])
            is added to the fixed mass of such an equation, as MMPEVEM adds it (getTotalMass)

        The result is a view of an (E, C, n) array (what :meth:`Ledger.book` uses).
        """
        E, C, n = len(self.equations), len(LEDGER_CATEGORIES), len(x)
        out = np.zeros((E * C, n))
        for mass, terms, entries, arrays, mean, sumo in self._live_groups(app):
            xm = (x_mean if mean and x_mean is not None else x).with_mass(mass)
            if mean and mass is not None and x_mean is not None and "load_kg" in x_mean.signals:
                xm = replace(xm, mass=xm.mass + np.asarray(x_mean.signals["load_kg"], float))
            if sumo:  # (a vtype_energy equation: SUMO's slope and radius)
                xm = as_sumo_inputs(xm)
            vals = np.empty((len(terms), n))
            for i, t in enumerate(terms):
                vals[i] = t.evaluate(xm)
            if n <= 32:  # out[row] += c·term, entry by entry: np.add.at adds them in order in one call
                u, rows, c = arrays  # (at up to 32 vehicles; at more its per-element cost is more)
                np.add.at(out, rows, c * vals[u])
            else:
                for u, row, c in entries:
                    out[row] += c * vals[u]
        if self.rot_fixed:  # (m' + m_rot)·v̄·a at the booked mass m' (riders, a setMass), not (1 + m_rot/m)·m'
            va = (x.v if x.v_acc is None else x.v_acc) * x.a
            for i, k, m_rot in self.rot_fixed:
                out[i * C + LEDGER_CATEGORIES.index("acc")] -= (k * np.asarray(x.mass, float) - m_rot) * va
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
        # closed edge segments: energies (edges, 2, E, C) [traction, recuperable], distances
        self._edge_closed = np.zeros((n_edges, 2, self.E, self.C))
        self._edge_dist_closed = np.zeros(n_edges)
        self._edge_time_closed = np.zeros(n_edges)
        self._edge_dist_eq_closed = np.zeros((n_edges, self.E))
        self._edge_time_eq_closed = np.zeros((n_edges, self.E))  # vehicle-seconds of each equation's vehicles
        self._edge_cache = None
        self.edge_count = np.zeros((n_edges, self.E))
        #: accounted vehicles that entered each edge (SUMO's edgeData ``entered``)
        self.edge_entered = np.zeros(n_edges)
        #: teleports ended on each edge (weighted by each equation's applicability) and their
        #: [kinetic, potential] energy jumps [J], (edges, E, 2): apart from driving (sim/teleport.py)
        self.edge_teleports = np.zeros((n_edges, self.E))
        self.edge_tele = np.zeros((n_edges, self.E, 2))
        self.teleports = 0  # accounted vehicles put back on a lane by a teleport's end
        #: cumulative edge totals at interval boundaries: [(time [s], energies, distances,
        #: times, counts, entered, teleports, their energies)] (see :meth:`snapshot`)
        self.snapshots: list[tuple] = []
        self.n_veh = 0
        self._alloc(capacity)
        self.veh_ids: list[str] = []
        self.veh_type: list[str] = []
        self.veh_class: list[str] = []
        #: vehicle-steps per equation outside the equation's speed/acceleration range
        self.out_of_range = np.zeros(n_equations, np.int64)
        self.steps = 0
        self.samples = 0
        self.corrected = 0
        self.clipped = 0
        #: lane/position reads of tracked positions, and resync reads that disagreed
        self.position_reads = 0
        self.position_mismatches = 0
        #: vehicle-steps that decelerated beyond any brake (sim/loop.IMPOSSIBLE_DECEL_MPS2),
        #: and the hardest such deceleration [m/s²]
        self.hard_brakes = 0
        self.hard_brake_max_mps2 = 0.0
        #: vehicle-steps booked with riding persons, and the most they weighed
        self.load_samples = 0
        self.load_max_kg = 0.0
        #: vehicle-steps on a clipped slope, per lane number (sized by the loop)
        self.lane_clipped = np.zeros(0, np.int64)
        #: battery/fuel accounts (sumo_drvpw.sim.chain.ChainLedger) when an equation has a chain
        self.chain = None
        #: vClass → accounted vehicles no battery or fuel chain of the run applies to (their
        #: driving energy is booked; their kWh, litres and CO₂ are not)
        self.chainless: dict[str, int] = {}
        #: the same by vType
        self.chainless_vtypes: dict[str, int] = {}
        #: where finished vehicles' rows go (``write(ledger, slots)``, ``write_chain(rows)``:
        #: :class:`sumo_drvpw.sim.spill.VehicleSpill`); None keeps every vehicle in memory
        self.spill = None
        #: finished vehicles held before they are flushed to :attr:`spill`
        self.flush_vehicles = 1024
        self.n_done = 0
        #: steps a vehicle that left standing stays in memory before it may be flushed (an
        #: FCD replay: one that vanished from its rows standing may be in a teleport and come
        #: back, sim/fcd.py TELEPORT_HOLD_S; 0: none held)
        self.hold_steps = 0
        #: those among them that left moving are held too where this says they may come back
        #: (slots → bool per slot, asked once as they leave; an FCD replay: not on their route's
        #: last edge, sim/fcd_stops.may_return — a collision's teleport of a moving car); None: none
        self.may_return = None
        #: vehicles written out by :meth:`flush` (all, and the accounted ones), their vTypes
        self.flushed_vehicles = 0
        self.flushed_kept = 0
        self.flushed_types: set[str] = set()
        #: most vehicles held in memory at once
        self.peak_held = 0
        #: vClass labels in the order vehicles of them were first registered (veh_cls indexes it)
        self.class_list: list[str] = []
        #: vClass label → the vTypes of its accounted vehicles, in the order first seen
        self.class_vtypes: dict[str, dict[str, None]] = {}
        #: the trajectories' driving dynamics against real driving (EU RDE)
        self.dynamics = Dynamics()

    def _edges(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Edge energies (edges, 2, E, C), distances, times, and distances and times per
        equation (edges, E) of the vehicles it applies to: closed plus open segments."""
        if self._edge_cache is None:
            energy, dist = self._edge_closed.copy(), self._edge_dist_closed.copy()
            etime = self._edge_time_closed.copy()
            dist_eq, time_eq = self._edge_dist_eq_closed.copy(), self._edge_time_eq_closed.copy()
            n = self.n_veh
            open_ = np.flatnonzero(self.veh_prev_edge[:n] >= 0)
            e = self.veh_prev_edge[open_]
            np.add.at(energy, e, self._veh_energy[open_] - self._seg_energy[open_])
            np.add.at(dist, e, self.veh_dist[open_] - self._seg_dist[open_])
            np.add.at(dist_eq, e, self.veh_dist_eq[open_] - self._seg_dist_eq[open_])
            np.add.at(etime, e, self.veh_time[open_] - self._seg_time[open_])
            np.add.at(time_eq, e, self.veh_time_eq[open_] - self._seg_time_eq[open_])
            self._edge_cache = (energy, dist, etime, dist_eq, time_eq)
        return self._edge_cache

    @property
    def edge_dist_eq(self) -> np.ndarray:
        """Distance driven per edge by the vehicles each equation applies to [m], (edges, E)."""
        return self._edges()[3]

    @property
    def edge_time_eq(self) -> np.ndarray:
        """Vehicle-seconds per edge of the vehicles each equation applies to [s], (edges, E):
        standing ones too (an equation with vehicles on an edge that drove none of it)."""
        return self._edges()[4]

    @property
    def edge_time(self) -> np.ndarray:
        """Vehicle-seconds spent per edge [s] (SUMO's ``sampledSeconds``), (edges,)."""
        return self._edges()[2]

    def snapshot(self, t: float) -> None:
        """Keep the cumulative edge totals at time ``t`` [s] (an interval boundary)."""
        energy, dist, etime, dist_eq, time_eq = self._edges()
        if self.chain is not None:
            self.chain.snapshot(t)
        self.snapshots.append((float(t), energy.copy(), dist_eq.copy(), etime.copy(),
                               self.edge_count.copy(), self.edge_entered.copy(),
                               self.edge_teleports.copy(), self.edge_tele.copy(), time_eq.copy()))

    @property
    def edge_trac(self) -> np.ndarray:
        """Traction energy per edge, equation, category [J], (edges, E, C)."""
        return self._edges()[0][:, 0]

    @property
    def edge_recup(self) -> np.ndarray:
        """Recuperable energy per edge, equation, category [J], (edges, E, C)."""
        return self._edges()[0][:, 1]

    @property
    def edge_dist(self) -> np.ndarray:
        """Distance driven per edge [m], (edges,)."""
        return self._edges()[1]

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
        grow("_seg_energy", (cap, 2, E, C))  # running totals when the edge was entered
        grow("_seg_dist", (cap,))
        grow("_seg_time", (cap,))
        grow("veh_dist", (cap,))
        grow("veh_time", (cap,))
        # per equation: the distance [m] and time [s] driven while it applied (a vType changed
        # in the trip: each equation its own part), and whether it ever applied
        grow("veh_dist_eq", (cap, E))
        grow("veh_time_eq", (cap, E))
        grow("veh_app_seen", (cap, E), bool, False)
        grow("_seg_dist_eq", (cap, E))  # veh_dist_eq when the edge was entered
        grow("_seg_time_eq", (cap, E))  # veh_time_eq when the edge was entered
        grow("veh_mass", (cap,), float, np.nan)
        grow("veh_load", (cap,), float, 0.0)  # riding persons [kg]
        grow("veh_app", (cap, E))
        grow("veh_keep", (cap,), bool, False)
        grow("veh_prev_edge", (cap,), np.int64, -1)
        grow("veh_prev_speed", (cap,), float, np.nan)
        grow("veh_prev_angle", (cap,), float, np.nan)  # SUMO's angle a step ago [deg]
        grow("veh_lane", (cap,), np.int64, -2)  # tracked lane (-2: never read)
        grow("veh_pos", (cap,), float, np.nan)  # tracked lane position [m]
        grow("veh_at", (cap, 4), float, np.nan)  # last step's lane, position, profile z, rise not yet booked
        grow("veh_done", (cap,), bool, False)  # left the simulation, not yet flushed
        grow("veh_done_step", (cap,), np.int64, 0)  # the step it left at
        grow("veh_may_return", (cap,), bool, False)  # left where it may come back (may_return)
        grow("veh_joined", (cap,), bool, False)  # on the road when the booking began (not departing)
        grow("veh_parked", (cap,), bool, False)  # parked off the lane: not read, not booked
        grow("veh_stand", (cap,), float, 0.0)  # standing since [s] (sim/shutoff.py)
        grow("veh_auto_off", (cap,), float, np.inf)  # its vType's shutOffAutoDuration [s]
        grow("veh_teleports", (cap,), np.int64, 0)  # teleports it ended (sim/teleport.py)
        grow("veh_tele", (cap, E, 2))  # their [kinetic, potential] energy jumps [J]
        grow("veh_rde", (cap, 4), float, np.nan)  # its last two 1-Hz samples (sim/dynamics.py)
        grow("veh_cls", (cap,), np.int64, -1)  # its vClass label's place in class_list
        self.capacity = cap

    #: per-vehicle arrays and their empty value (what :meth:`flush` compacts)
    _VEH_ARRAYS = (("_veh_energy", 0.0), ("_seg_energy", 0.0), ("_seg_dist", 0.0),
                   ("_seg_time", 0.0), ("veh_dist", 0.0), ("veh_time", 0.0),
                   ("veh_dist_eq", 0.0), ("veh_time_eq", 0.0), ("veh_app_seen", False), ("_seg_dist_eq", 0.0),
                   ("_seg_time_eq", 0.0),
                   ("veh_mass", np.nan), ("veh_load", 0.0), ("veh_app", 0.0),
                   ("veh_keep", False),
                   ("veh_prev_edge", -1), ("veh_prev_speed", np.nan), ("veh_prev_angle", np.nan),
                   ("veh_lane", -2),
                   ("veh_pos", np.nan), ("veh_at", np.nan), ("veh_done", False), ("veh_done_step", 0), ("veh_may_return", False),
                   ("veh_joined", False),
                   ("veh_parked", False),
                   ("veh_stand", 0.0), ("veh_auto_off", np.inf), ("veh_teleports", 0),
                   ("veh_tele", 0.0), ("veh_rde", np.nan), ("veh_cls", -1))

    def add_vehicle(self, vid: str, vtype: str, mass: float, app: np.ndarray,
                    keep: bool, vclass: str = "") -> int:
        """Register a vehicle; returns its index."""
        if self.n_veh >= self.capacity:
            self._alloc(2 * self.capacity)
        i = self.n_veh
        self.veh_ids.append(vid)
        self.veh_type.append(vtype)
        self.veh_class.append(vclass)
        self.veh_mass[i] = mass
        self.veh_load[i] = 0.0
        self.veh_parked[i] = False
        self.veh_at[i] = np.nan
        self.veh_stand[i] = 0.0
        self.veh_auto_off[i] = np.inf
        self.veh_rde[i] = np.nan
        self.set_app(i, app)
        self.veh_keep[i] = keep
        if keep and self.chain is not None and self.chain.active and not np.any(np.asarray(app)[self.chain.active]):
            self.chainless[vclass or "unknown"] = self.chainless.get(vclass or "unknown", 0) + 1
            self.chainless_vtypes[vtype] = self.chainless_vtypes.get(vtype, 0) + 1
        self.n_veh += 1
        if self.n_veh > self.peak_held:
            self.peak_held = self.n_veh
        label = vclass or "unknown"
        if keep:
            self.class_vtypes.setdefault(label, {})[vtype] = None
        if label not in self.class_list:
            self.class_list.append(label)
        self.veh_cls[i] = self.class_list.index(label)
        return i

    def set_app(self, i: int, app) -> None:
        """The equations that apply to vehicle ``i`` from now (0/1 per equation): at its
        registration, and when its vType changes in the trip."""
        new = np.asarray(app, float)
        e = self.veh_prev_edge[i]
        if e >= 0:  # changed on an edge: the equations new to it count it there
            self.edge_count[e] += np.maximum(new - self.veh_app[i], 0.0)
            self._edge_cache = None
        self.veh_app[i] = new
        self.veh_app_seen[i] |= new > 0

    @property
    def vehicles_total(self) -> int:
        """Accounted vehicles of the run: held in memory plus flushed."""
        return int(np.count_nonzero(self.veh_keep[:self.n_veh])) + self.flushed_kept

    @property
    def types_seen(self) -> set[str]:
        """vTypes of every vehicle registered in the run."""
        return set(self.veh_type[:self.n_veh]) | self.flushed_types

    def booked_mass(self, vi: np.ndarray, ei: np.ndarray) -> np.ndarray:
        """The mass [kg] each (vehicle slot ``vi``, equation ``ei``) was booked at: the
        equation's own fixed mass (a MOVES source mass, SUMO's Energy-model mass of a
        ``vtype_energy``: :attr:`eq_mass`, set by the loop), else the vehicle's (as it ended
        its trip, riders included)."""
        veh = self.veh_mass[vi]
        fixed = getattr(self, "eq_mass", None)
        if fixed is None or len(fixed) == 0:
            return veh
        own = np.asarray(fixed, float)[ei]
        return np.where(np.isfinite(own), own, veh)

    def retire(self, slots, at_end: bool = False) -> None:
        """Mark vehicles ``slots`` as gone (arrived, removed; ``at_end``: on the road when the
        run ended, flushed all the same: step -1, :meth:`on_road_at_end`); flushed by :meth:`flush`."""
        slots = np.asarray(slots, np.int64)
        new = slots[~self.veh_done[slots]]
        self.veh_done[new] = True
        self.veh_done_step[new] = -1 if at_end else self.steps
        self.veh_may_return[new] = False if at_end or self.may_return is None else self.may_return(new)
        self.n_done += len(np.unique(new))

    def on_road_at_end(self, slots) -> np.ndarray:
        """Whether vehicles ``slots`` were still driving when the run (or the recording) ended."""
        return ~self.veh_done[slots] | (self.veh_done_step[slots] == -1)

    def _flushable(self) -> np.ndarray:
        """Finished vehicles that may leave memory: all but those that left standing (last
        speed ≤ :data:`HALTING_SPEED_MPS`, as a car stuck in a jam when SUMO teleports it) or
        where :attr:`may_return` said they may come back, less than :attr:`hold_steps` ago."""
        n = self.n_veh
        done = self.veh_done[:n]
        if self.hold_steps > 0:
            done = done & ~((self.veh_done_step[:n] > self.steps - self.hold_steps)
                            & ((self.veh_prev_speed[:n] <= HALTING_SPEED_MPS) | self.veh_may_return[:n]))
        return done

    def unretire(self, i: int) -> None:
        """A vehicle back in an FCD replay after steps without its rows (a teleport): it
        books on in the same row."""
        if self.veh_done[i]:
            self.veh_done[i] = False
            self.n_done -= 1

    def flush_due(self) -> bool:
        if self.spill is None or self.n_done < self.flush_vehicles:
            return False
        return self.hold_steps <= 0 or int(np.count_nonzero(self._flushable())) >= self.flush_vehicles

    def _close_segments(self, vo: np.ndarray) -> None:
        """Add the open edge segments of vehicles ``vo`` (on an edge) to the closed totals."""
        old = self.veh_prev_edge[vo]
        np.add.at(self._edge_closed, old, self._veh_energy[vo] - self._seg_energy[vo])
        np.add.at(self._edge_dist_closed, old, self.veh_dist[vo] - self._seg_dist[vo])
        np.add.at(self._edge_dist_eq_closed, old, self.veh_dist_eq[vo] - self._seg_dist_eq[vo])
        np.add.at(self._edge_time_closed, old, self.veh_time[vo] - self._seg_time[vo])
        np.add.at(self._edge_time_eq_closed, old, self.veh_time_eq[vo] - self._seg_time_eq[vo])

    def flush(self) -> np.ndarray | None:
        """Write the finished vehicles (those finished :attr:`hold_steps` ago) to
        :attr:`spill` and drop them from memory.

        Returns the slot map old → new (−1: flushed) for the caller's id → slot table, or
        None when nothing was finished. Edge totals are unchanged (the open segments of the
        leaving vehicles are closed first); the finished rows go out in slot order.
        """
        n = self.n_veh
        done = self._flushable()
        gone = np.flatnonzero(done)
        if len(gone) == 0:
            return None
        on_edge = gone[self.veh_prev_edge[gone] >= 0]
        if len(on_edge):
            self._close_segments(on_edge)
            self.veh_prev_edge[on_edge] = -1
        self._edge_cache = None
        if self.spill is not None:
            self.spill.write(self, gone)
        if self.chain is not None:
            self.chain.flush(gone, [self.veh_class[i] or "unknown" for i in gone],
                             [self.veh_ids[i] for i in gone], self.spill)
        self.flushed_vehicles += len(gone)
        self.flushed_kept += int(np.count_nonzero(self.veh_keep[gone]))
        self.flushed_types.update(self.veh_type[i] for i in gone)
        keep = np.flatnonzero(~done)
        m = len(keep)
        for name, fill in self._VEH_ARRAYS:
            arr = getattr(self, name)
            arr[:m] = arr[keep]
            arr[m:n] = fill
        for name in ("veh_ids", "veh_type", "veh_class"):
            old = getattr(self, name)
            setattr(self, name, [old[i] for i in keep])
        if self.chain is not None:
            self.chain.compact(keep, n)
        remap = np.full(n, -1, np.int64)
        remap[keep] = np.arange(m)
        self.n_veh, self.n_done = m, int(np.count_nonzero(self.veh_done[:m]))  # held ones stay
        return remap

    def book(self, vidx: np.ndarray, eidx: np.ndarray, v: np.ndarray, dt: float,
             pc: np.ndarray, app: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Book one step for vehicles ``vidx`` on edges ``eidx``.

        Parameters
        ----------
        vidx, eidx : vehicle and edge numbers (each vehicle once)
        v : speed [m/s]
        dt : step length [s]
        pc : power per vehicle, equation, category [W], (n, E, C), already zero where an
             equation does not apply to a vehicle
        app : the vehicles' ``veh_app[vidx]`` where the caller has it (None: read here)

        Returns traction and recuperable energies [J] of the step, (n, E, C) each.
        """
        E, C = self.E, self.C
        n = len(vidx)
        pct = pc.transpose(1, 2, 0)  # (E, C, n): contiguous when pc is from EquationSet
        split = np.empty((2, E, C, n))  # [traction, recuperable] energies of the step
        energy = np.multiply(pct, dt, out=split[1])
        pos = energy.sum(axis=1) > 0.0
        np.multiply(energy, pos[:, None, :], out=split[0])
        split[1] -= split[0]
        self._edge_cache = None
        enter = eidx != self.veh_prev_edge[vidx]
        if enter.any():  # close the segments on the edges left, open new ones
            vi = vidx[enter]
            old = self.veh_prev_edge[vi]
            had = old >= 0
            if had.any():
                self._close_segments(vi[had])
            self._seg_energy[vi] = self._veh_energy[vi]
            self._seg_dist[vi] = self.veh_dist[vi]
            self._seg_dist_eq[vi] = self.veh_dist_eq[vi]
            self._seg_time[vi] = self.veh_time[vi]
            self._seg_time_eq[vi] = self.veh_time_eq[vi]
            self.veh_prev_edge[vi] = eidx[enter]
            np.add.at(self.edge_count, eidx[enter], self.veh_app[vi])
            np.add.at(self.edge_entered, eidx[enter], 1.0)
        # one scatter-add of the vehicle rows: the per-call overhead, not the arithmetic,
        # dominates at a few thousand vehicles
        self._veh_energy[vidx] += split.transpose(3, 0, 1, 2)
        d = v * dt
        self.veh_dist[vidx] += d
        self.veh_time[vidx] += dt
        app = self.veh_app[vidx] if app is None else app
        self.veh_dist_eq[vidx] += d[:, None] * app
        self.veh_time_eq[vidx] += dt * app
        self.samples += n
        return split[0].transpose(2, 0, 1), split[1].transpose(2, 0, 1)
