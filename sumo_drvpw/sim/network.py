"""The network table (sumolib): edges with class and length, lanes with robust slope profiles.

Internal junction lanes (ids starting with ``:``) are booked on the edge they lead to
(following chains of internal lanes), so every joule lands on a real edge and its road
class; ``summary.json`` says so under ``"internal_edges"``.

Robust slope: SUMO's ``getSlope`` comes from the vehicle's front and back positions and
is noisy on real networks (MoST: ±80° on short stretches). Each lane's 3D shape is
resampled every ``BIN_M`` metres; the slope at a point is the rise over a centred window
of ``window`` metres of horizontal distance (shrunk at the lane ends, the whole lane if
shorter), θ = atan(Δz/Δs), clipped to ±``max_rad`` — and what clipping takes off is
spread over the lane's other bins, so that the profile still climbs the lane's rise
(:func:`lane_profile`). The loop books a vehicle's grade from the profile's elevation at
the step's start and end (:meth:`Network.elevation`), so m·g·Δz over a route is exact,
clipped or not; no step steeper than ``max_rad`` (a rise beyond it, an elevation step
between two lanes, is carried to the vehicle's next steps: :meth:`Network.step_grade`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.sim.lane_geometry import BIN_M, flat_profile, lane_headings, lane_profile
from sumo_drvpw.sim.scenario import MAX_RAD_LIMIT, RoadClassRule

#: Front-to-back distance of the raw (getSlope-like) geometric slope: a car length [m].
RAW_LENGTH_M = 5.0
#: a vehicle found on another edge farther along than the step moved it by more than this
#: [m] jumped there (a teleport): its rise starts afresh (:meth:`Network.step_grade`);
#: FCD's positions and speeds to 2 decimals, SUMO's lane lengths, lie well within it
JUMP_TOL_M = 0.5
#: the acceleration [m/s²] a vehicle may gain and lose again between two FCD rows written
#: less often than the step (unseen steps): SUMO's default accel is 2.6 (passenger) or less,
#: 6.0 for a motorcycle; a car faster in between covers up to ¼·a·Δt² more road
HIDDEN_ACCEL_MPS2 = 5.0


@dataclass
class Network:
    """Edges (non-internal) and lanes (all) as arrays; lookup dicts built once.

    Attributes
    ----------
    edge_ids, edge_class, edge_type : per edge
    edge_length : length of the edge's first lane [m]
    edge_speed : speed limit [m/s]
    edge_shapes : 2D polyline per edge (for maps)
    lane_index : lane id → lane number
    lane_edge : lane number → edge number (internal lanes: the edge they lead to)
    lane_length : SUMO lane length (3D) [m], the scale of ``getLanePosition``
    lane_offset, lane_nbins : where each lane's profile starts in ``profile``
    profile : robust slope per bin [rad]; ``clipped`` marks bins cut at ±max_rad
    """

    path: Path
    edge_ids: list[str]
    edge_class: np.ndarray
    edge_type: list[str]
    edge_length: np.ndarray
    edge_speed: np.ndarray
    edge_shapes: list[np.ndarray]
    lane_index: dict[str, int]
    lane_edge: np.ndarray
    lane_length: np.ndarray
    lane_offset: np.ndarray
    lane_nbins: np.ndarray
    profile: np.ndarray
    clipped: np.ndarray
    classes: list[str]
    #: per lane, nb + 1 values: the elevation the profile climbs to at each bin edge [m]
    #: (from the shape's first z to its last: :func:`lane_profile`); lane ``k``'s start at
    #: ``lane_offset[k] + k``
    z_node: np.ndarray | None = None
    #: the slope limit the profile keeps [rad]
    max_rad: float = 0.25
    #: per lane: the steepest rise of its profile per metre of SUMO position [-] (the slope
    #: limit, more where the lane's length is shorter than its shape or it is an elevation step)
    lane_steep: np.ndarray | None = None
    raw: np.ndarray | None = None
    heading_deg: np.ndarray | None = None
    #: per lane: the shortest lane length of its edge [m]; a car whose position stays
    #: below it cannot have left the edge, whichever of its lanes it changed to
    lane_end: np.ndarray | None = None
    #: per lane: number of the edge it belongs to, internal edges included (unlike
    #: ``lane_edge``, which maps internal lanes to the edge they lead to)
    lane_own_edge: np.ndarray | None = None
    #: per lane: the opposite-direction lane SUMO lets vehicles overtake on (the net's
    #: ``<neigh>``, netconvert --opposites.guess), -1 none; its positions run the other way
    lane_opposite: np.ndarray | None = None
    #: per lane: how far its edge's lanes' profiles part [m] (sim/lane_spread.py)
    lane_spread: np.ndarray | None = None
    #: lane ids in lane-number order (for naming lanes in the summary)
    lane_ids: list[str] | None = None
    #: False when no lane shape has a z coordinate other than 0 (slopes are then all 0)
    has_elevation: bool = True
    #: share of the lane length whose shape carries a non-zero z [-]
    z_share: float = 1.0
    #: per bin: the lane centre line's x, y at the bin centre [m]; per lane: width [m]
    #: (to tell a parked vehicle in FCD from a standing one: :func:`off_lane`)
    centre_x: np.ndarray | None = None
    centre_y: np.ndarray | None = None
    lane_width: np.ndarray | None = None
    #: road [m] a vehicle may cover between two steps beyond max(v_t−1, v_t)·Δt: 0 live;
    #: an FCD written less often than its run's step sets :func:`hidden_steps_slack`
    jump_slack_m: float = 0.0

    def bin_index(self, lane: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Index into the per-bin arrays (``profile``, ``clipped``, ``raw``,
        ``heading_deg``) of lane numbers ``lane`` at positions ``pos`` [m]."""
        b = np.minimum((np.maximum(pos, 0.0) * (1.0 / BIN_M)).astype(np.int64), self.lane_nbins[lane] - 1)
        return self.lane_offset[lane] + b

    def heading(self, lane: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Direction of the lane at ``pos`` [deg clockwise from north, SUMO's angle]."""
        return self.heading_deg[self.bin_index(lane, pos)]

    def elevation(self, lane: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Elevation [m] of the robust profile at lane numbers ``lane``, positions ``pos``
        [m] (linear within a bin): its differences along a vehicle's path are the rise the
        profile's slopes integrate to, across lanes and junctions alike."""
        b = np.minimum((np.maximum(pos, 0.0) * (1.0 / BIN_M)).astype(np.int64), self.lane_nbins[lane] - 1)
        frac = np.clip((pos - b * BIN_M) / np.maximum(np.minimum(self.lane_length[lane] - b * BIN_M, BIN_M), 1e-9),
                       0.0, 1.0)
        i = self.lane_offset[lane] + lane + b
        return self.z_node[i] + frac * (self.z_node[i + 1] - self.z_node[i])

    def step_grade(self, lane, pos, ds, last, theta, reach=None) -> tuple[np.ndarray, np.ndarray]:
        """The grade of each vehicle's step, and where it is now.

        θ with sin θ = Δz/Δs: Δz the rise of the profile (:meth:`elevation`) from where the
        vehicle was at its last step to lane numbers ``lane``, positions ``pos`` [m], across
        lanes and junctions; Δs = ``ds``, the distance the step books (v·Δt [m]). So
        m·g·v·sin θ·Δt = m·g·Δz and a route's potential energy is booked exactly. ``theta``
        (the slope at the position) where the step's start is unknown (first step, after a
        teleport or a parking: NaN elevation), Δs shorter than 1 cm, or the rise steeper than
        the profile allows over the road covered (a jump: moveTo with positions read).

        No step books a grade steeper than ``max_rad``: where the profile rises faster over
        a step — a lane's elevation step to the next (MoST: 7.6 m between two lanes, booked
        at 1.10 rad, 2.7 MW of a trailer's grade power), a lane steeper on average than the
        limit — the step books the limit's rise, sin(max_rad)·Δs, and the rest is carried
        to the vehicle's next steps (its rows' fourth column), so a route's potential energy
        stays m·g·Δz but for what a trip's last steps still carry.

        ``last`` : (n, 4) rows [lane, pos, z, rise not yet booked] of each vehicle's last
        step (NaN: none). ``reach`` : the road [m] the vehicle may have covered since (default
        ``ds``): max(v_t−1, v_t)·Δt, so that an FCD written less often than the step
        (``--device.fcd.period 2`` at 1-s steps: a braking car covers more than v_t·Δt between
        its rows) is no jump; a teleported car stood before it reappears (v_t−1 = 0), so that
        bound is its v_t·Δt. Returns (θ, the rows of this step)."""
        z = self.elevation(lane, pos)
        dz = z - last[:, 2]
        prev = np.where(np.isfinite(last[:, 0]), last[:, 0], lane).astype(np.int64)
        # a jump rises faster than the profile lets a vehicle climb over the road covered (v·Δt, or pos on one lane)
        road = np.maximum((ds if reach is None else np.maximum(ds, reach)) + self.jump_slack_m,
                          np.where(last[:, 0] == lane, pos - last[:, 1], 0.0))
        steep = np.maximum(self.lane_steep[lane], self.lane_steep[prev])
        ok = np.isfinite(dz)  # (+ FCD's cm, + how far the lanes of an edge part: a lane change, sim/lane_spread.py)
        spread = 0.0 if self.lane_spread is None else np.maximum(self.lane_spread[lane], self.lane_spread[prev])
        ok[ok] = (np.abs(dz) <= road * steep + spread + 0.01 * np.minimum(road, 1.0))[ok]
        still, ok = ok & (ds < 0.01), ok & (ds >= 0.01)  # (< 1 cm: booked at the slope, the rest carried)
        if self.lane_own_edge is not None and ok.any():
            # a jump to another edge (a teleport SUMO starts and ends in one step, which FCD
            # shows without a gap; the live run hears of it): the road from the last position
            # to its lane's end and on to this position, or the straight line between them
            # (a junction crossed in between: its lane is longer than that line), is longer
            # than the step covered (the line: bins of BIN_M, a lane change in the step)
            k = np.flatnonzero(ok & (self.lane_own_edge[prev] != self.lane_own_edge[lane]))
            if len(k):
                ok[k[self.jumped(prev[k], last[k, 1], lane[k], pos[k], road[k])]] = False
        owed = last[:, 3] if last.shape[1] > 3 else np.zeros(len(lane))  # (nan_to_num: slow on a few rows)
        owed = owed.copy() if np.isfinite(owed).all() else np.nan_to_num(owed)
        if ok.any():  # sin θ = Δz/(v·Δt): m·g·v·sin θ·Δt = m·g·Δz, at most sin(max_rad)
            want = np.where(ok, dz + owed, 0.0)
            lim = np.sin(min(self.max_rad, 0.5 * np.pi)) * np.where(ok, ds, 0.0)
            booked = np.clip(want, -lim, lim)
            theta = np.where(ok, np.arcsin(np.clip(booked / np.where(ok, ds, 1.0), -1.0, 1.0)), theta)
            owed = np.where(ok, want - booked, owed)
        # (a step booked from the slope — a first step, one < 1 cm, e.g. a lane change standing — at most
        # max_rad too: a lane steeper on average keeps its mean gradient; a short step's rest is carried)
        theta = np.clip(theta, -min(self.max_rad, 0.5 * np.pi), min(self.max_rad, 0.5 * np.pi))
        owed = np.where(still, owed + np.where(still, dz, 0.0) - np.sin(theta) * ds, owed)
        return theta, np.array([lane, pos, z, owed], float).T  # (n, 4); np.column_stack's, at less cost

    def jumped(self, lp, p0, ln, p1, road) -> np.ndarray:
        """Which moves from lane numbers ``lp``, positions ``p0`` [m] to lanes ``ln`` of
        other edges, positions ``p1`` [m] cover more than ``road`` [m]: a jump (a teleport SUMO
        starts and ends in one step, which FCD shows without a gap). The road from the last
        position to its lane's end and on to this position, or the straight line between them
        (a junction crossed in between: its lane is longer than that line), is longer than
        ``road`` (the line: bins of BIN_M, a lane change in the step); a car overtaking on an
        opposite-direction lane counts that lane's positions back."""
        along = self.lane_length[lp] - p0 + p1
        if self.lane_opposite is not None:
            o0, o1 = self.lane_opposite[lp] >= 0, self.lane_opposite[ln] >= 0
            along = (np.minimum(self.lane_length[lp] - p0, np.where(o0, p0, np.inf))
                     + np.minimum(p1, np.where(o1, self.lane_length[ln] - p1, np.inf)))
            pair = (self.lane_opposite[lp] == ln) | (self.lane_opposite[ln] == lp)  # same road
            along[pair] = np.abs(0.5 * (self.lane_length[lp] + self.lane_length[ln]) - p0 - p1)[pair]
        jump = along > road + JUMP_TOL_M
        if self.centre_x is not None:
            i, j = self.bin_index(lp, p0), self.bin_index(ln, p1)
            line = np.hypot(self.centre_x[i] - self.centre_x[j], self.centre_y[i] - self.centre_y[j])
            jump |= line > road + BIN_M + self.lane_width[lp] + JUMP_TOL_M
        return jump

    def place(self, lane: np.ndarray, pos: np.ndarray) -> np.ndarray:
        """Rows [lane, pos, z, 0] of vehicles at lane numbers ``lane``, positions ``pos`` [m]
        (as :meth:`step_grade` returns them): where their next step starts (a rise not yet
        booked went with the jump's potential energy, booked apart: sim/teleport.put_back)."""
        z = self.elevation(lane, pos) if self.z_node is not None else np.full(len(lane), np.nan)
        return np.column_stack([lane, pos, z, np.zeros(len(lane))])

    def own_side_after(self, last, ds, lane, pos):
        """:meth:`own_side` for vehicles whose last step ended at rows ``last`` [lane, pos, z]
        (:meth:`step_grade`) and that moved ``ds`` [m] since (v·Δt)."""
        known = np.isfinite(last[:, 0])
        return self.own_side(np.where(known, last[:, 0], -1).astype(np.int64), last[:, 1] + ds, lane, pos)

    def own_side(self, tracked, pred, lane, pos):
        """Lane numbers and positions [m] read (``lane``, ``pos``) of vehicles tracked on lanes
        ``tracked`` to positions ``pred`` [m]: one found on an opposite-direction lane
        (overtaking; SUMO counts its positions the other way) where its own lane's place
        matches the tracked one and the read does not (on the same edge within
        :data:`JUMP_TOL_M` + one bin, or that far past the tracked lane's end on the next),
        is put back on its own lane at that place, so that tracking it by v·Δt moves it on."""
        if self.lane_opposite is None or not len(lane):
            return lane, pos
        opp = np.where(lane >= 0, self.lane_opposite[np.maximum(lane, 0)], -1)
        k = np.flatnonzero((tracked >= 0) & (opp >= 0))  # on a lane with an opposite one
        if not len(k):
            return lane, pos
        t, o, p_pred, ln, p = tracked[k], opp[k], pred[k], lane[k], pos[k]
        fwd = np.maximum(0.5 * (self.lane_length[o] + self.lane_length[ln]) - p, 0.0)

        def near(lanes, at):  # where (lanes, at) is where the tracked position says
            same = self.lane_own_edge[lanes] == self.lane_own_edge[t]
            return (np.abs(np.where(same, at - p_pred, p_pred - self.lane_length[t] - at))
                    <= BIN_M + JUMP_TOL_M + self.jump_slack_m)

        back = near(o, fwd) & ~near(ln, p)
        if back.any():
            lane, pos = lane.copy(), pos.copy()
            lane[k[back]], pos[k[back]] = o[back], fwd[back]
        return lane, pos

    def slope(self, lane: np.ndarray, pos: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Robust slope [rad] and clipped flag at lane numbers ``lane``, positions ``pos`` [m]."""
        i = self.bin_index(lane, pos)
        return self.profile[i], self.clipped[i]


def hidden_steps_slack(step: float | None, dt: float | None) -> float:
    """:attr:`Network.jump_slack_m` for rows ``dt`` [s] apart from a run stepped every
    ``step`` [s]: ¼·HIDDEN_ACCEL_MPS2·Δt² when rows are sparser than the step (a car that
    sped up and slowed again between them), else 0."""
    if not step or not dt or dt <= step + 1e-9:
        return 0.0
    return 0.25 * HIDDEN_ACCEL_MPS2 * dt * dt


def lane_numbers(lane_index: dict, lane_ids) -> np.ndarray:
    """Lane numbers of SUMO lane ids (-1 for a lane the network lacks)."""
    try:
        return np.fromiter(map(lane_index.__getitem__, lane_ids), np.int64, len(lane_ids))
    except KeyError:  # a lane the net file lacks (should not happen): no lane
        return np.fromiter((lane_index.get(x, -1) for x in lane_ids), np.int64, len(lane_ids))


class LaneNumbers:
    """:func:`lane_numbers` for a run's reads, counting the reads of lane ids the network
    lacks (``unknown``; ``first`` the first of them). Reads of such lanes only
    (:data:`FOREIGN_READS` of them, none on its lanes yet) are a UserError naming
    ``net_file``: the scenario's network is not the one SUMO runs (its vehicles were booked
    nowhere: zeros, silently). ``net_file`` None: reads not counted (an FCD replay, which
    checks its rows' lanes itself). The ids are looked at one by one only when one is
    unknown (a KeyError of the fast path)."""

    FOREIGN_READS = 20

    def __init__(self, lane_index: dict, net_file=None):
        self.index, self.net_file = lane_index, net_file
        self.unknown, self.first, self.any_known = 0, None, False

    def __call__(self, lane_ids) -> np.ndarray:
        if self.net_file is None:
            return lane_numbers(self.index, lane_ids)
        try:
            out = np.fromiter(map(self.index.__getitem__, lane_ids), np.int64, len(lane_ids))
        except KeyError:
            bad = [x for x in lane_ids if x not in self.index]
            self.unknown += len(bad)
            if self.first is None:
                self.first = bad[0]
            out = np.fromiter((self.index.get(x, -1) for x in lane_ids), np.int64, len(lane_ids))
        if not self.any_known:
            self.any_known = bool((out >= 0).any())
            if not self.any_known and self.unknown >= self.FOREIGN_READS:
                raise UserError(f"SUMO's vehicles drive on lanes the network {self.net_file} lacks (the "
                                f"first: {self.first!r}; none on its lanes): the scenario's network is not "
                                "the one SUMO runs — give the net-file SUMO runs")
        return out

    def warning(self) -> str | None:
        """What the run's summary says of reads on lanes the network lacks, if any."""
        if not self.unknown:
            return None
        return (f"{self.unknown} reads of vehicles on lanes the network {Path(str(self.net_file)).name} lacks "
                f"(the first: {self.first!r}) were not booked: is the scenario's network the one SUMO runs?")


#: a vehicle standing farther than this beyond its lane's edge is no longer on the lane:
#: SUMO has parked it beside (a parking stop, a parkingArea) [m]
PARKED_BEYOND_EDGE_M = 0.1
#: … unless it is farther than this from the lane: its x, y are not the network's
#: (``--fcd-output.geo``/``.utm``) or an explicit parking space far away [m]
PARKED_MAX_OFFSET_M = 50.0


def off_lane(net: Network, lane: np.ndarray, pos: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Whether points (x, y) [m] lie beside their lanes (lane numbers ``lane``, SUMO
    position ``pos``): farther from the lane's centre line than half its width plus
    ``PARKED_BEYOND_EDGE_M``, and nearer than ``PARKED_MAX_OFFSET_M``. A vehicle on its
    lane has its front centre within the lane (the sublane model included); SUMO draws a
    parked one beside it, at the parking space. Lanes < 0 and missing x, y: False."""
    lane = np.asarray(lane, np.int64)
    out = np.zeros(len(lane), bool)
    ok = (lane >= 0) & np.isfinite(x) & np.isfinite(y) & np.isfinite(pos)
    if net.centre_x is None or not ok.any():
        return out
    i = net.bin_index(lane[ok], np.asarray(pos, float)[ok])
    h = np.radians(net.heading_deg[i])
    dx, dy = np.asarray(x, float)[ok] - net.centre_x[i], np.asarray(y, float)[ok] - net.centre_y[i]
    lateral = np.abs(dx * np.cos(h) - dy * np.sin(h))  # across the heading (0° = north)
    out[ok] = ((lateral > 0.5 * net.lane_width[lane[ok]] + PARKED_BEYOND_EDGE_M)
               & (lateral <= PARKED_MAX_OFFSET_M))
    return out


def load_network(path: Path, rule: RoadClassRule, window: float = 20.0, max_rad: float = 0.25) -> Network:
    """:func:`read_network`, kept on disk for the next load of the same file, settings and code (sim/net_cache.py)."""
    from sumo_drvpw.sim.net_cache import cached_network
    return cached_network(path, (rule, float(window), float(max_rad)), lambda: read_network(path, rule, window, max_rad))


def read_network(path: Path, rule: RoadClassRule, window: float = 20.0, max_rad: float = 0.25) -> Network:
    """Read a SUMO network with sumolib and build the edge/lane table (see module doc)."""
    import sumolib

    from sumo_drvpw.sim.lane_spread import lane_spread

    if not 0 < max_rad <= MAX_RAD_LIMIT:
        raise UserError(f"[slope] max_rad must be above 0 and at most {MAX_RAD_LIMIT:g} rad (86°), got {max_rad:g}")
    try:
        net = sumolib.net.readNet(str(path), withInternal=True)
    except Exception as e:  # sumolib raises assorted SAX/IO errors
        raise UserError(f"SUMO network {path}: cannot read: {e}") from None
    edges = [e for e in net.getEdges() if e.getFunction() != "internal"]
    if not edges or not any(e.getLanes() for e in edges):
        raise UserError(f"SUMO network {path}: not a SUMO network (no edges with lanes in it)")
    edge_ids = [e.getID() for e in edges]
    eidx = {e: i for i, e in enumerate(edge_ids)}
    types = [e.getType() or "" for e in edges]
    speeds = np.array([e.getSpeed() for e in edges], float)
    classes = np.array([rule.classify(e.getID(), t, s, set().union(*(ln.getPermissions() for ln in e.getLanes())))
                        for e, t, s in zip(edges, types, speeds)], dtype=object)  # (rail, waterway: no road)
    lanes = [ln for e in net.getEdges() for ln in e.getLanes()]
    lane_index = {ln.getID(): i for i, ln in enumerate(lanes)}

    def target_edge(lane, depth=0) -> int:
        edge = lane.getEdge()
        if edge.getFunction() != "internal":
            return eidx[edge.getID()]
        if depth > 20:
            return -1
        for c in lane.getOutgoing():
            t = target_edge(c.getToLane(), depth + 1)
            if t >= 0:
                return t
        return -1

    lane_edge = np.array([target_edge(ln) for ln in lanes], np.int64)
    # an internal lane leading nowhere (dead end): book it on the edge it comes from
    for i in np.flatnonzero(lane_edge < 0):
        inc = lanes[i].getIncoming() if hasattr(lanes[i], "getIncoming") else []
        lane_edge[i] = eidx.get(inc[0].getEdge().getID(), 0) if inc else 0
    profs, clips, raws, znodes, steep, shapes = [], [], [], [], [], []
    z_len = 0.0
    for ln in lanes:
        shape = ln.getShape3D()
        shapes.append(shape)
        has_z = any(len(p) > 2 and p[2] != 0.0 for p in shape)
        if has_z:
            z_len += ln.getLength()
        if not has_z and len(shape) >= 2:
            # a lane without z (most of a network built without elevation): its profiles
            # are 0, as lane_profile gives them, at a fraction of the time
            th, cl, zn = flat_profile(ln.getLength())
            rise, raw = 0.0, th
        else:
            th, cl, zn = lane_profile(shape, ln.getLength(), window, max_rad, nodes=True)
            pos_w = np.diff(np.minimum(np.arange(len(zn)) * BIN_M, max(ln.getLength(), 1e-9)))
            rise = float(np.max(np.abs(np.diff(zn)) / np.maximum(pos_w, 1e-9)))
            raw = lane_profile(shape, ln.getLength(), RAW_LENGTH_M, np.inf, behind=True)[0]
        profs.append(th)
        clips.append(cl)
        znodes.append(zn)
        steep.append(rise)
        raws.append(raw)
    heads, cxs, cys = lane_headings(shapes, [ln.getLength() for ln in lanes])
    lane_length = np.array([ln.getLength() for ln in lanes], float)
    with_lanes = [e for e in net.getEdges() if e.getLanes()]  # lanes are listed edge by edge
    lane_end = np.concatenate(
        [np.full(len(e.getLanes()), min(ln.getLength() for ln in e.getLanes()))
         for e in with_lanes] or [np.zeros(0)])
    lane_own_edge = np.repeat(np.arange(len(with_lanes)), [len(e.getLanes()) for e in with_lanes]).astype(np.int64)
    nb = np.array([len(p) for p in profs], np.int64)
    off = np.concatenate([[0], np.cumsum(nb)[:-1]]).astype(np.int64)
    all_classes = list(rule.classes)
    for c in classes:
        if c not in all_classes:
            all_classes.append(c)
    out = Network(
        path=Path(path), edge_ids=edge_ids, edge_class=classes, edge_type=types,
        edge_length=np.array([e.getLength() for e in edges], float), edge_speed=speeds,
        edge_shapes=[np.asarray(e.getLanes()[0].getShape(), float)[:, :2] for e in edges],
        lane_index=lane_index, lane_edge=lane_edge,
        lane_length=lane_length, lane_end=lane_end, lane_own_edge=lane_own_edge,
        lane_offset=off, lane_nbins=nb, profile=np.concatenate(profs), z_node=np.concatenate(znodes),
        clipped=np.concatenate(clips), classes=all_classes, raw=np.concatenate(raws),
        heading_deg=np.concatenate(heads), lane_ids=[ln.getID() for ln in lanes],
        centre_x=np.concatenate(cxs), centre_y=np.concatenate(cys),
        lane_width=np.array([ln.getWidth() for ln in lanes], float), max_rad=float(max_rad),
        lane_opposite=np.array([lane_index.get(getattr(ln, "getNeigh", lambda: None)() or "", -1)
                                for ln in lanes], np.int64),
        lane_steep=np.maximum(np.array(steep, float), np.tan(max_rad)),
        has_elevation=z_len > 0.0, z_share=float(z_len / max(float(lane_length.sum()), 1e-9)))
    out.lane_spread = lane_spread(out)
    return out
