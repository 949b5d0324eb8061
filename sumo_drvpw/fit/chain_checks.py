"""Is a calibrated energy chain physical, and on what was it fitted?

:func:`check_chain` runs after :func:`sumo_drvpw.fit.chain.calibrate_on` and

* reads the fuel chain's zero-output fuel (``idle_fuel_power_w``, the Willans intercept:
  the fuel an engine burns running without output — friction, pumping, warm-up) in L/h
  against what a passenger car's engine burns idling, and a power-split hybrid's engine-on
  rule against what such a car does at idle and light load (it drives electrically);
* records the range of driving power and speed the chain was fitted on in its provenance
  (``power_range_w``, ``speed_range_mps``): a SUMO run counts the vehicle-steps outside it
  as it does for a road-load equation's speed and acceleration range (summary.json
  ``out_of_range_samples``; sim/loop.py), since a chain's parameters say nothing of
  driving they were not fitted on;
* gathers every parameter reading (:func:`reading`: one line per calibrated parameter,
  flagging implausible values) flagged IMPLAUSIBLE or NOT IDENTIFIED into
  ``ChainFit.warnings``, which ``calibrate`` prints and the equation file keeps
  (``[chain.provenance] warnings``).

References
----------
[DOE861] US DOE Vehicle Technologies Office, Fact of the Week #861 (23 Feb 2015), "Idle
Fuel Consumption for Selected Gasoline and Diesel Vehicles" (Argonne National Laboratory
worksheet; no load: no A/C, fans): petrol compact sedan, 2.0 L, 0.16 gal/h (0.61 L/h);
petrol large sedan, 4.6 L, 0.39 gal/h (1.48 L/h); diesel compact sedan, 2.0 L, 0.17 gal/h.
"""

from __future__ import annotations

import math

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import FUELS

#: what a passenger car's warm engine burns idling with no load [L/h] ([DOE861]: 0.61 L/h
#: for a 2.0-L compact, 1.48 L/h for a 4.6-L large sedan, rounded outwards). An engine
#: running without output burns at least its idle fuel; more than a 4.6-L engine's idle is
#: no passenger car's zero-output fuel but a fit that extrapolates the Willans line from
#: loaded driving (or a trip's cold start spread over it).
IDLE_FUEL_L_PER_H = (0.5, 1.5)
#: the engine whose band IDLE_FUEL_L_PER_H is, when scaled by displacement [L]: [DOE861]'s
#: 2.0-L compact (0.61 L/h: inside 0.5–1.5)
IDLE_FUEL_REF_DISPLACEMENT_L = 2.0
#: powertrains whose engine is off at standstill and drives electrically at light load
HYBRID_POWERTRAINS = ("power_split",)
#: readings that make a warning
FLAGS = ("IMPLAUSIBLE", "NOT IDENTIFIED", "CHECK THE TARGET", "ATTENUATED", "WINDOWS DISAGREE")
#: a battery chain's recuperation efficiency below which it returns next to nothing: no
#: electric or hybrid car's (a rehearsal's Nissan Leaf on a traction-only power: 0.001)
RECUPERATION_MIN = 0.15


def fuel_l_per_h(power_w: float, fuel: str = "gasoline") -> float:
    """A fuel power ṁ·LHV [W] as a volume flow [L/h]."""
    f = FUELS[fuel]
    return power_w / f["lhv_j_per_kg"] / f["density_kg_per_l"] * 3600.0


def fitted_ranges(p_drive_w, v_mps, use) -> dict:
    """(min, max) of the driving power [W] and speed [m/s] over the samples a chain was
    fitted on (``use``), as the equation file's ``[chain.provenance]`` keeps them."""
    p = np.asarray(p_drive_w, float)
    v = np.broadcast_to(np.asarray(v_mps, float), p.shape)
    ok = np.asarray(use, bool) & np.isfinite(p) & np.isfinite(v)
    if not ok.any():
        return {}
    return {"power_range_w": [float(p[ok].min()), float(p[ok].max())],
            "speed_range_mps": [float(v[ok].min()), float(v[ok].max())]}


def idle_fuel_band(displacement_l: float | None = None) -> tuple[float, float]:
    """The plausible zero-output fuel of an engine [L/h]: :data:`IDLE_FUEL_L_PER_H` for a
    passenger car of unknown engine; for an engine of ``displacement_l`` [L] (the vehicle
    file's ``powertrain.displacement_l``) that band scaled by displacement / 2.0 L.

    Source of the scaling: idle fuel is about proportional to displacement — [DOE861]
    gives 0.61 L/h for a 2.0-L and 1.48 L/h for a 4.6-L petrol engine, 0.305 and 0.322 L/h
    per litre (the friction and pumping work of a cycle scale with the swept volume at
    about the same idle speed) — so the band around the 2.0-L compact's idle fuel,
    0.5–1.5 L/h, is taken per litre: 0.25–0.75 L/h per litre of displacement. A 4.6-L
    engine's 1.48 L/h and the EPA fleet fit's zero-output fuel (built-in ``epa_*``
    equations: 0.45 L/h per litre for petrol) are inside; a fixed band flagged a large
    engine's plausible fuel and passed a small one's implausible one.
    """
    lo, hi = IDLE_FUEL_L_PER_H
    if displacement_l is None:
        return lo, hi
    k = float(displacement_l) / IDLE_FUEL_REF_DISPLACEMENT_L
    return lo * k, hi * k


def idle_fuel_note(value_w: float, engine_off_below_w: float, fuel: str, powertrain: str | None,
                   displacement_l: float | None = None) -> str:
    """The zero-output fuel in L/h, and why it is implausible when it is ([DOE861]; the
    band for the engine's ``displacement_l`` [L] when known: :func:`idle_fuel_band`)."""
    lph = fuel_l_per_h(value_w, fuel)
    lo, hi = idle_fuel_band(displacement_l)
    s = f" = {lph:.2f} L/h"
    always_on = engine_off_below_w == -np.inf
    whose = ("a passenger car's engine" if displacement_l is None
             else f"a {displacement_l:g}-L engine ({IDLE_FUEL_L_PER_H[0] / IDLE_FUEL_REF_DISPLACEMENT_L:g}–"
                  f"{IDLE_FUEL_L_PER_H[1] / IDLE_FUEL_REF_DISPLACEMENT_L:g} L/h per litre)")
    if lph > hi:
        s += (f"; IMPLAUSIBLE: more than {whose} burns idling ({lo:.2g}–{hi:.2g} L/h with no "
              f"load, DOE Fact #861: 2.0 L 0.61, 4.6 L 1.48 L/h); a Willans line extrapolated from loaded "
              f"driving (or a cold start spread over the trip) books it "
              + ("at every stop" if always_on else "on every step the engine runs, however light the load"))
    elif lph < lo and always_on:
        s += ("; IMPLAUSIBLE for an engine that idles at stops: below "
              + ("a small car's idle fuel" if displacement_l is None else f"the idle fuel of {whose}")
              + f" ({lo:.2g}–{hi:.2g} L/h, DOE Fact #861)")
    if powertrain in HYBRID_POWERTRAINS and always_on:
        s += "; a power-split hybrid's engine is off at idle, so it burns nothing standing"
    return s


#: a measured fuel flow at standstill beyond this multiple of the idle band's top is no
#: idling engine (a cold engine idles at up to about twice its warm fuel)
STANDING_FUEL_MAX_FACTOR = 2.5


def standing_fuel_note(standing, fuel: str, displacement_l: float | None = None) -> str:
    """Why the log's own fuel at standstill says the fuel target is wrong, when it does:
    ``standing`` = [standing s, with fuel flowing s, that fuel J]
    (:func:`sumo_drvpw.fit.chain_fuel.standing_sums`); the band :func:`idle_fuel_band`."""
    if standing is None or len(standing) < 3 or standing[1] <= 0:
        return ""
    lph = fuel_l_per_h(standing[2] / standing[1], fuel)
    hi = idle_fuel_band(displacement_l)[1]
    if lph <= STANDING_FUEL_MAX_FACTOR * hi:  # (an unknown engine's band is wide: say what would judge it)
        return (f"; CHECK THE TARGET: the log's own fuel flow while the car stands is {lph:.2f} L/h, above a 2.0-L car's idle "
                f"({hi:.2g} L/h): give the engine's powertrain.displacement_l in the vehicle file to judge it "
                "(a diesel's air flow or a flow in other units reads so)") if displacement_l is None and lph > hi else ""
    return (f"; IMPLAUSIBLE TARGET: the log's own fuel flow while the car stands is {lph:.2f} L/h "
            f"({standing[1]:.0f} s), {lph / hi:.1f}× the most an idling "
            + ("passenger car's engine" if displacement_l is None else f"{displacement_l:g}-L engine")
            + f" burns ({hi:.2g} L/h, DOE Fact #861): no engine idles so; a fuel estimated from the "
            "mass air flow of a diesel (unthrottled and lean: its air says nothing of its fuel), a flow "
            "in other units, or the wrong fuel declared — the chain fits that target, not the car's fuel")


#: the most a fuel chain's zero-output fuel (in gear, at driving engine speeds) plausibly
#: exceeds the fuel the same engine burns standing with the engine idling, as the log shows
#: it: friction and pumping grow with engine speed, yet the EPA fleet fit's zero-output
#: fuel is about 1.5× the idle fuel of [DOE861] per litre (0.45 against 0.30 L/h per litre,
#: docs/epa-fleet.md) and a warm truck's or car's accessories run standing too. Beyond it
#: the Willans line is flattened — its slope (the marginal efficiency) too high, its
#: intercept booked at every stop — by noise in the driving power: a grade from a noisy
#: elevation, a lag between fuel and speed, a mass or body declared wrong. A rehearsal's
#: heavy-duty PEMS logs (docs/adapters.md): 99 kW fitted where the truck stood at 10 kW.
IDLE_OVER_STANDING_MAX = 4.0


def idle_over_standing_note(value_w: float, engine_off_below_w: float, standing, fuel: str) -> str:
    """Why an engine's zero-output fuel is implausible against the log's own fuel at
    standstill (:data:`IDLE_OVER_STANDING_MAX`), when the engine runs at stops (always on)
    and the log shows it idling there; else ''."""
    from sumo_drvpw.fit.chain_fuel import idles_at_stops

    if engine_off_below_w != -np.inf or standing is None or len(standing) < 3 or not idles_at_stops(standing):
        return ""
    idle_w = standing[2] / standing[1]
    if not idle_w > 0 or value_w <= IDLE_OVER_STANDING_MAX * idle_w:
        return ""
    return (f"; IMPLAUSIBLE: {value_w / idle_w:.1f}× the fuel the log's engine burns standing "
            f"({fuel_l_per_h(idle_w, fuel):.2f} L/h over {standing[1]:.0f} s; in gear at most about "
            f"{IDLE_OVER_STANDING_MAX:g}×): a Willans line flattened by noise in the driving power (a grade "
            "from a noisy elevation, a lag between fuel and speed, a mass or body declared wrong) books it at "
            "every stop, and its marginal efficiency reads too high")


def engine_off_note(value_w: float, powertrain: str | None, idle_l_per_h: float) -> str:
    """Why a power-split hybrid's chain that starts the engine at any positive driving
    power is implausible (``idle_l_per_h``: its zero-output fuel [L/h])."""
    if powertrain in HYBRID_POWERTRAINS and value_w <= 0.0:
        return ("; IMPLAUSIBLE for a power-split hybrid: its engine is off at idle and at light load "
                "(it drives electrically), but this chain runs it at any positive driving power, so a SUMO "
                f"vehicle creeping in a queue books at least the zero-output fuel, {idle_l_per_h:.2f} L/h, "
                "on every such step (the fit "
                "found no light-load engine-off in these data: too little low-power driving, or too short "
                "a log)")
    return ""


#: the driving power [W] a chain's efficiency needs the usable samples to exceed: below it
#: a log holds standing, idling or creeping only, and the slope of battery or fuel power on
#: driving power is not identified (an idling log's fit put η_m at its bound, 1, exit 0);
#: for a car of :data:`IDENTIFY_DRIVE_MASS_KG`, scaled by mass (:func:`identify_drive_w`)
IDENTIFY_DRIVE_W = 2000.0
IDENTIFY_DRIVE_MASS_KG = 1500.0


def identify_drive_w(vehicle) -> float:
    """The driving power [W] a log must exceed for a chain's efficiency: :data:`IDENTIFY_DRIVE_W`
    per :data:`IDENTIFY_DRIVE_MASS_KG` of the vehicle file's mass (≈ 1.3 W/kg: accelerating at
    0.3 m/s² through 16 km/h, or climbing 3 % at 16 km/h — driving, not creeping, at any mass, as
    the power to accelerate and climb is the mass's; a log's own power range cannot say whether it
    drives): a 94 kg e-scooter's 125 W, a 30 t truck's 40 kW; 2 kW without a vehicle file."""
    mass = getattr(vehicle, "mass_kg", None)
    ok = mass is not None and np.isfinite(mass) and mass > 0
    return IDENTIFY_DRIVE_W * (float(mass) / IDENTIFY_DRIVE_MASS_KG if ok else 1.0)


#: the fewest trips' worth of an HVAC regressor a heating or cooling gain is read from: the
#: air temperature changes between trips and hardly within one (weather), so the gain is
#: identified between trips, and from fewer than this many it reads whatever else sets those
#: trips apart — route, direction, load, a battery energy read from its SOC — as the climate's
#: draw. Counted as the effective number (Σ H)² / Σ H² of the trips' H = ∫ max(T_set − T, 0) dt
#: (heating; cooling alike): n equal trips count n, one trip that holds it all counts 1.
HVAC_TRIPS_MIN = 5.0


def hvac_trip_sums(trip, temp_c, setpoint_c: float, dt_s, ok) -> dict:
    """Per trip (its key as text): [∫ max(T_set − T, 0) dt, ∫ max(T − T_set, 0) dt] [K·s]
    over the samples ``ok`` with a known temperature ``temp_c`` [°C]: what an HVAC gain is
    fitted on, trip by trip (mergeable: batches hold whole trips)."""
    t = np.asarray(temp_c, float)
    ok = np.asarray(ok, bool) & np.isfinite(t)
    if not ok.any():
        return {}
    w = np.nan_to_num(np.asarray(dt_s, float))[ok]
    heat, cool = np.maximum(setpoint_c - t[ok], 0.0) * w, np.maximum(t[ok] - setpoint_c, 0.0) * w
    keys, inv = np.unique(np.asarray(trip)[ok].astype(str), return_inverse=True)
    h, c = np.bincount(inv, heat, len(keys)), np.bincount(inv, cool, len(keys))
    return {k: [float(a), float(b)] for k, a, b in zip(keys, h, c)}


def hvac_trips_note(name: str, value: float, by_trip: dict | None) -> str:
    """Why an HVAC gain ``name`` (``hvac.heating_w_per_k`` or ``hvac.cooling_w_per_k``) of
    ``value`` [W/K] is not identified, when it rests on fewer than :data:`HVAC_TRIPS_MIN`
    trips' worth of its regressor (``by_trip``: :func:`hvac_trip_sums`); else ''."""
    if not by_trip or not value > 0 or name not in ("hvac.heating_w_per_k", "hvac.cooling_w_per_k"):
        return ""
    k = 0 if name == "hvac.heating_w_per_k" else 1
    h = np.array([x[k] for x in by_trip.values()], float)
    if not h.sum() > 0:
        return ""
    n_eff = h.sum() ** 2 / float(h @ h)
    if n_eff >= HVAC_TRIPS_MIN:
        return ""
    what, below = ("heating", "below") if k == 0 else ("cooling", "above")
    share = h.max() / h.sum()
    return (f"; NOT IDENTIFIED: the {what} rests on {n_eff:.1f} trips' worth of the temperature {below} the set-point "
            f"({int((h > 0).sum())} of {len(h)} trips carry it, the largest {share:.0%}; at least {HVAC_TRIPS_MIN:g} "
            f"needed): the air temperature changes between trips, hardly within one, so this gain is whatever else "
            f"sets those trips apart (route, direction, load, a battery read from its state of charge) — "
            f"{value * h.sum() / 3.6e6:.2f} kWh booked on them as {what}, in a car that may have no such "
            f"system; fit it on trips across more temperatures, or leave the HVAC out")


def unexplained_note(r2: float, predicts: str, powertrain: str | None) -> str:
    """Why a chain that explains none of its target (R² < 0 on the samples it was fitted on:
    the bounded physical form is worse than the target's mean) was fitted on the wrong
    target, when it is; else ''."""
    if not r2 < 0:
        return ""
    s = (f"; CHECK THE TARGET: the chain explains none of the {predicts} power it was fitted on (R² {r2:.2f}: "
         "worse than its mean), so the efficiencies read at their bounds say nothing of the powertrain")
    if predicts == "battery" and powertrain in HYBRID_POWERTRAINS:
        return s + (" — a power-split hybrid's battery is charged by its engine and drives the car at light "
                    "load only: its power is no function of the driving power alone; its fuel target books the "
                    "battery's share")
    return s + " — a battery or fuel flow of another vehicle, in other units, or of a sign flipped in part of the log"


def check_chain(fit, vehicle, p_drive_w, v_mps, use, ranges: dict | None = None,
                where: str = "the logs", counts: dict | None = None, hvac_trips: dict | None = None,
                measured: bool = False) -> None:
    """Add the readings, fitted ranges and warnings of this module to a ``ChainFit``
    (in place; see the module docstring); ``ranges``: the fitted ranges when known (a
    streamed fit's), else from ``p_drive_w``, ``v_mps`` and ``use``; ``counts``: the log
    reader's (a fuel target read from an unthrottled engine's air flow is said from them);
    ``hvac_trips``: :func:`hvac_trip_sums` of a chain with HVAC gains (:func:`hvac_trips_note`);
    ``measured``: the chain was fitted on a measured driving power, not an equation's
    (:func:`dilution_note`; an implausible traction efficiency blames it, :data:`MEASURED_OFF`).
    UserError, naming ``where``, when the driving power never exceeds :func:`identify_drive_w`."""
    chain = fit.chain
    ranges = fitted_ranges(p_drive_w, v_mps, use) if ranges is None else ranges
    need = identify_drive_w(vehicle)
    if ranges and ranges["power_range_w"][1] < need:
        (p0, p1), (_, v1) = ranges["power_range_w"], ranges["speed_range_mps"]
        what = "marginal efficiency" if chain.predicts == "fuel" else "traction efficiency"
        raise UserError(f"{where}: the driving power stays within {p0 / 1000:.1f} … {p1 / 1000:.1f} kW "
                        f"(speed up to {v1 * 3.6:.0f} km/h) on the usable samples, never above "
                        f"{need / 1000:.3g} kW" + (f" ({need / vehicle.mass_kg:.2f} W/kg of its {vehicle.mass_kg:.0f} kg)"
                                                  if need != IDENTIFY_DRIVE_W else "")
                        + f": the chain's {what} cannot be told from "
                        "such a log (standing, idling or creeping only); calibrate on logs that drive")
    powertrain = vehicle.powertrain_type if vehicle is not None else None
    params = fit.parameters
    if chain.predicts == "fuel" and "idle_fuel_power_w" in params:
        params["idle_fuel_power_w"]["reading"] += idle_fuel_note(
            chain.idle_fuel_power_w, chain.engine_off_below_w, chain.fuel, powertrain,
            vehicle.powertrain.get("displacement_l") if vehicle is not None else None)
        target_note = standing_fuel_note(getattr(fit, "standing", None), chain.fuel,
                                         vehicle.powertrain.get("displacement_l") if vehicle is not None else None)
        params["idle_fuel_power_w"]["reading"] += target_note or idle_over_standing_note(
            chain.idle_fuel_power_w, chain.engine_off_below_w, getattr(fit, "standing", None), chain.fuel)
        from sumo_drvpw.data.powertrain import unthrottled_note

        params["idle_fuel_power_w"]["reading"] += unthrottled_note(counts)
        if "engine_off_below_w" in params:
            params["engine_off_below_w"]["reading"] += engine_off_note(
                chain.engine_off_below_w, powertrain, fuel_l_per_h(chain.idle_fuel_power_w, chain.fuel))
    if chain.predicts == "fuel" and "marginal_efficiency" in params:
        params["marginal_efficiency"]["reading"] += dilution_note(fit, ranges, measured)
    slope = "traction_efficiency" if chain.predicts == "battery" else "marginal_efficiency"
    if measured and slope == "traction_efficiency" and slope in params:  # (no road load was fitted on)
        params[slope]["reading"] = params[slope].get("reading", "").replace(ROAD_LOAD_OFF, MEASURED_OFF)
    if slope in params:
        params[slope]["reading"] = params[slope].get("reading", "") + unexplained_note(
            getattr(fit, "r2", math.nan), chain.predicts, powertrain)
    for name in ("hvac.heating_w_per_k", "hvac.cooling_w_per_k"):
        if name in params:
            params[name]["reading"] = params[name].get("reading", "") + hvac_trips_note(
                name, params[name]["value"], hvac_trips)
    chain.provenance = {**chain.provenance, **ranges}
    fit.warnings = [f"energy chain {name} = {_value(p['value'])}: {p.get('reading', '')}"
                    for name, p in params.items() if any(f in p.get("reading", "") for f in FLAGS)]
    if fit.warnings:
        chain.provenance["warnings"] = list(fit.warnings)


def dilution_note(fit, ranges: dict | None = None, measured: bool = False) -> str:
    """Why a fuel chain's per-sample line is attenuated (regression dilution: noise in the driving
    power flattens it), when its refits on windowed means (``fit.windowed``:
    :func:`~sumo_drvpw.fit.chain_windows.windowed_lines`) move its marginal efficiency by more
    than :data:`~sumo_drvpw.fit.chain_windows.DILUTION_REL` and beyond twice their standard
    error; else ''. Says the windowed figures and what to do. ATTENUATED where a windowed line reads
    η lower (noise in the regressor reads it high per sample); WINDOWS DISAGREE where every moved
    one reads it higher, which no dilution does. The noise it names is the input's:
    an equation's driving power holds an acceleration derived from a logged speed and a grade from
    a logged elevation; a ``measured`` one (torque × speed, the power-split P_PTdrv) has neither,
    and its windows move the line also where its signals are logged out of step with the fuel or
    the line bends (the Prius Gen-2's, fitted on one trip: η 0.373 per sample, 0.326 on 60-s
    windows, flagged, and no better held out, docs/energy-chain.md)."""
    from sumo_drvpw.fit.chain_windows import DILUTION_REL

    rows = getattr(fit, "windowed", None) or []
    eta, idle = fit.chain.marginal_efficiency, fit.chain.idle_fuel_power_w
    moved = [r for r in rows if abs(r["marginal_efficiency"] - eta) > max(DILUTION_REL * eta, 2.0 * (r["std_err"] or 0.0))]
    if not moved:
        return ""
    figs = "; ".join(f"{r['window_s']:g} s: η {r['marginal_efficiency']:.3f}"
                     + (f" ± {r['std_err']:.3f}" if r["std_err"] is not None else "")
                     + f", {r['idle_fuel_power_w'] / 1000:.1f} kW at zero output ({r['windows']} windows)" for r in rows)
    p = (ranges or {}).get("power_range_w")
    span = f" (here {p[0] / 1000:.0f} … {p[1] / 1000:.0f} kW)" if p else ""
    if all(r["marginal_efficiency"] > eta for r in moved):  # (noise reads η high per sample: not this)
        return (f"; WINDOWS DISAGREE: refitted on means over windows of the same trips — {figs} — against η "
                f"{eta:.3f} and {idle / 1000:.1f} kW on the samples, the windowed lines read the efficiency higher, "
                "which noise in the driving power does not do (it flattens the per-sample line, reading η high): the "
                "line is not straight over the power driven, or the fuel is logged out of step with the power; keep "
                "the fit better on held-out trips (window_s, e.g. 30 s; docs/energy-chain.md)")
    head = (f"; ATTENUATED (errors in the variables): refitted on means over windows of the same trips — {figs} — "
            f"against η {eta:.3f} and {idle / 1000:.1f} kW on the samples: ")
    if measured:  # no derivative in it: noise or timing, or a bent line, and only held-out trips tell
        return head + (
            f"noise in the measured driving power{span} — its torque and speed signals' own, or the fuel logged out "
            "of step with them (a logger polling its signals one after another) — flattens the per-sample line, "
            "or the line is not straight and the windows average over its bend (the Prius Gen-2's windowed lines "
            "were no better held out); fit on windowed means (window_s, e.g. 30 s; docs/energy-chain.md) and keep "
            "the one better on held-out trips")
    return head + (
        f"noise in the driving power{span} — an "
        "acceleration derived from a logged speed, times the mass; a grade from a logged elevation — flattens "
        "the per-sample line, and SUMO, whose inputs are clean, would book its efficiency and zero-output fuel; "
        "fit on windowed means (window_s, e.g. 30 s; docs/energy-chain.md) and compare the two on held-out trips")


def range_note(ranges: dict) -> str:
    """One line: the driving power and speed a chain was fitted on."""
    if not ranges:
        return ""
    (p0, p1), (v0, v1) = ranges["power_range_w"], ranges["speed_range_mps"]
    return (f"fitted on driving power {p0 / 1000:.1f} … {p1 / 1000:.1f} kW and speed {v0 * 3.6:.0f} … "
            f"{v1 * 3.6:.0f} km/h (kept in [chain.provenance]; a SUMO run counts its vehicle-steps outside "
            "them in summary.json out_of_range_samples)")


def _value(x: float) -> str:
    return "-inf" if x == -math.inf else f"{x:.4g}"


#: plausible marginal (Willans-slope) efficiency of an engine by fuel: (checked band, the
#: expected range said). Petrol 0.3–0.45; diesel 0.35–0.5, around the diesel slope ≈ 0.45
#: of the Willans-line literature [RGB99] and the EPA light-duty diesels' measured 0.412 at
#: the wheels (docs/sources.md, docs/hdv-fuel.md)
MARGINAL_EFFICIENCY = {"gasoline": ((0.25, 0.5), "0.3–0.45", "petrol"),
                       "diesel": ((0.3, 0.55), "0.35–0.5", "diesel")}


#: why a traction efficiency fitted on an equation's driving power is implausible (:func:`reading`),
#: and, fitted on a measured one (no road load in the fit, :func:`check_chain` ``measured``), why then
ROAD_LOAD_OFF = ": the road load is off"
MEASURED_OFF = (": the measured driving power it was fitted on (a motor's torque × speed, a power-split "
                "signal; not a road load's power) is off against the battery — a torque or speed signal's scale "
                "(a 2020 Leaf's LeafSpy τ·ω is 0.77 of its V·I, docs/adapters.md) or timing — or a draw beside it")


def reading(name: str, val: float, fuel: str | None = None) -> str:
    """One-line physical reading of a calibrated parameter, flagging implausible values
    (an engine's by its ``fuel``, a key of :data:`sumo_drvpw.model.constants.FUELS`)."""
    if name == "traction_efficiency":
        s = f"battery → wheel on traction {val:.1%} (motor, inverter, gear, battery resistance)"
        return s + ("; IMPLAUSIBLE for a BEV (expected 0.75–0.95)" + ROAD_LOAD_OFF
                    if not 0.7 <= val <= 0.97 else "")
    if name == "recuperation_efficiency":
        s = f"wheel → battery on braking {val:.1%} (incl. the blended friction share)"
        if val >= 0.99:
            return s + ("; IMPLAUSIBLE (no generator is lossless): the braking power is "
                        "underestimated or other terms absorb losses")
        if val < RECUPERATION_MIN:  # (a battery chain is an electric or hybrid car's: it recuperates)
            return s + ("; IMPLAUSIBLE for a car that recuperates (electric and hybrid cars return "
                        "about 0.5–0.7 at the battery): the braking energy does not reach this target — "
                        "a road-load equation fitted on a power logged for traction only, or a battery "
                        "energy too coarse to show it (state-of-charge steps)")
        return s + ("; low: friction braking or a recuperation limit dominates" if val < 0.4 else "")
    if name == "recuperation_limit_w":
        return f"braking power beyond {val / 1000:.1f} kW goes to the friction brakes"
    if name == "aux_power_w":
        return f"constant auxiliary draw {val:.0f} W (12 V net, pumps, control; accrues at standstill)"
    if name.startswith("loads.") and fuel is not None:  # a fuel chain: engine output per W logged
        s = f"{val:.3f} W of engine output per W logged"
        return s + ("; IMPLAUSIBLE: an electrical load costs the engine about 1.2–3 W per W (alternator), a "
                    "mechanical one about 1" if not 0.8 <= val <= 3.0 else "")
    if name.startswith("loads."):
        s = f"{val:.3f} W at the battery per W logged"
        return s + ("; far from 1: the logged load is not electrical power at the battery"
                    if not 0.7 <= val <= 1.3 else "")
    if name == "hvac.warmup_j_per_k":
        return (f"cabin warm-up at a cold start {val / 1000:.0f} kJ per K below the set-point "
                f"({val * 15 / 3.6e6:.2f} kWh from 15 K below)")
    if name.startswith("hvac."):
        return f"{val:.0f} W per K from the set-point"
    if name == "marginal_efficiency":
        # (a calibrated fuel chain's driving power is the road load's or the log's, at the wheels
        # or the powertrain's output, with traction_efficiency 1: its slope holds the driveline too)
        s = f"fuel → driving power at the margin {val:.1%} (Willans slope: engine and driveline together)"
        (lo, hi), said, kind = MARGINAL_EFFICIENCY.get(fuel, MARGINAL_EFFICIENCY["gasoline"])
        return s + (f"; IMPLAUSIBLE for a {kind} engine (expected {said})" if not lo <= val <= hi else "")
    if name == "idle_fuel_power_w":
        return f"fuel power with the engine on at zero output {val / 1000:.2f} kW (friction, pumping, warm-up, auxiliaries)"
    if name == "engine_off_below_w":
        if val == -np.inf:
            return "engine always on (a conventional engine: idles at stops and while braking)"
        return f"engine off below {val / 1000:.1f} kW of driving power"
    if name == "engine_on_above_mps":
        return f"engine always on above {val * 3.6:.0f} km/h"
    return ""


#: driving powers beyond this [W] test the battery current's sign (_check_chain_inputs)
SIGN_CHECK_W = 1000.0


def _check_chain_inputs(m, use: np.ndarray, loads, p_drive=None) -> None:
    """UserError, naming the log and the column, where a chain cannot be calibrated: a
    measured battery or fuel power that never departs from 0 (a voltage logged as 0, a
    fuel flow never filled: the fit would return efficiencies at their bounds and an R² of
    NaN), a battery power that falls where the driving power ``p_drive`` rises (the
    current's sign flipped: the fit returned η_r = 0.001 and R² −2.9, exit 0), or a load
    column without a number on the usable samples."""
    where = m.log.describe()
    y = np.asarray(m.power_w, float)[use]
    if use.any() and not np.any(np.nan_to_num(y) != 0):
        raise UserError(f"{where}: the measured {m.target} power ({m.source}) is 0 on every "
                        f"one of the {int(use.sum())} usable samples: nothing to calibrate a "
                        "chain on (a voltage, current or fuel flow logged as 0?)")
    if m.target == "battery" and p_drive is not None:
        from sumo_drvpw.data.measured import refuse_falling_battery

        refuse_falling_battery(where, m.source, np.asarray(p_drive, float)[use], y, np.ones(len(y), bool),
                               SIGN_CHECK_W, "the driving power")
    check_load_columns(m, loads, use)


def not_a_power(column: str) -> str:
    """'' for a load column whose name may hold a power; else why not: its unit suffix is
    another dimension's (``coolant_c``: a temperature; data.adapters._common.DIMENSIONS)."""
    from sumo_drvpw.data.adapters._common import DIMENSIONS

    other = {s: d for d, s in DIMENSIONS.items() if s and s != "w"}
    suffix = column.rsplit("_", 1)[-1] if "_" in column else ""
    if suffix == "kw":  # a power, not in W: a gain 1000× off
        return f"'{column}' holds a power in kW by its name's suffix: a load is a power in W (convert it, …_w)"
    return (f"'{column}' holds a {other[suffix].replace('_', ' ')} by its name's suffix '_{suffix}': a load is "
            "a power in W (a column named …_w)") if suffix in other else ""


def check_load_columns(m, loads, use=None) -> None:
    """UserError naming the log and the column: a load column that is missing, not numeric,
    or without a number on the usable samples ``use`` (default: the log's usable samples) —
    checked before anything is fitted."""
    where, use = m.log.describe(), (m.usable if use is None else use)
    for c in loads or ():
        if not_a_power(c):
            raise UserError(f"{where}: load column {not_a_power(c)}")
        col = m.inputs.signals.get(c)
        if col is None and c in m.log.df.columns:
            first = m.log.df[c].dropna()
            raise UserError(f"{where}: load column '{c}' is not numeric (first value "
                            f"{first.iloc[0] if len(first) else None!r}): a load is power in W")
        if col is None:
            raise UserError(f"{where}: no load column '{c}' (extra columns: "
                            f"{', '.join(sorted(m.inputs.signals)) or 'none'})")
        check_load_values(where, c, col)
        if not np.isfinite(np.asarray(col, float)[use]).any():
            raise UserError(f"{where}: load column '{c}' has no number on the "
                            f"{int(use.sum())} usable samples")


def check_load_values(where: str, c: str, col) -> None:
    """UserError naming the log ``where``, the load column ``c``, the row and the value: an
    infinite load, or one beyond any road vehicle's power
    (:data:`~sumo_drvpw.data.ranges.POWER_MAX_W`; an auxiliary draws kilowatts: a logger's
    garbage). Empty cells (NaN) stay: those samples are left out."""
    from sumo_drvpw.data.ranges import POWER_MAX_W

    x = np.asarray(col, float)
    bad = np.isinf(x) | (np.abs(x) > POWER_MAX_W)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise UserError(f"{where}: load column '{c}' is {x[i]:g} at row {i}: "
                        + ("values must be finite" if np.isinf(x[i]) else
                           f"beyond ±{POWER_MAX_W:.0e} W, more than any road vehicle's power (a load is power in W)"))


def driving_power_of(path) -> str | None:
    """The measured driving power a drive log file's own columns give, in the order
    :func:`sumo_drvpw.data.powertrain.measured_power` tries them (None: none, battery V·I at
    most; also when its header cannot be read)."""
    from sumo_drvpw.data.powertrain import POWER_SOURCES
    from sumo_drvpw.data.stream import column_names

    names = set(column_names(path) or ())
    labels = ("direct (power_w)", "power-split (MG1, MG2, engine)", "single motor (motor_torque_nm)",
              "single motor (motor_torque_nm)")  # POWER_SOURCES but the battery's V·I
    return next((lab for cols, lab in zip(POWER_SOURCES, labels) if all(c in names for c in cols)), None)


def check_one_driving_power(files) -> None:
    """Files read into one table that differ in their measured driving power (one logs it,
    another not, or another kind) are refused, naming the first that differs from the first
    file: the chain takes one input for all samples, and in one table the rows of a file
    without the others' columns have no measured driving power and drop out of the fit
    silently (the streamed fit refuses them too, :meth:`~sumo_drvpw.fit.chain_stream.ChainStats.check_inputs`)."""
    src = {str(f): driving_power_of(f) for f in files}
    first = next(iter(src), None)
    for f, s in src.items():
        if s != src[first]:
            a, b = (first, f) if src[first] is not None else (f, first)
            what = (f"{b}: no measured driving power (power_w, motor torque, the power-split signals) while "
                    f"{a} has one ({src[a]})" if src[b] is None else
                    f"{f}: measured driving power {s} while {first} has {src[first]}")
            raise UserError(f"{what}: the chain takes one input for all files (in one table the rows without "
                            "it would drop out of the fit); calibrate them apart, or give every file the same columns")
