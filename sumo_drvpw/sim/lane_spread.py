"""How far the elevation profiles of one edge's lanes part (:func:`lane_spread`), which a
step's rise may hold beside the road it covered: a lane change within an edge — in the step,
or one the live run's tracked positions (:mod:`sumo_drvpw.sim.loop`) missed until its next
read, which may find the vehicle on another lane or on the next edge — crosses that
difference, and :meth:`sumo_drvpw.sim.network.Network.step_grade` books it as any rise
(clipped at the slope limit, the rest carried) rather than as a jump.

A 3D network's lanes each have their own shape: MoST's lanes of one edge lie up to 0.6 m
apart in the robust profile (3.8 m on edge -152409#0)."""

from __future__ import annotations

import numpy as np
import pandas as pd

def lane_spread(net) -> np.ndarray:
    """Per lane of ``net`` (:class:`~sumo_drvpw.sim.network.Network`): the largest
    difference [m] between the profile elevations (:meth:`~sumo_drvpw.sim.network.Network.elevation`)
    of its edge's lanes at the same position (0 for an edge of one lane, or a network
    without elevation). Compared at every node of the profiles' bins (BIN_M apart from each
    lane's start, and its end): the profile is linear between them, so lanes of equal length
    part at most there. (Before 2026-11-29 at 33 fractions of each lane's length: on a lane
    rising 3 m to a crest 100 m in and falling again, 2.906 m where the lanes part 2.940 m at
    106 m; a lane change standing there was taken for a jump and its 2.93-m rise lost.)"""
    from sumo_drvpw.sim.lane_geometry import BIN_M

    n = len(net.lane_length)
    if net.z_node is None or net.lane_own_edge is None or not n:
        return np.zeros(n)
    edge = np.asarray(net.lane_own_edge)
    length = np.asarray(net.lane_length, float)
    longest = pd.Series(length).groupby(edge).transform("max").to_numpy()
    nk = np.ceil(longest / BIN_M).astype(np.int64) + 2  # (nodes 0, BIN_M, …, and the lane's end)
    lane = np.repeat(np.arange(n, dtype=np.int64), nk)
    k = np.arange(len(lane), dtype=np.int64) - np.repeat(np.cumsum(nk) - nk, nk)
    pos = np.minimum(k * BIN_M, length[lane])
    pos[k == np.repeat(nk - 1, nk)] = length[lane][k == np.repeat(nk - 1, nk)]
    z = pd.DataFrame({"edge": edge[lane], "k": k, "z": net.elevation(lane, pos)})
    g = z.groupby(["edge", "k"])["z"]
    spread = (g.max() - g.min()).groupby(level=0).max()
    return np.nan_to_num(spread.reindex(edge).to_numpy(float))
