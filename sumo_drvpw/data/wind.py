"""Wind along the direction of travel, from a wind vector and the heading of each sample.

A steady wind adds to the air speed the car meets: a head wind raises the aero power, a
tail wind lowers it, by ≈ 2·P_aero·w/v. On an out-and-back pair of trips (the shared
Prius Gen-2 logs: one trip east, one west, docs/closing-the-loop.md) a wind of a few m/s
moves each trip's energy by several per cent in opposite directions, so an equation
calibrated on one direction carries that day's wind in its aero coefficient. Wind is a
condition of the day, not of the car: it belongs in the log (the canonical column
``wind_mps``, tailwind positive, air speed = speed − wind_mps), never in an equation.

The import command's wind option (SPEED@FROM) writes ``wind_mps`` from a wind vector (e.g. the
hourly record of a nearby weather station: speed [m/s], direction it blows *from* [°
clockwise from north], as meteorology gives it) and each sample's heading: a ``heading_deg``
or ``bearing_deg`` column, else the direction of travel between GPS positions
(``latitude_deg``, ``longitude_deg``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from sumo_drvpw.errors import UserError

if TYPE_CHECKING:  # (pandas is imported where a log is read: a SUMO run's tailwind_mps needs none)
    import pandas as pd

#: columns that give the heading [° clockwise from north] directly, first found wins
HEADING_COLUMNS = ("heading_deg", "bearing_deg")
#: distance over which GPS positions are differenced for a heading [m]: well above the
#: metre-scale jitter of a phone or logger GPS fix, below a street's length
HEADING_BASE_M = 20.0
#: below this speed [m/s] a heading from positions is not read (a standing car's GPS
#: wanders); aero power vanishes there anyway
HEADING_MIN_SPEED_MPS = 1.0
#: the largest wind a drive log may be given [m/s] (Beaufort 12 starts at 32.7 m/s)
MAX_WIND_MPS = 40.0
EARTH_RADIUS_M = 6371008.8


def parse_wind(text: str, where: str) -> tuple[float, float]:
    """``"SPEED@FROM"`` → (speed [m/s], direction it blows from [°, 0 ≤ d < 360]); errors
    name ``where`` (the option or key the text came from)."""
    speed, sep, frm = str(text).partition("@")
    try:
        s, d = float(speed), float(frm)
    except ValueError:
        s = d = math.nan
    if not sep or not (math.isfinite(s) and math.isfinite(d)):
        raise UserError(f"{where} {text}: give SPEED@FROM, the wind speed in m/s and the direction "
                        "it blows from in degrees clockwise from north, e.g. 4.2@210")
    if not 0.0 <= s <= MAX_WIND_MPS:
        raise UserError(f"{where} {text}: the speed must be in 0…{MAX_WIND_MPS:g} m/s")
    if not -360.0 <= d <= 720.0:  # (1e308 % 360 is a direction no one gave)
        raise UserError(f"{where} {text}: the direction must be in degrees, 0…360")
    return s, d % 360.0


def tailwind_mps(heading_deg, speed_mps: float, from_deg: float) -> np.ndarray:
    """The wind component along the direction of travel, tailwind positive [m/s]: a wind
    blowing from ``from_deg`` meets a car heading ``heading_deg`` head-on at
    cos(heading − from); NaN headings give 0 (still air assumed there)."""
    h = np.asarray(heading_deg, float)
    w = -speed_mps * np.cos(np.radians(h - from_deg))
    return np.where(np.isfinite(w), w, 0.0)


def heading_from_positions(lat_deg, lon_deg, speed_mps, trip_ids,
                           base_m: float = HEADING_BASE_M) -> np.ndarray:
    """Heading [° clockwise from north] of each sample from GPS positions, within trips:
    the direction from the position about ``base_m`` behind to the one about ``base_m``
    ahead along the driven path (local flat-earth east/north; distance from the positions
    themselves); NaN where the car moves slower than HEADING_MIN_SPEED_MPS, where a
    position is missing, or where the trip has no such span."""
    import pandas as pd

    from sumo_drvpw.data.trips import trip_codes_of, trip_starts

    lat = np.asarray(lat_deg, float)
    lon = np.asarray(lon_deg, float)
    v = np.asarray(speed_mps, float)
    out = np.full(lat.shape, np.nan)
    codes = trip_codes_of(pd.Series(np.asarray(trip_ids)))
    starts = np.flatnonzero(trip_starts(codes))
    for a, b in zip(starts, np.r_[starts[1:], len(codes)]):
        la, lo = lat[a:b], lon[a:b]
        ok = np.isfinite(la) & np.isfinite(lo)
        if ok.sum() < 2:
            continue
        idx = np.flatnonzero(ok)
        lat0 = math.radians(float(np.nanmedian(la)))
        north = np.radians(la[idx]) * EARTH_RADIUS_M
        east = np.radians(lo[idx]) * EARTH_RADIUS_M * math.cos(lat0)
        s = np.r_[0.0, np.cumsum(np.hypot(np.diff(north), np.diff(east)))]
        back = np.searchsorted(s, s - base_m, side="right") - 1
        ahead = np.searchsorted(s, s + base_m, side="left")
        fine = (back >= 0) & (ahead < len(s))
        back, ahead = np.clip(back, 0, len(s) - 1), np.clip(ahead, 0, len(s) - 1)
        h = np.degrees(np.arctan2(east[ahead] - east[back], north[ahead] - north[back])) % 360.0
        h = np.where(fine & (ahead > back), h, np.nan)
        seg = np.full(b - a, np.nan)
        seg[idx] = h
        out[a:b] = seg
    out[~(v >= HEADING_MIN_SPEED_MPS)] = np.nan
    return out


def heading_of(df: pd.DataFrame, where: str = "the log") -> tuple[np.ndarray, str]:
    """Heading per sample [°] and where it came from: a heading column
    (:data:`HEADING_COLUMNS`), else GPS positions (:func:`heading_from_positions`); NaN
    where the car moves slower than :data:`HEADING_MIN_SPEED_MPS` either way. A log
    with neither is a UserError naming the columns."""
    import pandas as pd

    for c in HEADING_COLUMNS:
        if c in df:
            h = pd.to_numeric(df[c], errors="coerce").to_numpy(float)
            # (a standing car's heading is not read, as from positions: still air there)
            moving = pd.to_numeric(df["speed_mps"], errors="coerce").to_numpy(float) >= HEADING_MIN_SPEED_MPS
            return np.where(np.isfinite(h) & moving, h % 360.0, np.nan), f"column {c}"
    if {"latitude_deg", "longitude_deg"} <= set(df.columns):
        return (heading_from_positions(df["latitude_deg"], df["longitude_deg"], df["speed_mps"],
                                       df["trip_id"]),
                f"GPS positions (latitude_deg, longitude_deg) over {HEADING_BASE_M:g} m")
    raise UserError(f"{where}: a wind along the direction of travel needs the heading: a column "
                    f"{' or '.join(HEADING_COLUMNS)}, or latitude_deg and longitude_deg")


def add_wind(df: pd.DataFrame, speed_mps: float, from_deg: float, where: str = "the log") -> tuple[pd.DataFrame, dict]:
    """A copy of a canonical log with ``wind_mps`` (tailwind positive) from the wind vector
    and each sample's heading, and a report entry. A log that already carries
    ``wind_mps`` or ``airspeed_mps`` is a UserError (measured wind wins; say which)."""
    for c in ("wind_mps", "airspeed_mps"):
        if c in df:
            raise UserError(f"{where}: column {c!r} already gives the wind; a wind given for the "
                            "day would replace a measurement (leave one out)")
    h, source = heading_of(df, where)
    out = df.copy()
    out["wind_mps"] = tailwind_mps(h, speed_mps, from_deg)
    known = np.isfinite(h)
    return out, {"speed_mps": speed_mps, "from_deg": from_deg, "heading_source": source,
                 "samples_with_heading": int(known.sum()), "samples": int(len(h))}
