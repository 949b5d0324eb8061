"""The one number formatter of every report, table and figure label.

Fixed decimals for measured quantities, significant digits for coefficients; a missing
or non-finite value prints as "–"; a negative sign is the typographic minus "−" and a
value that rounds to zero never prints as "−0.00". Quantities stay SI inside the code;
the ``scale`` argument converts at this edge (``KW`` W → kW, ``KWH`` J → kWh).

>>> num(-0.004), num(-1234.5, 1, KW), num(float("nan")), coef(-0.000123456)
('0.00', '−1.2', '–', '−0.0001235')
"""

from __future__ import annotations

import math

#: W → kW, J → kJ (display only)
KW = 1e-3
#: J → kWh (display only)
KWH = 1.0 / 3.6e6
#: what a missing or non-finite value prints as
MISSING = "–"


def _finite(x, scale: float = 1.0) -> float | None:
    """float(x)·scale, or None when x is None, not a number, NaN or infinite."""
    if x is None:
        return None
    try:
        f = float(x) * scale
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def num(x, nd: int = 2, scale: float = 1.0) -> str:
    """``x·scale`` with ``nd`` decimals, "–" when missing, "−" as minus, no "−0.00".

    Parameters
    ----------
    x : the value (any unit; None and NaN allowed)
    nd : decimals [-]
    scale : factor applied before formatting (e.g. ``KW`` to print W as kW)
    """
    f = _finite(x, scale)
    if f is None:
        return MISSING
    s = f"{f:.{nd}f}"
    if s.startswith("-") and float(s) == 0.0:
        s = s[1:]
    return s.replace("-", "−")


def kw(w, nd: int = 2) -> str:
    """Power or energy rate given in W, printed in kW with ``nd`` decimals."""
    return num(w, nd, KW)


def coef(x, sig: int = 4) -> str:
    """A coefficient with ``sig`` significant digits ("−" as minus, "–" when missing)."""
    f = _finite(x)
    if f is None:
        return MISSING
    return f"{f:.{sig}g}".replace("-", "−")


# ------------------------------------------------ partial trips (fit/trip_energy.py)

def _share(x) -> str:
    return "–" if x is None else f"{100 * x:.0f} %"


def partial_trip_flag(entry: dict) -> str:
    """A trip table's flag for a partial trip (``partial`` in its per-trip energy entry):
    its left-out shares of time, measured traction and net energy; "" when not partial."""
    if not entry.get("partial"):
        return ""
    net, unknown = entry.get("left_out_net_energy_share"), entry.get("left_out_power_unknown_time_share")
    return (f"partial: {_share(entry.get('left_out_time_share'))} of time, "
            f"{_share(entry.get('left_out_energy_share'))} of measured traction energy"
            + (f", {_share(net)} of net energy" if net is not None and net == net else "") + " left out"
            + (f" (power not measured on {_share(unknown)} of the time)" if unknown else ""))


def partial_trip_lines(trip_doc: dict | None,
                       energies: str = "per-trip energies (`trip_energy`, `trip_net_energy`)") -> list[str]:
    """One line naming the trips whose per-trip energies are partial (more than
    ``partial_trip_share`` of their measured energy, or of their time without a measured
    power, on left-out samples: fit/trip_energy.py ``partial_share``), if any; ``energies``
    names what covers only the rest. And one naming the small trips the mean and worst
    per-trip error leave out (fit/trip_energy.py ``SMALL_TRIP_SHARE``), if any."""
    if not trip_doc:
        return []
    out = []
    if trip_doc.get("partial_trips"):
        trips = trip_doc["trips"]
        parts = [f"{t} ({partial_trip_flag(trips[t])[len('partial: '):]})" for t in trip_doc["partial_trips"]]
        out.append(f"**Partial trips**: more than {100 * trip_doc['partial_trip_share']:.0f} % of the measured "
                   f"energy (or of the time without a measured power) of {len(parts)} trip(s) lies on left-out "
                   f"samples, so their {energies} cover only the rest: {'; '.join(parts)}.")
    small = trip_doc.get("small_trips") or []
    if small:  # fit/trip_energy.py SMALL_TRIP_SHARE
        out.append(f"**Small trips**: {len(small)} trip(s) measured under {100 * trip_doc['small_trip_share']:.0f} % "
                   f"of the median trip's energy ({', '.join(small[:8])}{', …' if len(small) > 8 else ''}): their "
                   "errors are kept per trip but left out of the mean and worst per-trip error, which a near-zero "
                   "energy would swamp.")
    return out
