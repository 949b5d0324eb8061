"""A plug-in petrol hybrid car for SUMO's plug-in hybrid classes: the built-in ``epa_gasoline_phev_car``.

Run::

    .venv/bin/python -m sumo_drvpw.validation.epa_phev [DATA_FOLDER]

writes the built-in equation (``sumo_drvpw/model/builtin/equations/epa_gasoline_phev_car.toml``)
and prints what it took. Every number is computed by the run or read from a cited table below.

**Road load**: the medians over the plug-in hybrid *cars* of the US EPA Test Car List (the
configurations with a charge-depleting test on the petrol certification fuel, a physical road
load, vehicle type ``Car``) of the target coefficients A per kg of test weight, B and C, as
:func:`~sumo_drvpw.validation.epa_fleet.class_defaults` takes them for the other classes.

**Once its battery is spent** a plug-in hybrid sustains its charge as a full hybrid: the
``[chain]`` is the built-in full hybrid's, ``epa_gasoline_hybrid_car`` (fitted on the same
lists' full hybrids' certification tests, docs/epa-hybrid.md), unchanged.

**Its charge-depleting start** (``[chain.depleting]``, model/chain_plugin.py) from NREL's
FASTSim vehicle database (``python/fastsim/resources/FASTSim_py_veh_db.csv``, commit
bd9111bb; docs/sources.md [FASTSIM-PHEV]), its blended plug-in hybrid cars (the range-extended
BEV i3 REx, with no charge-depleting range given, left out): usable energy = ess_max_kwh ×
(max_soc − min_soc), the median; battery → wheels η_t = trans_eff × the motor's efficiency at
part load (FASTSim's map: 0.91 at 10 %, 0.93 at 20 % of its power) × √ess_round_trip_eff (one
way of the battery's round trip); wheels → battery η_r = max_regen × the same; the motor's
power, the median mc_max_kw, bounds the braking it takes back.
"""

from __future__ import annotations

import statistics
import sys
from pathlib import Path

from sumo_drvpw.errors import UserError
from sumo_drvpw.model.constants import G
from sumo_drvpw.validation import epa_fleet as ef

NAME = "epa_gasoline_phev_car"
FULL_HYBRID = "epa_gasoline_hybrid_car"
#: FASTSim's plug-in hybrid cars (FASTSim_py_veh_db.csv, commit bd9111bb): name →
#: (ess_max_kwh, min_soc, max_soc, mc_max_kw, val_cd_range_mi); trans_eff 0.98,
#: ess_round_trip_eff 0.97, max_regen 0.98 on every row
FASTSIM_PHEV = {"2017 Prius Prime": (8.8, 0.25, 0.9, 53.0, 25.0),
                "2016 CHEVROLET Volt": (18.4, 0.15, 0.9, 111.0, 53.0),
                "2016 FORD C-MAX (PHEV)": (7.6, 0.15, 0.9, 65.0, 20.0),
                "2016 HYUNDAI Sonata PHEV": (9.8, 0.15, 0.9, 50.0, 27.0)}
TRANS_EFF, ESS_ROUND_TRIP, MAX_REGEN = 0.98, 0.97, 0.98
#: FASTSim's motor efficiency at part load (its map: 0.91 at 10 %, 0.93 at 20 % of its power)
MOTOR_PART_LOAD = 0.92


def phev_cars(lists):
    """The plug-in hybrid cars' tests of the lists (:func:`epa_fleet.read_lists`): configurations
    with a charge-depleting test on the petrol certification fuel, physical road load, type Car."""
    cd = lists["procedure"].str.startswith("Charge Depleting") & lists["fuel"].eq(ef.TEST_FUELS["gasoline"])
    plug = set(lists.loc[cd, "config"])
    return lists[lists["config"].isin(plug) & ef.physical_road_load(lists) & lists["vehicle_type"].eq("Car")]


def depleting() -> dict:
    """``[chain.depleting]`` from :data:`FASTSIM_PHEV` (module docstring)."""
    usable = statistics.median(k * (hi - lo) for k, lo, hi, _, _ in FASTSIM_PHEV.values())
    eta_t = TRANS_EFF * MOTOR_PART_LOAD * ESS_ROUND_TRIP ** 0.5
    return {"usable_j": round(usable * 3.6e6, -3), "traction_efficiency": round(eta_t, 4),
            "recuperation_efficiency": round(MAX_REGEN * eta_t, 4),
            "recuperation_limit_w": 1000.0 * statistics.median(r[3] for r in FASTSIM_PHEV.values())}


def builtin_equation(data: Path) -> tuple[dict, dict]:
    """(the built-in's document, what it took: configurations, models, medians)."""
    from sumo_drvpw.model.equations import load_equation

    lists = ef.read_lists(Path(data) / ef.DATASET)
    cars = phev_cars(lists)
    if cars.empty:
        raise UserError(f"{Path(data) / ef.DATASET}: no plug-in hybrid car tested charge-depleting on "
                        f"{ef.TEST_FUELS['gasoline']}")
    dfl = ef.class_defaults(cars.assign(vehicle_type="Car"))["car"]
    full = load_equation(FULL_HYBRID)
    chain = full.chain.to_dict()
    dep = depleting()
    chain["depleting"] = dep
    kwh = dep["usable_j"] / 3.6e6
    chain["reading"] = {**chain.get("reading", {}), "depleting": (
        f"{kwh:.2f} kWh usable: the median of FASTSim's blended plug-in hybrid cars' ess_max_kwh × (max_soc − "
        f"min_soc) ({', '.join(FASTSIM_PHEV)}); η_t = trans_eff {TRANS_EFF} × motor {MOTOR_PART_LOAD} at part load × "
        f"√ess_round_trip_eff {ESS_ROUND_TRIP}, η_r = max_regen {MAX_REGEN} × η_t; the limit: the median motor power. "
        "Spent from each vehicle's departure (a charged battery, or the charge its SUMO battery device declares), "
        "then the full hybrid's chain")}
    chain["provenance"] = {"fuel_chain": f"{FULL_HYBRID}'s, unchanged (docs/epa-hybrid.md)",
                           "etw_kg_median": round(dfl["etw_kg"], 1), "road_load_a_n_per_kg": dfl["a_n_per_kg"],
                           "road_load_b_n_per_mps": dfl["b_n_per_mps"], "road_load_c_n_per_mps2": dfl["c_n_per_mps2"]}
    doc = {"equation": {
        "name": NAME,
        "description": (f"plug-in petrol hybrid car: median road load of the {dfl['configurations']} EPA-certified "
                        f"plug-in hybrid cars (charge-depleting tests on petrol), {kwh:.2f} kWh of usable battery "
                        "spent first (FASTSim's plug-in hybrids, median), then the full hybrid's fuel chain "
                        f"({FULL_HYBRID}); each vehicle departs charged unless its battery device's device.battery.chargeLevel "
                        "says otherwise. In a bare SUMO config it books the "
                        "cars whose emissionClass names a plug-in hybrid (HBEFA 4's PC_PHEV_…_(P))"),
        "source": ("US EPA Test Car List (data.gov) road loads; NREL FASTSim vehicle database (commit bd9111bb) "
                   "battery and motor; python -m sumo_drvpw.validation.epa_phev (docs/energy-chain.md)"),
        "vclasses": list(full.vclasses)},
        "terms": {"roll": round(dfl["a_n_per_kg"] / G, 6), "v2": round(dfl["b_n_per_mps"], 4),
                  "aero_rho": round(2.0 * dfl["c_n_per_mps2"] / ef.COASTDOWN_RHO, 5), "acc": 1.0, "grade": 1.0},
        "provenance": {
            "aero_rho": f"C_d·A = 2·C/ρ_ref [m²]: the median target coefficient C = {dfl['c_n_per_mps2']:.4f} "
                        f"N/(m/s)² at ρ_ref = {ef.COASTDOWN_RHO} kg/m³ (as {FULL_HYBRID})",
            "roll": "A/(m·g): the target coefficient A per kg of test weight (tyres, driveline)",
            "v2": "B [N/(m/s)]: the target coefficient B (tyres, driveline; speed-proportional)"},
        "chain": chain}
    took = {"configurations": dfl["configurations"], "etw_kg_median": dfl["etw_kg"],
            "models": sorted(set(cars["model"].str.upper())), "years": sorted(int(y) for y in cars["model_year"].unique()),
            "usable_kwh": kwh, "depleting": dep}
    return doc, took


def main(argv=None) -> int:
    """``python -m sumo_drvpw.validation.epa_phev [DATA_FOLDER]`` (default $SUMO_DRVPW_DATA or
    ../shared/data): writes the built-in. Exit 2 with one line when the data are absent."""
    from sumo_drvpw.model.equations import BUILTIN_DIR, equation_from_dict, save_equation
    from sumo_drvpw.validation.data import positional, resolve_data

    try:
        args = positional(sys.argv[1:] if argv is None else argv, "[DATA_FOLDER]")
        data = resolve_data(args[0] if args else None, (ef.DATASET,))
        doc, took = builtin_equation(data)
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    save_equation(equation_from_dict(doc), BUILTIN_DIR / f"{NAME}.toml")
    print(f"wrote {NAME}: {took['configurations']} configurations (model years {took['years']}), "
          f"ETW median {took['etw_kg_median']:.0f} kg, usable {took['usable_kwh']:.2f} kWh, {took['depleting']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
