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

#: positions along each lane where the profiles are compared (fractions of its length)
SAMPLES = 33


def lane_spread(net) -> np.ndarray:
    """Per lane of ``net`` (:class:`~sumo_drvpw.sim.network.Network`): the largest
    difference [m] between the profile elevations (:meth:`~sumo_drvpw.sim.network.Network.elevation`)
    of its edge's lanes at the same share of their length (0 for an edge of one lane, or
    a network without elevation)."""
    n = len(net.lane_length)
    if net.z_node is None or net.lane_own_edge is None or not n:
        return np.zeros(n)
    f = np.linspace(0.0, 1.0, SAMPLES)
    lane = np.repeat(np.arange(n, dtype=np.int64), SAMPLES)
    z = net.elevation(lane, np.tile(f, n) * np.repeat(net.lane_length, SAMPLES)).reshape(n, SAMPLES)
    g = pd.DataFrame(z).groupby(net.lane_own_edge)
    spread = (g.max() - g.min()).max(axis=1)
    return np.nan_to_num(spread.reindex(net.lane_own_edge).to_numpy(float))
