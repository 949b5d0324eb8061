"""The diesel-electric hybrid transit bus's fuel chain, set from published physics, and its check.

Run::

    .venv/bin/python -m sumo_drvpw.validation.hdv_hybrid [REPORT.md [DATA_FOLDER]]

writes the built-in equation ``moves_transit_bus_hybrid_diesel``
(``sumo_drvpw/model/builtin/equations/``), the Markdown report (default ``docs/hdv-hybrid.md``)
and ``<report>.json`` beside it.

**The chain is not fitted.** It is ``moves_transit_bus_diesel`` (validation/hdv_fuel.py: the
MOVES transit bus road load, the heavy-duty diesel Willans line η_e = 0.45, its driveline 0.85,
idle fuel and 10-kW accessories) made a charge-sustaining hybrid (docs/energy-chain.md)::

    P_fuel = on·P_idle + (max(P, 0)/η_d + P_aux + η_rt·max(min(P, 0), −P_lim)/η_d)/η_e

* **regenerative braking**: of the braking energy at the wheels (P < 0), up to the traction
  motor's power P_lim, the share η_rt comes back at the wheels from the battery and replaces
  engine output (``recuperation_round_trip``, ``recuperation_limit_w``; :data:`REGEN`);
* **engine off at rest**: the engine stops while the bus stands (no idle fuel), runs while
  it moves (``engine_on_above_mps``) and is cut in overrun as the diesel's; its accessories
  are paid at the margin throughout (``charge_sustaining``: the battery carries them at a stop
  and the engine puts that energy back later).

**The check** (no parameter is changed by it): the hybrid and the diesel chain drive the
same schedules of ``cycles/`` (those of hdv_fuel.py plus the WLTC's low and medium phases,
the slowest urban schedules there) at the MOVES source mass; the hybrid's fuel saving per
cycle stands beside the published savings of hybrid over conventional buses on bus cycles
of a similar mean speed (:data:`PUBLISHED`: NREL's chassis-dynamometer tests and in-service
evaluations) and beside SUMO's own HBEFA 4 hybrid class against its diesel twin
(:data:`SUMO_PAIR`, through ``emissionsDrivingCycle``).
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

import numpy as np

from sumo_drvpw.validation.hdv_fuel import (CHAINS, CYCLES, ENGINE_WILLANS, builtin_doc as diesel_doc,
                                            chain_run, read_cycle, study_main, sumo_l_per_100km)

NAME = "moves_transit_bus_hybrid_diesel"
DIESEL = "moves_transit_bus_diesel"
#: the schedules the check drives: hdv_fuel.py's and the WLTC's low and medium phases
CHECK_CYCLES = ("wltc_low_3", "udds", "wltc_medium_3b", "wltc_3b", "us06", "hwfet")

#: references, key → what was read (docs/sources.md, "Diesel-electric hybrid transit bus")
SOURCES = {
    "NREL-KCM-LAB": "Hayes, Williams, Ireland & Walkowicz (NREL, Sep 2006), 'King County Metro Transit: Allison "
                    "Hybrid Electric Transit Bus Laboratory Testing', NREL/TP-540-39761 (abstract, AFDC "
                    "publications): two 2004 New Flyer 60-ft articulated buses, Caterpillar C9, one with the "
                    "GM-Allison hybrid drive, on NREL ReFUEL's chassis dynamometer: the hybrid's fuel economy "
                    "higher by 74.6 % on the Manhattan cycle, 50.6 % OCTA, 48.3 % CBD, 30.3 % KCM cycle",
    "NREL-KCM": "NREL (Dec 2006), 'King County Metro Transit Hybrid Articulated Buses: Final Evaluation "
                "Results' (greencarcongress.com 2006/12): ten New Flyer 60-ft GM-Allison hybrids, 12 months in "
                "service, 27 % higher fuel economy than the diesel buses of a similar duty cycle",
    "NREL-NYCT": "NREL (2006), 'New York City Transit (NYCT) Hybrid (125 Order) and CNG Transit Buses: Final "
                 "Evaluation Results' (eepower.com 3 Dec 2006; duty cycle 6.1–6.5 mph, hitpages.com): Orion VII "
                 "BAE HybriDrive series hybrids, average fuel economy 34 % higher than the standard diesel buses",
    "GCC-ORION": "greencarcongress.com (Oct 2005), 'New York City Orders 500 More Orion Diesel Hybrid Buses': Orion "
                 "VII BAE HybriDrive, 5.9-L 194-kW Cummins engine, 120-kW generator, 186-kW traction motor, "
                 "regenerative braking into the batteries",
    "FASTSIM-HEV": "NREL FASTSim vehicle database, fastsim/resources/FASTSim_py_veh_db.csv (commit 1178bcfc), "
                   "its hybrids' rows: battery essRoundTripEff 0.97, maxRegen 0.98 (the share of braking the "
                   "motor may take), motor efficiency map (mcPwrOutPerc → largeBaselineEff) 0.91 at 10 %, "
                   "0.93 at 20 %, 0.94 at 40–60 % of its power",
    "METRO-SERIESE": "Metro Magazine (Sep 2013), 'BAE Systems' latest HybriDrive solution cutting more fuel, "
                     "maintenance': the Series-E powers the air conditioning, power steering, cooling fans and "
                     "air compressor electrically (from the battery and regenerative braking), so the engine "
                     "need not run for them at a stop",
}

#: one-way efficiency wheel ↔ battery terminal: motor at part load × final drive
MOTOR_PART_LOAD = 0.92
FINAL_DRIVE = 0.96
#: the battery's round trip and the share of braking the motor takes [FASTSIM-HEV]
BATTERY_ROUND_TRIP = 0.97
REGEN_SHARE = 0.98
#: η_rt: wheel → battery → wheel
ROUND_TRIP = round(REGEN_SHARE * (MOTOR_PART_LOAD * FINAL_DRIVE) ** 2 * BATTERY_ROUND_TRIP, 4)
#: P_lim: the Orion VII's traction motor [GCC-ORION] [W]
MOTOR_W = 186000.0
#: the engine runs above this speed [m/s] (the chain's standstill: it stops at rest)
ENGINE_ON_ABOVE_MPS = 0.1
#: the driving power below which, standing, the engine is off [W] (any P > 0 at rest; flat: P = 0)
ENGINE_OFF_BELOW_W = 1000.0

REGEN = {
    "recuperation_round_trip": (
        ROUND_TRIP, f"wheel → battery → wheel: the share of braking the motor takes ({REGEN_SHARE} [FASTSIM-HEV]) × "
        f"(motor at part load {MOTOR_PART_LOAD} [FASTSIM-HEV] × final drive {FINAL_DRIVE}, ESTIMATE)² × the "
        f"battery's round trip {BATTERY_ROUND_TRIP} ([FASTSIM-HEV], lithium-ion; the first Orion VII hybrids' "
        "lead-acid batteries lose more) = " + f"{ROUND_TRIP:.4f}; the energy it gives back replaces engine output "
        "at the diesel's driveline and Willans slope"),
    "recuperation_limit_w": (
        MOTOR_W, "the Orion VII BAE HybriDrive's traction motor, 186 kW (250 hp) [GCC-ORION]: braking beyond it "
                 "goes to the friction brakes (the battery's charge power may cap it lower: ESTIMATE)"),
    "engine_on_above_mps": (
        ENGINE_ON_ABOVE_MPS, "the engine runs while the bus moves (a series hybrid's engine-generator keeps the "
                             "battery charged; fuel cut in overrun as the diesel's [MB-DFCO]) and stops at rest: "
                             "electric accessories (BAE Series-E [METRO-SERIESE]) need no engine at a stop"),
    "engine_off_below_w": (
        ENGINE_OFF_BELOW_W, "1 kW: standing, the driving power is 0 (each term is a force times the speed), "
                            "below it, so the engine is off at rest; moving, engine_on_above_mps keeps it on (no published threshold for a "
                            "bus's engine-off while moving was read: none is assumed)"),
    "charge_sustaining": (
        True, "the battery's energy at a stop (the accessories' 10 kW) and below the engine-off power is put back "
              "by the engine later: booked at the margin all the same; only the idle fuel stops with the engine"),
}

MPH_KMH = 1.609344
#: published saving of hybrid over conventional diesel buses: (what, mean speed [mph] or
#: None, fuel economy gain [share], source key); fuel saving = 1 − 1/(1 + gain). The bus
#: cycles' mean speeds (Manhattan 6.8 mph, OCTA 12.3, CBD 12.6) are WVU's cycle definitions
#: as usually quoted, not read from a source here (ESTIMATE); NYCT's is the report's duty cycle
PUBLISHED = [
    ("Manhattan cycle, chassis dynamometer, 60-ft New Flyer GM-Allison vs diesel", 6.8, 0.746, "NREL-KCM-LAB"),
    ("OCTA cycle, same buses", 12.3, 0.506, "NREL-KCM-LAB"),
    ("CBD cycle, same buses", 12.6, 0.483, "NREL-KCM-LAB"),
    ("KCM cycle (King County's routes), same buses", None, 0.303, "NREL-KCM-LAB"),
    ("NYCT Orion VII BAE series hybrids in service, 6.1–6.5 mph", 6.3, 0.34, "NREL-NYCT"),
    ("King County 60-ft GM-Allison hybrids in service", None, 0.27, "NREL-KCM"),
]

#: SUMO's HBEFA 4 hybrid standard bus and its diesel twin (the vClass bus default)
SUMO_PAIR = ("HBEFA4/UBus_Std_gt15-18t_HEV_Euro-VI_A-C", "HBEFA4/UBus_Std_gt15-18t_Euro-VI_A-C")


def fuel_saving(gain: float) -> float:
    """Fuel saved per km [share] of a fuel-economy gain (mpg higher by ``gain``)."""
    return 1.0 - 1.0 / (1.0 + gain)


def builtin_doc(name: str = NAME) -> dict:
    """The TOML document of the hybrid built-in: the diesel transit bus's, made a hybrid."""
    doc = diesel_doc(DIESEL)
    c = CHAINS[DIESEL]
    doc["equation"]["name"] = NAME
    doc["equation"]["description"] = (
        "diesel-electric hybrid transit bus: MOVES transit bus road load, the diesel bus's Willans line, "
        "regenerative braking and the engine off at rest, from published physics (not fitted); the mass comes "
        "from the vType. In a bare SUMO config it books the buses whose emissionClass names a hybrid "
        "(HBEFA 4's UBus_*_HEV_*)")
    doc["equation"]["source"] = (doc["equation"]["source"].split("; chain:")[0] + "; chain: docs/hdv-hybrid.md, "
                                 "docs/sources.md 'Diesel-electric hybrid transit bus' (written by python -m "
                                 "sumo_drvpw.validation.hdv_hybrid)")
    ch = doc["chain"]
    for k, (val, reading) in REGEN.items():
        ch[k] = val
        ch["reading"][k] = reading
    ch["fuel_cut_below_w"] = 0.0
    ch["reading"]["fuel_cut_below_w"] = ("0: the diesel's overrun fuel cut-off [MB-DFCO] — rolling with a negative "
                                         "driving power the injection is cut; standing, the engine is off "
                                         "(engine_off_below_w), so it never idles")
    ch["reading"]["idle_fuel_power_w"] = (ch["reading"]["idle_fuel_power_w"] + "; burnt only while the engine "
                                          "runs: moving, never at rest (engine_on_above_mps)")
    ch["reading"]["marginal_efficiency"] = ch["reading"]["marginal_efficiency"] + (
        "; the diesel bus's engine: a hybrid's engine at better operating points is not credited (ESTIMATE: "
        "conservative)")
    ch["reading"]["traction_efficiency"] = (c["driveline_reading"] + "; the hybrid's engine → generator → motor "
                                            "→ wheel path taken as the diesel's driveline (ESTIMATE)")
    ch["provenance"]["sources"] = ("docs/sources.md 'Diesel-electric hybrid transit bus' and 'Heavy-duty diesel "
                                   "chains'; " + "; ".join(f"[{k}]" for k in SOURCES if any(
                                       f"[{k}]" in r for _, r in REGEN.values())))
    ch["provenance"]["diesel_twin"] = DIESEL
    return doc


def write_builtins() -> list[Path]:
    """Write ``moves_transit_bus_hybrid_diesel.toml`` (hdv_fuel.write_builtins with its doc)."""
    from sumo_drvpw.validation.hdv_fuel import write_builtins as write

    return write([NAME], lambda _n: builtin_doc())


def check(data: Path) -> dict:
    """Per schedule: the hybrid's and the diesel's L/100 km at the MOVES source mass, the
    saving, and SUMO's HBEFA 4 hybrid and diesel standard buses (None without SUMO)."""
    from sumo_drvpw.model.equations import equation_from_dict, load_equation

    mass = float(load_equation("moves_transit_bus").provenance["source_mass_t"]) * 1000.0
    hyb = equation_from_dict(builtin_doc(), f"<{NAME}>")
    dsl = equation_from_dict(diesel_doc(DIESEL), f"<{DIESEL}>")
    rows = {}
    with tempfile.TemporaryDirectory() as td:
        for cyc in CHECK_CYCLES:
            v = read_cycle(Path(data) / CYCLES, cyc)
            h, d = chain_run(hyb, v, mass), chain_run(dsl, v, mass)
            sh, sd = (sumo_l_per_100km(c, v, Path(td)) for c in SUMO_PAIR)
            rows[cyc] = {"mean_speed_kmh": float(3.6 * np.mean(0.5 * (v[1:] + v[:-1]))),
                         "stop_share": float(np.mean(v < 0.1)), "hybrid": h, "diesel": d,
                         "saving": 1.0 - h["l_per_100km"] / d["l_per_100km"],
                         "sumo_hybrid": sh, "sumo_diesel": sd,
                         "sumo_saving": None if sh is None or sd is None
                         else 1.0 - sh["l_per_100km"] / sd["l_per_100km"]}
    return {"mass_kg": mass, "round_trip": ROUND_TRIP, "cycles": rows,
            "published": [{"what": w, "mean_speed_kmh": None if s is None else s * MPH_KMH, "fe_gain": g, "fuel_saving": fuel_saving(g),
                           "source": k} for w, s, g, k in PUBLISHED]}


def render(res: dict) -> str:
    """The report of a :func:`main` result."""
    chk = res["check"]
    doc = builtin_doc()["chain"]
    L = ["# Diesel-electric hybrid transit bus: a fuel chain on MOVES road load", "",
         f"Generated by `{res['command']}` in {res['seconds']:.0f} s; every number below is computed by that run "
         "from the parameters in `sumo_drvpw/validation/hdv_hybrid.py` (module docstring: model and check). The "
         "chain: [energy-chain.md](energy-chain.md); the diesel it starts from: [hdv-fuel.md](hdv-fuel.md); "
         "sources: [sources.md](sources.md), 'Diesel-electric hybrid transit bus'.", "",
         f"`{NAME}` is `{DIESEL}` — the MOVES transit bus road load and the heavy-duty diesel's Willans line "
         f"(η_e {ENGINE_WILLANS}, driveline {CHAINS[DIESEL]['driveline']}, idle {CHAINS[DIESEL]['idle_gal_h']} "
         f"gal/h, accessories {CHAINS[DIESEL]['aux_w']:,.0f} W) — made a charge-sustaining hybrid, not fitted to "
         "anything: P_fuel = on·P_idle + (max(P, 0)/η_d + P_aux + η_rt·max(min(P, 0), −P_lim)/η_d)/η_e.", "",
         "## What the hybrid adds", "", "| key | value | reading |", "|---|---|---|"]
    for k, (val, reading) in REGEN.items():
        L.append(f"| `{k}` | {val} | {reading} |")
    L += ["", f"Everything else is the diesel's (`idle_fuel_power_w` {doc['idle_fuel_power_w']:,.0f} W, "
          f"`aux_power_w` {doc['aux_power_w']:,.0f} W, `fuel_cut_below_w` 0). A braking second books negative "
          "fuel — the battery's credit, which the next acceleration uses — so a trip's or a route's total is the "
          "hybrid's, and a single braking edge may read below zero.", "",
          "## Check: the saving over the diesel bus, per cycle (not a fit)", "",
          f"Both chains drive each schedule of the shared data (`cycles/`) at the MOVES source mass "
          f"({chk['mass_kg']:,.0f} kg), flat road. No bus cycle (Manhattan, OCTA, CBD) is in the shared data: the "
          "WLTC's low phase is the slowest urban schedule there, close to OCTA's and CBD's mean speed. "
          f"SUMO: `{SUMO_PAIR[0]}` against `{SUMO_PAIR[1]}` through `emissionsDrivingCycle` (HBEFA 4.2, speed and "
          "acceleration only).", "",
          "| cycle | mean km/h | standing | diesel L/100 km | hybrid L/100 km | hybrid vs diesel | SUMO diesel "
          "| SUMO hybrid | SUMO hybrid vs diesel |", "|---|---|---|---|---|---|---|---|---|"]

    def pct(x):  # a saving as less fuel: 0.2 → "-20 %"
        return "–" if x is None else f"{-x:+.0%}".replace("%", " %")

    def lit(r):
        return "–" if r is None else f"{r['l_per_100km']:.1f}"

    for cyc, r in chk["cycles"].items():
        L.append(f"| {cyc} | {r['mean_speed_kmh']:.1f} | {100 * r['stop_share']:.0f} % | {r['diesel']['l_per_100km']:.1f} | "
                 f"{r['hybrid']['l_per_100km']:.1f} | {pct(r['saving'])} | "
                 f"{lit(r['sumo_diesel'])} | {lit(r['sumo_hybrid'])} | {pct(r['sumo_saving'])} |")
    L += ["", "Published, hybrid over conventional diesel buses (fuel saving = 1 − 1/(1 + fuel-economy gain)):", "",
          "| what | mean km/h | fuel economy | fuel saving | source |", "|---|---|---|---|---|"]
    for p in chk["published"]:
        s = "–" if p["mean_speed_kmh"] is None else f"{p['mean_speed_kmh']:.1f}"
        L.append(f"| {p['what']} | {s} | +{100 * p['fe_gain']:.1f} % | −{100 * p['fuel_saving']:.0f} % | "
                 f"[{p['source']}] |")
    cy = chk["cycles"]
    slow, fast = min(cy, key=lambda c: cy[c]["mean_speed_kmh"]), max(cy, key=lambda c: cy[c]["mean_speed_kmh"])
    least = min(cy, key=lambda c: cy[c]["saving"])
    L += ["", f"Reading: the published savings fall with the cycle's mean speed (Manhattan's the largest, OCTA's and "
          "CBD's at 20 km/h next, in service less); the chain's come from its physics alone — the braking energy a "
          f"cycle has, the time it stands — and fall too: {pct(cy[slow]['saving'])} on {slow} "
          f"({cy[slow]['mean_speed_kmh']:.0f} km/h), {pct(cy[least]['saving'])} on {least}, where little is "
          "braked. The dynamometer's buses are 60-ft articulated ones and the lab's hybrid also ran its engine at "
          "better points, which this chain does not credit (the diesel's Willans line). SUMO's HBEFA 4 hybrid "
          f"class books {pct(cy[fast]['sumo_saving'])} against its diesel twin on {fast} and "
          f"{pct(cy[slow]['sumo_saving'])} on {slow}: " + (
              "it does not show the published pattern (a hybrid's saving largest in slow stop-and-go)."
              if (cy[slow]['sumo_saving'] or 0) < (cy[fast]['sumo_saving'] or 0) else
              "its saving, too, is the larger in slow stop-and-go."), "",
          "## How a SUMO run books a hybrid bus", "",
          f"A bare SUMO config's equations include `{NAME}` (sim/scenario.py CONFIG_EQUATIONS): a vType of vClass "
          "bus whose emissionClass names a hybrid (HBEFA 4's `UBus_Std_gt15-18t_HEV_Euro-VI_A-C`, `UBus_Artic_"
          f"gt18t_HEV_…`, `UBus_Midi_lt15t_HEV_…`) is booked by it, any other diesel bus by `{DIESEL}` "
          "(sim/resolver.py, summary.json `assumptions.powertrain`). Before it, a hybrid bus was booked by the "
          "diesel chain — engine idling at every stop, no braking energy back — with a warning that no hybrid "
          "chain is made for its vClass.", "",
          "Its battery is unbounded: the chain declares no usable battery window (`battery_usable_j`, "
          "docs/energy-chain.md), as no published usable energy of these buses' batteries was found to cite, so a long "
          "descent is credited in full at η_rt. Where a study's buses' window is known, a copy of this file with "
          "`battery_usable_j` under `[chain]` credits braking only while the battery has room and books the rest on "
          "the friction brakes.", ""]
    return "\n".join(L)


def main(argv=None) -> int:
    """``python -m sumo_drvpw.validation.hdv_hybrid [REPORT.md [DATA_FOLDER]]``: writes the
    built-in, the report and its JSON. Exit 2 with one line on bad input."""
    return study_main(argv, "sumo_drvpw.validation.hdv_hybrid", "docs/hdv-hybrid.md", "RUN", "run",
                      check, lambda _p: None, render, write_builtins)


if __name__ == "__main__":
    sys.exit(main())
