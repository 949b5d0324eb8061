"""The grade at the wheels: a motor-side equation's grade coefficient read through the
drivetrain efficiency the same fit shows elsewhere (issue #11 §3).

A power measured behind a drivetrain (motor shaft, powertrain output) is the wheel power
divided by η while the car drives and multiplied by η while it recuperates. Potential
energy is exact at the wheels (m·g·Δh), so a free grade coefficient above 1 may be that
1/η, or a grade the corrections exaggerate, or a mass the log understates — the
coefficient alone cannot tell. Two effects of the closed loop measure η without the grade:

* **inertia by direction** (``acc_pos``): kinetic energy goes in at 1/η and comes back at
  η, so (c_acc + c_acc_pos)/c_acc = 1/η²;
* **regime** (recuperation on its own scale 1 + r): every term's braking power comes back
  at η² of the traction side's, so 1 + r = η².

With that η the grade at the wheels is c_grade·η: 1 when the grade and the drivetrain tell
one story. The product is 1 whichever way the fit shares η between its terms: on a planted
symmetric drivetrain (η 0.85–0.95, tests/test_drivetrain.py) the inertia candidate reads
η too high (it also absorbs what the other terms lose in braking: 0.92 for 0.85) and the
free grade too low by about the same factor (1.09 for 1/0.85 = 1.18), and the product
stays within 1 % of 1. A product well away from 1 says the grade and the drivetrain
disagree: a grade the data attenuate or exaggerate, a mass the log gets wrong, or an
asymmetry that is no drivetrain. (A power signal that reads
s_t times true in traction and s_r times in recuperation gives c_grade·η = √(s_t·s_r): one
that over-reads one direction as much as it under-reads the other looks like a drivetrain.)
"""

from __future__ import annotations

import math

#: the inertia-by-direction candidate reads as (c_acc + c_acc_pos)/c_acc = 1/η²: η below
#: this (ratio above 1/η²) is not a drivetrain; nor is η above 1
ETA_INERTIA_MIN = 0.8
#: grade at the wheels (c_grade·η) read as consistent: potential energy is exact, the
#: band leaves 10 % for the declared mass and the grade's measurement (issue #11's band)
WHEEL_GRADE_BAND = (0.9, 1.1)


def drivetrain_eta(terms: dict[str, float], regime_scale: float | None = None) -> tuple[float, str] | None:
    """η of the drivetrain as the fit shows it without the grade, and where from; None when
    the fit has neither inertia by direction nor a recuperation scale (or they read no η)."""
    a, ap = terms.get("acc"), terms.get("acc_pos")
    if a is not None and ap is not None and float(a) > 0:
        ratio = (float(a) + float(ap)) / float(a)
        if ratio > 0 and math.isfinite(ratio):
            return 1.0 / math.sqrt(ratio), "inertia by direction: (c_acc + c_acc_pos)/c_acc = 1/η²"
    if regime_scale is not None and 0.0 < float(regime_scale) and math.isfinite(float(regime_scale)):
        return math.sqrt(float(regime_scale)), "recuperation scale 1 + r = η²"
    return None


def wheel_grade(terms: dict[str, float], regime_scale: float | None = None) -> dict | None:
    """The grade coefficient at the wheels, c_grade·η (module docstring), or None without a
    grade term or without a drivetrain's η (:func:`drivetrain_eta`; η outside
    ``ETA_INERTIA_MIN`` … 1 is none, and its own reading says so).

    Returns ``{"value", "eta", "eta_from", "plausible", "note"}``.
    """
    g = terms.get("grade")
    got = drivetrain_eta(terms, regime_scale)
    if g is None or got is None:
        return None
    eta, src = got
    if not ETA_INERTIA_MIN <= eta <= 1.0:
        return None
    w = float(g) * eta
    lo, hi = WHEEL_GRADE_BAND
    ok = lo <= w <= hi
    return {"value": w, "eta": eta, "eta_from": src, "plausible": ok, "note": "" if ok else (
        "the grade and the drivetrain's η disagree: "
        + ("an attenuated grade, an overstated mass or an asymmetry that is no drivetrain" if w < lo
           else "an exaggerated grade or an understated mass"))}


def describe(w: dict) -> str:
    """One phrase for a report: the grade at the wheels and the η it is read with."""
    return (f"at the wheels c_grade·η = {w['value']:.3f} (η = {w['eta']:.3f}, {w['eta_from'].split(':')[0]})"
            + ("" if w["plausible"] else f" — {w['note']}"))
