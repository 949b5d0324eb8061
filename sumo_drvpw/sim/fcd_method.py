"""How a recorded run moved its vehicles — Euler or ballistic — for an FCD replay: from the
FCD's own header, the scenario's SUMO options, or, where neither says (SUMO's tabular FCD
has no header), the rows themselves.

A step moves a vehicle v_t·Δt (Euler, SUMO's default) or (v_t−1 + v_t)/2·Δt (ballistic).
Booked the wrong way, a ballistic run's replay was 0.4 % long in distance and 0.3–0.7 % in
energy, without a word (a rehearsal, 2026-11-29: a 1-s ballistic run's CSV FCD).
"""

from __future__ import annotations

import numpy as np

#: rows of the file looked at to tell the method (the first ones)
PEEK_ROWS = 200_000
#: pairs of rows needed, each one step apart on one lane with the speed changing by ≥ 0.5 m/s
MIN_PAIRS = 20


def stated_method(sc, head: dict | None) -> str | None:
    """"ballistic" or "euler" by SUMO's rule (:func:`sumo_drvpw.sim.sumo_start.ballistic_update`)
    on the options of the FCD file's own header ``head`` (:func:`~sumo_drvpw.sim.fcd_read.header_options`:
    SUMO writes those of the run that differ from its defaults), else on the scenario's SUMO
    options and config; None when neither names either option (the rows tell:
    :func:`method_of_rows`; else SUMO's default, Euler)."""
    from sumo_drvpw.sim.sumo_start import ballistic_update, scenario_option

    keys = ("step-method.ballistic", "default.action-step-length")
    given = ([head.get(k) for k in keys] if head is not None
             else [scenario_option(sc, k) for k in keys])
    if head is None and all(g is None for g in given):
        return None
    return "ballistic" if ballistic_update(*given) else "euler"


def method_of_rows(cols: dict, dt: float | None) -> str | None:
    """The method the rows ``cols`` (an FCD block's: time, id, lane, pos, speed, person) were
    moved by: on pairs of one vehicle's rows one step ``dt`` apart on one lane, with the speed
    changing by at least 0.5 m/s, the distance Δpos against v_t·Δt and (v_t−1 + v_t)/2·Δt;
    the one whose median miss is under a quarter of the other's. None when fewer than
    :data:`MIN_PAIRS` pairs tell or neither fits (rows sparser than the step)."""
    t, ids = np.asarray(cols["time"], float), np.asarray(cols["id"], object)
    lane, pos, v = np.asarray(cols["lane"], object), np.asarray(cols["pos"], float), np.asarray(cols["speed"], float)
    keep = ~np.asarray(cols.get("person", np.zeros(len(t), bool)), bool)
    order = np.lexsort((t[keep], ids[keep]))
    t, ids, lane, pos, v = (a[keep][order] for a in (t, ids, lane, pos, v))
    if len(t) < 2:
        return None
    step = float(dt) if dt else float(np.median(np.diff(np.unique(t)))) if len(np.unique(t)) > 1 else 0.0
    if not step > 0:
        return None
    ok = ((ids[1:] == ids[:-1]) & (lane[1:] == lane[:-1]) & (np.abs(np.diff(t) - step) < 1e-6)
          & (np.abs(np.diff(v)) >= 0.5) & (np.diff(pos) > 0))
    if np.count_nonzero(ok) < MIN_PAIRS:
        return None
    ds = np.diff(pos)[ok]
    euler = np.median(np.abs(ds - v[1:][ok] * step))
    ballistic = np.median(np.abs(ds - 0.5 * (v[1:] + v[:-1])[ok] * step))
    if ballistic < 0.25 * euler:
        return "ballistic"
    if euler < 0.25 * ballistic:
        return "euler"
    return None


def recorded_method(sc, head: dict | None, fcd_file, dt: float | None) -> tuple[str, str | None]:
    """The method to replay ``fcd_file`` by, and a note when its rows told it (a tabular FCD
    without a header, a scenario that does not say)."""
    said = stated_method(sc, head)
    if said is not None:
        return said, None
    from pathlib import Path

    from sumo_drvpw.sim.fcd_read import iter_fcd_blocks

    first = next(iter(iter_fcd_blocks(fcd_file, PEEK_ROWS)), None)
    found = None if first is None else method_of_rows(first.cols, dt)
    if found != "ballistic":
        return "euler", None
    return "ballistic", (f"FCD {Path(fcd_file).name}: its rows move each vehicle by the mean of the step's "
                         "two speeds (SUMO's ballistic update), and neither the file nor the scenario names the "
                         "step method: replayed as ballistic (give the run's config with the scenario to say so)")
