"""Teleports booked apart from driving: the energy SUMO's placing a car back on a lane adds.

SUMO ends a teleport by placing the car on a later edge of its route at that lane's speed
(MSVehicleTransfer::checkInsertions → MSLane::freeInsertion; :func:`sumo_drvpw.sim.reader.
reinserted` tells the step). That step is not driven and the ledger books none of it as
driving, yet the car's kinetic and potential energy jump there: from its speed and elevation
at its last step on the lane it left (``v_before``, usually ≈ 0 in a jam; ``z_before``) to
those where it is put back (``v_after``, ``z_after``). Per teleport, vehicle and equation::

    kinetic   = ½·m·(v_after² − v_before²)        [J]
    potential = m·g·(z_after − z_before)           [J]  (0 without elevation)

with m the mass the equation books the vehicle at (its own ``mass_kg``, else the vehicle's
with its riders), where the equation applies. They are kept on their own line (vehicles,
the edge it is put back on, road class, summary), never in traction, recuperable or net:
those stay the driving energy. Over a trip of a vehicle an equation with the term c·acc books
c·(½m(v_last² − v_first²) − kinetic) in its acc term, and its grade term books
m·g·(z_last − z_first) − potential (plus its first step's slope × v·Δt): the teleport line
closes the vehicle's energy balance. A car stood in a jam and put back at 13.9 m/s then
brakes from a speed it was never booked to reach; ``kinetic`` is what that braking draws on.
"""

from __future__ import annotations

import numpy as np

from sumo_drvpw.model.constants import G

#: vehicles.parquet / edges.parquet / classes.parquet columns, in this order
COLUMNS = ("teleports", "teleport_kinetic_j", "teleport_potential_j")


def equation_masses(ledger, equations, vi: np.ndarray) -> np.ndarray:
    """The mass [kg] each equation books vehicles ``vi`` at, times its applicability,
    (n, E): an equation's own ``mass_kg``, else the vehicle's plus its riders'."""
    m = ledger.veh_mass[vi] + ledger.veh_load[vi]
    own = np.array([np.nan if getattr(e, "mass_kg", None) is None else float(e.mass_kg)
                    for e in equations])
    return np.where(np.isnan(own)[None, :], m[:, None], own[None, :]) * ledger.veh_app[vi]


def put_back(ledger, net, equations, sel, vidx, lane, pos, v, v_before) -> None:
    """Book the teleports that ended with the vehicles ``sel`` (a mask) of slots ``vidx``
    (each once) placed at lane numbers ``lane``, positions ``pos`` [m], speeds ``v`` [m/s];
    ``v_before`` [m/s]: their speeds at their last step on a lane (NaN: never read, no jump).
    Their next step drives on from there (``ledger.veh_at``)."""
    vi, lane, pos, v, v_before = vidx[sel], lane[sel], pos[sel], v[sel], v_before[sel]
    rows = net.place(lane, pos)
    v0 = np.where(np.isfinite(v_before), v_before, v)
    # NaN: no elevation, or its last z unknown; a rise its steps had not yet booked (steeper
    # than max_rad: Network.step_grade) goes with the jump
    dz = rows[:, 2] - ledger.veh_at[vi, 2] + np.nan_to_num(ledger.veh_at[vi, 3])
    per_kg = np.column_stack([0.5 * (v * v - v0 * v0), G * np.where(np.isfinite(dz), dz, 0.0)])
    e = equation_masses(ledger, equations, vi)[:, :, None] * per_kg[:, None, :]  # (n, E, 2)
    ledger.veh_tele[vi] += e
    ledger.veh_teleports[vi] += 1
    edge = net.lane_edge[lane]
    np.add.at(ledger.edge_tele, edge, e)
    np.add.at(ledger.edge_teleports, edge, ledger.veh_app[vi])
    ledger.teleports += len(vi)
    ledger.veh_at[vi] = rows


def columns(count, energy) -> dict[str, np.ndarray]:
    """Table columns (:data:`COLUMNS`) from teleport counts and (…, 2) energies [J]."""
    return {COLUMNS[0]: np.asarray(count), COLUMNS[1]: energy[..., 0], COLUMNS[2]: energy[..., 1]}


def edge_attrs(name: str, count: float, energy) -> list[str]:
    """edgedata.xml attributes of equation ``name`` on an edge where ``count`` teleports
    ended in an interval, with their [kinetic, potential] ``energy`` [J] (none without)."""
    if count <= 0:
        return []
    return [f'{name}_teleports="{count:.0f}"', f'{name}_teleport_kinetic_j="{energy[0]:.3f}"',
            f'{name}_teleport_potential_j="{energy[1]:.3f}"']


def by_class(ledger, net, classes: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """Teleports (K, E) and their energies (K, E, 2) [J] per road class of the edge the
    vehicles were put back on."""
    k = np.array([classes.index(c) for c in net.edge_class], np.int64)
    count = np.zeros((len(classes), ledger.E))
    energy = np.zeros((len(classes), ledger.E, 2))
    np.add.at(count, k, ledger.edge_teleports)
    np.add.at(energy, k, ledger.edge_tele)
    return count, energy


#: a teleport total this share of an equation's net driving energy (either sign) is warned of
WARN_SHARE = 0.01


def summary(ledger, net, names: list[str], classes: list[str], net_j: dict[str, float]) -> tuple[dict, dict, list]:
    """summary.json's ``teleports`` block, per equation its ``teleports`` by class, and the
    warnings: teleport energy of at least :data:`WARN_SHARE` of an equation's net driving
    energy ``net_j`` (equation → J)."""
    count, energy = by_class(ledger, net, classes)
    per_eq = {name: {c: {"count": float(count[ki, e]), "kinetic_j": float(energy[ki, e, 0]),
                         "potential_j": float(energy[ki, e, 1])} for ki, c in enumerate(classes)}
              for e, name in enumerate(names)}
    kin, pot = energy[:, :, 0].sum(axis=0), energy[:, :, 1].sum(axis=0)
    block = {"count": int(ledger.teleports),
             "kinetic_j": {n: float(kin[e]) for e, n in enumerate(names)},
             "potential_j": {n: float(pot[e]) for e, n in enumerate(names)},
             "definition": "vehicles SUMO put back on a lane at a teleport's end (placed, not "
                           "driven): kinetic ½m(v_after² − v_before²), potential m·g·Δz of each "
                           "jump, booked apart from the driving energy (energy_j, "
                           "recuperable_energy_j), which they are not part of"}
    warnings = []
    big = [n for e, n in enumerate(names)
           if abs(kin[e]) + abs(pot[e]) >= WARN_SHARE * max(abs(net_j.get(n, 0.0)), 1.0)]
    if ledger.teleports and big:
        faster = any(kin[names.index(n)] > 0 for n in big)
        warnings.append(
            f"{ledger.teleports} teleports put vehicles back on a lane (SUMO's "
            "--time-to-teleport): the energy of those jumps, not driven and not in the driving "
            "energy, is " + "; ".join(
                f"{n} kinetic {kin[names.index(n)] / 3.6e6:+.2f} kWh, potential "
                f"{pot[names.index(n)] / 3.6e6:+.2f} kWh beside a net driving energy of "
                f"{net_j.get(n, 0.0) / 3.6e6:.2f} kWh" for n in big)
            + (": vehicles that stood were put back at speed and later brake from speeds they were "
               "never booked to reach, so the run books less than if they had driven off" if faster else "")
            + " (summary.json teleports; vehicles.parquet teleport_kinetic_j, teleport_potential_j)")
    return block, per_eq, warnings


def may_return(declared, net, ledger):
    """For :attr:`Ledger.may_return`: whether vehicles ``slots`` whose rows ended may come
    back (a teleport SUMO ends later), read as they leave: all but those whose last row was on
    their route's last edge (``declared`` :attr:`sumo_drvpw.sim.fcd_stops.DeclaredStops.destinations`, an FCD replay's route files). SUMO arrives
    a vehicle there, and one teleported there too ("teleports beyond arrival edge"); elsewhere
    — on a junction, where a moving car collides and is taken off until the next edge has
    room — it may be back. A vehicle of unknown route is held; one that reaches its arrival
    position in the step it enters its last edge is held needlessly (memory only); one never
    read on a lane (booked by no equation) is not held."""
    def test(slots):
        out = np.zeros(len(slots), bool)
        for j, i in enumerate(np.asarray(slots).tolist()):
            vid, lane = ledger.veh_ids[i], ledger.veh_at[i, 0]
            if not np.isfinite(lane):
                continue
            flow, _, n = vid.rpartition(".")
            to = declared.destinations.get(vid) or (declared.destinations.get(flow) if n.isdigit() else None)
            out[j] = to is None or net.lane_ids[int(lane)].rpartition("_")[0] != to
        return out
    return test
