"""The stepping loop: read every vehicle's state into arrays, evaluate, book.

The connection is passed in: the ``libsumo`` module, a ``traci`` connection, or any
object with the same ``simulationStep``/``simulation``/``vehicle`` API (tests use a
fake). With libsumo, plain getters mapped over the id list are the cheapest way to read
(design.md: ≈1.15× a bare step vs 1.4–1.7× for subscriptions, which build Python dicts);
with traci each getter is a socket round trip, so one context subscription on the
simulation reads every vehicle (sim/reader.py).

Per step and vehicle: speed [m/s]; by default the rest follows from it and the network
(see :class:`Physics`): acceleration as (v_t − v_t−1)/Δt, lane and position tracked under
SUMO's Euler update, heading and front-to-back slope from the lane shape. Each can be
read from SUMO instead (getAcceleration, getLaneID/getLanePosition every step, getAngle,
getSlope). Everything after reading is vectorized over the vehicles of the step.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable

import numpy as np

from sumo_drvpw.model.constants import G
from sumo_drvpw.model.terms import Inputs
from sumo_drvpw.sim.chain_charge import book_departures
from sumo_drvpw.sim.dynamics import whole_second
from sumo_drvpw.sim.ledger import EquationSet, Ledger
from sumo_drvpw.sim.network import LaneNumbers, Network
from sumo_drvpw.sim.parking import Parking
from sumo_drvpw.sim.reader import Reader, calibrator_lanes, on_road_acceleration, reinserted, tailwind, yaw_rate  # noqa: F401,E501
from sumo_drvpw.sim.riders import OwnCopies, Riders
from sumo_drvpw.sim.shutoff import ShutOff
from sumo_drvpw.sim.sumo_start import NewRun, action_step_switches, step_method
from sumo_drvpw.sim.teleport import put_back

@dataclass
class Physics:
    """Run-wide physics settings: wind speed [m/s] and direction it blows FROM [deg
    clockwise from north], air density [kg/m³], slope tolerance [rad]."""

    wind_speed: float = 0.0
    wind_from_deg: float = 0.0
    rho: float = 1.2041
    #: ambient air temperature [°C] given to the equations (``cold`` factor) and the
    #: chains (HVAC) as the signal ``ambient_c``; None: unknown (``cold`` = 0, reference)
    ambient_c: float | None = None
    #: share of departing vehicles whose cold start fuel chains book (sim/chain.py), and
    #: the shares of vehicles, flows, vTypes and vClasses with their own (in this order)
    cold_start: float = 0.0
    cold_start_vtypes: dict | None = None
    cold_start_vclasses: dict | None = None
    cold_start_vehicles: dict | None = None  # vehicle id → share (the route files' params)
    cold_start_flows: dict | None = None     # flow id → share of its vehicles
    slope_tol: float = 0.01
    #: "getslope": compare the robust slope with SUMO's getSlope (one more getter per
    #: vehicle); "geometry": with the same front-to-back slope taken from the lane shape
    slope_reference: str = "geometry"
    #: "getter": vehicle.getAcceleration; "speed_difference": (v_t − v_t−1)/Δt from the
    #: speeds already read, which is how SUMO defines getAcceleration (0 when first seen)
    acceleration: str = "speed_difference"
    #: "getangle": vehicle.getAngle for the wind projection; "geometry": the lane's
    #: direction at the vehicle's position (no getter; differs only during lane changes)
    heading: str = "geometry"
    #: "tracked": lane and position are read when a vehicle is first seen, when its
    #: position advanced by v·Δt (SUMO's Euler update) reaches the end of its edge (the
    #: shortest lane of the edge), when a teleport starts or ends or it starts parking (off
    #: the lane: not booked), and for every vehicle each
    #: ``resync_steps`` steps; otherwise they follow from the speed. A lane change keeps
    #: edge and position, so until the next read the tracked lane may be a neighbour of
    #: the same edge (same slope profile unless the lanes' shapes differ); a different
    #: edge or position at a full read is counted in ``Ledger.position_mismatches``.
    #: "getter": read every step. Tracking needs getters and the Euler update; with
    #: traci or ``--step-method.ballistic`` the loop reads every step whatever this says.
    positions: str = "tracked"
    resync_steps: int = 25
    ballistic_given: str | None = None  # step-method.ballistic as the scenario gives it
    #: persons riding in a vehicle add their vTypes' masses while they ride (SUMO's
    #: EnergyParams::getTotalMass); read at a vehicle's departure and when one of its
    #: stops ends — boarding and alighting happen at stops, standing
    transportable_mass: bool = True


#: a deceleration [m/s²] beyond any brake, on tyres or on rails (1.2 g; a car's best
#: emergency stop is about 1 g): a step SUMO ends at such a rate (its emergency braking, a
#: train stopped at a red signal within one step from 64 m/s) sheds its kinetic energy in
#: friction brakes, not in a battery — the chains recuperate none of it that step, as SUMO's
#: own emission output booked only the auxiliary power there (its test
#: rail/bidi_noconflict_insertion with a 400-t Energy-model train, SUMO 1.28, 2026-11-29)
IMPOSSIBLE_DECEL_MPS2 = 1.2 * G

def flat_network(net) -> bool:
    """Whether ``net`` has no elevation at all: every profile node at z = +0 and every bin's
    slope +0 (a network without z in its shapes). Its steps' grades (Network.step_grade) are
    then the slope given where the vehicle stands, and its rows [lane, pos, 0, 0]: Δz is +0
    on every step, so nothing is owed and no jump is told."""
    z, prof = getattr(net, "z_node", None), getattr(net, "profile", None)
    return (z is not None and prof is not None and not np.any(z) and not np.signbit(z).any()
            and not np.any(prof) and not np.signbit(prof).any())


#: every this many steps the running vehicles' vTypes are read again (a script's setType):
#: a change books from then on (over traci, each read a round trip: 10× as many); vehicles
#: on a calibrator's edge, where SUMO changes vTypes itself, are read every step, and in a
#: step where SUMO's vType count changed, those whose own copy it gained (a setMass's; all of
#: them where it gained another vType: sim/riders.OwnCopies)
TYPE_CHECK_STEPS = 25


class Stepper:
    """Books one SUMO step at a time: call :meth:`after_step` after every
    ``simulationStep`` (``sim.stepping.run_loop`` does; so does :class:`sumo_drvpw.sim.Accountant`
    as a step listener in the user's own loop).

    Parameters
    ----------
    conn : libsumo module, traci connection or a fake with the same API
    net : network table (lanes → edges, robust slopes)
    eqset : the equations
    ledger : accumulators (filled in place)
    physics : wind, air density, slope tolerance
    resolve : vType id, vehicle id → (mass [kg], applicability per equation, keep)
    trace : optional object with ``write(t, vidx, eidx, v, a, theta, wind, pc)``
    use_subscriptions : read with subscriptions (traci) instead of getters (libsumo)
    """

    def __init__(self, conn, net: Network, eqset: EquationSet, ledger: Ledger,
                 physics: Physics, resolve: Callable[[str, str], tuple[float, np.ndarray, bool]],
                 trace=None, use_subscriptions: bool = False):
        self.conn, self.net, self.eqset, self.ledger = conn, net, eqset, ledger
        #: each equation's own fixed mass [kg] (NaN: the vehicle's), for the rows' booked mass
        ledger.eq_mass = np.array([np.nan if e.mass_kg is None else float(e.mass_kg) for e in eqset.equations])
        if ledger.chain is None:  # battery/fuel accounts when an equation has a chain (#12)
            from sumo_drvpw.sim.chain import COLD_START_KEYWORDS, chain_ledger

            ledger.chain = chain_ledger(
                eqset.equations, ledger.n_edges,
                None if physics.ambient_c is None else {"ambient_c": physics.ambient_c},
                **{k: getattr(physics, k) for k in COLD_START_KEYWORDS})
        self.physics, self.resolve, self.trace = physics, resolve, trace
        self.use_subscriptions = use_subscriptions
        self.dt = float(conn.simulation.getDeltaT())
        if len(ledger.lane_clipped) != len(net.lane_edge):
            ledger.lane_clipped = np.zeros(len(net.lane_edge), np.int64)
        self.vmap: dict[str, int] = {}
        self.lane_index = dict(net.lane_index)
        # (a replay checks its rows' lanes itself: sim/fcd_warn.lane_warnings)
        self.lane_numbers = LaneNumbers(self.lane_index, None if getattr(conn, "is_replay", False)
                                        else getattr(net, "path", None))
        #: vehicles whose teleport ended this step: their next step's rise starts afresh
        self.teleport_ends = getattr(conn.simulation, "getEndingTeleportIDList", lambda: ())
        self.lane_index[""] = -1
        self.lane_edge_ext = np.append(net.lane_edge, -1)  # lane -1 → edge -1
        read_accel = physics.acceleration == "getter"
        self.read_slope = physics.slope_reference == "getslope"
        #: a vtype_energy equation books SUMO's own slope (sim/sumo_inputs.as_sumo; an FCD without slopes: NaN)
        self.sumo_slope = eqset.uses_sumo_slope
        self.yaw = eqset.uses_yaw  # an equation's ``radial`` factor: the angle's change per step
        self.reader = Reader(conn, use_subscriptions,
                              (True, read_accel, self.yaw or (
                                  physics.wind_speed != 0.0 and physics.heading == "getangle"),
                               True, True, self.read_slope or self.sumo_slope))
        self.heading_from_lane = physics.wind_speed != 0.0 and physics.heading == "geometry"
        #: a network without elevation (every node's z and every bin's slope +0): a step's grade
        #: is the slope where it stands (0 but at a parking space's), no rise is carried
        self.flat = flat_network(net)
        method = step_method(conn, physics.ballistic_given)
        self.ballistic = method == "ballistic"
        #: SUMO switches Euler to ballistic when a vehicle of a vType with its own action step
        #: length is built, where step-method.ballistic is not given (sumo_start.action_step_switches):
        #: the vType of each vehicle registered is asked then (None: no switch to watch for)
        may_switch = (getattr(conn, "asl_may_switch", False) if getattr(conn, "is_replay", False)
                      else physics.ballistic_given is None)
        self.asl = (getattr(getattr(conn, "vehicletype", None), "getActionStepLength", None)
                    if method == "euler" and may_switch else None)
        self.asl_seen: set = set()
        self.tracking = (physics.positions == "tracked" and not use_subscriptions
                         and method == "euler" and net.lane_end is not None
                         and net.lane_own_edge is not None)
        if self.tracking:
            # lanes -1 (no lane) and -2 (never read): an end of −∞, so they are always read
            self.lane_end = np.append(net.lane_end - 1e-6, [-np.inf, -np.inf])
            # vehicles whose lane changed without their reaching a lane end: teleports
            # that ended or started, and parking that started (off the lane: not booked,
            # no auxiliary power); they are read again in the step the event happened
            sim = conn.simulation
            events = [getattr(sim, name) for name in (
                "getEndingTeleportIDList", "getStartingTeleportIDList",
                "getParkingStartingVehiclesIDList") if hasattr(sim, name)]
            self.lane_events = lambda: [v for f in events for v in f()]
            self.resync = max(1, int(physics.resync_steps))
            # a lane change keeps the position and the edge (internal ones included), so
            # only a different edge or position is a disagreement; lanes -1, -2 belong to none
            self.lane_own = np.append(net.lane_own_edge, [-1, -1])
        #: per lane: on a calibrator's edge (None: the run has no calibrator)
        self.calib_lane = calibrator_lanes(conn, net)
        self.every_equation_applies = True  # to every vehicle accounted so far
        #: (equation number, speed [m/s], acceleration [m/s²], driving power [W] range or None;
        #: the power range that of the equation's chain fit: Equation.validity)
        self.ranges = [(k, *r) for k, r in ((k, e.validity() if hasattr(e, "validity") else (None,) * 3)
                                            for k, e in enumerate(eqset.equations)) if any(x is not None for x in r)]
        self.first = True
        self.prev_ids, self.prev_sel = None, None
        #: simulation time of the last booked step [s]; steps skipped (a
        #: ``simulationStep(t)`` jumping several steps) are counted in ``missed_steps``
        self.last_t: float | None = None
        self.missed_steps = 0
        #: calls for a step already booked (the same simulation time): not booked again
        self.repeated_steps = 0
        #: an FCD replay that starts after the file's first timestep sets ``skipped``: the
        #: vehicles of its first step were on the road already, not departing (cold starts)
        self.replay_info: dict = {}
        #: the run resumes a saved state (SUMO's load-state): its first step's vehicles are that
        #: state, the step the saving run booked last: seeded, not booked again (set by the Accountant)
        self.resumed = False
        #: persons (pedestrians, also riding) are never booked; a resolver with
        #: ``skip_person`` counts them by vClass and vType (one more call per step)
        self.count_persons = (hasattr(resolve, "skip_person") and hasattr(conn, "person")
                              and hasattr(conn.simulation, "getDepartedPersonIDList"))
        #: vehicles that left the simulation (SUMO's arrived list) are retired from the
        #: ledger, and flushed out of memory when it has a spill (bounded memory)
        self.arrived = getattr(conn.simulation, "getArrivedIDList", None)
        self.last_ids = None  # the id list of the last step (vehicles removed between steps)
        self.is_replay = bool(getattr(conn, "is_replay", False))  # an FCD replay
        #: riding persons (Physics.transportable_mass; sim/riders.py)
        self.riders = Riders(conn, physics.transportable_mass)
        self.own = OwnCopies(conn, self.is_replay)  # a script's setMass (sim/riders.py)
        self.retyped = 0  # vehicles whose vType changed during their trip (check_types)
        self.seen_type: dict[str, str] = {}  # vehicle id → its last vType id seen there
        so = ShutOff(conn)  # long planned stops switch vehicles off, as in SUMO
        self.shutoff = so if so.available else None
        #: parked vehicles: not read while parked, booked standing at a bus stop's bay
        #: or idling in their space while their way out is blocked (sim/parking.py)
        self.parking = Parking(conn, net, self.lane_index, self.shutoff, self.riders)

    def now(self) -> float:
        """Simulation time [s]; after an interrupted exchange with SUMO (a signal in the
        middle of a call), the time of the last booked step."""
        try:
            return float(self.conn.simulation.getTime())
        except Exception:  # traci/libsumo errors after an interrupted call
            return float(self.last_t) if self.last_t is not None else float("nan")

    @property
    def step_method(self) -> str:
        return "ballistic" if self.ballistic else "euler"

    def register(self, vid: str) -> int:
        ledger = self.ledger
        vt = self.conn.vehicle.getTypeID(vid)
        if self.asl is not None and vt not in self.asl_seen:
            self.asl_seen.add(vt)
            if action_step_switches(float(self.asl(vt)), self.dt):  # SUMO moves ballistic from now
                self.ballistic, self.tracking, self.asl = True, False, None
        # on its own copy when first seen (a state saved after a setMass): booked as its type is
        base = vt[:-len(vid) - 1] if vt.endswith("@" + vid) and hasattr(self.resolve, "own_copy") else None
        res = self.resolve(base or vt, vid)
        mass, app, keep = res[:3]
        i = ledger.add_vehicle(vid, base or vt, mass, app, keep, res[3] if len(res) > 3 else "")
        self.vmap[vid] = i
        self.seen_type.pop(vid, None)
        if base is not None and keep:  # then at the copy's mass (sim/resolver.own_mass)
            self.seen_type[vid] = vt
            self.own.track(vid, vt)
            self.resolve.own_copy(ledger, i, base, vt)
        if self.shutoff is not None:
            self.shutoff.registered(ledger, i, base or vt, vid)
        if keep and not np.all(ledger.veh_app[i] == 1.0):
            self.every_equation_applies = False
        self.reader.subscribe_existing([vid])
        return i

    def check_types(self, kids, vidx) -> None:
        """vTypes changed during a trip: ``vehicle.setType`` books on with the new vType's
        mass, class and equations; ``setMass`` and the other vType setters give the vehicle
        a type of its own, ``<type>@<id>``, which keeps its type's resolution (scenario
        settings, equations, filter) and takes only a mass or an emissionClass of another
        energy carrier SUMO now gives it (:meth:`VTypeResolver.own_copy`; ``retyped`` counts
        both)."""
        ledger, get, seen = self.ledger, self.conn.vehicle.getTypeID, self.seen_type
        types, tget = ledger.veh_type, getattr(self.conn, "vehicletype", None)
        for vid, i in zip(kids, vidx.tolist()):
            vt = get(vid)
            if vt == seen.get(vid, types[i]):
                continue
            seen[vid] = vt
            if vt == f"{types[i]}@{vid}":  # its own copy: a mass or an emissionClass the script set
                own = getattr(self.resolve, "own_copy", None)  # (a VTypeResolver's)
                self.own.track(vid, vt)
                if own and tget is not None and own(ledger, i, types[i], vt):
                    self.retyped += 1
                    self.every_equation_applies &= bool(np.all(ledger.veh_app[i] == 1.0))
                continue
            res = self.resolve(vt, vid)
            types[i] = vt
            ledger.veh_mass[i], ledger.veh_keep[i] = res[0], res[2]
            ledger.set_app(i, res[1])
            if len(res) > 3:
                ledger.veh_class[i] = res[3]
            if self.shutoff is not None:
                self.shutoff.registered(ledger, i, vt, vid)
            if res[2] and not np.all(res[1] == 1.0):
                self.every_equation_applies = False
            self.retyped += 1
            self.prev_ids = None  # (a vType no equation books is read no more)

    def flush(self) -> None:
        """Write the finished vehicles out of the ledger (:meth:`Ledger.flush`) and renumber
        the running ones."""
        if self.trace is not None and hasattr(self.trace, "flush"):
            self.trace.flush()  # its buffered rows name vehicles by their current numbers
        remap = self.ledger.flush()
        if remap is None:
            return
        self.vmap = {vid: int(remap[i]) for vid, i in self.vmap.items() if remap[i] >= 0}
        self.prev_ids, self.prev_sel = None, None

    def after_step(self) -> None:
        """Read the state SUMO reached in the step just made and book its energies."""
        conn, ledger, net, physics, dt = self.conn, self.ledger, self.net, self.physics, self.dt
        vmap = self.vmap
        t_now = conn.simulation.getTime()
        if self.last_t is not None and t_now < self.last_t - 1e-9:  # a load() began a new run
            raise NewRun(self.last_t, t_now)
        if self.last_t is not None and t_now <= self.last_t + 1e-9:  # this step is booked already
            self.repeated_steps += 1  # (a listener added twice, or beside a script's own step())
            return
        ledger.steps += 1
        if self.last_t is not None and t_now - self.last_t > 1.5 * dt:
            self.missed_steps += int(round((t_now - self.last_t) / dt)) - 1
        self.last_t = t_now
        ids = conn.vehicle.getIDList()
        if self.parking.resumed:  # parked cars whose stop a script ended: out of SUMO's list
            ids = self.parking.with_resumed(ids)
        if self.first:
            self.reader.subscribe_existing(ids)
            self.first = False
        if self.count_persons:
            for pid in conn.simulation.getDepartedPersonIDList():
                self.resolve.skip_person(conn.person.getTypeID(pid))
        departed = conn.simulation.getDepartedIDList()
        back = self.teleport_ends()
        if self.arrived is not None:
            gone = self.arrived()
            if not self.is_replay:  # and those a script removed between steps
                gone = list(gone) + self.reader.removed(self.last_ids, ids, gone, departed, back)
                if self.reader.kept and self.parking.signals is not None:  # out, not gone: parked
                    ids = (*ids, *self.parking.resume(ledger, vmap, self.reader.kept, t_now))  # cars resumed
            self.last_ids = ids
            if gone:
                ledger.retire([vmap[v] for v in gone if v in vmap])
                for v in gone:
                    self.parking.forget(v)
                    self.seen_type.pop(v, None)
                    self.riders.at_stop.discard(v)
                if self.shutoff is not None:
                    self.shutoff.arrived(gone)
                if ledger.flush_due():  # before the new ones come: memory ≤ running vehicles
                    self.flush()
                    vmap = self.vmap
        ends = np.array([vmap[v] for v in back if v in vmap], np.int64)  # teleports ended: placed
        starts, start_ids = [], []  # vehicles first seen departing: trips that start
        joined = []  # vehicles first seen on the road, not departing: accounting began mid-trip
        for vid in departed:
            if self.is_replay and vid in vmap:  # back after a teleport (no FCD rows): the same
                ledger.unretire(vmap[vid])  # trip, put back on the lane there, as live
                ends = np.append(ends, vmap[vid])
                continue
            if vid in vmap:  # an id used again (vehicle.add after it left): a new trip, its
                ledger.retire([vmap[vid]])  # own row, vType and mass (the old row is done)
                self.prev_ids = None
            starts.append(self.register(vid))
            start_ids.append(vid)
        if starts and ledger.steps == 1 and ((self.is_replay and self.replay_info.get("skipped")) or self.resumed):
            joined = starts  # an FCD replay from --begin (a saved state's: SUMO departs them again): driving
        if starts and ledger.chain is not None and ledger.chain.cold_start_on \
                and not (ledger.steps == 1 and (self.replay_info.get("skipped") or self.resumed)):
            ledger.chain.depart(starts, start_ids, ledger.veh_type, ledger.veh_class)
        if starts and ledger.chain is not None:  # a plug-in's charge (sim/chain_charge.py; driving: unknown)
            book_departures(ledger.chain, starts, start_ids, ledger.veh_type, ledger.veh_app, bool(joined))
        self.riders.step(ledger, vmap, departed)
        if self.parking.on and self.parking.step(ledger, vmap, t_now, dt):
            self.prev_ids = None  # the selection of vehicles read changes
        if self.shutoff is not None:
            self.shutoff.step(self, ids)
        if len(ids) == 0:
            return
        if ids == self.prev_ids:  # no arrival or departure: same vehicles, same order
            vidx, kids = self.prev_sel
        else:
            n_all = len(ids)
            try:
                vidx = np.fromiter(map(vmap.__getitem__, ids), np.int64, n_all)
            except KeyError:
                n_known = ledger.n_veh
                vidx = np.fromiter((vmap[v] if v in vmap else self.register(v) for v in ids),
                                   np.int64, n_all)
                joined = vidx[vidx >= n_known].tolist() + joined  # (those registered just now)
            kept = ledger.veh_keep[vidx] & ~ledger.veh_parked[vidx]
            if kept.all():
                kids = ids
            else:  # only the vehicles accounted for and not parked are read
                sel = np.flatnonzero(kept)
                vidx, kids = vidx[sel], [ids[i] for i in sel]
            self.prev_ids, self.prev_sel = ids, (vidx, kids)
        if joined:  # its trip began before the booking did (vehicles.parquet on_road_at_begin)
            ledger.veh_joined[np.asarray(joined, np.int64)] = True
        n = len(kids)
        if n == 0:
            return
        if ledger.steps % (TYPE_CHECK_STEPS * (10 if self.reader.subs else 1)) == 0:
            self.check_types(kids, vidx)  # (a replay: at the steps a live libsumo run reads them)
            self.own.type_masses(self)  # and a script's vehicletype.setMass
        self.own.step(self, kids, vidx)  # and when a vType copy was made; a copy's mass each step
        tracking = self.tracking
        v, a, angle, ln, pos, raw = self.reader.read(kids, skip_lanes=tracking)
        if self.parking.resumed:
            self.parking.at_rest(kids, (v, a, angle, raw))
        if tracking:
            lane = ledger.veh_lane[vidx]
            pos = ledger.veh_pos[vidx] + v * dt  # SUMO's Euler update: x += v_t·Δt
            trusted = pos < self.lane_end[lane]
            full = ledger.steps % self.resync == 0
            stale = np.ones(n, bool) if full else ~trusted
            gone = self.lane_events()
            if gone:
                stale[np.isin(vidx, [vmap[x] for x in gone if x in vmap])] = True
            k = np.flatnonzero(stale)
            if len(k):
                get_lane, get_pos = self.reader.getters[3], self.reader.getters[4]
                sub = kids if len(k) == n else [kids[i] for i in k]
                lk = self.lane_numbers(list(map(get_lane, sub)))
                pk = np.fromiter(map(get_pos, sub), float, len(k))
                lk, pk = net.own_side(lane[k], pos[k], lk, pk)  # overtaking on the opposite lane: tracked on its own
                if full:  # were the tracked ones right?
                    lane_own = self.lane_own
                    ledger.position_mismatches += int(np.count_nonzero(
                        trusted & ((lane_own[lk] != lane_own[lane])
                                   | (np.abs(pk - pos) > 1e-6))))
                lane[k], pos[k] = lk, pk
                ledger.position_reads += len(k)
            ledger.veh_lane[vidx] = lane
            ledger.veh_pos[vidx] = pos
        else:
            lane, pos = net.own_side_after(ledger.veh_at[vidx], v * dt, self.lane_numbers(ln), pos)
        if self.calib_lane is not None:  # where SUMO changes vTypes: booked from the step it does
            j = np.flatnonzero(self.calib_lane[lane])
            if len(j):
                self.check_types([kids[i] for i in j], vidx[j])
        prev = ledger.veh_prev_speed[vidx]  # last step's (a teleport's: on the lane it left)
        ledger.veh_prev_speed[vidx] = v
        if a is None:  # SUMO's definition: (v_t − v_t−1)/Δt, 0 when first seen
            a = (v - prev) / dt
            if joined:  # on the road when accounting began: SUMO's own (v_t − v_t−1)/Δt of the step
                on_road_acceleration(a, vidx, joined, prev, kids, self.reader.getters[1])
            a[np.isnan(a)] = 0.0
        if angle is None:
            angle = np.zeros(n)
        yaw = None
        if self.yaw:  # SUMO's angle difference of the step, as its Energy model reads it
            yaw = yaw_rate(ledger.veh_prev_angle[vidx], angle, dt)
            ledger.veh_prev_angle[vidx] = angle
        if raw is not None:
            raw = np.radians(raw)
        own = raw if self.sumo_slope else None  # SUMO's slope of the vehicle, for vtype_energy
        if not self.read_slope:
            raw = None
        placed = reinserted(net, ledger, vidx, lane, pos, v, a, dt, ends, self.is_replay,  # not driven
                            prev, getattr(conn, "type_accel", None))
        on_lane, tilt = lane >= 0, None
        if self.parking.on and not on_lane.all():  # parked, dwelling, idling, or teleporting
            for j in np.flatnonzero(~on_lane):
                d = self.parking.dwell.get(kids[j])
                if d is None:  # parks now: this step's move into its space booked (not a trip's first)
                    i = int(vidx[j])
                    d = self.parking.started(ledger, kids[j], i, t_now, i not in starts and i not in joined)
                    if ledger.veh_parked[i]:
                        self.prev_ids = None  # the selection of vehicles read changes
                if d is not None:  # at a bus stop's bay, idling in its space, or moving into it
                    lane[j], pos[j] = d
                    if kids[j] in self.parking.grade:  # idling, at the slope SUMO gives it there
                        tilt = np.full(len(kids), np.nan) if tilt is None else tilt
                        tilt[j] = self.parking.grade[kids[j]]
            on_lane = lane >= 0
        if self.parking.once:  # back on the lane from a parking, or parking, at its space's slope this step
            tilt = self.parking.tilt(kids, tilt)
        if self.is_replay and getattr(conn, "entry_slope", None):  # (the FCD's slope of a row a car parks in)
            tilt = self.parking.tilt(kids, tilt, conn.entry_slope)
        if placed.any():  # put back by a teleport: its energy jump booked apart, then driven on
            put_back(ledger, net, self.eqset.equations, placed, vidx, lane, pos, v, prev)
            on_lane &= ~placed
        if self.resumed and ledger.steps == 1 and joined:  # a saved state: where its next step starts
            seed = on_lane & np.isin(vidx, joined)
            ledger.veh_at[vidx[seed]] = np.column_stack([lane[seed], pos[seed], net.elevation(lane[seed], pos[seed])
                                                         if net.z_node is not None else np.nan, np.zeros(seed.sum())])
            on_lane &= ~seed
        if not on_lane.all():  # teleporting, parked: no lane, not booked (nor a saved state's first row)
            ledger.veh_at[vidx[(lane < 0)], 2] = np.nan  # (its next step starts its rise afresh)
            ledger.veh_prev_angle[vidx[(lane < 0)]] = np.nan  # (and its turning)
            vidx, lane, v, a, angle, pos = (
                x[on_lane] for x in (vidx, lane, v, a, angle, pos))
            raw, yaw, tilt, own = (None if x is None else x[on_lane] for x in (raw, yaw, tilt, own))
            if len(vidx) == 0:
                return
        at = net.bin_index(lane, pos)  # robust slope, shape slope, heading there
        theta, clipped = net.profile[at], net.clipped[at]
        if self.heading_from_lane:
            angle = net.heading_deg[at]
        if raw is None:
            raw = net.raw[at]
        ledger.corrected += int(np.count_nonzero(
            (np.abs(raw - theta) > physics.slope_tol) | clipped))
        if tilt is not None:  # SUMO's slope in a parking space: that step's grade, not the lane's rise
            theta = np.where(np.isnan(tilt), theta, tilt)
            ledger.veh_at[vidx[~np.isnan(tilt)], 2] = np.nan
        nclip = int(np.count_nonzero(clipped))
        if nclip:
            ledger.clipped += nclip
            np.add.at(ledger.lane_clipped, lane[clipped], 1)
        wind = tailwind(angle, physics.wind_speed, physics.wind_from_deg)
        m = len(vidx)
        # energy conserved at any Δt: the acc factor takes the step's mean speed, so
        # m·v̄·a·Δt = ½m(v_t² − v_t−1²); the other terms the speed of the distance SUMO
        # moved the car in the step (Euler: v_t·Δt; ballistic: v̄·Δt)
        v_mean = v - 0.5 * dt * a
        v_state = v  # the speed SUMO gives the state (its outputs write it), whatever books the distance
        if self.ballistic:
            v = v_mean
        if self.flat:  # no rise anywhere: step_grade's θ and rows, without its work
            lim = min(net.max_rad, 0.5 * np.pi)
            theta = np.minimum(np.maximum(theta, -lim), lim)  # (np.clip's values, without its per-call cost)
            rows = np.zeros((m, 4))
            rows[:, 0], rows[:, 1] = lane, pos
            ledger.veh_at[vidx] = rows
        elif net.z_node is not None:  # the step's grade: m·g·Δz exactly
            theta, ledger.veh_at[vidx] = net.step_grade(lane, pos, v * dt, ledger.veh_at[vidx], theta,
                                                        (v_mean + 0.5 * dt * np.abs(a)) * dt)  # max(v_t−1, v_t)·Δt
        sig = {} if physics.ambient_c is None else {"ambient_c": np.full(m, physics.ambient_c)}
        if yaw is not None:
            sig["yaw_rate_rps"] = yaw
        if own is not None:
            sig["sumo_slope_rad"] = own
        mass = ledger.veh_mass[vidx]
        if self.riders.any_load:  # riding persons (SUMO's getTotalMass)
            load = ledger.veh_load[vidx]
            riding = load > 0.0
            if riding.any():
                mass, sig["load_kg"] = mass + load, load
                ledger.load_samples += int(np.count_nonzero(riding))
                ledger.load_max_kg = max(ledger.load_max_kg, float(load.max()))
        x = Inputs(v, a, theta, wind, mass, np.full(m, physics.rho), sig, v_acc=v_mean)
        xm = replace(x, v=v_mean, signals={**sig, "load_kg": ledger.veh_load[vidx]}) if self.eqset.uses_mean else None
        app = ledger.veh_app[vidx]  # (read once: the ledger and the chains book by it too)
        pc = self.eqset.category_powers(x, None if self.every_equation_applies else app, xm)
        for k, vr, ar, pr in self.ranges:  # vehicle-steps outside an equation's validity range
            out = np.zeros(m, bool)
            if vr is not None:
                out |= (v < vr[0]) | (v > vr[1])
            if ar is not None:
                out |= (a < ar[0]) | (a > ar[1])
            if pr is not None:  # the driving power its chain was fitted on
                pk = pc[:, k].sum(axis=1)
                out |= (pk < pr[0]) | (pk > pr[1])
            if not self.every_equation_applies:
                out &= ledger.veh_app[vidx, k] > 0
            ledger.out_of_range[k] += int(np.count_nonzero(out))
        eidx = self.lane_edge_ext[lane]
        ledger.book(vidx, eidx, v, dt, pc, app)
        ledger.dynamics.step(ledger, vidx, v_mean, a, v, dt, theta)
        if whole_second(t_now - dt, dt):  # the trajectories at 1 Hz, as the RDE reads a trip (at the
            # time SUMO's outputs give this state: the step's begin, getTime() − Δt after the step)
            ledger.dynamics.sample(ledger, vidx, v_state, t_now - dt)
        hard = a < -IMPOSSIBLE_DECEL_MPS2  # braked beyond any brake: booked at the wheels, not recuperated
        any_hard = bool(hard.any())
        if any_hard:
            ledger.hard_brakes += int(np.count_nonzero(hard))
            ledger.hard_brake_max_mps2 = max(ledger.hard_brake_max_mps2, float(-a[hard].min()))
        if ledger.chain is not None:  # battery/fuel accounts (sim/chain.py), standing included
            p_chain = pc.sum(axis=2)
            if any_hard:
                p_chain[hard] = np.maximum(p_chain[hard], 0.0)
            off = None if self.shutoff is None else self.shutoff.auto_off(ledger, vidx, v, dt)
            ledger.chain.book(vidx, eidx, v, dt, p_chain, app=app, engine_off=off, accel=a,
                              v_mean=v_mean, grade=theta, load=None if xm is None else xm.signals["load_kg"])
        if self.trace is not None:
            # (at the time SUMO's own outputs give this state, as its FCD and emission output do:
            # the step's start, getTime() − Δt after the step)
            self.trace.write(t_now - dt, vidx, eidx, v, a, theta, wind, pc)
