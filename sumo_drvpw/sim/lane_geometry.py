"""A lane's geometry from its shape (the network table's lanes, sim/network.py): its robust
slope profile per ``BIN_M`` bin, its rise kept where the profile is clipped, and its heading
and centre line per bin, batched over the lanes of a network."""

from __future__ import annotations

import numpy as np

#: Resolution of the lane slope profiles [m].
BIN_M = 2.0


def lane_profile(shape3d, length: float, window: float, max_rad: float, behind: bool = False, nodes: bool = False):
    """Robust slope profile of one lane: (θ per bin [rad], clipped flags[, z at the bin
    edges [m] with ``nodes``]).

    Parameters
    ----------
    shape3d : lane polyline [(x, y, z)] [m]
    length : SUMO lane length [m] (positions along the lane are in this scale)
    window : distance window [m]
    max_rad : clip limit [rad]

    The clipped profile keeps the lane's rise: what clipping takes off the steepest bins
    (an elevation spike, a step between two shapes) is spread over the bins with room below
    the limit, in proportion to that room (:func:`conserve_rise`), so the profile climbs from
    the shape's first z to its last one — potential energy is conserved over any route, as
    in SUMO's network, whatever is clipped. (A lane steeper on average than the limit, an
    elevation step, takes its mean gradient everywhere, and its ``clipped`` flags say so.)
    ``nodes``: the elevation the profile climbs to at each bin edge, nb + 1 values from the
    shape's first z.
    """
    p = np.asarray(shape3d, dtype=float)
    if p.ndim != 2 or len(p) < 2:
        return (np.zeros(1), np.zeros(1, bool)) + ((np.zeros(2),) if nodes else ())
    if p.shape[1] < 3:
        p = np.column_stack([p, np.zeros(len(p))])
    seg_h = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
    seg_3d = np.hypot(seg_h, np.diff(p[:, 2]))
    s_h = np.concatenate([[0.0], np.cumsum(seg_h)])    # horizontal distance
    s_3 = np.concatenate([[0.0], np.cumsum(seg_3d)])   # along-shape distance
    total_h, total_3 = s_h[-1], s_3[-1]
    nb = lane_bins(length)
    if total_h <= 1e-6:
        return (np.zeros(nb), np.zeros(nb, bool)) + ((np.full(nb + 1, p[0, 2]),) if nodes else ())
    scale = total_3 / max(length, 1e-9)  # SUMO position → along-shape distance
    # bin centres in SUMO position scale → along-shape → horizontal distance
    centre = np.minimum((np.arange(nb) + 0.5) * BIN_M * scale, total_3)
    sh = np.interp(centre, s_3, s_h)
    w = min(window, total_h)
    if behind:  # [s − w, s]: a vehicle's back and front
        hi = np.clip(sh, w, total_h)
        lo = hi - w
    else:
        lo = np.clip(sh - 0.5 * w, 0.0, total_h - w)
        hi = lo + w
    z_lo = np.interp(lo, s_h, p[:, 2])
    z_hi = np.interp(hi, s_h, p[:, 2])
    tan = (z_hi - z_lo) / np.maximum(hi - lo, 1e-9)
    clipped = np.abs(tan) > np.tan(max_rad) if np.isfinite(max_rad) else np.zeros(nb, bool)
    if not np.isfinite(max_rad):
        return (np.arctan(tan), clipped) + ((None,) if nodes else ())
    # horizontal length of each bin (edges at 0, BIN_M, …, length in SUMO positions)
    edges = np.minimum(np.arange(nb + 1) * BIN_M, length) * scale
    edges[-1] = total_3
    wid = np.diff(np.interp(edges, s_3, s_h))
    tan = conserve_rise(np.clip(tan, -np.tan(max_rad), np.tan(max_rad)), wid,
                        float(p[-1, 2] - p[0, 2]), float(np.tan(max_rad)))
    out = (np.arctan(tan), clipped)
    if nodes:
        out += (p[0, 2] + np.concatenate([[0.0], np.cumsum(tan * wid)]),)
    return out


def lane_bins(length):
    """The number of ``BIN_M`` bins of a lane of SUMO ``length`` [m] (at least one); of
    each lane for an array of lengths."""
    nb = np.maximum(1, np.ceil(np.maximum(length, 1e-9) / BIN_M).astype(np.int64))
    return int(nb) if np.ndim(nb) == 0 else nb


def flat_profile(length: float):
    """:func:`lane_profile` of a lane of ``length`` [m] whose shape (two points or more) has
    no z: (θ, clipped, z at the bin edges), all 0."""
    nb = lane_bins(length)
    return np.zeros(nb), np.zeros(nb, bool), np.zeros(nb + 1)


def conserve_rise(tan: np.ndarray, width: np.ndarray, rise: float, limit: float) -> np.ndarray:
    """Gradients ``tan`` (|tan| ≤ ``limit``) over bins of horizontal ``width`` [m], changed
    so that Σ tan·width = ``rise`` [m] with |tan| ≤ ``limit`` still: the missing rise goes
    to every bin in proportion to its room below the limit in that direction (the flattest
    bins take the most). Where the room is too small (the lane's mean gradient beyond the
    limit: a step in the network's elevation) every bin gets the lane's mean gradient, so the
    rise is kept there too (a route's potential energy is the network's)."""
    gap = rise - float(np.dot(tan, width))
    if gap == 0.0:
        return tan
    room = (limit - tan) if gap > 0 else (limit + tan)
    cap = float(np.dot(room, width))
    if cap <= abs(gap):  # steeper on average than the limit (an elevation step): its mean gradient
        return np.full_like(tan, rise / max(float(width.sum()), 1e-9))
    return tan + np.sign(gap) * (abs(gap) / cap) * room


def lane_heading(shape, length: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lane direction per ``BIN_M`` bin [deg clockwise from north]: the heading of the
    shape segment under each bin centre (what ``vehicle.getAngle`` reports for a car
    following the lane; it differs only while a car changes lanes); and the bin centres'
    x, y on the lane's centre line [m] (positions scaled from SUMO's lane length to the
    shape's length, as SUMO places a vehicle)."""
    p = np.asarray(shape, dtype=float)[:, :2]
    nb = lane_bins(length)
    if len(p) < 2:
        q = p[0] if len(p) else np.zeros(2)
        return np.zeros(nb), np.full(nb, q[0]), np.full(nb, q[1])
    d = np.diff(p, axis=0)
    seg = np.hypot(d[:, 0], d[:, 1])
    s = np.concatenate([[0.0], np.cumsum(seg)])
    ang = np.degrees(np.arctan2(d[:, 0], d[:, 1])) % 360.0
    centre = np.minimum((np.arange(nb) + 0.5) * BIN_M * (s[-1] / max(length, 1e-9)), s[-1])
    k = np.clip(np.searchsorted(s, centre, side="right") - 1, 0, len(seg) - 1)
    f = (centre - s[k]) / np.maximum(seg[k], 1e-12)
    return ang[k], p[k, 0] + f * d[k, 0], p[k, 1] + f * d[k, 1]


#: lanes of up to this many shape points are computed together by :func:`lane_headings`
HEADING_BATCH_POINTS = 16


def lane_headings(shapes: list, lengths) -> tuple[list, list, list]:
    """:func:`lane_heading` of every lane (shapes, SUMO lengths), as lists of arrays in lane
    order; the lanes of 2 … ``HEADING_BATCH_POINTS`` shape points (nearly all of a network)
    computed together, one batch per point count, with the operations :func:`lane_heading`
    makes for each (equal to rounding)."""
    n = len(shapes)
    heads: list = [None] * n
    cxs: list = [None] * n
    cys: list = [None] * n
    groups: dict[int, list[int]] = {}
    for i, sh in enumerate(shapes):
        if 2 <= len(sh) <= HEADING_BATCH_POINTS:
            groups.setdefault(len(sh), []).append(i)
        else:
            heads[i], cxs[i], cys[i] = lane_heading(sh, lengths[i])
    for m, idx in groups.items():
        p = np.array([[q[:2] for q in shapes[i]] for i in idx], float)  # lanes × m × 2
        length = np.array([lengths[i] for i in idx], float)
        d = np.diff(p, axis=1)
        seg = np.hypot(d[..., 0], d[..., 1])                             # lanes × (m − 1)
        s = np.concatenate([np.zeros((len(idx), 1)), np.cumsum(seg, axis=1)], axis=1)
        ang = np.degrees(np.arctan2(d[..., 0], d[..., 1])) % 360.0
        nb = lane_bins(length)
        lane = np.repeat(np.arange(len(idx)), nb)
        j = np.arange(len(lane)) - np.repeat(np.cumsum(nb) - nb, nb)
        total = s[:, -1]
        centre = np.minimum((j + 0.5) * BIN_M * (total / np.maximum(length, 1e-9))[lane], total[lane])
        # searchsorted(s, centre, "right") − 1, clipped to the lane's segments
        k = np.clip((s[lane, 1:] <= centre[:, None]).sum(axis=1), 0, m - 2)
        f = (centre - s[lane, k]) / np.maximum(seg[lane, k], 1e-12)
        cx = p[lane, k, 0] + f * d[lane, k, 0]
        cy = p[lane, k, 1] + f * d[lane, k, 1]
        cuts = np.cumsum(nb)[:-1]
        for i, h, x, y in zip(idx, np.split(ang[lane, k], cuts), np.split(cx, cuts), np.split(cy, cuts)):
            heads[i], cxs[i], cys[i] = h, x, y
    return heads, cxs, cys
