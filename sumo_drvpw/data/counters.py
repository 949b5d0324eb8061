"""Battery power from a battery management system's energy counters.

Many EV logs carry no battery voltage and current, but the BMS's cumulative counters of the
energy the battery has delivered and taken in: Hyundai's and Kia's CED and CEC ("cumulative
energy discharged / charged", kWh, in their BMS diagnostic response and Car Scanner's EV
PIDs), the JLU car's ``tot_disc`` and ``tot_char``. In a drive log they are
``battery_discharge_energy_j`` and ``battery_charge_energy_j`` [J], each non-decreasing within
a trip (where they start does not matter). Where a trip has no battery V·I, the battery
target is their rate (:func:`counter_power`).

The per-sample power keeps the counters' energy exactly (:class:`CounterView`): the counters
are read where either rises (and at each trip's and stretch's ends), their net taken as
linear in time between those instants, and differenced across each sample's time weight
``dt_s`` (half the way to each neighbour; none across a logging gap). So Σ P·dt_s over a
trip is the counters' change between its first and last reading (less what they count
across a logging gap, which no sample carries, as for V·I). How finely the power follows
the driving depends on the counters' step and how often they rise (:func:`describe`, in the
import's notes): a counter of 0.1-kWh steps books a trip's energy to within a step but
spreads it over the minutes between its steps. A fit therefore sees its model's power as
the counters would book it (calling the view on it): ``fit.chain.calibrate_battery``,
memory and streamed.

What a counter counts is the BMS's choice. On the JLU road trips (``scripts/jlu_counters.py``)
the discharge counter reads 1.1–2.3 % more than the terminal V·I and the charge counter
0.2–1.1 % less: the signs of a count at the cells' open-circuit voltage (terminal V·I plus
the pack's I²R on discharge, minus it on charge), though one resistance does not fit all
trips within a counter step (docs/energy-chain.md).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError

#: the counters, in the order (discharged, charged): the battery's net power is their rate's difference
COUNTERS = ("battery_discharge_energy_j", "battery_charge_energy_j")
#: the measured power's source text (one text for every batch of a streamed log: the
#: counters' steps are said where a log is imported, :func:`describe`)
COUNTER_SOURCE = "battery energy counters (discharged − charged)"
#: a fall of a counter within a trip larger than this share of its step is refused (a reset or
#: a wrong column); smaller falls are a logger's rounding and are held at the value before
FALL_TOLERANCE_STEPS = 0.5


def check_counters(df, p: Path, trip: np.ndarray) -> None:
    """Refuse a counter that falls within a trip by more than half its step, naming the file,
    the column and the first such row (a reset, a wrapped field or a column that is no counter)."""
    same = trip[1:] == trip[:-1]
    for c in COUNTERS:
        if c not in df:
            continue
        x = df[c].to_numpy(float, na_value=np.nan)
        rows = np.flatnonzero(np.isfinite(x))
        if len(rows) < 2:
            continue
        d = np.diff(x[rows])
        within = same[rows[1:] - 1] & (trip[rows[1:]] == trip[rows[:-1]])
        step = _step(d[within & (d > 0)])
        bad = within & (d < -FALL_TOLERANCE_STEPS * step)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            i, j = int(rows[k]), int(rows[k + 1])
            raise UserError(f"{p}: column '{c}' falls within trip '{df['trip_id'].iloc[j]}' at row {j} "
                            f"({x[i]:.6g} then {x[j]:.6g} J): a cumulative energy counter never falls "
                            "(a reset or wrapped counter: split the trip there; or the column is no counter)")


#: a counter whose rises span more than one step this often is read at a cadence slower than it
#: counts (the JLU car's: once a second): its reading at a rise is as far into its step as anywhere
CADENCE_MULTI_STEP_SHARE = 0.1


def _half_step(up: np.ndarray) -> float:
    """Half the step of a counter that reports each step as it is crossed (its rises ``up``
    nearly all one step): its reading where it rises is the energy it counted, elsewhere on
    average half a step less. 0 for a counter read at a cadence (rises of several steps at
    once are common): its reading is on average half a step short everywhere, which cancels."""
    step = _step(up)
    if step <= 0 or np.mean(up > 1.5 * step) > CADENCE_MULTI_STEP_SHARE:
        return 0.0
    return 0.5 * step


def _step(up: np.ndarray) -> float:
    """A counter's step: the median of its rises (0 when it never rises)."""
    return float(np.median(up)) if len(up) else 0.0


class CounterView:
    """The counters' view of a log: their knots (where they are read: each trip's first and
    last sample holding both, the samples at a logging gap, and every sample where either
    rises) and each sample's weight window (the reader's ``dt_s``: half the way to each
    neighbour over an interval that carries weight; a logging gap carries none, and then its
    two samples' weights together fall short of it, a gap being longer than any weighted
    interval beside it).

    :meth:`power` is the battery power the counters give; calling the view on any power
    series (or a 2-D array of columns) gives that series *as the counters would book it*:
    integrated, read at the knots, taken as linear between them and differenced over each
    sample's window. A fit of a model's terms seen so against the counters' power is free of
    the spreading between their steps (the counters' power is the battery's power seen so):
    its coefficients are those a fit on V·I would give, not biased where the power changes
    sign within a step. Rows outside ``rows`` (trips that log V·I) are left as they are.

    A counter that stays flat while the other rises books nothing there: the battery
    delivers or takes in, not both at once, so the energy between two rises of one counter
    is not spread over the other's. A logger's rounding fall is held at the value before."""

    def __init__(self, time_s, dt_s, codes, discharged_j, charged_j, rows=None):
        t = np.asarray(time_s, float)
        dt = np.asarray(dt_s, float)
        codes = np.asarray(codes)
        n = len(t)
        self.rows = np.ones(n, bool) if rows is None else np.asarray(rows, bool)
        d = np.asarray(discharged_j, float)
        c = np.asarray(charged_j, float)
        start = np.r_[True, codes[1:] != codes[:-1]]
        end = np.r_[start[1:], True]
        # one monotone clock over all trips (each trip after the last, 1 s apart)
        seg = np.cumsum(start) - 1
        t0 = t[start][seg]
        dur = np.r_[0.0, np.cumsum((t[end] - t[start]) + 1.0)][:-1]
        tau = t - t0 + dur[seg]
        step = np.diff(tau)
        weighted = ~start[1:] & (dt[:-1] + dt[1:] >= step * (1.0 - 1e-9))
        half = np.where(weighted, 0.5 * step, 0.0)
        self.left, self.right = tau - np.r_[0.0, half], tau + np.r_[half, 0.0]
        self.width = self.right - self.left
        ok = np.isfinite(d) & np.isfinite(c) & self.rows
        dk = pd.Series(np.where(ok, d, -np.inf)).groupby(seg).cummax().to_numpy()
        ck = pd.Series(np.where(ok, c, -np.inf)).groupby(seg).cummax().to_numpy()
        prev_same = np.r_[False, ~start[1:]]
        with np.errstate(invalid="ignore"):  # −∞ before a trip's first reading
            rise_d = np.r_[False, np.diff(dk) > 0] & prev_same
            rise_c = np.r_[False, np.diff(ck) > 0] & prev_same
        rise = rise_d | rise_c
        edge = ~np.r_[True, weighted] | ~np.r_[weighted, True]
        # the first and last finite sample of each trip
        first = ok & (pd.Series(ok).groupby(seg).cumsum().to_numpy() == 1)
        last = ok & (pd.Series(ok[::-1]).groupby(seg[::-1]).cumsum().to_numpy()[::-1] == 1)
        self.knots = np.flatnonzero(ok & (rise | edge | first | last))
        # where one counter rises it was just crossed: it reads the energy; the other, between
        # its steps, reads on average half a step less than it has counted
        k = self.knots
        with np.errstate(invalid="ignore"):
            half_d, half_c = (_half_step(np.diff(x)[(r & ok)[1:]]) for x, r in ((dk, rise_d), (ck, rise_c)))
        # (not at a trip's or stretch's ends: there the readings are the reference, so each
        # stretch books the counters' change between its ends)
        mid = ~(edge | first | last)[k]
        self.net = (dk[k] + half_d * (mid & ~rise_d[k])) - (ck[k] + half_c * (mid & ~rise_c[k]))
        self.tau = tau
        ktrip = seg[self.knots]
        lo = np.full(seg.max() + 1, np.inf)
        hi = np.full(seg.max() + 1, -np.inf)
        np.minimum.at(lo, ktrip, tau[self.knots])
        np.maximum.at(hi, ktrip, tau[self.knots])
        two = np.bincount(ktrip, minlength=seg.max() + 1) >= 2
        self.inside = self.rows & two[seg] & (tau >= lo[seg]) & (tau <= hi[seg])

    @property
    def nbytes(self) -> int:
        """Bytes its arrays hold (a streamed calibration keeps it with its batch)."""
        return sum(a.nbytes for a in (self.rows, self.left, self.right, self.width, self.knots, self.net,
                                      self.tau, self.inside))

    def _rate(self, tk: np.ndarray, xk: np.ndarray) -> np.ndarray:
        """The rate over each sample's window of the line through (knot times ``tk``, energies ``xk``)."""
        n = len(self.tau)
        if len(tk) < 2:
            return np.full(n, np.nan)
        e = np.interp(np.r_[self.left, self.right], tk, xk)
        with np.errstate(invalid="ignore", divide="ignore"):
            p = (e[n:] - e[:n]) / self.width
        lone = ~(self.width > 0)  # a sample without weight (alone between gaps): the slope there
        if lone.any():
            i = np.clip(np.searchsorted(tk, self.tau[lone]), 1, len(tk) - 1)
            p[lone] = (xk[i] - xk[i - 1]) / (tk[i] - tk[i - 1])
        return p

    def power(self) -> np.ndarray:
        """Battery power [W], positive when discharging: the counters' net rate (NaN outside
        ``rows`` and before a trip's first or after its last counter value)."""
        p = self._rate(self.tau[self.knots], self.net)
        return np.where(self.inside, p, np.nan)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """``x`` (per sample, or samples × columns) as the counters would book it; rows
        outside ``rows`` unchanged, NaN read as 0 inside them."""
        x = np.asarray(x, float)
        one = x.ndim == 1
        cols = x[:, None] if one else x
        out = cols.copy()
        w = self.width
        for j in range(cols.shape[1]):
            xj = np.where(self.rows, np.nan_to_num(cols[:, j]), 0.0)
            # energy up to each sample's instant: the windows before it and its own left part
            before = np.r_[0.0, np.cumsum(xj * w)[:-1]] + xj * (self.tau - self.left)
            q = self._rate(self.tau[self.knots], before[self.knots])
            out[:, j] = np.where(self.inside, q, np.where(self.rows, np.nan, cols[:, j]))
        return out[:, 0] if one else out


def counter_power(time_s: np.ndarray, dt_s: np.ndarray, codes: np.ndarray,
                  discharged_j: np.ndarray, charged_j: np.ndarray) -> np.ndarray:
    """Battery power [W], positive when discharging, from the cumulative counters of each trip
    (``codes``: integer trip codes, rows of a trip contiguous): the rate of (discharged −
    charged) over each sample's weight ``dt_s``, so Σ P·dt_s per trip is the counters' net
    change (see the module and :class:`CounterView`). NaN before a trip's first and after its
    last counter value."""
    return CounterView(time_s, dt_s, codes, discharged_j, charged_j).power()


def resolution(time_s: np.ndarray, codes: np.ndarray, x: np.ndarray) -> tuple[float, float]:
    """(step [J], median interval between rises [s]) of a counter over all trips; NaN when it
    never rises."""
    t = np.asarray(time_s, float)
    x = np.asarray(x, float)
    ok = np.isfinite(x)
    t, x, c = t[ok], x[ok], codes[ok]
    same = c[1:] == c[:-1]
    d = np.diff(x)
    rise = same & (d > 0)
    if not rise.any():
        return float("nan"), float("nan")
    tr = t[1:][rise]
    cr = c[1:][rise]
    gaps = np.diff(tr)[cr[1:] == cr[:-1]]
    return _step(d[rise]), (float(np.median(gaps)) if len(gaps) else float("nan"))


def describe(time_s, codes, discharged_j, charged_j) -> str:
    """The source text of a counter-derived battery power: the counters' steps and update intervals."""
    parts = []
    for name, x in (("discharged", discharged_j), ("charged", charged_j)):
        step, every = resolution(time_s, codes, x)
        parts.append(f"{name} in steps of {step / 1000:.3g} kJ every {every:.3g} s" if np.isfinite(step)
                     else f"{name} never rises")
    return "battery energy counters (" + "; ".join(parts) + ")"


#: a trip whose SOC readings leave more than this [s] at its ends unread is noted
SOC_UNREAD_NOTE_S = 10.0
#: a SOC reading is a misread only when it departs from both neighbours by more than this
#: many of the SOC's steps too (a value dithering by a step or two between readings stays)
SOC_SPIKE_STEPS = 5.0


def _without_soc_spikes(soc: np.ndarray, trips: np.ndarray, time: np.ndarray, index, report: dict) -> np.ndarray:
    """``soc`` [%] with its one-sample misreads NaN, noted with the first's data row: a reading
    that departs from both its neighbours in the same trip the same way, each by more than
    the SOC's change at :data:`~sumo_drvpw.model.constants.SOC_RATE_MAX_C` over that interval
    and by more than :data:`SOC_SPIKE_STEPS` of its steps (a BMS read wrong once: 14.72 →
    0.02 → 13.32 % in 2 s is 3 MW out and back in of a 6.1-kWh pack). A lasting jump (the
    BMS correcting its estimate) is no spike and is kept."""
    from sumo_drvpw.model.constants import SOC_RATE_MAX_C

    ok = np.flatnonzero(np.isfinite(soc))
    if len(ok) < 3:
        return soc
    moves = np.abs(np.diff(soc[ok]))
    step = _step(moves[moves > 0])
    s, t, tr = soc[ok], time[ok], trips[ok]
    d_prev, d_next = s[1:-1] - s[:-2], s[1:-1] - s[2:]
    rate = SOC_RATE_MAX_C * 100.0 / 3600.0  # [% per s]
    lim_prev = np.maximum(rate * (t[1:-1] - t[:-2]), SOC_SPIKE_STEPS * step)
    lim_next = np.maximum(rate * (t[2:] - t[1:-1]), SOC_SPIKE_STEPS * step)
    spike = ((np.sign(d_prev) == np.sign(d_next)) & (np.abs(d_prev) > lim_prev) & (np.abs(d_next) > lim_next)
             & (tr[1:-1] == tr[:-2]) & (tr[1:-1] == tr[2:]))
    if not spike.any():
        return soc
    rows = ok[1:-1][spike]
    k = int(np.flatnonzero(spike)[0]) + 1  # the first, among the readings
    report["notes"].append(
        f"soc_pct read as missing on {len(rows)} sample(s) that leave both neighbours faster than "
        f"{SOC_RATE_MAX_C:g} C moves any traction battery (a misread, not energy); the first at data row "
        f"{index[ok[k]]}: {s[k - 1]:g} → {s[k]:g} → {s[k + 1]:g} %")
    out = soc.copy()
    out[rows] = np.nan
    return out


def soc_counters(df: pd.DataFrame, report: dict, capacity_kwh: float) -> pd.DataFrame:
    """A file's frame with the battery's energy counters (:data:`COUNTERS`) estimated from
    its state of charge ``soc_pct`` [%] and the energy its 0–100 % spans, ``capacity_kwh``
    (a mapping's ``options.soc_capacity_kwh``): per trip, every fall of SOC × capacity adds
    to the discharged count, every rise to the charged one, where ``soc_pct`` is logged
    (NaN between), so the net of the counters is the SOC's energy change exactly. What it
    cannot carry, the import's note says: the SOC's step (a 0.5-% step of 23 kWh is 115 Wh),
    and that a BMS counts charge, not energy at the terminals. Refused, naming the file and
    the first row: a SOC outside 0–100 %. A frame that has the counters keeps them."""
    if all(c in df for c in COUNTERS):
        report["notes"].append("options.soc_capacity_kwh not used: the file logs the battery's energy counters")
        return df
    soc = df["soc_pct"].to_numpy(float, na_value=np.nan)
    bad = np.isfinite(soc) & ((soc < 0) | (soc > 100))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise UserError(f"{report['file']}: column 'soc_pct' is {soc[i]:g} at data row {df.index[i]}: a state "
                        "of charge is 0–100 % (options.soc_capacity_kwh reads it in %)")
    trips = df["trip_id"].astype(str).to_numpy() if "trip_id" in df else np.zeros(len(df), str)
    time = df["time_s"].to_numpy(float)
    soc = _without_soc_spikes(soc, trips, time, df.index, report)
    e = soc * (capacity_kwh * 3.6e6 / 100.0)
    dis, chg = np.full(len(df), np.nan), np.full(len(df), np.nan)
    unread = []  # (trip, seconds before its first and after its last SOC reading)
    for t in dict.fromkeys(trips.tolist()):
        own = np.flatnonzero(trips == t)
        rows = own[np.isfinite(e[own])]
        if len(rows) == 0:
            unread.append((t, time[own[-1]] - time[own[0]]))
            continue
        d = np.diff(e[rows], prepend=e[rows[0]])
        dis[rows], chg[rows] = np.cumsum(np.maximum(-d, 0.0)), np.cumsum(np.maximum(d, 0.0))
        ends = (time[rows[0]] - time[own[0]]) + (time[own[-1]] - time[rows[-1]])
        if ends > SOC_UNREAD_NOTE_S:
            unread.append((t, ends))
    out = df.assign(**{COUNTERS[0]: dis, COUNTERS[1]: chg})
    if unread:
        report["notes"].append("soc_pct is not logged before the first or after the last reading of "
                               + ", ".join(f"trip {t} ({s:.0f} s)" for t, s in unread[:3])
                               + (f" and {len(unread) - 3} more" if len(unread) > 3 else "")
                               + ": the battery energy there is not counted")
    moves = np.abs(np.diff(soc[np.isfinite(soc)]))
    step = _step(moves[moves > 0]) if (moves > 0).any() else float("nan")
    report["notes"].append(
        f"battery energy counters estimated from soc_pct × {capacity_kwh:g} kWh (options.soc_capacity_kwh): "
        f"an estimate — the SOC's step{f' ({step:g} %, {step * capacity_kwh * 10:.0f} Wh)' if step == step else ''} "
        "limits each trip's energy, and a BMS counts charge, not energy at the terminals; the battery "
        "target reads V·I where a trip logs them")
    return out
