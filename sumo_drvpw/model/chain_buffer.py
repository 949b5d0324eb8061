"""A charge-sustaining hybrid's usable battery window (``[chain] battery_usable_j``).

A fuel chain with ``recuperation_round_trip`` η_rt credits a hybrid's braking energy as the
engine output it replaces (model/chain.py). Unbounded (no window, the default), every braking
sample is credited, so a long descent books negative litres that a hybrid's small battery
could never hold. With a usable window W [J of battery energy] the braking energy goes
through a buffer of stored energy s (0 ≤ s ≤ W, empty at the start of a trip or of a
vehicle's run)::

    braking  (P < 0):  in  = √η_rt · min(−P, P_lim) · Δt            (battery energy offered)
                       acc = min(in, W − s);  s += acc               (only while there is room)
                       given back at the wheels later: √η_rt · acc   (credited now, as before)
    traction (P > 0):  out = min(s, min(P, P_lim) · Δt / √η_rt);  s −= out
                       (the stored energy drives the next traction, up to the motor's P_lim)

The round trip is split evenly between storing and giving back (√η_rt each way; a chain
declares η_rt only). Unbounded, acc = in and the credit is η_rt·max(P, −P_lim)·Δt, the
unbounded chain's to the joule. Over any stretch, Σ acc ≤ W + Σ out (energy conservation:
the buffer holds at most W).

Two ways to carry the state, one rule: samples of one series in time order (a drive log's
trips, ``trip`` resets the buffer to empty where it changes), or one sample per vehicle
whose state before the sample is ``stored_j`` (a SUMO step; the caller keeps each
vehicle's state between steps, live and in an FCD replay alike).
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.chain_values import _nonneg


#: the smallest battery energy a chain may declare other than 0 [J] (10 kJ, 2.8 Wh: braking at
#: 20 kW fills it in half a second; a Prius's usable window is about 0.5 kWh, 1.8 MJ): a smaller
#: number is a kWh or Wh figure written as joules (``battery_usable_j = 0.5`` held 0.5 J)
BATTERY_ENERGY_MIN_J = 1e4


def battery_energy(val, key: str, where: str) -> float:
    """A battery energy [J] of a chain (``battery_usable_j``, ``depleting.usable_j``): a number
    ≥ 0, refused between 0 and :data:`BATTERY_ENERGY_MIN_J` as kWh or Wh written as joules."""
    x = _nonneg(val, key, where)
    if 0 < x < BATTERY_ENERGY_MIN_J:
        raise UserError(f"{where} [chain]: '{key}' = {val!r} J is below any vehicle battery's "
                        f"(≥ {BATTERY_ENERGY_MIN_J:g} J): joules, not kWh or Wh ({val!r} kWh = {x * 3.6e6:g} J)")
    return x


def usable_window(doc: dict, round_trip, where: str) -> float:
    """``[chain] battery_usable_j`` checked: a number ≥ 0 (:func:`battery_energy`), for a chain
    with a round trip."""
    w = battery_energy(doc["battery_usable_j"], "battery_usable_j", where)
    if not round_trip:
        raise UserError(f"{where} [chain]: 'battery_usable_j' is the battery window of a hybrid's round trip: "
                        f"only with recuperation_round_trip > 0, got {doc['battery_usable_j']!r}")
    return w


def buffered_return(p_w, dt_s, round_trip: float, limit_w: float, window_j: float,
                    stored_j=None, trip=None, where: str = "<equation>") -> tuple[np.ndarray, np.ndarray]:
    """(wheel power the battery gives back for each sample's braking [W] (≥ 0, 0 while
    driving), the buffer's stored energy after each sample [J]).

    Parameters
    ----------
    p_w : driving power per sample [W] (NaN: no flow)
    dt_s : sample durations [s] (scalar or per sample)
    round_trip : η_rt in [0, 1]
    limit_w : the motor's power P_lim [W] (inf: none)
    window_j : usable battery energy W [J]
    stored_j : per-sample state before it (one vehicle each); None: one series in order
    trip : with ``stored_j`` None, trip id per sample: the buffer is empty at each trip's start
    where : the chain's file, named where the durations are missing
    """
    dt_s = _durations(dt_s, where)
    p = np.nan_to_num(np.asarray(p_w, float), nan=0.0)
    dt = np.broadcast_to(np.asarray(dt_s, float), p.shape)
    leg = np.sqrt(round_trip)
    brake = np.minimum(-np.minimum(p, 0.0), limit_w) * dt
    offer = leg * brake
    drive = np.minimum(np.maximum(p, 0.0), limit_w) * dt
    want = np.divide(drive, leg, out=np.zeros_like(drive), where=leg > 0)
    if stored_j is not None:  # one step of independent vehicles
        s0 = np.broadcast_to(np.asarray(stored_j, float), p.shape)
        acc = np.minimum(offer, np.maximum(window_j - s0, 0.0))
        after = s0 + acc - np.minimum(want, s0)
    else:
        acc, after = _series(offer, want, window_j, _starts(trip, p.size))
    given = np.divide(leg * acc, dt, out=np.zeros_like(acc), where=dt > 0)
    return given, after


def _durations(dt_s, where: str):
    """``dt_s``, which a battery's state needs: a UserError naming the chain's file without it."""
    if dt_s is None:
        raise UserError(f"{where} [chain]: a hybrid's battery (battery_usable_j, [chain.depleting]) needs each "
                        "sample's duration, which this use of the chain does not give")
    return dt_s


def _starts(trip, n: int) -> np.ndarray:
    """Where a new trip begins (the first sample always)."""
    start = np.zeros(n, bool)
    if n:
        start[0] = True
    if trip is not None and n > 1:
        t = np.asarray(trip)
        start[1:] = t[1:] != t[:-1]
    return start


def _series(offer, want, window: float, start) -> tuple[np.ndarray, np.ndarray]:
    """The buffer stepped through one series in order: (accepted [J], stored after [J])."""
    acc = np.zeros(offer.size)
    after = np.empty(offer.size)
    s = 0.0
    for i, (a, w, new) in enumerate(zip(offer.tolist(), want.tolist(), start.tolist())):
        if new:
            s = 0.0
        if a > 0.0:
            a = min(a, window - s)
            s += a
            acc[i] = a
        elif w > 0.0:
            s -= min(w, s)
        after[i] = s
    return acc, after
