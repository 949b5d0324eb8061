"""A calibrated equation's coefficients against the vehicle file's body: the ``aero`` term
read as C_d·A against the declared drag, the ``roll`` term as a rolling coefficient against
the declared c_r (each a warning when it is no property of this car: the data could not tell
the terms apart, and SUMO would book it at every speed).
"""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.model.constants import RHO_DEFAULT


#: the fitted drag may exceed the vehicle file's by the drivetrain's 1/η (a target behind
#: a drivetrain: ≤ 1.25) and differ by the published figures' and the air density's
#: uncertainty (±10 % each): together at most ~1.5×; beyond this factor either way (zero
#: drag included) the aero coefficient is no drag of this car (a rehearsal's Nissan Leaf:
#: 0.41× its C_d·A, the rest in a c_r of 0.018, passed the factor 3 used before)
DRAG_RATIO_MAX = 2.0


def declared_cda(vehicle) -> tuple[float, str] | None:
    """(C_d·A [m²], where it comes from) as the vehicle file declares it: ``[body]``
    C_d × A, else the published road load's C = ½ρ·C_d·A (ρ of the standard test,
    :data:`RHO_DEFAULT`); None when it declares neither."""
    if vehicle is None:
        return None
    body, rl = vehicle.body or {}, vehicle.road_load or {}
    if body.get("drag_coefficient") and body.get("frontal_area_m2"):
        cd, a = float(body["drag_coefficient"]), float(body["frontal_area_m2"])
        return cd * a, f"C_d {cd:g} × A {a:g} m²"
    if rl.get("c_n_per_mps2"):
        c = float(rl["c_n_per_mps2"])
        return 2.0 * c / RHO_DEFAULT, f"road load C = {c:.4g} N/(m/s)²"
    return None


def drag_against_vehicle(eq, vehicle, rho_kgm3: float = RHO_DEFAULT) -> str | None:
    """A note when the equation's aero coefficient, read as C_d·A, is more than
    :data:`DRAG_RATIO_MAX` times above or below what the vehicle file declares (None when
    it is within, or there is no aero term or no declared drag). A constrained fit can put
    the drag at its bound 0, and a short log or a narrow speed range lets ``aero`` trade
    with ``roll`` and ``acc``: such a coefficient is no drag, and SUMO would apply it at
    every speed. The note is kept in ``eq.provenance["physical"]["vehicle_drag"]``."""
    term = next((t for t in ("aero", "aero_rho") if t in eq.terms), None)
    ref = declared_cda(vehicle)
    if term is None or ref is None or not ref[0] > 0:
        return None
    c = float(eq.terms[term])
    cda = 2.0 * c / rho_kgm3 if term == "aero" else c
    ratio = cda / ref[0]
    return _kept(eq, "vehicle_drag", ratio, DRAG_RATIO_MAX, lambda: (
        f"{term} = {c:.4g} reads as C_d·A = {cda:.3g} m² at ρ = {rho_kgm3:.4g} kg/m³, "
        f"{ratio:.2g} × the {ref[0]:.3g} m² of {_named(vehicle)} "
        f"({ref[1]}): not this car's drag (outside 1/{DRAG_RATIO_MAX:g} … {DRAG_RATIO_MAX:g}×); "
        "the data do not tell the drag apart from the other terms (a short log, a narrow "
        "speed range?) — check the equation before using it at other speeds"),
        term=term, coefficient=c, cda_m2=cda, declared_cda_m2=ref[0], declared_from=ref[1])


def _kept(eq, key: str, ratio: float, most: float, note, **fields) -> str | None:
    """None when ``ratio`` lies within 1/``most`` … ``most``; else the ``note()`` text, kept
    with ``fields``, the ratio and itself in ``eq.provenance["physical"][key]``."""
    if 1.0 / most <= ratio <= most:
        return None
    text = note()
    eq.provenance.setdefault("physical", {})[key] = {**fields, "ratio": ratio, "note": text}
    return text


#: a fitted ``roll`` coefficient carries, beside the tyres' c_r, the losses of a drivetrain
#: and its bearings that grow with speed (up to about twice the tyres' on the logs here:
#: the i3's road-load fits); beyond this factor of the vehicle file's c_r it is no rolling
#: resistance of this car (a rehearsal's Prius Gen 2: 0.0221, 3.6× its 0.0061, read plausible)
ROLL_RATIO_MAX = 3.0


def _named(vehicle) -> str:
    """The vehicle file's name, else the vehicle's."""
    return Path(vehicle.path).name if vehicle.path else vehicle.name


def roll_against_vehicle(eq, vehicle) -> str | None:
    """A note when the equation's ``roll`` coefficient (c_r) is more than
    :data:`ROLL_RATIO_MAX` times above, or below 1/ROLL_RATIO_MAX of, the vehicle file's
    rolling resistance (``[body] rolling_coefficient``, else the published road load's
    A/(m·g)); None when it is within, or either is missing. Kept in
    ``eq.provenance["physical"]["vehicle_roll"]``."""
    from sumo_drvpw.model.constants import G

    if vehicle is None or "roll" not in eq.terms:
        return None
    body, rl = vehicle.body or {}, vehicle.road_load or {}
    if body.get("rolling_coefficient"):
        ref, src = float(body["rolling_coefficient"]), "c_r"
    elif rl.get("a_n") and vehicle.mass_kg:
        ref, src = float(rl["a_n"]) / (float(vehicle.mass_kg) * G), f"road load A = {float(rl['a_n']):.4g} N / (m·g)"
    else:
        return None
    c = float(eq.terms["roll"])
    ratio = c / ref if ref > 0 else float("inf")
    return _kept(eq, "vehicle_roll", ratio, ROLL_RATIO_MAX, lambda: (
        f"roll = {c:.4g} reads as a rolling coefficient {ratio:.2g} × the {ref:.3g} of "
        f"{_named(vehicle)} ({src}): not this car's rolling "
        f"resistance (outside 1/{ROLL_RATIO_MAX:g} … {ROLL_RATIO_MAX:g}×, drivetrain losses included); the "
        "term carries what the other terms leave (the drag, a speed-dependent loss, a narrow speed range?) "
        "— SUMO books it at every speed"), coefficient=c, declared=ref, declared_from=src)
