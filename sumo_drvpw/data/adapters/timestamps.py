"""A mapped timestamp column read as datetimes (its ``time_format``'s names in English
whatever the process's locale) and as seconds since its first timestamp (a time of day
without a date carried past midnight); :mod:`sumo_drvpw.data.adapters.columns` reads with it."""

from __future__ import annotations

import numpy as np
import pandas as pd

from sumo_drvpw.data.adapters._common import carry_midnight


def to_datetimes(s: pd.Series, time_format) -> pd.Series:
    """Timestamps as datetimes (NaT where a cell is none), in UTC where they carry a UTC
    offset: a file holding a summer (+02:00) and a winter (+01:00) trip, or a trip across a
    daylight-saving change, stays on one clock. Without a ``time_format``, ISO 8601 (with or
    without fractions of a second, with or without an offset) is tried first, then the
    format pandas infers from the first cell; the reading that leaves fewer cells unread
    wins."""
    if time_format is not None:
        s, fmt, pm = _english_names(s, str(time_format))
        t = pd.to_datetime(s, format=fmt, errors="coerce", utc=True)
        return t if pm is None else t + pd.to_timedelta(np.where(pm, 12, 0), unit="h")
    best = None
    for fmt in ("ISO8601", None):
        try:
            t = pd.to_datetime(s, format=fmt, errors="coerce", utc=True)
        except (ValueError, TypeError):  # a format pandas cannot infer from the first cell
            continue
        if best is None or t.isna().sum() < best.isna().sum():
            best = t
    return best if best is not None else pd.Series(pd.NaT, index=s.index, dtype="datetime64[ns, UTC]")


_MONTHS = ("january", "february", "march", "april", "may", "june", "july", "august", "september", "october",
           "november", "december")
_DAYS = ("monday", "tuesday", "wednesday", "thursday", "friday", "saturday", "sunday")


def _words(names) -> str:
    """A regex of ``names`` and their 3-letter abbreviations as whole words, any case."""
    return "(?i)(?<![a-z])(" + "|".join(sorted({*names, *(n[:3] for n in names)}, key=len, reverse=True)) + ")(?![a-z])"


def _english_names(s: pd.Series, fmt: str) -> tuple[pd.Series, str, np.ndarray | None]:
    """A ``time_format``'s names read in English whatever the process's LC_TIME (pandas reads
    %b, %B, %a, %A, %p and the locale's %c, %x, %X in it: under German no 'Mar', under Turkish
    no 'Oct', no 'PM'): %c, %x, %X as the C locale writes them, month names (%b, %B, %h) as
    their numbers (%m), weekday names (%a, %A) left out, AM/PM (%p) left out and returned as
    a mask of the PM cells (12 h added to them: %I without %p reads 12 as 0). Returns (cells,
    format, PM mask or None)."""
    if not (pd.api.types.is_object_dtype(s) or pd.api.types.is_string_dtype(s)):
        return s, fmt, None  # (timestamps already, e.g. a Parquet file's: no text to read)
    fmt = fmt.replace("%c", "%a %b %d %H:%M:%S %Y").replace("%x", "%m/%d/%y").replace("%X", "%H:%M:%S")
    if not any(d in fmt for d in ("%b", "%B", "%h", "%a", "%A", "%p")):
        return s, fmt, None
    s, pm = s.astype("string"), None
    if any(d in fmt for d in ("%b", "%B", "%h")):
        s = s.str.replace(_words(_MONTHS), lambda m: f"{[n[:3] for n in _MONTHS].index(m[1][:3].lower()) + 1:02d}",
                          regex=True)
        fmt = fmt.replace("%b", "%m").replace("%B", "%m").replace("%h", "%m")
    if "%a" in fmt or "%A" in fmt:
        s, fmt = s.str.replace(_words(_DAYS), "", regex=True), fmt.replace("%a", "").replace("%A", "")
    if "%p" in fmt:
        pm = s.str.contains("(?i)(?<![a-z])pm(?![a-z])", regex=True).fillna(False).to_numpy(bool)
        s, fmt = s.str.replace("(?i)(?<![a-z])[ap]m(?![a-z])", "", regex=True), fmt.replace("%p", "")
    return s, fmt, pm


_DATE_DIRECTIVES = ("%d", "%j", "%m", "%b", "%B", "%y", "%Y", "%U", "%W", "%G", "%V", "%x", "%c", "%s")


def _seconds(t: pd.Series, time_format, rep: dict) -> pd.Series:
    """Seconds since the first timestamp. A time of day without a date (``%H:%M:%S.%f``,
    as phone OBD apps log it) that steps back by more than 12 h has passed midnight: the
    day is carried on (:func:`carry_midnight`) instead of the samples reading as time going
    backwards."""
    s = (t - t.min()).dt.total_seconds()
    if time_format is None or str(time_format).upper() == "ISO8601" \
            or any(d in str(time_format) for d in _DATE_DIRECTIVES):
        return s
    x, n = carry_midnight(s.to_numpy(float))
    if not n:
        return s
    rep["notes"].append(f"time of day without a date passes midnight {n} time(s): the day is carried on")
    return pd.Series(x - np.nanmin(x), index=s.index)
