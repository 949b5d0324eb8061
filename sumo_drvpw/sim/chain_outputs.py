"""What a run's battery and fuel accounts (:class:`sumo_drvpw.sim.chain.ChainLedger`) write
and say: the per-class summary for summary.json, the warnings on what they assumed, and the
chain CSVs (vehicles, edges, classes)."""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.model.constants import CABIN_WARMUP_TAU_S, FUEL_COLD_START_TAU_S, T_REF_C
from sumo_drvpw.sim.chain import KWH, ChainLedger
from sumo_drvpw.sim.chain_charge import begin_warning


def _motors(chain: ChainLedger) -> list[int]:
    """The active equations whose chain is SUMO's MMPEVEM motor."""
    return [e for e in chain.active if chain.chains[e].motor is not None]


#: a vehicle class's per-km chain figures are said to stand for few trips below this [km]
THIN_CLASS_KM = 10.0


def chain_summary(chain: ChainLedger, veh_ids: list[str], veh_classes: list[str],
                  class_order=None) -> dict:
    """Per vehicle class and equation: battery kWh (traction, recuperated, auxiliary, net)
    and kWh/km, or fuel L, L/100 km and CO₂ kg, g/km; plus the run's totals."""
    rep = chain.report(veh_ids, veh_classes, [], class_order)
    per_start = {chain.names[e]: chain.chains[e].cold_start(chain.air_temperature_c)["fuel_l"]
                 for e in chain.active if chain.chains[e].predicts == "fuel"}
    warmup = {chain.names[e]: chain.chains[e].cold_start(chain.air_temperature_c)["battery_j"] / KWH
              for e in chain.active if chain.chains[e].predicts == "battery"
              and (chain.chains[e].hvac or {}).get("warmup_j_per_k")}
    return {"classes": rep["classes"],
            "quantities": "battery: traction/recuperated/auxiliary/net kWh (auxiliary accrues "
                          "while standing); fuel: litres (LHV, density of the chain's fuel), CO2 kg"
                          + ("; cold_start_l: the part of the litres that cold starts took"
                             if chain.cold_start_on else ""),
            "cold_start": {"booked": chain.cold_start_on, "share": chain.cold_start,
                           **({"share_by_vtype": chain.cold_start_vtypes} if chain.cold_start_vtypes else {}),
                           **({"share_by_vclass": chain.cold_start_vclasses} if chain.cold_start_vclasses else {}),
                           **({"own_share_vehicles": len(chain.cold_start_vehicles)} if chain.cold_start_vehicles else {}),
                           **({"own_share_flows": len(chain.cold_start_flows)} if chain.cold_start_flows else {}),
                           "vehicles": chain.cold_starts,
                           "expected_cold_starts": round(chain.cold_starts_expected, 9),
                           **({"fuel_l_per_start": per_start} if per_start else {}),
                           **({"battery_kwh_per_start": warmup} if warmup else {}),
                           "air_temperature_c": chain.air_temperature_c,
                           "rule": "the chain's cold_start_fuel_l (a battery chain: its cabin warm-up) for each "
                                   "vehicle departing during the run, times its share (its own param, else its vType's, else its "
                                   "vClass's, else the run's), "
                                   "as it decays from the departure, e^(-t/tau) (tau: fuel "
                                   f"{FUEL_COLD_START_TAU_S:.0f} s, cabin {CABIN_WARMUP_TAU_S:.0f} s), on the edges "
                                   "driven then: a trip of T seconds takes 1 - e^(-T/tau) of it "
                                   "([vehicles] cold_start, [vtypes.<id>] / "
                                   "[vclasses.<vClass>] cold_start, or the run command's cold-start option)"
                                   if chain.cold_start_on else
                                   "not booked: every trip taken as starting warm (through traffic, "
                                   "or engines already warm); [vehicles] cold_start = true or "
                                   "the run command's cold-start option books it"} if per_start or warmup else None,
            **({"departure_charge": chain.charges.summary()} if chain.charges is not None else {}),
            **({"mmpevem_nan_steps": {chain.names[e]: int(chain.motor_invalid[e]) for e in _motors(chain)}}
               if _motors(chain) else {}),
            "signals_assumed_zero": sorted(chain.assumed_zero),
            "signal_values": chain.signal_values,
            **({"warm_running": chain.warm_running()} if chain.running_columns else {}),
            **over_engine_summary(chain),
            "hvac_air_temperature_c": chain.air_temperature_c if chain.hvac_columns else None,
            "hvac_air_temperature_assumed": chain.air_temperature_assumed}


#: vTypes named in the warning on vehicles no chain books (the rest counted)
CHAINLESS_VTYPES_SHOWN = 8


def chain_warnings(chain: ChainLedger | None, chainless: dict | None = None,
                   by_vtype: dict | None = None, emission_class: dict | None = None) -> list[str]:
    """What a run's battery/fuel accounts assumed that the scenario did not say, and the
    vClasses they leave out (``chainless``: vClass → vehicles no chain applies to;
    ``by_vtype``: the same per vType, named with its ``emission_class`` where known)."""
    if chain is None:
        return []
    out = []
    if chainless:
        top = sorted((by_vtype or {}).items(), key=lambda x: (-x[1], x[0]))
        named = [f"{vt} {n}" + (f" ({emission_class[vt]})" if (emission_class or {}).get(vt) else "")
                 for vt, n in top[:CHAINLESS_VTYPES_SHOWN]]
        if len(top) > CHAINLESS_VTYPES_SHOWN:
            named.append(f"{len(top) - CHAINLESS_VTYPES_SHOWN} more vTypes")
        out.append("no battery or fuel chain applies to "
                   + ", ".join(f"{n} {c}" for c, n in sorted(chainless.items(), key=lambda x: -x[1]))
                   + " vehicle(s)" + (f" — vTypes {', '.join(named)}, a carrier no chain of the run books "
                                      "or a class none is made for (summary.json chain.chainless)" if named else "")
                   + ": their driving energy is booked, but the kWh, litres and CO2 totals "
                   "leave them out (give them an equation with a chain: [vclasses.<vClass>] or "
                   "[vtypes.<id>] equations)")
    if chain.air_temperature_assumed:
        out.append(f"no air temperature given: the energy chains' HVAC, cold starts and warm-running fuel read "
                   f"{T_REF_C:g} °C (the "
                   "default air, as the air density and the cold terms do); give the season's "
                   "air temperature (the scenario's [air] temperature_c, or the run command's "
                   "air-temperature option)")
    nan = {chain.names[e]: int(chain.motor_invalid[e]) for e in _motors(chain) if chain.motor_invalid[e]}
    if nan:
        out.append("SUMO's MMPEVEM would write nan on " + ", ".join(f"{n} vehicle-steps of {k}" for k, n in nan.items())
                   + ": the demand exceeds the motor's torque or power, or leaves its loss map (a vType faster "
                   "or quicker than its motor: check maxSpeed and accel); booked at the motor's limits, with the "
                   "loss at the map's edge (summary.json chain.mmpevem_nan_steps)")
    out += over_engine_warnings(chain) + begin_warning(chain.charges)
    if chain.cold_start_on:  # fuel chains that drove but carry no cold-start fuel: booked warm, said
        drove = chain.edge_dist.sum(axis=0) > 0
        warm = [chain.names[e] for j, e in enumerate(chain.active) if drove[j] and chain.chains[e].predicts == "fuel"
                and not chain.chains[e].cold_start(chain.air_temperature_c)["fuel_l"]]
        if warm:
            out.append("cold starts asked for, but " + ", ".join(warm) + (" carries" if len(warm) == 1 else " carry")
                       + " no cold-start fuel (cold_start_fuel_l: a chain calibrated on logs, which do not say "
                       "whether an engine started cold, and the heavy-duty chains, whose sources give none): "
                       + ("its" if len(warm) == 1 else "their") + " trips are booked warm")
    if chain.assumed_zero:
        out.append("chain loads SUMO has no signal for were taken as 0: "
                   + ", ".join(sorted(chain.assumed_zero))
                   + " (a logged load has no counterpart in SUMO: for a SUMO study use a chain whose "
                   "heating and cooling follow the air temperature, [chain.hvac], as bmw_i3_battery's do)")
    return out


def write_chain_outputs(out_dir, result) -> dict[str, str]:
    """Write ``chain_vehicles.csv``, ``chain_edges.csv``, ``chain_classes.csv`` of a run
    (:class:`sumo_drvpw.sim.outputs.RunResult` whose ledger has a ``chain``) and put the
    per-class summary under ``result.summary["chain"]``; returns name → path."""
    from sumo_drvpw.fileio import write_text
    from sumo_drvpw.sim.table_text import rows_csv

    led = result.ledger
    chain = led.chain
    n = led.n_veh
    ids, classes = list(led.veh_ids[:n]), [c or "unknown" for c in led.veh_class[:n]]
    order = list(getattr(led, "class_list", []) or [])
    rep = chain.report(ids, classes, list(result.net.edge_ids), order)
    road = dict(zip(result.net.edge_ids, map(str, result.net.edge_class)))
    for r in rep.get("edges", []):  # (litres or kWh per road class: summed over this column)
        r["road_class"] = road.get(r.get("key"), "")
    files = {}
    spill = getattr(led, "spill", None)
    for key, rows in rep.items():
        path = Path(out_dir) / f"chain_{key}.csv"
        if key == "vehicles" and spill is not None and spill.has_chain_rows:
            spill.write_chain_csv(path, rows)  # the flushed vehicles' rows, then the rest
        else:
            write_text(path, rows_csv(rows, None if rows else chain.columns()))  # (pandas' text)
        files[f"chain_{key}"] = str(path)
    result.summary["chain"] = chain_summary(chain, ids, classes, order)
    result.summary["chain"]["chainless"] = {  # accounted vehicles no chain books
        "by_vclass": dict(sorted(getattr(led, "chainless", {}).items())),
        "by_vtype": dict(sorted(getattr(led, "chainless_vtypes", {}).items()))}
    thin = {r["key"]: r["distance_km"] for r in rep["classes"] if 0 < r["distance_km"] < THIN_CLASS_KM}
    if thin:
        result.summary.setdefault("warnings", []).append(
            "per-km battery or fuel figures of classes driven less than "
            f"{THIN_CLASS_KM:g} km in the run stand for few trips: "
            + ", ".join(f"{c} {km:.1f} km" for c, km in thin.items())
            + " (chain_classes.csv; over a few km a class's standing at stops and its trips cut by "
            "the run's begin and end weigh heavily: a longer run or a larger demand gives a figure "
            "to quote)")
    return files


def _capped(chain: ChainLedger) -> list[int]:
    return [e for e in chain.active if chain.chains[e].engine_max_w is not None]


def over_engine_summary(chain: ChainLedger) -> dict:
    """summary.json's ``engine_over_rated``: per equation with an engine's rated output
    (``engine_max_w``), the vehicle-steps and kWh of engine output demanded beyond it; {} where
    no chain of the run has one (its summary unchanged)."""
    if not _capped(chain):
        return {}
    return {"engine_over_rated": {chain.names[e]: {"vehicle_steps": int(chain.over_engine[e, 0]),
                                                   "kwh": float(chain.over_engine[e, 1]) / 3.6e6}
                                  for e in _capped(chain)}}


def over_engine_warnings(chain: ChainLedger) -> list[str]:
    """One warning per equation whose vehicles asked more than its engine's rated output."""
    return [f"{chain.names[e]}: {int(chain.over_engine[e, 0])} vehicle-steps asked more than its engine's rated "
            f"output (engine_max_w = {chain.chains[e].engine_max_w / 1000:g} kW), {chain.over_engine[e, 1] / 3.6e6:.3g} "
            "kWh in all: SUMO drove those vehicles faster, or up steeper, than their engine can (check the vTypes' "
            "accel and the grades); fuel is booked at the rated output (summary.json chain.engine_over_rated)"
            for e in _capped(chain) if chain.over_engine[e, 0]]
