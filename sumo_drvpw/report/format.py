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
from dataclasses import dataclass

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


# ------------------------------------------------ energy in the unit of what is predicted

@dataclass(frozen=True)
class EnergyUnit:
    """How a report shows an energy [J] of what is compared: kWh (driving power at the wheel
    or powertrain, a battery's V·I), or litres of a fuel (fuel energy at its lower heating
    value, the unit its chain predicts in: :func:`sumo_drvpw.model.chain.fuel_j_per_l`).
    Build with :func:`energy_unit`; ``unit(j)`` formats an energy in J."""

    label: str                 # "kWh" or "L"
    scale: float               # display units per J
    nd: int = 3                # decimals
    fuel: str | None = None    # the fuel, for litres
    j_per_l: float | None = None

    def __call__(self, j) -> str:
        return num(j, self.nd, self.scale)

    @property
    def what(self) -> str:
        """The unit with its fuel: "kWh", "L of gasoline"."""
        return self.label if self.fuel is None else f"{self.label} of {self.fuel}"

    def note(self) -> str:
        """One sentence on how litres follow from the fuel energy; "" for kWh."""
        if self.fuel is None:
            return ""
        return (f"Litres of {self.fuel}: fuel energy at its lower heating value over "
                f"{num(self.j_per_l / 1e6, 2)} MJ per litre (model/constants.py FUELS); the measured fuel "
                f"energy is read back into litres of the same fuel.")


def energy_unit(target: str | None, chain: dict | None = None) -> EnergyUnit:
    """The unit a report shows energies of ``target`` in (``wheel``, ``powertrain_output``,
    ``battery``: kWh; ``fuel``: litres of the fuel of ``chain``, a ``[chain]`` table as in a
    report's JSON, gasoline when it names none).

    >>> energy_unit("battery")(7.2e6), energy_unit("fuel", {"fuel": "diesel"}).what
    ('2.000', 'L of diesel')
    """
    if target != "fuel":
        return EnergyUnit("kWh", KWH)
    from sumo_drvpw.model.chain import fuel_j_per_l

    fuel = str((chain or {}).get("fuel") or "gasoline")
    per_l = fuel_j_per_l(fuel)
    return EnergyUnit("L", 1.0 / per_l, fuel=fuel, j_per_l=per_l)


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
