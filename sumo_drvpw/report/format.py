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
