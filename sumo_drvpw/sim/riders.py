"""Riding persons: their mass, read into the ledger when it changes, as SUMO's emission
models add it (``EnergyParams::getTotalMass``: mass + loading + transportable mass).

SUMO changes a vehicle's transportable mass as persons board and alight: at the start of a
stop (those leaving, those waiting there), during it (those arriving while it dwells) and
at a departure (a triggered one). The loop reads a vehicle's riders when it departs, when
a stop of it starts or ends, and every step while it stands at a stop (not parked: a
parked vehicle is not booked; its riders are read when its stop ends, or when it starts
to idle in its space, its way out blocked: sim/parking.py) — from the step its
stop starts, as SUMO's emission output books them (probed 2026-11-27 with SUMO 1.28's
MMPEVEM, whose holding torque on a slope shows the mass of every standing step:
tests/test_mmpevem_riders.py). Containers are not booked (TraCI has no containers'
vehicle). The FCD replay answers the same getters from the persons' rows
(:mod:`sumo_drvpw.sim.fcd_conn`).
"""

from __future__ import annotations


class Riders:
    """The riders' mass of the vehicles of one run (``Stepper.riders``)."""

    def __init__(self, conn, enabled: bool):
        sim = conn.simulation
        self.conn = conn
        self.ending = getattr(sim, "getStopEndingVehiclesIDList", None)
        self.starting = getattr(sim, "getStopStartingVehiclesIDList", None)
        #: on when the run books riders and the connection can tell them
        self.on = bool(enabled and self.ending is not None and hasattr(conn.vehicle, "getPersonIDList")
                       and hasattr(conn, "person"))
        self.any_load = False          # a booked vehicle has carried riders
        self.at_stop: set[str] = set()  # vehicles standing at a stop: read every step
        self._type_mass: dict[str, float] = {}

    def load_kg(self, vid: str) -> float:
        """Mass of the persons riding in vehicle ``vid`` [kg]: the sum of their vTypes'
        masses, as SUMO's emission models add them."""
        conn, kg = self.conn, 0.0
        for r in conn.vehicle.getPersonIDList(vid):
            vt = conn.person.getTypeID(r)
            m = self._type_mass.get(vt)
            if m is None:
                m = self._type_mass[vt] = float(conn.vehicletype.getMass(vt))
            kg += m
        return kg

    def update(self, ledger, vmap, vids) -> None:
        """Read the riders' mass of the vehicles ``vids`` (those booked) into the ledger."""
        for vid in vids:
            i = vmap.get(vid)
            if i is not None and ledger.veh_keep[i]:
                kg = self.load_kg(vid)
                ledger.veh_load[i] = kg
                if kg > 0.0:
                    self.any_load = True

    def step(self, ledger, vmap, departed) -> None:
        """Once per step, after it was made: the vehicles that departed, whose stop started or
        ended, and those standing at a stop, while any persons are in the network."""
        if not self.on:
            return
        ending = list(self.ending())
        starting = list(self.starting()) if self.starting is not None else []
        self.at_stop.update(starting)
        self.at_stop.difference_update(ending)  # (the loop drops those that left the network)
        if self.any_load or self.conn.person.getIDCount():
            # a parked vehicle (off the lane, not booked: Stepper.parking_started) is not read
            # while it stands; its riders are read when its stop ends (``ending``), so a
            # parked fleet costs no getter calls, also while persons walk
            parked = ledger.veh_parked
            gone = [v for v in self.at_stop if (i := vmap.get(v)) is not None and parked[i]]
            self.at_stop.difference_update(gone)  # until its stop ends: parked all along
            self.update(ledger, vmap, [*departed, *ending, *self.at_stop])
