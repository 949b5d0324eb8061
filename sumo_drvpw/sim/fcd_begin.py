"""An FCD replay from ``--begin`` (a run's warm-up left out): the vehicles of its first
timestep were driving already. Their first step books the kinetic-energy change SUMO gave
them in it, as a live Accountant attached at that time does (sim/reader.on_road_acceleration):
from the file's acceleration where SUMO wrote it (``--fcd-output.acceleration``), else from
the speeds of the timestep left out just before."""

from __future__ import annotations

import numpy as np
import pandas as pd


def accel_at_begin(first: dict, before: dict, t_first: float, t_before: float) -> dict:
    """The first replayed timestep's rows (a replay from ``--begin``) with their acceleration
    filled, where the file has none, from the speeds of the timestep before it (``before``,
    left out): (v_t − v_t−1)/Δt, SUMO's getAcceleration, for the vehicles driving then; the
    first step of a vehicle already on the road books its kinetic-energy change as a live
    Accountant attached then does (sim/reader.on_road_acceleration); rows sparser than the
    step give the mean acceleration between them, as the loop's (v_t − v_t−1)/Δt does.
    Persons and vehicles not in ``before`` keep NaN (then 0)."""
    n = len(first["id"])
    acc = np.asarray(first["accel"], float).copy() if "accel" in first else np.full(n, np.nan)
    if n == 0 or not np.isnan(acc).any() or not len(before["id"]) or t_first <= t_before:
        return first
    ok = ~np.asarray(before["person"], bool) if "person" in before else np.ones(len(before["id"]), bool)
    was = pd.Series(np.asarray(before["speed"], float)[ok], index=np.asarray(before["id"])[ok])
    was = was[~was.index.duplicated()]
    prev = pd.Series(np.asarray(first["id"])).map(was).to_numpy(float)
    fill = np.isnan(acc)
    acc[fill] = (np.asarray(first["speed"], float)[fill] - prev[fill]) / (t_first - t_before)
    return {**first, "accel": acc}


def begin_frame(df: pd.DataFrame, t_before: float, t_first: float) -> pd.DataFrame:
    """``df``'s rows from ``t_first`` on, the first timestep's accelerations filled from the
    timestep ``t_before`` (:func:`accel_at_begin`)."""
    first = df["time"].to_numpy() == t_first
    cols = ["id", "speed", "person", *(["accel"] if "accel" in df.columns else [])]
    got = accel_at_begin({k: df.loc[first, k].to_numpy() for k in cols},
                         {k: df.loc[df["time"].to_numpy() == t_before, k].to_numpy() for k in cols},
                         t_first, t_before)
    out = df[df["time"].to_numpy() >= t_first].copy()
    if "accel" in got:
        if "accel" not in out.columns:
            out["accel"] = np.nan
        out.loc[out["time"].to_numpy() == t_first, "accel"] = got["accel"]
    return out
