"""Reading the per-vehicle state of a step from SUMO: plain getters mapped over the id list
(libsumo: the cheapest way, design.md) or, through traci (each getter a socket round trip),
one context subscription on the simulation that returns every vehicle's variables; and what
a vehicle's heading gives: the wind along it, the yaw rate from its change."""

from __future__ import annotations

import numpy as np

from sumo_drvpw.sim.network import JUMP_TOL_M

# traci variable ids (traci.constants), fixed by the TraCI protocol
_VAR_SPEED, _VAR_ACCEL, _VAR_ANGLE = 0x40, 0x72, 0x43
_VAR_LANE_ID, _VAR_LANEPOSITION, _VAR_SLOPE = 0x51, 0x56, 0x36
_TRACI_VARS = (_VAR_SPEED, _VAR_ACCEL, _VAR_ANGLE, _VAR_LANE_ID, _VAR_LANEPOSITION, _VAR_SLOPE)
_CMD_GET_VEHICLE_VARIABLE = 0xa4
#: the vehicle's mass, subscribed too: a vehicle on its own vType copy has it read every step
#: (sim/riders.OwnCopies), which over traci was a round trip per such vehicle and step
_VAR_MASS = 0xc8
#: the context subscription's range [m]: the whole network around the simulation's "" (SUMO
#: collects the vehicles on the lanes within it every step, so a vehicle a script removed is
#: simply not among them; a subscription per vehicle made SUMO answer each of its variables
#: with an error, and the traci client print one, in the step after the removal: SUMO drops a
#: vehicle's subscriptions only when the vehicle arrives in that step,
#: TraCIServer::postProcessSimulationStep)
_EVERYWHERE_M = 1e9


def known_to_sumo(get, vid: str) -> bool:
    """Whether SUMO still has vehicle ``vid``: its getter ``get`` answers (a TraCIException,
    "Vehicle '…' is not known", says it has not; a failed connection raises)."""
    try:
        get(vid)
    except Exception as e:
        if type(e).__name__ == "FatalTraCIError":  # the connection itself failed
            raise
        return False
    return True


def tailwind(angle_deg: np.ndarray, speed: float, from_deg: float) -> np.ndarray:
    """Wind along the heading ``angle_deg`` (SUMO's, deg clockwise from north), tailwind
    positive [m/s], of a wind of ``speed`` [m/s] blowing from ``from_deg``
    (:func:`sumo_drvpw.data.wind.tailwind_mps`, as a drive log's wind is written)."""
    if speed == 0.0:
        return np.zeros(len(angle_deg))
    from sumo_drvpw.data.wind import tailwind_mps  # (only where there is wind)

    return tailwind_mps(angle_deg, speed, from_deg)


def yaw_rate(prev_deg: np.ndarray, angle_deg: np.ndarray, dt: float) -> np.ndarray:
    """The yaw rate [rad/s] of a step: the change of SUMO's vehicle angle [deg] since the
    last step, the short way round (GeomHelper::angleDiff), over Δt [s]; 0 where there is no
    last angle (NaN: first seen, back from a teleport). It is the angle change SUMO's Energy
    model reads for its radial drag (probed with SUMO 1.28.0, 2026-11-27: on a 90° arc of 50 m
    radius at 21.2 m/s its emission output's electricity rose by radialDragCoefficient·m·v·|Δψ|/Δt
    per step to 1e-9, Δψ the FCD angles' change in rad, at Δt 1, 0.5 and 0.25 s). SUMO caps
    the radius v·Δt/|Δψ| at 10 km, so a change below v·Δt/10⁴ rad books as that radius: the
    ``vtype_energy`` equations take it so (sim/sumo_inputs.as_sumo), where the angle read changes
    at all — a change of SUMO's rounding (~1e-16 rad) is lost in its angle in degrees."""
    d = np.asarray(angle_deg, float) - prev_deg  # (not (d + 180) % 360 − 180: that rounds a change
    d = np.where(d > 180.0, d - 360.0, np.where(d < -180.0, d + 360.0, d))  # below 3e-14° to 0)
    w = np.radians(d) / dt
    return np.where(np.isfinite(w), w, 0.0)


def calibrator_lanes(conn, net) -> np.ndarray | None:
    """Per lane of ``net`` (plus lanes -1, -2: none), whether it lies on the edge of one of
    SUMO's calibrators — where SUMO changes a passing vehicle's vType (a calibrator whose
    flow gives a type and no flow); None when the run has none. Asked of SUMO (its
    ``calibrator`` domain; an FCD replay's answers from the scenario's files)."""
    dom = getattr(conn, "calibrator", None)
    try:
        ids = list(dom.getIDList()) if dom is not None else []
    except Exception as e:  # a SUMO server without the domain: checked every 25 steps only
        if type(e).__name__ == "FatalTraCIError":
            raise
        return None
    edges = {dom.getEdgeID(c) for c in ids}
    idx = [i for i, e in enumerate(net.edge_ids) if e in edges]
    if not idx:
        return None
    on = np.isin(net.lane_edge, idx)
    return np.append(on, [False, False])


class Reader:
    """Reads the per-vehicle state of a step as lists (getters or traci subscriptions)."""

    def __init__(self, conn, use_subscriptions: bool, need: tuple[bool, ...] = (True,) * 6):
        self.conn = conn
        self.subs = use_subscriptions
        self.need = need  # speed, accel, angle, lane, position, slope
        self.subscribed = False
        self.fallback_reads = 0  # vehicle-steps read by getters: missing from the subscription
        #: vehicles :meth:`removed` found gone from the id list but still in the simulation
        #: (teleporting; parked, their stop ended by a script: sim/parking.py)
        self.kept: list = []

        V = conn.vehicle
        self.getters = [V.getSpeed, V.getAcceleration, V.getAngle, V.getLaneID,
                        V.getLanePosition, V.getSlope]
        if getattr(conn, "__name__", "") == "libsumo":
            # the compiled functions behind libsumo's Python wrappers: same calls,
            # ~25 % less per-call overhead (measured: 0.27 vs 0.36 ms per 1000 getSpeed calls)
            try:
                from libsumo import _libsumo as raw

                self.getters = [getattr(raw, "vehicle_" + g.__name__) for g in self.getters]
            except (ImportError, AttributeError):
                pass

    def read(self, ids, skip_lanes: bool = False):
        """(speed, accel, angle, lane, position, slope) of ``ids``: float arrays, a list
        of lane ids, or None for what is not needed (and lane/position if skip_lanes)."""
        if not self.subs:
            n = len(ids)
            return tuple(
                None if not need or (skip_lanes and k in (3, 4))
                else list(map(g, ids)) if k == 3 else np.fromiter(map(g, ids), float, n)
                for k, (g, need) in enumerate(zip(self.getters, self.need)))
        res = self.conn.simulation.getContextSubscriptionResults("") or {}
        rows = [res.get(vid) for vid in ids]
        for j, r in enumerate(rows):
            if not r:  # a vehicle on no lane SUMO collects from: its getters, this step only
                rows[j] = {k: g(ids[j]) for k, g in zip(_TRACI_VARS, self.getters)}
                self.fallback_reads += 1
        cols = [[r[k] for r in rows] for k in _TRACI_VARS]
        # (the subscription answers every variable; SUMO's slope is used only where asked for,
        # as without subscriptions: else the geometry's, whatever the connection)
        return tuple(None if k == 5 and not self.need[5] else c if k == 3 else np.asarray(c, float)
                     for k, c in enumerate(cols))

    def removed(self, last_ids, ids, gone, departed, back=()) -> list:
        """Vehicles of the last step that are gone without being in this step's arrived list
        ``gone``: removed by a script between steps (SUMO lists a vehicle removed through TraCI
        as arrived at once, in the list a step listener has already read). Looked for only when
        the counts say a vehicle left unseen — the counts take the vehicles back from a
        teleport this step (``back``, getEndingTeleportIDList), which are in no departed list:
        else a removal in the step a teleport ends went unseen. A teleporting vehicle also
        leaves the id list but SUMO still has it loaded, a removed one it has not: one
        getLoadedIDList then (no getter on a vehicle that is gone: through traci SUMO prints
        an error line for each)."""
        self.kept = []  # those gone from the list but still in the simulation (set below)
        if last_ids is None:
            return []
        came = sum(1 for v in back if v not in last_ids) if back else 0
        if len(ids) == len(last_ids) - len(gone) + len(departed) + came:
            return []
        now = set(ids).union(gone)
        lost = [vid for vid in last_ids if vid not in now]
        if not lost:
            return []
        loaded = getattr(self.conn.vehicle, "getLoadedIDList", None)
        if loaded is not None:
            try:
                known = set(loaded())
            except Exception as e:  # a SUMO server older than the client: ask for each
                if type(e).__name__ == "FatalTraCIError":
                    raise
            else:
                self.kept = [vid for vid in lost if vid in known]
                return [vid for vid in lost if vid not in known]
        out = []
        for vid in lost:  # a connection without getLoadedIDList: ask for each
            (self.kept if known_to_sumo(self.conn.vehicle.getTypeID, vid) else out).append(vid)
        return out

    def subscribe_existing(self, ids):
        """Through traci: the one context subscription, made at the first call."""
        if self.subs and not self.subscribed:
            self.conn.simulation.subscribeContext("", _CMD_GET_VEHICLE_VARIABLE, _EVERYWHERE_M,
                                                  (*_TRACI_VARS, _VAR_MASS))
            self.subscribed = True

    def mass_of(self, vid: str) -> float | None:
        """SUMO's mass of vehicle ``vid`` this step [kg] from the subscription (traci), None
        without one or where it does not hold the vehicle (then its getter)."""
        if not self.subscribed:
            return None
        r = (self.conn.simulation.getContextSubscriptionResults("") or {}).get(vid)
        return r.get(_VAR_MASS) if r else None


#: a step's speed gain [m/s²] no vehicle reaches by driving (SUMO's vClass default
#: accelerations are at most 2.6 m/s², its motorcycles' 6 in some versions): a vehicle on
#: another edge in the next row this much faster was put there by a teleport
REINSERT_ACCEL_MPS2 = 8.0
#: where the replay knows a vehicle's vType's acceleration bound (``type_accel``: sim/dynamics.
#: accel_bounds), a gain beyond this multiple of it (plus :data:`SPEED_TOL_MPS`) tells the same
VTYPE_ACCEL_MARGIN = 1.25
#: the speed gain [m/s] a row's written precision may add (SUMO's FCD: 2 decimals by default)
SPEED_TOL_MPS = 0.02


def reinserted(net, ledger, vidx, lane, pos, v, a, dt, ends, replay: bool, prev_v=None, type_accel=None):
    """Which vehicles of a step SUMO put back on a lane at a teleport's end: placed, not
    driven (MSVehicleTransfer::checkInsertions → MSLane::freeInsertion: the front at its length
    from the next edge's start, at that lane's speed limit or the vType's maxSpeed, in the
    step after the moves). ``ends``: slots SUMO says ended a teleport (a live run; a replay: back
    after steps without rows). A replay also tells one SUMO started and ended in one step (no
    gap in the FCD) by its row: on another edge, it stood (≤ 0.1 m/s) and is faster by more
    than its speed could gain by driving or farther along the lanes than its speed took it
    (v_t·Δt, plus :attr:`Network.jump_slack_m` for rows sparser than the step), or it moved
    (a collision's teleport) and is that much faster or farther than max(v_t−1, v_t)·Δt (+ that
    slack) took it (:meth:`Network.jumped`, the test the grade makes of a jump). The gain
    driving can reach in Δt: :data:`VTYPE_ACCEL_MARGIN` × its vType's bound (``type_accel``,
    vType id → m/s²; SUMO caps each step's gain at the vType's accel) + :data:`SPEED_TOL_MPS`,
    at most and where the bound is unknown :data:`REINSERT_ACCEL_MPS2`·Δt (a car put back
    from 7.3 at 13.9 m/s on a junction's next edge 10 m on: neither 8 m/s² faster nor farther
    than it could go, 6.6 m/s faster than its accel of 2.6 m/s² allows). Parameters:
    lane numbers, positions [m], speeds [m/s], accelerations [m/s²] of slots ``vidx``, Δt [s];
    ``prev_v``: their speeds of the last row (NaN: none; None: (v_t − v_t−1)/Δt is ``a``)."""
    fresh = (np.isin(vidx, ends) if len(ends) else np.zeros(len(vidx), bool)) & (lane >= 0)
    if replay and net.lane_own_edge is not None:
        prev = ledger.veh_at[vidx, 0]
        k = np.flatnonzero(np.isfinite(prev) & (lane >= 0))
        k = k[net.lane_own_edge[prev[k].astype(np.int64)] != net.lane_own_edge[lane[k]]]
        if len(k):
            lp, p0, was = prev[k].astype(np.int64), ledger.veh_at[vidx[k], 1], v[k] - a[k] * dt
            if prev_v is not None:  # (``a`` may be the FCD's acceleration: at a placement not the jump's)
                was = np.where(np.isfinite(prev_v[k]), prev_v[k], was)
            gain = v[k] - was
            limit = np.full(len(k), REINSERT_ACCEL_MPS2 * dt)
            if type_accel:
                bound = np.array([type_accel.get(ledger.veh_type[i], np.nan) for i in vidx[k].tolist()])
                limit = np.where(np.isfinite(bound),
                                 np.minimum(limit, VTYPE_ACCEL_MARGIN * bound * dt + SPEED_TOL_MPS), limit)
            fast = gain > limit
            stood = was <= 0.1
            along = net.lane_length[lp] - p0 + pos[k]
            fresh[k[stood & (fast | (along > v[k] * dt + net.jump_slack_m + JUMP_TOL_M))]] = True
            m = ~stood  # a moving car put back (a collision's teleport): faster or farther than it could go
            fresh[k[m][fast[m] | net.jumped(lp[m], p0[m], lane[k][m], pos[k][m],
                                            np.maximum(v[k][m], was[m]) * dt + net.jump_slack_m)]] = True
    return fresh


def on_road_acceleration(a, vidx, joined, prev, kids, get_accel) -> None:
    """Into ``a``: SUMO's acceleration of the step just made (getAcceleration: (v_t − v_t−1)/Δt,
    exact) for the vehicles of slots ``joined`` that were on the road when they were first
    seen (no speed of theirs read before, ``prev`` NaN): an Accountant attached mid-run, an
    FCD replay from ``--begin``. Without it their first step booked no kinetic-energy change
    (a = 0), one step's ½m(v_t² − v_t−1²) off each. A replay whose file has no acceleration
    leaves NaN (then 0)."""
    j = np.flatnonzero(np.isin(vidx, joined) & np.isnan(prev))
    for i in j.tolist():
        x = get_accel(kids[i])
        a[i] = np.nan if x is None else float(x)
