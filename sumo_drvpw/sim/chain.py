"""Battery and fuel accounts of a SUMO run: the energy chain booked per vehicle, edge and class.

Each step, the driving power of every vehicle under every equation (what the SUMO loop
already computes for the road-load ledger) goes through that equation's energy chain
(:class:`sumo_drvpw.model.chain.EnergyChain`, one vectorized evaluation per equation and
step) and is booked in quantities a user pays for::

    traction_j, recuperated_j (≤ 0), auxiliary_j, net_j    battery chains [J]
    fuel_j (LHV), fuel_l [L], co2_kg [kg]                    fuel chains
    cold_start_l [L]                                         fuel chains: the part of fuel_l
                                                             that cold starts took

Auxiliary power accrues at every step a vehicle is in the network, standing or driving.
With ``cold_start`` (the scenario's ``[vehicles] cold_start``, a share of the trips, or
``[vtypes.<id>] cold_start`` / ``[vclasses.<vClass>] cold_start`` for some vehicles, or a
vehicle's, trip's or flow's own ``drvpw.cold_start`` param in the route files) a fuel
chain's ``cold_start_fuel_l`` — and a battery chain's cabin warm-up, ``[chain.hvac]
warmup_j_per_k`` × (T_set − T)⁺, as auxiliary energy — times the vehicle's share is booked
for each vehicle that departs while the run accounts, spread over its first minutes as a
rate decaying from its departure, share · V · (e^(−t/τ) − e^(−(t+Δt)/τ)) in the step from t
to t + Δt of its booked time (τ: constants.FUEL_COLD_START_TAU_S, CABIN_WARMUP_TAU_S), on
the edges it drives then: a trip of T seconds takes V · (1 − e^(−T/τ)), a trip much longer
than τ the whole cold start, a 60-s hop not the energy of a whole warm-up. Vehicles already
on the road when accounting starts (a user's TraCI script attaching mid-run) get none.
Vehicles' running totals take one scatter-add per step, edges one ``np.add.at``; class totals
are sums of the vehicle totals, so vehicle, edge and class totals agree by construction
(tests check it on a real SUMO run, with the per-step sums).
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.model.constants import CABIN_WARMUP_TAU_S, FUEL_COLD_START_TAU_S, T_REF_C
from sumo_drvpw.model.mmpevem import evaluate_where
from sumo_drvpw.sim.chain_tables import KWH, ChainTables

#: a cold start is booked until this many decay times after the departure (e^−20: all of it)
COLD_DONE = 20.0
#: Quantities booked per vehicle/edge and equation, in this order (units in the names).
QUANTITIES = ("traction_j", "recuperated_j", "auxiliary_j", "net_j", "fuel_j", "fuel_l", "co2_kg",
              "cold_start_l")
#: quantity columns a fuel chain books (QUANTITIES indices), and a battery chain
FUEL_COLS, BATTERY_COLS = (4, 5, 6, 7), (0, 1, 2, 3)


class ChainLedger(ChainTables):
    """Accumulators of chain quantities (vehicles × equations × quantities, edges × …).

    Parameters
    ----------
    names : equation names, in the order of the driving powers given to :meth:`book`
    chains : each equation's chain, or None (that equation books nothing here)
    n_edges : number of edges
    cold_start : the share of departing vehicles that start a cold engine (0 … 1; True: 1):
        each fuel chain books that share of its cold start from a vehicle's departure, as it
        decays (:meth:`start`, :meth:`book`), the expected fuel of a fleet of which that share
        starts cold
    cold_start_vtypes, cold_start_vclasses : shares for vehicles of these vTypes / vClasses,
        in place of ``cold_start`` (vType first; :meth:`share_of`)
    cold_start_vehicles, cold_start_flows : shares of single vehicles (vehicle id → share)
        and of a flow's vehicles (flow id → share, for ids ``<flow>.<n>``), the route
        files' own ``drvpw.cold_start`` params: these win over every other share
    """

    def __init__(self, names: list[str], chains: list[EnergyChain | None], n_edges: int,
                 capacity: int = 1024, signal_values: dict | None = None, cold_start: float = 0.0,
                 cold_start_vtypes: dict | None = None, cold_start_vclasses: dict | None = None,
                 cold_start_vehicles: dict | None = None, cold_start_flows: dict | None = None):
        #: constant values of the chains' signals (loads, ambient temperature) in SUMO,
        #: which has no such columns; a load not given is taken as 0 and listed in
        #: :attr:`assumed_zero` (a logged heater or A/C load then adds nothing)
        self.signal_values = dict(signal_values or {})
        self.assumed_zero: set[str] = set()
        self.names = list(names)
        self.chains = list(chains)
        self.active = [i for i, c in enumerate(self.chains) if c is not None and c.predicts != "wheel"]
        #: the chains' HVAC temperature columns (any name): in SUMO each reads the run's air
        #: temperature, ``signal_values["ambient_c"]``, else T_REF_C (20 °C, that of ρ = 1.2041
        #: kg/m³ and the ``cold`` reference), and :attr:`air_temperature_assumed` says so
        self.hvac_columns = {self.chains[i].temperature_column
                             for i in self.active if self.chains[i].hvac}
        #: the same for the temperature of warm-running fuel factors (running_fuel_per_k)
        self.running_columns = {self.chains[i].temperature_column for i in self.active
                                if self.chains[i].running_fuel_per_k}
        self._running_active = [j for j, e in enumerate(self.active) if self.chains[e].running_fuel_per_k]
        self.air_temperature_c = float(self.signal_values.get("ambient_c", T_REF_C))
        self._hvac_active = [j for j, e in enumerate(self.active) if self.chains[e].hvac]
        self._reads_accel, self._motor = (any(self.chains[e].reads_accel for e in self.active),
                                          {e for e in self.active if self.chains[e].motor is not None})
        #: per equation: vehicle-steps its SUMO MMPEVEM motor could not serve (beyond its torque or
        #: power, off its loss map), where SUMO writes nan and the chain books the motor's limits
        self.motor_invalid = np.zeros(len(self.names), np.int64)
        #: per equation: [vehicle-steps, J] of engine output demanded beyond its rated output (engine_max_w)
        self.over_engine = np.zeros((len(self.names), 2))
        self.E, self.Q = len(self.names), len(QUANTITIES)
        #: (equation, quantity) columns a chain books: battery 0–3, fuel 4–7
        self._cols = [(e, k) for e in self.active for k in self._booked(e)]
        self._ce = np.array([e for e, _ in self._cols], np.int64)
        self._ck = np.array([k for _, k in self._cols], np.int64)
        # compact storage: only the booked columns, (rows, C); veh/edge expand on read
        self._edge = np.zeros((n_edges, len(self._cols)))
        #: distance [m] per edge and active chain equation (``active`` order), by the vehicles
        #: it applies to: its per-km figures count those (petrol litres over petrol cars' km)
        self.A = len(self.active)
        self.edge_dist = np.zeros((n_edges, self.A))
        self._veh = np.zeros((capacity, len(self._cols)))
        #: per vehicle row and active chain equation: distance [m] and time [s] it drove
        #: while the equation applied (a vType changed in the trip: each its own part), and
        #: whether it ever applied (:meth:`vehicle_dist`, :meth:`vehicle_time`)
        self.veh_dist = np.zeros((capacity, self.A))
        self.veh_time = np.zeros((capacity, self.A))
        self._app = np.zeros((capacity, self.A), bool)
        #: which active chain equations booked any vehicle so far
        self.booked_any = np.zeros(self.A, bool)
        #: cumulative edge totals at interval boundaries [(time [s], (edges, E, Q))]
        self.snapshots: list[tuple[float, np.ndarray]] = []
        #: totals of vehicles flushed out of memory (Ledger.flush): class → [(E, Q), m]
        self.flushed_class: dict[str, list] = {}
        #: share of the departing vehicles whose cold start is booked (0: none), for vehicles
        #: whose vType or vClass has no share of its own
        self.cold_start = float(cold_start)
        self.cold_start_vtypes = {str(k): float(v) for k, v in (cold_start_vtypes or {}).items()}
        self.cold_start_vclasses = {str(k): float(v) for k, v in (cold_start_vclasses or {}).items()}
        self.cold_start_vehicles = {str(k): float(v) for k, v in (cold_start_vehicles or {}).items()}
        self.cold_start_flows = {str(k): float(v) for k, v in (cold_start_flows or {}).items()}
        #: any vehicle may start cold: cold starts are booked and reported (``cold_start_l``)
        self.cold_start_on = self.cold_start > 0 or any(
            v > 0 for d in (self.cold_start_vtypes, self.cold_start_vclasses, self.cold_start_vehicles,
                            self.cold_start_flows) for v in d.values())
        #: one cold start's quantities per booked column at the run's air temperature, (C,)
        self._cs = np.zeros(len(self._cols))
        for j, (e, k) in enumerate(self._cols):
            cs = self.chains[e].cold_start(self.air_temperature_c)
            self._cs[j] = {2: cs["battery_j"], 3: cs["battery_j"], 4: cs["fuel_j"], 5: cs["fuel_l"],
                           6: cs["co2_kg"], 7: cs["fuel_l"]}.get(k, 0.0)
        #: the booked columns of fuel chains, and the decay time of each one's cold start [s], (C,)
        self._fuel_cols = np.array([self.chains[e].predicts == "fuel" for e, _ in self._cols], bool)
        self._tau = np.where(self._fuel_cols, FUEL_COLD_START_TAU_S, CABIN_WARMUP_TAU_S)
        #: per vehicle row: its share of a cold start while that is being booked (0: none
        #: or done), the time booked since it began [s], and whether it is yet to be counted
        self._starting = np.zeros(capacity)
        self._cold_age = np.zeros(capacity)
        self._cold_new = np.zeros(capacity, bool)
        #: per vehicle row and active chain equation: the energy a hybrid's battery window holds
        #: [J] (``battery_usable_j``: model/chain_buffer.py), carried from step to step
        self._bounded = {e for e in self.active if self.chains[e].battery_usable_j is not None
                         and self.chains[e].recuperation_round_trip}
        self._stored = np.zeros((capacity, self.A))
        #: the same for a plug-in hybrid's battery energy spent ([chain.depleting]: model/chain_plugin.py)
        self._spent = np.zeros((capacity, self.A))
        self.charges = None  #: the charges at departure that vehicles declare (sim/chain_charge.py), or None
        #: per step, what does not change between steps (a live run books a few vehicles a step,
        #: where per-call overhead dominates): the chains' signals, each active chain's
        #: (row, equation, chain, output keys, which keys an engine switched off zeroes, its
        #: battery states), the constant signals' values (:meth:`_constant_signals`)
        self._signal_set = set().union(*(self.chains[i].signals for i in self.active)) if self.active else set()
        self._plan, j = [], 0
        for a, e in enumerate(self.active):  # (… and its first booked column)
            self._plan.append((a, e, self.chains[e], *self._keys(e), j))
            j += len(self._plan[-1][3])
        self._active = np.array(self.active, np.int64)
        self._const: dict[str, np.ndarray] = {}
        self._const_n = -1
        self._const_views: dict[int, dict] = {}  # n → the n-vehicle views (:meth:`_constant_signals`)
        self._apps: dict = {}  # a few vehicles' app → what it gives (:meth:`_by_app`)
        #: departures booked (share of a cold start > 0) by a chain with one; their shares' sum
        self.cold_starts = 0
        self.cold_starts_expected = 0.0

    def _keys(self, e: int) -> tuple:
        """Chain ``e``'s output keys in its booked columns' order (None: booked at departures
        only), whether an engine switched off zeroes each, its battery states' keys, and every
        output a step reads of it (those, ``invalid``, ``over_engine_j``)."""
        ch = self.chains[e]
        keys = (("power_j", "fuel_l", "co2_kg", None) if ch.predicts == "fuel" else
                ("traction_j", "recuperated_j", "auxiliary_j", "power_j"))
        if ch.predicts == "fuel" and ch.depleting is not None:  # (FUEL_COLS, then BATTERY_COLS)
            keys += ("battery_traction_j", "battery_recuperated_j", "battery_auxiliary_j", "battery_j")
        off = tuple(k is not None and ch.predicts == "fuel" and not k.startswith("battery") for k in keys)
        state = tuple(key for key, on_ in (("stored_j", e in self._bounded),
                                           ("spent_j", ch.predicts == "fuel" and ch.depleting is not None)) if on_)
        return keys, off, state, frozenset(k for k in keys + state if k) | {"invalid", "over_engine_j"}

    def _booked(self, e: int) -> tuple:
        """The quantity columns chain ``e`` books: a fuel chain's, and a plug-in hybrid's battery too."""
        ch = self.chains[e]
        return BATTERY_COLS if ch.predicts != "fuel" else FUEL_COLS + (BATTERY_COLS if ch.depleting else ())

    def plug_in(self, e: int) -> bool:
        """Whether chain ``e`` is a plug-in hybrid's: fuel and battery columns."""
        return self.chains[e].predicts == "fuel" and self.chains[e].depleting is not None

    @property
    def signals(self) -> set[str]:
        """Vehicle signals the chains read (logged loads have no SUMO source: give them as
        constants per vehicle, or leave them out of chains used in SUMO)."""
        return set(self._signal_set)

    def expand(self, compact: np.ndarray) -> np.ndarray:
        """(rows, C) booked columns → (rows, E, Q), zeros where a chain books nothing."""
        out = np.zeros((compact.shape[0], self.E, self.Q))
        out[:, self._ce, self._ck] = compact
        return out

    @property
    def veh(self) -> np.ndarray:
        """Running totals per vehicle, equation and quantity, (capacity, E, Q)."""
        return self.expand(self._veh)

    @property
    def air_temperature_assumed(self) -> bool:
        """A chain with HVAC or a warm-running fuel factor, or a booked cold start that depends
        on the temperature, booked a vehicle and the run gave no air temperature."""
        if "ambient_c" in self.signal_values:
            return False
        cold = [j for j, e in enumerate(self.active)
                if self.cold_start_on and self.chains[e].predicts == "fuel" and self.chains[e].cold_start_fuel_l_per_k]
        return bool(self.booked_any[self._hvac_active + self._running_active + cold].any())

    def warm_running(self) -> dict:
        """Per chain with a warm-running fuel factor: its share per kelvin, reference and the
        factor at the run's air temperature (:meth:`EnergyChain.running_factor`)."""
        out = {}
        for e in self.active:
            ch = self.chains[e]
            if ch.running_fuel_per_k:
                t = float(self.signal_values.get(ch.temperature_column, self.air_temperature_c))
                out[self.names[e]] = {"per_k": ch.running_fuel_per_k, "ref_c": ch.cold_start_ref_c,
                                      "factor": round(float(ch.running_factor(1, {ch.temperature_column: t})[0]), 9)}
        return out

    def booked(self, name: str) -> int:
        """Column of equation ``name`` in :meth:`vehicle_dist`, :meth:`vehicle_time`, :attr:`edge_dist`."""
        return self.active.index(self.names.index(name))

    def vehicle_dist(self, n: int) -> np.ndarray:
        """Distance [m] each of the first ``n`` vehicle rows drove under each active chain
        equation (0 where it does not apply), (n, A)."""
        self._grow(n)
        return self.veh_dist[:n]

    def vehicle_time(self, n: int) -> np.ndarray:
        """Time [s] each of the first ``n`` vehicle rows was booked by each active chain
        equation, (n, A)."""
        self._grow(n)
        return self.veh_time[:n]

    @property
    def edge(self) -> np.ndarray:
        """Totals per edge, equation and quantity, (edges, E, Q)."""
        return self.expand(self._edge)

    def _grow(self, n: int) -> None:
        cap = len(self.veh_dist)
        if n <= cap:
            return
        new = max(n, 2 * cap)
        for k in ("_veh", "veh_dist", "veh_time", "_app", "_starting", "_cold_age", "_cold_new", "_stored", "_spent"):
            x = getattr(self, k)
            setattr(self, k, np.concatenate([x, np.zeros((new - cap, *x.shape[1:]), x.dtype)]))

    def share_of(self, vtype: str, vclass: str, vid: str | None = None) -> float:
        """The share of a cold start a vehicle of this vType and vClass books from its departure:
        its own (vehicle ``vid``'s, else its flow's: the route files' param), else its
        vType's, else its vClass's, else the run's :attr:`cold_start`."""
        if vid is not None and (self.cold_start_vehicles or self.cold_start_flows):
            if vid in self.cold_start_vehicles:
                return self.cold_start_vehicles[vid]
            flow, dot, n = vid.rpartition(".")
            if dot and n.isdigit() and flow in self.cold_start_flows:
                return self.cold_start_flows[flow]
        if vtype in self.cold_start_vtypes:
            return self.cold_start_vtypes[vtype]
        return self.cold_start_vclasses.get(vclass, self.cold_start)

    def set_vehicle_share(self, vid: str, share: float) -> None:
        """Vehicle ``vid``'s own cold-start share (0–1, checked by the caller), as a route
        file's param gives one; cold starts are booked from now on if it is above 0."""
        self.cold_start_vehicles[str(vid)] = float(share)
        self.cold_start_on = self.cold_start_on or share > 0

    def depart(self, vidx, ids, veh_type, veh_class) -> None:
        """Vehicle rows ``vidx`` (ids ``ids``) departed this step: :meth:`start` with each
        one's :meth:`share_of` (its vType and vClass from the row arrays given)."""
        self.start(vidx, [self.share_of(veh_type[i], veh_class[i], vid) for i, vid in zip(vidx, ids)])

    def start(self, vidx, shares=None) -> None:
        """Vehicle rows ``vidx`` departed this step: from their next booked step on, each
        chain's cold start times ``shares`` (one per vehicle; default :attr:`cold_start`) is
        booked as it decays (:meth:`book`)."""
        if not self.cold_start_on or not self._cs.any():
            return
        vidx = np.asarray(vidx, np.int64)
        if vidx.size:
            self._grow(int(vidx.max()) + 1)
            self._starting[vidx] = self.cold_start if shares is None else np.asarray(shares, float)
            self._cold_age[vidx] = 0.0
            self._cold_new[vidx] = True

    def step_quantities(self, p_drive_w: np.ndarray, v: np.ndarray, dt: float,
                        signals: dict | None = None, engine_off=None, v_mean=None, app=None,
                        vidx=None, by=None) -> np.ndarray:
        """Chain quantities of one step, (n vehicles, C booked columns) (:meth:`expand` gives
        (n, E, Q)); each chain is evaluated only where ``app`` (n, E) > 0 (zeros elsewhere,
        and not at all in a step none of its vehicles is in: a bare config's thirteen
        built-in chains each book one kind of vehicle).

        Parameters
        ----------
        p_drive_w : driving power per vehicle and equation [W], (n, E)
        v : speed [m/s], (n,)
        dt : step length [s]
        signals : column → (n,) arrays for the chains' loads and HVAC temperature
        engine_off : optional (n,) bool: engines a start-stop system switched off: no fuel
        vidx : the vehicles' rows: a hybrid's battery window is carried in them from step to step
            (None: each step from an empty battery, nothing kept)
        by : what ``app`` gives (:meth:`_by_app`) where the caller has it already (:meth:`book`)
        """
        p = np.asarray(p_drive_w, float)
        n = p.shape[0]
        q = np.zeros((n, len(self._cols)))
        # the chains of the step's vehicles only (a bare config's thirteen: one or two a step)
        if app is not None and by is None:
            by = self._by_app(np.asarray(app, float), dt)
        on, plan = (None, self._plan) if app is None else by[:2]
        for a, e, ch, keys, zero_off, states, read, j in plan:
            sel = None if on is None else on[:, e]
            vv = v if v_mean is None or e not in self._motor else v_mean
            # each vehicle's battery: a hybrid's window, a plug-in's energy spent
            state = {key: np.zeros(n) if vidx is None else (self._stored if key == "stored_j" else self._spent)[vidx, a]
                     for key in states}
            out = (evaluate_where(ch, sel, p[:, e], vv, dt, signals, read, **state)
                   if sel is not None else ch.evaluate(p[:, e], vv, dt, signals, **state))
            if vidx is not None:
                keep = slice(None) if sel is None else sel
                for key in state:
                    (self._stored if key == "stored_j" else self._spent)[vidx[keep], a] = out[key][keep]
            if "invalid" in out:
                self.motor_invalid[e] += int(np.count_nonzero(out["invalid"]))
            if "over_engine_j" in out:  # not delivered: the vType accelerates or climbs beyond its engine
                self.over_engine[e] += over_engine(out["over_engine_j"], engine_off)
            for key, z in zip(keys, zero_off):
                if key is not None:  # cold_start_l: booked at departures only (book)
                    q[:, j] = out[key]
                    if engine_off is not None and z:
                        q[engine_off, j] = 0.0
                j += 1
        return q

    def book(self, vidx: np.ndarray, eidx: np.ndarray, v: np.ndarray, dt: float,
             p_drive_w: np.ndarray, signals: dict | None = None, app=None, engine_off=None,
             accel=None, v_mean=None, grade=None, load=None) -> np.ndarray:
        """Book one step for vehicles ``vidx`` (each once) on edges ``eidx``; returns the
        step's quantities (n, C) (:meth:`expand` → (n, E, Q)). ``app`` (n, E): 1 where an
        equation applies to the vehicle, 0 where not (nothing booked, not even auxiliary
        power); ``engine_off`` (n,): no fuel (:meth:`step_quantities`); ``accel`` (n,): the
        step's acceleration [m/s²] (signal ``accel_mps2``); ``v_mean``, ``grade``, ``load`` (n,): the step's
        mean speed, grade [rad] and riders' mass [kg], at which chains with SUMO's MMPEVEM motor book."""
        vidx = np.asarray(vidx, np.int64)
        if vidx.size:
            self._grow(int(vidx.max()) + 1)
        if signals is None:
            signals = self._constant_signals(len(vidx))
        if accel is not None and self._reads_accel:
            signals = {**signals, "accel_mps2": accel}
        if grade is not None and self._motor:
            signals = {**signals, "grade_rad": grade, **({} if load is None else {"load_kg": load})}
        by = None if app is None else self._by_app(np.asarray(app, float), dt)  # (once a step: not kept above 64)
        q = self.step_quantities(p_drive_w, v, dt, signals, engine_off, v_mean if self._motor else None, app,
                                 vidx, by)
        if self.cold_start_on:
            share = self._starting[vidx]
            s = share > 0
            if s.any():
                vs = vidx[s]
                age = self._cold_age[vs, None]
                part = np.exp(-age / self._tau) - np.exp(-(age + dt) / self._tau)
                if engine_off is not None:  # a start-stop system's engine off: no fuel, warm-up or not
                    part[np.ix_(np.asarray(engine_off, bool)[s], self._fuel_cols)] = 0.0
                q[s] += share[s, None] * self._cs * part
                self._cold_age[vs] += dt
                self._starting[vs[self._cold_age[vs] > COLD_DONE * self._tau.max()]] = 0.0
                # a departure counts when a chain with a cold start books the vehicle
                new = self._cold_new[vs]
                hit = new if app is None else new & \
                    (np.asarray(app)[s][:, self._ce[self._cs > 0]] > 0).any(axis=1)
                self._cold_new[vs] = False
                self.cold_starts += int(hit.sum())
                self.cold_starts_expected += float(share[s][hit].sum())
        if by is None:
            by = self._by_app(np.ones((len(vidx), len(self.names))), dt)
        _, _, app_ce, a, a_dt, booked, any_ = by
        q *= app_ce
        self._veh[vidx] += q
        d = np.asarray(v, float) * dt
        da = d[:, None] * a  # (each applying equation's distance of the step)
        self.veh_dist[vidx] += da
        self.veh_time[vidx] += a_dt
        self._app[vidx] |= booked
        self.booked_any |= any_
        # the edges the step's vehicles are on, once each: a bincount per column over those
        # (none for a chain without vehicles in this step), far cheaper than np.add.at, and
        # not over every edge of the network (at a few vehicles, that was most of a step)
        eidx = np.asarray(eidx, np.int64)
        if (len(set(eidx.tolist())) == len(eidx) if len(eidx) <= 64 else  # one vehicle per edge:
                bool((np.diff(np.sort(eidx)) != 0).all())):  # each edge's sum is 0 + its row
            self._edge[eidx] += q + 0.0
            self.edge_dist[eidx] += da + 0.0
            return q
        edges, at = np.unique(eidx, return_inverse=True)
        w = np.ascontiguousarray(np.concatenate([q, da], axis=1).T)
        c = q.shape[1]
        for j in np.flatnonzero(w.any(axis=1)):
            col = np.bincount(at, w[j], minlength=len(edges))
            if j < c:
                self._edge[edges, j] += col
            else:
                self.edge_dist[edges, j - c] += col
        return q

    def _by_app(self, app: np.ndarray, dt: float) -> tuple:
        """What a step's ``app`` (n, E) gives: ``app > 0``, the chains to evaluate, ``app`` per
        booked column and per active equation, that times ``dt``, whether each books, and whether
        any does; kept for the next step with the same (a few vehicles' app rarely changes)."""
        key = (app.shape, app.tobytes(), dt) if len(app) <= 64 else None  # (many: not kept)
        if (got := self._apps.get(key)) is None:
            on, a = app > 0, app[:, self._active]
            got = (on, [self._plan[i] for i in np.flatnonzero(on[:, self._active].any(axis=0))],
                   app[:, self._ce], a, dt * a, a > 0, (a > 0).any(axis=0))
            if key is not None:
                self._apps = {**(self._apps if len(self._apps) < 64 else {}), key: got}
        return got

    def snapshot(self, t: float) -> None:
        """Keep the cumulative edge totals at time ``t`` [s] (with :meth:`Ledger.snapshot`)."""
        self.snapshots.append((float(t), self.edge))

    def edge_attrs(self, q: np.ndarray, booked=None) -> list[str]:
        """edgeData attributes of one edge's quantities ``q`` (E, Q) of an interval:
        ``<eq>_battery_{traction,recuperated,auxiliary,net}_kwh`` or ``<eq>_fuel_l``,
        ``<eq>_co2_kg``; none for an equation that booked nothing there (``booked``: per
        equation, whether any vehicle of it was on the edge; None: all)."""
        out = []
        for e in self.active:
            n = self.names[e]
            if booked is not None and not booked[e] and not np.any(q[e]):
                continue
            if self.chains[e].predicts == "fuel":
                out += [f'{n}_fuel_l="{q[e, 5]:.6f}"', f'{n}_co2_kg="{q[e, 6]:.6f}"']
                if self.cold_start_on:
                    out.append(f'{n}_cold_start_l="{q[e, 7]:.6f}"')
            if self.chains[e].predicts != "fuel" or self.plug_in(e):
                out += [f'{n}_battery_{k}_kwh="{q[e, j] / KWH:.6f}"'
                        for j, k in enumerate(("traction", "recuperated", "auxiliary", "net"))]
        return out

    def _constant_signals(self, n: int) -> dict:
        """The chains' signals as n constants (views of read-only arrays kept between steps; the
        dict of them too, per n: its readers take it as it is)."""
        got = self._const_views.get(n)
        if got is not None:
            return got
        if self._const_n < n:
            self._const_views = {}
            self._const, m = {}, max(n, 64, 2 * self._const_n)
            self._const_n = m
            for s in self._signal_set:
                if s in self.signal_values:
                    x = np.full(m, float(self.signal_values[s]))
                elif s in self.hvac_columns or s in self.running_columns:
                    x = np.full(m, self.air_temperature_c)
                else:
                    self.assumed_zero.add(s)
                    x = np.zeros(m)
                x.flags.writeable = False
                self._const[s] = x
        if len(self._const_views) >= 64:
            self._const_views = {}
        got = self._const_views[n] = {s: x[:n] for s, x in self._const.items()}
        return got

    # ------------------------------------------------------------------ reports
    def vehicle(self, i: int) -> dict[str, dict[str, float]]:
        """Running totals of vehicle number ``i`` (``Accountant.stepper.vmap[id]``) during a
        run: equation → {quantity: value} for the equations with a chain."""
        self._grow(i + 1)
        out: dict[str, dict[str, float]] = {}
        for j, (e, k) in enumerate(self._cols):
            out.setdefault(self.names[e], {})[QUANTITIES[k]] = float(self._veh[i, j])
        return out

    def flush(self, gone: np.ndarray, labels: list[str], ids: list[str], spill) -> None:
        """Vehicles ``gone`` (slots) leave memory: their totals are added to their class's
        and their rows handed to ``spill.write_chain`` (``chain_vehicles.csv``)."""
        self._grow(int(gone.max()) + 1)
        tot = self.expand(self._veh[gone])
        dist = self.veh_dist[gone]
        for j, c in enumerate(labels):
            acc = self.flushed_class.setdefault(c, [np.zeros((self.E, self.Q)), np.zeros(self.A)])
            acc[0] += tot[j]
            acc[1] += dist[j]
        if spill is not None:
            spill.write_chain(self.table(tot, dist, ids), self.columns())  # every chain's columns

    def compact(self, keep: np.ndarray, n: int) -> None:
        """Move vehicles ``keep`` (slots, ascending) to the front, empty the rest up to ``n``."""
        self._grow(n)
        m = len(keep)
        for arr in (self._veh, self.veh_dist, self.veh_time, self._app, self._starting,
                    self._cold_age, self._cold_new, self._stored, self._spent):
            arr[:m] = arr[keep]
            arr[m:n] = 0.0

    def vehicle_totals(self, n: int) -> np.ndarray:
        """Totals of the first ``n`` vehicles, (n, E, Q)."""
        self._grow(n)
        return self.veh[:n]


#: ChainLedger's cold-start keywords (the same names as the loop's Physics fields)
COLD_START_KEYWORDS = ("cold_start", "cold_start_vtypes", "cold_start_vclasses", "cold_start_vehicles",
                       "cold_start_flows")


def chain_ledger(equations, n_edges: int, signal_values: dict | None = None,
                 **cold_start) -> ChainLedger | None:
    """A :class:`ChainLedger` for the equations that carry a battery or fuel chain, or None;
    ``cold_start``: its cold-start keywords (:data:`COLD_START_KEYWORDS`)."""
    chains = [getattr(e, "chain", None) for e in equations]
    if not any(c is not None and c.predicts != "wheel" for c in chains):
        return None
    return ChainLedger([e.name for e in equations], chains, n_edges, signal_values=signal_values,
                       **cold_start)


def over_engine(excess_j, engine_off=None) -> tuple[int, float]:
    """(vehicle-steps, J) of a step's engine output demand beyond the rated output, where the
    engine runs (not switched off by ``engine_off``)."""
    x = np.asarray(excess_j, float) if engine_off is None else np.where(engine_off, 0.0, excess_j)
    return int(np.count_nonzero(x > 0)), float(x.sum())
