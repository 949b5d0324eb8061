"""Standstill stretches of a drive log that are no standstill: external charging (energy into
the traction battery while the car stands, below) and a lost speed signal
(:func:`speed_dropout_mask`: the speed reads 0 while the measured power drives the car,
counted as ``excluded_speed_dropout``).

A battery-electric car that stands still cannot recuperate: its wheels deliver nothing, and
its auxiliaries (12 V net, heater, A/C, pumps) *draw* power. A standstill stretch whose
battery power (positive when discharging) stays below −``CHARGE_MIN_W`` is a charger
feeding the battery — a fast-charging stop inside a logged trip, or a log that runs on
while the car is plugged in. Those samples are no driving: they would teach a chain fit a
negative auxiliary power and turn a trip's net battery energy into a charge. They are left
out of the usable samples (of fits and of per-trip energies, measured and predicted alike)
and counted as ``excluded_charging``.

The rule reads the battery power, the target itself, but only where physics rules out every
driving explanation (no motion, power flowing in). It applies to the ``battery`` target of
cars without an engine: in a hybrid the engine may charge the battery at standstill, which
is part of its fuel story (:func:`sumo_drvpw.data.measured.measure` does not apply it when
the vehicle is a power-split hybrid or the log has a fuel-flow column).
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from sumo_drvpw.model.constants import STANDSTILL_MPS  # the car stands below it [m/s]

#: battery power below −this at standstill is a charger [W]: a household socket delivers
#: 1.4–2.3 kW (Mode 2, 6–10 A at 230 V), wallboxes and DC chargers more; a car at
#: standstill draws power, it does not return it
CHARGE_MIN_W = 1000.0
#: shortest standstill stretch read as charging [s] (a charger session, not a transient)
CHARGE_MIN_S = 30.0


def charging_mask(battery_w, speed_mps, time_s, trip_codes, min_w: float = CHARGE_MIN_W,
                  min_s: float = CHARGE_MIN_S) -> np.ndarray:
    """True on the samples of standstill stretches that are external charging.

    Parameters
    ----------
    battery_w : battery power per sample [W], positive when discharging (NaN: unknown)
    speed_mps : speed [m/s]; NaN counts as not standing
    time_s : time [s]; trip_codes : trip code per sample (a stretch never crosses a trip)
    min_w : the median battery power of the stretch must be below −min_w
    min_s : the stretch must last at least min_s (first to last sample)

    A stretch is a run of contiguous samples of one trip with speed < 0.1 m/s; it is
    charging when it lasts ``min_s`` and its median finite battery power is below −``min_w``
    (the median, so that a plug-in transient or a logger spike does not decide).
    """
    p = np.asarray(battery_w, float)
    v = np.asarray(speed_mps, float)
    t = np.asarray(time_s, float)
    codes = np.asarray(trip_codes)
    n = p.size
    if n == 0:
        return np.zeros(0, bool)
    stand = np.isfinite(v) & (v < STANDSTILL_MPS)
    new = np.r_[True, (stand[1:] != stand[:-1]) | (codes[1:] != codes[:-1])]
    seg = np.cumsum(new) - 1
    frame = pd.DataFrame({"seg": seg[stand], "t": t[stand], "p": p[stand]})
    if frame.empty:
        return np.zeros(n, bool)
    g = frame.groupby("seg", sort=False)
    stats = pd.DataFrame({"span": g["t"].max() - g["t"].min(), "median": g["p"].median()})
    charging = stats.index[(stats["span"] >= min_s) & (stats["median"] < -min_w)]
    return stand & np.isin(seg, charging.to_numpy())


#: battery power above this at standstill is driving [W]: more than a standing car's
#: auxiliaries draw at their worst (a resistive cabin heater 5–7 kW, an A/C compressor 3–5 kW,
#: battery conditioning, 12 V), the power of driving at 50–100 km/h
DRIVE_MIN_W = 15000.0

#: [s] a standstill stretch drives above :data:`DRIVE_MIN_W` for at least this long to be a lost
#: speed: a logger whose speed lags the power (OBD, about 1–2 s) reads 0 while the car already
#: pulls away, for a second or two at each start, which is no dropout
DROPOUT_MIN_S = 10.0

#: [W] and it takes power back below minus this: braking. A standing vehicle never feeds its
#: battery but from a charger (a steady flow in, :func:`charging_mask`), so a stretch that both
#: drives and brakes moved; one that only draws much (an e-bus's 20–30 kW of air conditioning at
#: a stop, a truck's power take-off) stood
DROPOUT_BRAKE_W = 3000.0


def speed_dropout_mask(power_w, speed_mps, trip_codes, time_s, min_w: float = DRIVE_MIN_W,
                       min_s: float = DROPOUT_MIN_S, brake_w: float = DROPOUT_BRAKE_W) -> np.ndarray:
    """True on the samples of standstill stretches (runs of a trip with speed < 0.1 m/s) in
    which the measured power exceeds ``min_w`` for at least ``min_s`` seconds (each sample
    counts its interval to the next, at most 5 s) and falls below −``brake_w`` somewhere: the
    car drove and braked while its speed read 0 (a logger that lost the speed signal, as
    LeafSpy does for minutes), so none of the stretch's samples is a standstill (its low-power
    samples are cruising). A lagging speed at a start or a stop, a spike, a large standing
    load and charging (power flowing in, never out) do not decide."""
    p = np.asarray(power_w, float)
    v = np.asarray(speed_mps, float)
    t = np.asarray(time_s, float)
    codes = np.asarray(trip_codes)
    if p.size == 0:
        return np.zeros(0, bool)
    stand = np.isfinite(v) & (v < STANDSTILL_MPS)
    new = np.r_[True, (stand[1:] != stand[:-1]) | (codes[1:] != codes[:-1])]
    seg = np.cumsum(new) - 1
    last = np.r_[codes[1:] != codes[:-1], True]
    dt = np.where(last, 0.0, np.clip(np.r_[np.diff(t), 0.0], 0.0, 5.0))
    dt[~np.isfinite(dt)] = 0.0
    k = int(seg[-1]) + 1
    high = np.bincount(seg, weights=np.where(stand & (p > min_w), dt, 0.0), minlength=k)
    brakes = np.bincount(seg, weights=(stand & (p < -brake_w)).astype(float), minlength=k)
    return stand & (high[seg] >= min_s) & (brakes[seg] > 0)
