"""Plausibility checks of drive logs across samples and files (beside the per-value rules
of :mod:`sumo_drvpw.data.log`): speeds that only make sense in km/h, trip ids in two files,
columns named twice."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError

#: 99th percentile of |Δv/Δt| over ~1 s above which m/s speeds are implausible [m/s²]:
#: real logs stay below 3.2 (BMW i3 trips 2.2 overall, 3.1 in the liveliest trip; Prius
#: Gen-2 OBD 1.7; JLU dynamometer cycles 1.5); the same speeds in km/h give 3.6× that.
KMH_SUSPECT_ACCEL_MPS2 = 4.5
#: the longest median sampling step of a drive log within a trip [s]: beyond it the
#: time is taken for milliseconds (or the log is too sparse for driving power)
MAX_MEDIAN_STEP_S = 30.0


def implied_acceleration(v: np.ndarray, t: np.ndarray, trip: np.ndarray, horizon_s: float = 1.0) -> np.ndarray:
    """|Δv/Δt| over about ``horizon_s`` within trips, for samples where the car moves [m/s²].

    Parameters
    ----------
    v : speed [m/s]; t : time [s], increasing within a trip; trip : trip id per sample
    horizon_s : time to the partner sample [s] (≥ 1 s damps quantisation noise)

    Each sample is paired with the first sample at least ``horizon_s`` later in the same
    trip; pairs more than 3·horizon apart (gaps) or both below 0.5 m/s are left out.
    """
    n = len(v)
    if n < 2:
        return np.zeros(0)
    codes = np.cumsum(np.r_[False, trip[1:] != trip[:-1]])  # contiguous runs: cheaper than factorize
    key = codes * (np.nanmax(np.abs(t)) * 4 + 4 * horizon_s + 1.0) + t  # trips never overlap
    j = np.searchsorted(key, key + horizon_s)
    ok = j < n
    i = np.flatnonzero(ok)
    j = j[ok]
    dt = t[j] - t[i]
    good = (codes[j] == codes[i]) & (dt > 0) & (dt <= 3 * horizon_s) & (np.maximum(v[i], v[j]) > 0.5)
    return np.abs((v[j] - v[i])[good] / dt[good])


def check_speed_unit(v: np.ndarray, t: np.ndarray, trip: np.ndarray, p: Path) -> None:
    """Refuse m/s speeds whose implied accelerations only make sense in km/h, over 1 s; a
    speed held between updates is judged interpolated between them, as it is read (its jumps
    are no km/h; judged over three update intervals instead, a km/h city drive held 3 s
    averaged its accelerations below the bound and passed as m/s)."""
    from sumo_drvpw.data.resolution import speed_hold, unheld_speed

    codes = np.cumsum(np.r_[False, trip[1:] != trip[:-1]]) if len(trip) else np.zeros(0, int)
    hold = speed_hold(v, t, codes)
    horizon = 1.0
    a = implied_acceleration(unheld_speed(v, t, codes, hold), t, trip, horizon)
    if len(a) < 50:
        return
    q = float(np.percentile(a, 99))
    if q > KMH_SUSPECT_ACCEL_MPS2:
        raise UserError(f"{p}: column 'speed_mps' implies accelerations of {q:.1f} m/s² (99th "
                        f"percentile over {horizon:.2g} s; real driving stays below {KMH_SUSPECT_ACCEL_MPS2:g}), "
                        f"{q / 3.6:.1f} m/s² if the speed is in km/h: is it km/h? declare the unit "
                        "(speed unit km/h or m/s)")


def check_distinct_trips(paths) -> None:
    """No trip id in two files (a file without ``trip_id`` is the trip named by its stem), no
    column named twice in a header: the checks the in-memory reader makes on whole files,
    for readers that see a file in batches of chosen columns.

    Reads only headers and the ``trip_id`` column; raises UserError naming the file.
    """
    from sumo_drvpw.data.log_files import expand_paths

    seen: dict[str, Path] = {}
    for p in expand_paths(paths):
        check_header(p)
        ids = trip_ids(p)
        for tid in ids:
            if tid in seen:
                raise UserError(f"{p}: trip_id '{tid}' is also in {seen[tid]}; samples of one trip "
                                "belong in one file, give each trip its own id")
        for tid in ids:
            seen[tid] = p


def trip_ids(p: Path) -> list[str]:
    """The trip ids of a log file as its reader names them (the file's stem without
    ``trip_id``), read from that column alone."""
    try:
        if p.suffix.lower() == ".parquet":
            import pyarrow.parquet as pq

            schema = pq.read_schema(p)
            if "trip_id" not in schema.names:
                return [p.stem]
            text = str(schema.field("trip_id").type) in ("string", "large_string")
            # text ids dictionary-encoded: the distinct ids, not one Python string per row
            col = pq.read_table(p, columns=["trip_id"],
                                read_dictionary=["trip_id"] if text else None).column(0).to_pandas()
            if isinstance(col.dtype, pd.CategoricalDtype):
                codes = col.cat.codes.to_numpy()
                return [str(x) for x in col.cat.categories[pd.unique(codes[codes >= 0])]]
        else:
            head = pd.read_csv(p, nrows=0)
            if "trip_id" not in head:
                return [p.stem]
            col = pd.read_csv(p, usecols=["trip_id"])["trip_id"]
    except pd.errors.EmptyDataError:
        return []
    except (OSError, ValueError, pd.errors.ParserError) as e:
        from sumo_drvpw.data.log_files import read_error

        raise read_error(p, e) from None
    return [str(x) for x in pd.unique(col.dropna().astype(str))]


def check_header(p: Path) -> None:
    """The header of a CSV log or the schema of a Parquet one, as a UserError naming it: a
    CSV separated by ';', tabs or '|' (one field holding them; the canonical drive log
    separates by commas), or a column named twice. A CSV header that is not UTF-8 is left to
    the reader, which names its first offending byte."""
    try:
        if p.suffix.lower() == ".parquet":
            import pyarrow.parquet as pq

            names = list(pq.read_schema(p).names)
        else:
            with open(p, "rb") as fh:
                head = (fh.readline(1 << 20).decode("utf-8-sig").splitlines() or [""])[0]  # (rows ending in CR alone)
            names = next(csv.reader([head]), [])
            if len(names) == 1:
                for sep, word in ((";", "semicolons"), ("\t", "tabs"), ("|", "'|'")):
                    if sep in head:
                        raise UserError(f"{p}: the header {head[:60]!r} is separated by {word}; a canonical "
                                        "CSV drive log separates columns by commas (convert it, or map it "
                                        "with the import command's columns format and its options.sep)")
    except (OSError, ValueError, csv.Error):  # UnicodeDecodeError among them
        return  # unreadable files are named by the reader itself
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise UserError(f"{p}: column '{dup[0]}' appears twice; give each column once")


def check_time_step(t: np.ndarray, same: np.ndarray, p: Path) -> None:
    """UserError when the median step of ``time_s`` within trips (``same``: sample i+1 in
    the trip of sample i) exceeds :data:`MAX_MEDIAN_STEP_S`: milliseconds, not seconds."""
    if same.any():
        step = float(np.median(np.diff(t)[same]))
        if step > MAX_MEDIAN_STEP_S:
            raise UserError(f"{p}: column 'time_s' steps by {step:g} (median within a trip), more than "
                            f"{MAX_MEDIAN_STEP_S:g} s: is it in milliseconds? The drive-log schema wants "
                            "seconds, and driving power needs samples seconds apart at most")


#: the shortest interval [s] a one-sample speed step is judged over (:func:`speed_steps`): in
#: faster logs a step of one sample is noise or a held value's update, read elsewhere
SPEED_STEP_MIN_DT_S = 0.5


def speed_steps(v: np.ndarray, t: np.ndarray, seg: np.ndarray, half_window_s: np.ndarray,
                limit_mps2: float) -> tuple[np.ndarray, int]:
    """Samples whose acceleration reaches across a one-sample speed step steeper than
    ``limit_mps2`` (the acceleration outlier limit) over at least :data:`SPEED_STEP_MIN_DT_S`,
    and how many such steps: recordings spliced without a mark, or a speed lost and found.

    A central difference over two samples halves a one-sample step, so the outlier rule on
    the derived acceleration kept it: a PEMS log's 15.1 m/s drop to 0 in one second read as
    −7.5 m/s² on two samples, under 8, and on a 30-t truck booked −3.4 MW. ``seg``: the
    stretches derivatives do not cross (trips, logging gaps), ``t`` increasing within each;
    ``half_window_s``: half the derivative window per sample (0 where the acceleration is
    logged): samples within it of the step are marked.

    A speed logged more often than it is updated (2-Hz rows of a speed updated once a
    second) changes by a whole update interval's Δv in one row: a step is judged over the
    longer of the row's interval and the stretch's update interval
    (:func:`update_interval`), so a held speed's updates are not steps (30 20-s trips of such
    rows, |a| ≤ 3 m/s², too short to be read as held: 82 of 1,200 samples left out at a
    5 m/s² limit; 94 at 8 m/s² with |a| ≤ 4.5) while a splice steeper than the limit over an
    update interval still is.
    """
    n = len(v)
    mask = np.zeros(n, bool)
    if n < 2:
        return mask, 0
    dt, dv = np.diff(t), np.diff(v)
    over = np.maximum(dt, update_interval(v, t, seg)[np.cumsum(np.r_[True, seg[1:] != seg[:-1]])[1:] - 1])
    step = np.flatnonzero((seg[1:] == seg[:-1]) & (dt >= SPEED_STEP_MIN_DT_S) & (np.abs(dv) > limit_mps2 * over))
    if not len(step):
        return mask, 0
    starts = np.flatnonzero(np.r_[True, seg[1:] != seg[:-1]])
    ends = np.r_[starts[1:], n]
    for i in step:
        k = np.searchsorted(starts, i, side="right") - 1
        s, e = starts[k], ends[k]
        lo = s + np.searchsorted(t[s:e], t[i] - half_window_s[i], side="left")
        hi = s + np.searchsorted(t[s:e], t[i + 1] + half_window_s[i + 1], side="right")
        mask[lo:max(hi, i + 2)] = True
    return mask, len(step)


#: a speed counts as moving, for the update interval (:func:`update_interval`) [m/s]
UPDATE_MIN_SPEED_MPS = 1.0
#: the longest update interval a speed is taken to be held for [s] (a longer run of one value
#: is a speed that did not change: a stop, a steady cruise)
UPDATE_MAX_S = 3.0
#: the quantile of the times between a moving speed's values taken for its update interval: a
#: held speed changes no sooner than its next update, a speed in steps (whole km/h at 1 Hz)
#: at its next sample wherever it changes by a step or more — but holds a value for seconds
#: in a cruise, so a median (3 s on a highway at 1 Hz) let a 9-m/s splice pass
UPDATE_QUANTILE = 0.1
#: a held speed's update clock (:func:`update_interval`): the median of the intervals between
#: its values (its first value's, cut by the stretch's start, aside) when it is at least
#: 1.5 rows and this share of them lie within a row of it — the jitter of a bus lands an
#: update near a row's edge one row early or late (1-s updates in 2-Hz rows: 0.5, 1 and
#: 1.5 s), where a low quantile read 0.5 s; not a speed in steps (whole km/h) that changes by
#: one step at a time, which holds its values as long as its drift takes to cross a step
UPDATE_CLOCK_SHARE = 0.8


def update_interval(v: np.ndarray, t: np.ndarray, seg: np.ndarray) -> np.ndarray:
    """The interval at which each stretch's speed is updated [s], per run of equal ``seg``
    (0, 1, … in order): the :data:`UPDATE_QUANTILE` quantile of the times from a value's first
    sample to the next value's, over the values held while moving (> :data:`UPDATE_MIN_SPEED_MPS`)
    but its first (held since before the stretch began, for all one knows), or their update
    clock where they keep one (:data:`UPDATE_CLOCK_SHARE`), at most :data:`UPDATE_MAX_S`; 0
    where no such value is followed by another in the stretch. A speed
    updated at every sample gives its sampling interval; a held one (a speed updated once a
    second in 2-Hz rows) its update interval — from the values themselves, so also in a trip
    too short for :func:`sumo_drvpw.data.resolution.speed_hold` to judge."""
    n = len(v)
    first = np.r_[True, seg[1:] != seg[:-1]] if n else np.zeros(0, bool)
    nseg = int(first.sum())
    out = np.zeros(nseg)
    if n < 2:
        return out
    new = first | np.r_[True, v[1:] != v[:-1]]  # a value's first sample (NaN: each its own)
    at = np.flatnonzero(new)
    follows = ~first[at[1:]]  # the next value is in the same stretch
    # a stretch's first value may have been updated before it began: its time is no interval
    ok = follows & ~first[at[:-1]] & (v[at[:-1]] > UPDATE_MIN_SPEED_MPS)
    if ok.any():
        run = (np.cumsum(first) - 1)[at[:-1][ok]]
        d = (t[at[1:]] - t[at[:-1]])[ok]
        low = pd.Series(d).groupby(run).quantile(UPDATE_QUANTILE)
        out[low.index.to_numpy()] = np.minimum(low.to_numpy(), UPDATE_MAX_S)
        row = pd.Series(np.diff(t)[~first[1:]]).groupby((np.cumsum(first) - 1)[1:][~first[1:]]).median()
        dv = np.abs(v[at[1:]] - v[at[:-1]])[ok]
        for r, g in pd.DataFrame({"d": d, "dv": dv}).groupby(run):
            m, dt_row = float(g["d"].median()), float(row.get(r, np.nan))
            steps = g["dv"].to_numpy()
            if (len(g) >= 3 and m >= 1.5 * dt_row
                    and np.mean(np.abs(g["d"].to_numpy() - m) <= dt_row + 1e-6) >= UPDATE_CLOCK_SHARE
                    and np.median(steps) >= 1.5 * steps.min()):  # (not a speed in steps, one at a time)
                out[r] = min(m, UPDATE_MAX_S)
    return out


def speed_step_note(counts: dict) -> str:
    """The console's line on :func:`speed_steps`' exclusions."""
    return (f"{counts.get('excluded_speed_step', 0)} sample(s) left out around {counts['speed_steps']} "
            f"one-sample speed step(s) steeper than {counts.get('accel_outlier_limit_mps2', '?')} m/s² (no "
            "vehicle brakes or accelerates so within one sample: recordings spliced without a mark, or a "
            "speed lost and found — give each recording a trip id of its own)")


def exclusions(counts: dict) -> str:
    """The non-zero exclusion counts of a read, for messages, naming the column or the
    rule: 'braking 12, grade_rad NaN 1600, |acceleration| > 8 m/s² (accel_mps2 column) 3'."""
    parts = []
    for k, v in counts.items():
        if not (k.startswith("excluded_") and k != "excluded_total" and isinstance(v, (int, np.integer)) and v):
            continue
        what = k[len("excluded_"):]
        if what.startswith("nan_"):
            label = f"{what[4:]} NaN"
        elif what == "accel_outlier":
            label = (f"|acceleration| > {counts.get('accel_outlier_limit_mps2', '?')} m/s² "
                     f"({counts.get('accel_source', 'acceleration')})")
        elif what == "grade_outlier":
            label = f"|grade| > {counts.get('grade_outlier_limit', '?')} rad ({counts.get('grade_source', 'grade')})"
        elif what == "speed_step":
            label = f"one-sample speed step > {counts.get('accel_outlier_limit_mps2', '?')} m/s²"
        elif what == "brake":
            label = "braking"
        elif what == "speed_dropout":  # data/charging.py speed_dropout_mask
            label = ("speed 0 while the measured power drives and brakes the car (over 15 kW for 10 s: the speed was not logged "
                     "there, and without it no acceleration, grade or drag can be fitted)")
        else:
            label = what.replace("_", " ")
        parts.append(f"{label} {int(v)}")
    return ", ".join(parts) or "none"
