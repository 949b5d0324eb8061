"""Diesel fuel chains for the heavy MOVES source types, set from published physics, and their check.

Run::

    .venv/bin/python -m sumo_drvpw.validation.hdv_fuel [REPORT.md [DATA_FOLDER [HAMBURG_RUN]]]

writes the built-in equations ``moves_single_unit_truck_diesel``,
``moves_combination_truck_diesel``, ``moves_transit_bus_diesel`` and
``moves_intercity_bus_diesel`` (``sumo_drvpw/model/builtin/equations/``), the Markdown report
(default ``docs/hdv-fuel.md``) and ``<report>.json`` beside it.

**The chains are not fitted.** Each is the MOVES road load of its source type (the terms of
``moves_<type>.toml``, docs/sources.md [MOVES-ST]) with a conventional diesel engine's
Willans line (docs/energy-chain.md, ``predicts = "fuel"``, engine running the whole trip, its
injection cut in overrun: no fuel while the vehicle rolls with P < 0)::

    P_fuel = P_idle + (max(P, 0)/η_d + P_aux)/η_e      (P ≥ 0 or standing; else 0)

η_d (``traction_efficiency``) is the driveline wheel ← engine, η_e (``marginal_efficiency``)
the engine's Willans slope, so fuel → wheel at the margin is η_e·η_d and an auxiliary load
is paid at the engine; P_idle (``idle_fuel_power_w``) is a measured idle fuel rate, P_aux
(``aux_power_w``) the accessories' draw at the engine. Every number is in :data:`CHAINS`
with the public source it comes from (:data:`SOURCES`) and its physical reading; the fuel
(LHV, density, CO₂) is the project's ``diesel`` (``model/constants.py`` ``FUELS``).

**The check** (no parameter is changed by it): the chains and SUMO's own HBEFA 4 default
class of each vClass (:data:`SUMO_CLASSES`, SUMO's vType defaults) drive the same speed
traces — the light-duty schedules of ``cycles/`` (FASTSim's files: UDDS, HWFET, US06,
WLTC class 3b; no heavy-duty schedule is in the shared data) — ours at the MOVES source
mass, SUMO's through ``emissionsDrivingCycle`` (HBEFA 4 functions of speed and
acceleration only: mass and slope are not inputs). Litres per 100 km side by side, flagged
where they differ by more than :data:`FLAG_SHARE`. With ``HAMBURG_RUN`` (the output folder of
a ``sumo-drvpw run`` of the Hamburg scenario) the report adds the L/100 km that run booked
per vClass, with the run's own command from its manifest, beside published real-world
fleet figures (:data:`FLEET_FIGURES`); without it the last report's Hamburg section is kept.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import FUELS

CYCLES = "cycles"
#: the light-duty schedules the check drives (FASTSim's files in ``cycles/``)
CHECK_CYCLES = ("udds", "hwfet", "us06", "wltc_3b")
#: US gallon [L]
GALLON_L = 3.785411784
#: |ours/SUMO − 1| above this is flagged in the report
FLAG_SHARE = 0.25
FUEL = "diesel"

#: references, key → what was read (docs/sources.md, "Heavy-duty diesel chains")
SOURCES = {
    "DOE861": "US DOE Vehicle Technologies Office, Fact of the Week #861 (23 Feb 2015), 'Idle Fuel "
              "Consumption for Selected Gasoline and Diesel Vehicles' (Argonne worksheet; transit bus, tow, "
              "combination and bucket truck from an ORNL study, delivery truck from NREL, medium heavy trucks "
              "from J. Air & Waste Manage. Assoc.): idle fuel with no load (no A/C, fans), gal/h",
    "FASTSIM": "NREL FASTSim vehicle database, fastsim/resources/FASTSim_py_veh_db.csv (commit 1178bcfc), "
               "rows 'Regional Delivery Class 8 Truck' (212 kW, transEff 0.85, auxKw 10) and 'Line Haul Conv' "
               "(321 kW, transEff 0.80, auxKw 10)",
    "RGB99": "Rizzoni, Guzzella & Baumann, 'Unified modeling of hybrid electric vehicle drivetrains', "
             "IEEE/ASME Trans. Mechatronics 4(3) 1999: the Willans line; the diesel slope ≈ 0.45 that "
             "docs/epa-fleet.md states",
    "EPA-TCL": "this project's EPA Test Car List study (docs/epa-fleet.md): light-duty diesels' Willans slope "
               "fuel → wheels 0.412 (engine × transmission), measured on certification tests",
    "NRC2012": "National Research Council (2012), Review of the 21st Century Truck Partnership, 2nd report, "
               "Finding 8-2: SuperTruck engine goal 50 % brake thermal efficiency (demonstrated 50.2 % and 50.5 % "
               "by the Daimler and Navistar engines, trucknews.com 'SuperTruck led to real-world truck gains')",
    "SUMO-DEF": "SUMO 1.28 vType defaults (docs/web/docs/Vehicle_Type_Parameter_Defaults.md): truck 4500 kg "
                "HBEFA4/RT_le7.5t_Euro-VI_A-C, trailer 13000 kg HBEFA4/TT_AT_gt34-40t_Euro-VI_A-C, bus 12000 kg "
                "HBEFA4/UBus_Std_gt15-18t_Euro-VI_A-C, coach 25000 kg HBEFA4/Coach_3-Axes_gt18t_Euro-VI_A-C; "
                "HelpersHBEFA4.h: fuel = f(v, a) per class, no mass or slope, zero while coasting",
    "MB-DFCO": "Mercedes-Benz service information GF07.10-P-1014OGR and GF07.10-D-1014TSA, 'Overrun Mode Fuel "
               "Shutoff, Function' (CDI common-rail diesels OM642, OM651): with the accelerator released and the "
               "vehicle rolling in gear the control unit switches the injectors off (engine braking, less fuel); "
               "they inject again when the pedal is pressed or the engine speed falls toward idle",
    "DOE626": "US DOE Vehicle Technologies Office, Fact #626 (7 Jun 2010), 'Fuel Economy of Light and Heavy "
              "Vehicles', from National Academy of Sciences (2010) Technologies and Approaches to Reducing the "
              "Fuel Consumption of Medium- and Heavy-Duty Vehicles, pp. 2-2, 2-3: fuel economy ranges by class",
    "MINN2013": "MinnPost / Salon (17 Sep 2013), 'Studying the benefits of greening a bus fleet' (University of "
                "Minnesota, Metro Transit): 'a typical bus gets only between four and six miles per gallon'",
    "TRUCKNEWS": "trucknews.com, 'SuperTruck led to real-world truck gains, and more are coming': good fleet "
                 "tractor-trailers 8 mpg (29.4 L/100 km), 2009 best trucks 6–7 mpg",
    "GILLESPIE": "T. D. Gillespie, Fundamentals of Vehicle Dynamics, SAE (1992), ch. 2: the mass factor of a "
                 "vehicle's rotating parts, 1 + 0.04 + 0.0025·N² at overall gear ratio N (the measured trucks' "
                 "check, validation/hdv_measured.py)",
    "ADVISOR": "NREL ADVISOR 2003 data files (public copy sateesh12/impact-of-uc-on-li-ion, advisor/data/): "
               "FC_CI330.m (Detroit Diesel Series 60 12.7 L, 332 kW; engine inertia = its mass 4.2 kg/kW × "
               "(1/3 + 2/9) × 0.075², the Bosch handbook's correlation: 4.36 kg·m²) and "
               "WH_TractorTrailer_midRR.m (275/80R22.5 drive tyre, rolling radius 0.501 m; 80 kg per tyre and "
               "wheel, 18 of them; mid-resistance tyres' rolling coefficient 0.0055 by axle load); "
               "VEH_KENT800Trailer.m (Kenworth T800 and trailer: C_D 0.70, frontal area 92 ft², WVU's rolling "
               "coefficient 0.00938); TX_RTLO12610B.m (Eaton Fuller RTLO-12610B 10-speed: efficiency 0.92, "
               "final drive loss unknown)",
    "ISA": "ISO 2533:1975 standard atmosphere: pressure 101.325·(1 − 2.25577e-5·h)^5.25588 kPa at height h [m] "
           "(the measured trucks' air density, validation/hdv_measured.py)",
}

#: the engine's Willans slope [-], shared by the four chains
ENGINE_WILLANS = 0.45
ENGINE_READING = ("engine Willans slope (fuel → crankshaft at the margin) of a heavy-duty diesel: the diesel value "
                  "0.45 of the Willans-line literature [RGB99]; the light-duty diesels' measured line "
                  "(0.412 at the wheels with the transmission [EPA-TCL]) implies 0.45 at a 0.92 transmission, and "
                  "heavy-duty engines' peak brake efficiency (about 0.42–0.46 in production, 0.50 for SuperTruck "
                  "research engines [NRC2012]) must sit below the slope. ESTIMATE: no heavy-duty Willans fit was read")

#: single-unit diesel trucks of [DOE861]: delivery 19,500 lb, tow 26,000 lb, medium heavy
#: 6–10 L 23,000–33,000 lb, bucket 37,000 lb [gal/h, no load]
SINGLE_UNIT_IDLE_GAL_H = (0.84, 0.59, 0.44, 0.90)

#: per built-in: the MOVES equation whose road load it takes, the driveline efficiency, the
#: idle fuel [US gal/h], the auxiliary power [W], each with its reading, SUMO's default class
#: of the vClass and a closer HBEFA class where the default's size differs
CHAINS = {
    "moves_single_unit_truck_diesel": {
        "base": "moves_single_unit_truck", "what": "single-unit short-haul truck (MOVES 52)",
        "driveline": 0.85,
        "driveline_reading": "driveline wheel ← engine: FASTSim's regional-delivery class-8 truck, transEff 0.85 "
                             "[FASTSIM] (stop-and-go duty, transmission and axle)",
        "idle_gal_h": statistics.median(SINGLE_UNIT_IDLE_GAL_H),
        "idle_reading": "median of the four single-unit diesel trucks of [DOE861] (delivery 0.84, tow 0.59, "
                        "medium heavy 6–10 L 0.44, bucket 0.90 gal/h, no load): 0.715 gal/h",
        "aux_w": 10000.0,
        "aux_reading": "accessories at the engine (fan, air compressor, alternator, steering pump): FASTSim's "
                       "class-8 trucks' auxKw 10 kW [FASTSIM]; drawn while standing too, on top of the no-load idle",
    },
    "moves_combination_truck_diesel": {
        "base": "moves_combination_truck", "what": "combination long-haul truck (MOVES 62)",
        "driveline": 0.80,
        "driveline_reading": "driveline wheel ← engine: FASTSim's line-haul conventional truck, transEff 0.80 "
                             "[FASTSIM]",
        "idle_gal_h": 0.49,
        "idle_reading": "[DOE861] diesel combination truck, 32,000 lb: 0.49 gal/h with no load",
        "aux_w": 10000.0,
        "aux_reading": "accessories at the engine: FASTSim's class-8 trucks' auxKw 10 kW [FASTSIM]",
    },
    "moves_transit_bus_diesel": {
        "base": "moves_transit_bus", "what": "transit bus (MOVES 42)",
        "driveline": 0.85,
        "driveline_reading": "driveline wheel ← engine: ESTIMATE, FASTSim's stop-and-go class-8 truck (0.85 "
                             "[FASTSIM]); no bus row was read (a torque-converter automatic may lose more)",
        "idle_gal_h": 0.97,
        "idle_reading": "[DOE861] diesel transit bus, 30,000 lb: 0.97 gal/h with no load",
        "aux_w": 10000.0,
        "aux_reading": "accessories at the engine: FASTSim's heavy trucks' auxKw 10 kW [FASTSIM], taken as the "
                       "bus's floor; a bus's HVAC, doors' air and kneeling draw more in summer — ESTIMATE, no "
                       "measured bus accessory load was read",
    },
    "moves_intercity_bus_diesel": {
        "base": "moves_intercity_bus", "what": "intercity bus (MOVES 41)",
        "driveline": 0.80,
        "driveline_reading": "driveline wheel ← engine: ESTIMATE, FASTSim's line-haul truck (0.80 [FASTSIM]), "
                             "the highway duty of a coach",
        "idle_gal_h": 0.49,
        "idle_reading": "ESTIMATE: [DOE861] has no coach; its diesel combination truck's 0.49 gal/h (a coach "
                        "carries a tractor-size 11–13 L engine)",
        "aux_w": 10000.0,
        "aux_reading": "accessories at the engine: FASTSim's heavy trucks' auxKw 10 kW [FASTSIM]; a coach's "
                       "HVAC draws more in summer — ESTIMATE",
    },
}

#: vClass of each built-in's road load → SUMO's default emission class ([SUMO-DEF]) and,
#: where its size differs from the MOVES source type, a closer HBEFA 4 class
SUMO_CLASSES = {
    "moves_single_unit_truck_diesel": ("truck", "HBEFA4/RT_le7.5t_Euro-VI_A-C", 4500.0,
                                       "HBEFA4/RT_gt7_5-12t_Euro-VI_A-C"),
    "moves_combination_truck_diesel": ("trailer", "HBEFA4/TT_AT_gt34-40t_Euro-VI_A-C", 13000.0, None),
    "moves_transit_bus_diesel": ("bus", "HBEFA4/UBus_Std_gt15-18t_Euro-VI_A-C", 12000.0, None),
    "moves_intercity_bus_diesel": ("coach", "HBEFA4/Coach_3-Axes_gt18t_Euro-VI_A-C", 25000.0, None),
}

#: published real-world figures per vClass: (what, low, high [L/100 km], source key)
FLEET_FIGURES = {
    "bus": [("US transit bus, 4–6 mpg", 235.215 / 6, 235.215 / 4, "MINN2013"),
            ("class 8a straight trucks incl. city bus, 2.5–6 mpg", 235.215 / 6, 235.215 / 2.5, "DOE626")],
    "truck": [("class 6 city delivery, 5–12 mpg", 235.215 / 12, 235.215 / 5, "DOE626"),
              ("class 7 (furniture, refrigerated, tanker …), 4–8 mpg", 235.215 / 8, 235.215 / 4, "DOE626")],
    "trailer": [("class 8b combination trucks, 4–7.5 mpg", 235.215 / 7.5, 235.215 / 4, "DOE626"),
                ("good fleet tractor-trailers today, 8 mpg", 29.4, 29.4, "TRUCKNEWS")],
    "coach": [],
}


def gal_h_to_w(gal_h: float) -> float:
    """Fuel power [W, LHV] of a diesel fuel rate [US gal/h]."""
    f = FUELS[FUEL]
    return gal_h * GALLON_L / 3600.0 * f["density_kg_per_l"] * f["lhv_j_per_kg"]


def builtin_doc(name: str) -> dict:
    """The TOML document of built-in ``name``: its MOVES base's road load and the chain."""
    from sumo_drvpw.model.equations import load_equation

    c = CHAINS[name]
    base = load_equation(c["base"])
    doc = base.to_dict()
    doc["equation"]["name"] = name
    doc["equation"]["description"] = (f"diesel {c['what']}: MOVES road load and a Willans fuel line from "
                                      "published heavy-duty diesel physics (not fitted); the mass comes from "
                                      "the vType")
    doc["equation"]["source"] = (f"road load: {base.source}; chain: docs/hdv-fuel.md, docs/sources.md "
                                 "'Heavy-duty diesel chains' (written by python -m sumo_drvpw.validation.hdv_fuel)")
    doc["equation"].pop("predicts", None)
    idle_w = gal_h_to_w(c["idle_gal_h"])
    doc["chain"] = {
        "predicts": "fuel", "fuel": FUEL, "traction_efficiency": c["driveline"],
        "marginal_efficiency": ENGINE_WILLANS, "idle_fuel_power_w": round(idle_w, 1),
        "aux_power_w": c["aux_w"], "engine_off_below_w": -np.inf, "fuel_cut_below_w": 0.0,
        "reading": {
            "traction_efficiency": c["driveline_reading"],
            "marginal_efficiency": ENGINE_READING + f"; fuel → wheel at the margin "
                                   f"{ENGINE_WILLANS * c['driveline']:.4f} (with the driveline)",
            "idle_fuel_power_w": c["idle_reading"] + f" = {idle_w:.0f} W of fuel (diesel LHV, density of "
                                 "model/constants.py FUELS)",
            "aux_power_w": c["aux_reading"],
            "engine_off_below_w": "-inf: the engine runs the whole trip and idles at stops (no stop-start)",
            "fuel_cut_below_w": "0: overrun fuel cut-off [MB-DFCO] — while the vehicle rolls with a negative "
                                "driving power (coasting down, braking) the wheels turn the engine and its "
                                "injection is cut, so no idle fuel is burnt then; its accessories run on the "
                                "vehicle's kinetic energy. Standing, it idles. (The injection resumes near idle "
                                "speed, just before a stop, and a wheel power below 0 but above the accessories' "
                                "draw (−P_aux·η_d) does not carry them all: the cut at 0 is slightly generous: "
                                "the transit bus books 43.28 L/100 km on UDDS with it in this check, 44.09 with "
                                "the cut at −P_aux·η_d.)",
            "cold_start_fuel_l": "0: no heavy-duty cold-start measurement was read; not booked",
            "running_fuel_per_k": "0: no heavy-duty warm-running temperature factor was read",
        },
        "provenance": {"idle_fuel_gal_per_h": c["idle_gal_h"], "fuel_to_wheel_at_margin":
                       round(ENGINE_WILLANS * c["driveline"], 6),
                       "sources": "docs/sources.md 'Heavy-duty diesel chains'; " + "; ".join(
                           f"[{k}]" for k in SOURCES if f"[{k}]" in " ".join(
                               (c["driveline_reading"], c["idle_reading"], c["aux_reading"], ENGINE_READING,
                                "[MB-DFCO]")))},
    }
    return doc


def write_builtins(names=None, doc=None) -> list[Path]:
    """Write built-in equations: ``names`` (default: the four of :data:`CHAINS`) from ``doc(name)``
    (default: :func:`builtin_doc`; validation/mc_fuel.py writes its own with it); returns their paths."""
    from sumo_drvpw.model.equations import BUILTIN_DIR, equation_from_dict, save_equation

    out = []
    for name in CHAINS if names is None else names:
        p = BUILTIN_DIR / f"{name}.toml"
        save_equation(equation_from_dict((doc or builtin_doc)(name), f"<{name}>"), p)
        out.append(p)
    return out


# ---------------------------------------------------------------------- the check
def read_cycle(folder: Path, name: str) -> np.ndarray:
    """Speed per second [m/s] of schedule ``name`` (FASTSim's CSV: cycSecs, cycMps)."""
    import pandas as pd

    p = Path(folder) / f"{name}.csv"
    try:
        d = pd.read_csv(p, encoding="utf-8-sig")
        t, v = d["cycSecs"].to_numpy(float), d["cycMps"].to_numpy(float)
    except (OSError, KeyError, ValueError) as e:
        raise UserError(f"{p}: not a speed schedule with columns cycSecs, cycMps ({e})") from None
    if t.size < 2 or np.any(np.diff(t) != 1.0):
        raise UserError(f"{p}: the check needs one row per second")
    return v


def chain_run(eq, v: np.ndarray, mass_kg: float) -> dict:
    """Equation ``eq`` (road load and chain) on schedule ``v`` at ``mass_kg``: 1-s steps at the
    step's mean speed, m·v̄·Δv the kinetic-energy change, flat road; fuel [L], distance [km],
    L/100 km, and the share of the fuel burnt with no traction (``share_no_traction``)."""
    from sumo_drvpw.model.terms import Inputs

    vm, dv = 0.5 * (v[1:] + v[:-1]), np.diff(v)
    z = np.zeros_like(vm)
    x = Inputs(v=vm, a=dv, theta=z, wind=z, mass=np.full_like(vm, float(mass_kg)),
               rho=np.full_like(vm, 1.2041), v_acc=vm)
    p = eq.power(x)
    r = eq.chain.evaluate(p, vm, dt_s=1.0)
    litres, km = float(r["fuel_l"].sum()), float(vm.sum()) / 1000.0
    idle = float(np.sum(r["power_j"] * (np.maximum(p, 0) == 0)) / np.sum(r["power_j"]))
    return {"fuel_l": litres, "km": km, "l_per_100km": 100.0 * litres / km, "share_no_traction": idle}


def ours_l_per_100km(name: str, v: np.ndarray, mass_kg: float) -> dict:
    """Built-in ``name`` (:func:`builtin_doc`) on schedule ``v`` at ``mass_kg`` (:func:`chain_run`)."""
    from sumo_drvpw.model.equations import equation_from_dict

    return chain_run(equation_from_dict(builtin_doc(name), f"<{name}>"), v, mass_kg)


def sumo_l_per_100km(cls: str, v: np.ndarray, workdir: Path, fuel: str = FUEL) -> dict | None:
    """SUMO's emission class ``cls`` on schedule ``v`` through emissionsDrivingCycle (speed
    and a = v(t) − v(t−1) per second, no slope); None without SUMO's tools. Litres from the
    tool's fuel mass with the density of the project's ``fuel`` (diesel unless told)."""
    from sumo_drvpw.validation.chain_sumo import sumo_tool

    tool = sumo_tool("emissionsDrivingCycle")
    if tool is None:
        return None
    tl, out = workdir / "timeline.csv", workdir / "out.csv"
    a = np.diff(v, prepend=v[0])
    np.savetxt(tl, np.column_stack([np.arange(v.size), v, a]), delimiter=";", fmt="%.6f")
    done = subprocess.run([tool, "-t", str(tl), "-e", cls, "-o", str(out)], capture_output=True, text=True)
    if done.returncode != 0:  # an emission class this SUMO lacks, a tool that fails: one line
        said = (done.stderr or done.stdout).strip().splitlines() or ["no message"]
        first = next((x for x in said if x.startswith("Error")), said[-1])
        raise UserError(f"SUMO's emissionsDrivingCycle with {cls}: exit {done.returncode}: {first}")
    mg = np.loadtxt(out, delimiter=";", ndmin=2)[:, 9]
    km = float(np.sum(0.5 * (v[1:] + v[:-1]))) / 1000.0
    litres = float(np.nansum(mg)) * 1e-6 / FUELS[fuel]["density_kg_per_l"]
    return {"fuel_l": litres, "km": km, "l_per_100km": 100.0 * litres / km,
            "idle_l_per_h": float(mg[v == 0].mean()) * 3.6e-3 / FUELS[fuel]["density_kg_per_l"]
            if np.any(v == 0) else None}


def check(data: Path) -> dict:
    """Per built-in and schedule, ours and SUMO's L/100 km (see the module docstring)."""
    from sumo_drvpw.model.equations import load_equation

    cycles = {c: read_cycle(Path(data) / CYCLES, c) for c in CHECK_CYCLES}
    out = {}
    with tempfile.TemporaryDirectory() as td:
        for name, (vclass, cls, sumo_mass, near) in SUMO_CLASSES.items():
            base = load_equation(CHAINS[name]["base"])
            mass = float(base.provenance["source_mass_t"]) * 1000.0
            rows = {}
            for cyc, v in cycles.items():
                row = {"ours": ours_l_per_100km(name, v, mass), "sumo": sumo_l_per_100km(cls, v, Path(td))}
                if near:
                    row["sumo_near"] = sumo_l_per_100km(near, v, Path(td))
                rows[cyc] = row
            eq_doc = builtin_doc(name)["chain"]
            out[name] = {"vclass": vclass, "mass_kg": mass, "sumo_class": cls, "sumo_vtype_mass_kg": sumo_mass,
                         "sumo_near_class": near, "cycles": rows,
                         "standing_l_per_h": (eq_doc["idle_fuel_power_w"] + eq_doc["aux_power_w"] / ENGINE_WILLANS)
                         * 3600.0 / FUELS[FUEL]["lhv_j_per_kg"] / FUELS[FUEL]["density_kg_per_l"]}
    return out


def hamburg(run: Path) -> dict:
    """The per-vClass fuel a finished run booked (``chain_classes.csv``), with its command
    (``manifest.json``), begin and end time, wall time (``summary.json``) and the warning of
    vehicles no chain booked (validation/mc_fuel.py reads its MoST run with it too)."""
    import pandas as pd

    run = Path(run)
    try:
        man = json.loads((run / "manifest.json").read_text(encoding="utf-8"))
        summ = json.loads((run / "summary.json").read_text(encoding="utf-8"))
        cls = pd.read_csv(run / "chain_classes.csv")
    except (OSError, ValueError) as e:
        raise UserError(f"{run}: not a finished sumo-drvpw run folder ({e})") from None
    try:
        veh = pd.read_parquet(run / "vehicles.parquet", columns=["equation", "distance_m", "time_s"])
    except (OSError, ValueError) as e:
        raise UserError(f"{run}: vehicles.parquet not readable ({e})") from None
    tot = veh.groupby("equation")[["distance_m", "time_s"]].sum()
    rows = [{"vclass": r.key, "equation": r.equation, "km": float(r.distance_km), "fuel_l": float(r.fuel_l),
             "l_per_100km": float(r.fuel_l_per_100km),
             "mean_speed_kmh": float(3.6 * tot.loc[r.equation, "distance_m"] / tot.loc[r.equation, "time_s"])}
            for r in cls.itertuples(index=False)]
    warn = [w for w in summ.get("warnings", []) if "no battery or fuel chain" in w]
    return {"command": " ".join(man.get("command", [])), "begin_s": summ.get("begin_s") or 0.0,
            "end_s": summ.get("end_s"), "wall_time_s": summ.get("wall_time_s"), "vehicles": summ.get("vehicles"),
            "classes": rows, "chainless_warning": warn[0] if warn else None}


def main(argv=None) -> int:
    """``python -m sumo_drvpw.validation.hdv_fuel [REPORT.md [DATA_FOLDER [HAMBURG_RUN]]]``:
    writes the built-ins, the report and its JSON. Exit 2 with one line on bad input."""
    from sumo_drvpw.validation.hdv_fuel_report import render

    return study_main(argv, "sumo_drvpw.validation.hdv_fuel", "docs/hdv-fuel.md", "HAMBURG_RUN", "hamburg",
                      check, hamburg, render, write_builtins)


def study_main(argv, module: str, default_out: str, run_arg: str, run_key: str, check_fn, run_fn, render_fn,
               write_fn) -> int:
    """The command of a fuel-chain study (this module's, validation/mc_fuel.py's): arguments
    ``[REPORT.md [DATA_FOLDER [RUN]]]``; writes the built-ins (``write_fn``), the check on the
    data's cycles (``check_fn``), the run's litres per class (``run_fn`` of a run folder given,
    else the report's JSON's ``run_key`` kept), the JSON and ``render_fn``'s report. Exit 2 with
    one line on bad input."""
    from sumo_drvpw.fileio import plain, write_json, write_text
    from sumo_drvpw.validation.data import positional, resolve_data

    t0 = time.perf_counter()
    try:
        args = positional(sys.argv[1:] if argv is None else argv, f"REPORT.md [DATA_FOLDER [{run_arg}]]")
        out = Path(args[0] if args else default_out)
        data = resolve_data(args[1] if len(args) > 1 else None, (CYCLES,))
        write_fn()
        res = {"check": check_fn(data)}
        if len(args) > 2:
            res[run_key] = run_fn(Path(args[2]))
        elif out.with_suffix(".json").is_file():
            res[run_key] = json.loads(out.with_suffix(".json").read_text(encoding="utf-8")).get(run_key)
        measured = (json.loads(out.with_suffix(".json").read_text(encoding="utf-8")).get("measured")
                    if out.with_suffix(".json").is_file() else None)
        if measured:  # a comparison on measured logs made by hand (not recomputed): kept
            res["measured"] = measured
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    res["seconds"] = round(time.perf_counter() - t0)
    res["command"] = f"python -m {module}" + (f" {out}" if args else "")
    write_json(out.with_suffix(".json"), plain(res))
    write_text(out, render_fn(res))
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
