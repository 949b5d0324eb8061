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
tests/test_mmpevem_riders.py). Containers count as persons do, in a live run whose route
files define them, read from the vehicle's container device (``device.container.IDList``;
TraCI has no container domain: each container's vType from those files). The FCD replay
answers the same getters from the persons' and containers' rows
(:mod:`sumo_drvpw.sim.fcd_conn`). The mass a script sets on a vehicle (``setMass``, its
own vType copy) is read from the step SUMO drives it: :class:`OwnCopies`.
"""

from __future__ import annotations

import numpy as np


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
        #: container id → its vType (the route files', sim/vtypes ``container_of``), set by a
        #: live run whose files define containers: their mass is read too (None: not read)
        self.box_of: dict[str, str] | None = None

    def _mass(self, vt: str) -> float:
        m = self._type_mass.get(vt)
        if m is None:
            m = self._type_mass[vt] = float(self.conn.vehicletype.getMass(vt))
        return m

    def load_kg(self, vid: str) -> float:
        """Mass of the persons and containers riding in vehicle ``vid`` [kg]: the sum of
        their vTypes' masses, as SUMO's emission models add them (the containers' from
        its container device, which TraCI names ``device.container.IDList``)."""
        conn = self.conn
        kg = sum(self._mass(conn.person.getTypeID(r)) for r in conn.vehicle.getPersonIDList(vid))
        if self.box_of and conn.vehicle.getParameter(vid, "has.container.device") == "true":
            of = self.box_of
            for c in conn.vehicle.getParameter(vid, "device.container.IDList").split():
                kg += self._mass(of.get(c) or of.get(c.rpartition(".")[0]) or "DEFAULT_CONTAINERTYPE")
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
        if self.any_load or self.box_of or self.conn.person.getIDCount():
            # a parked vehicle (off the lane, not booked: Stepper.parking_started) is not read
            # while it stands; its riders are read when its stop ends (``ending``), so a
            # parked fleet costs no getter calls, also while persons walk
            parked = ledger.veh_parked
            gone = [v for v in self.at_stop if (i := vmap.get(v)) is not None and parked[i]]
            self.at_stop.difference_update(gone)  # until its stop ends: parked all along
            self.update(ledger, vmap, [*departed, *ending, *self.at_stop])


def _copy_of(vt: str, at: dict) -> int | None:
    """``at``'s value (a row of the vehicles read) of the vehicle whose own copy ``vt``
    (``<type>@<id>``) is, None for another vType or a vehicle not read."""
    return next((at[v] for k, c in enumerate(vt) if c == "@" and (v := vt[k + 1:]) in at), None)


class OwnCopies:
    """Masses a script sets on running vehicles (``vehicle.setMass``; ``Stepper.own``):
    SUMO gives the vehicle its own copy of its vType, ``<type>@<id>``, and books the new
    mass from the next step. The copy adds one vType to SUMO's, so a changed vType count
    (one call a step) has the loop read in that step the vTypes of the vehicles whose copy
    SUMO's vType list gained (:meth:`_check_new`), or lost (a ``setType`` off a copy, which SUMO
    drops), not only every ``TYPE_CHECK_STEPS``; a vehicle on its own copy has its mass read every step, as
    a script may set it again without a new copy (:meth:`VTypeResolver.own_mass`). An FCD
    replay answers the count and the list from the vTypes its rows named (sim/fcd_conn.py)."""

    def __init__(self, conn, is_replay: bool):
        vt = getattr(conn, "vehicletype", None)
        self.count = getattr(vt, "getIDCount", None)
        self.last: int | None = None
        self.ids: set[str] | None = None  # SUMO's vType ids at the first step and each change of their count
        #: live: the vehicle's mass getter (a replay's copies carry none: told by the scenario)
        self.mass = None if is_replay or self.count is None else getattr(conn.vehicle, "getMass", None)
        self.replay = is_replay
        #: vehicle id → (its copy, the copy's mass last read [kg]; a replay's: NaN)
        self.on_copy: dict[str, tuple[str, float]] = {}

    def track(self, vid: str, copy: str) -> None:
        """Vehicle ``vid`` runs on its own copy ``copy`` from now on."""
        if self.mass is not None or self.replay:
            self.on_copy[vid] = (copy, float(self.mass(vid)) if self.mass is not None else np.nan)

    def step(self, st, kids, vidx) -> None:
        """Once per step, after it was made, for the vehicles read (``kids``, rows ``vidx``)."""
        if self.count is not None:
            n = int(self.count())
            if self.last is not None and n != self.last:  # a copy made (or a vType added, dropped)
                self._check_new(st, kids, vidx)
            elif self.last is None:  # (the list to tell a new copy by)
                ids = getattr(st.conn.vehicletype, "getIDList", None)
                self.ids = set(ids()) if ids is not None else None
            self.last = n
        ledger = st.ledger
        for vid, (copy, m) in list(self.on_copy.items()):
            i = st.vmap.get(vid)
            if i is None or ledger.veh_done[i] or f"{ledger.veh_type[i]}@{vid}" != copy:
                del self.on_copy[vid]  # gone, or a new trip under its id
                continue
            if self.mass is None:  # a replay: its rows name the vType, as live the mass tells a setType
                if st.conn.types.get(vid, copy) != copy:  # off the copy (below)
                    st.check_types([vid], np.array([i]))
                    del self.on_copy[vid]
                continue
            now = st.reader.mass_of(vid)  # (traci: the subscription's, no round trip)
            now = float(self.mass(vid) if now is None else now)
            if now != m and st.conn.vehicle.getTypeID(vid) != copy:  # a setType off its copy: SUMO
                st.check_types([vid], np.array([i]))  # dropped the copy; the new vType's mass (check_types)
                if f"{ledger.veh_type[i]}@{vid}" != copy:
                    del self.on_copy[vid]
                    continue
            if now != m:
                self.on_copy[vid] = (copy, now)
                own = getattr(st.resolve, "own_mass", None)  # (a VTypeResolver's)
                if own is not None and own(ledger, i, ledger.veh_type[i], copy):
                    st.retyped += 1

    def _check_new(self, st, kids, vidx) -> None:
        """The vTypes of the vehicles read whose own copy SUMO's vType list gained; all of
        theirs where it gained another vType (a script's ``vehicletype.copy``: a setType to it
        may follow) or the connection lists none. A script that sets a vType attribute on
        every departing vehicle (``setTau``, ``setShapeClass`` …) makes copies in most steps:
        each read once, not every running vehicle in each such step (over traci a round
        trip each)."""
        ids = getattr(st.conn.vehicletype, "getIDList", None)
        now = set(ids()) if ids is not None else None
        before, self.ids = self.ids, now
        if now is None or before is None:
            st.check_types(kids, vidx)
            return
        at = {vid: j for j, vid in enumerate(kids)}
        sel = [j for vt in before - now if (j := _copy_of(vt, at)) is not None]  # a copy SUMO dropped: a
        for vt in now - before:  # setType off it (a vehicle gone: not read)
            if "@" not in vt:
                st.check_types(kids, vidx)
                return
            j = _copy_of(vt, at)
            if j is not None:  # (a copy of a vehicle not read in this step: read when it is)
                sel.append(j)
        if sel:
            st.check_types([kids[j] for j in sel], np.asarray(vidx)[sel])

    def type_masses(self, st) -> None:
        """At the loop's vType checks: a script's ``vehicletype.setMass`` on a vType (not a
        vehicle) books its running vehicles at the new mass (not those on their own copies,
        which keep theirs, as in SUMO) and its later departures
        (:meth:`VTypeResolver.type_masses_changed`)."""
        changed = getattr(st.resolve, "type_masses_changed", None)
        new = changed() if changed is not None and self.mass is not None else None
        if not new:
            return
        ledger = st.ledger
        for i in range(ledger.n_veh):
            vt = ledger.veh_type[i]
            if vt in new and not ledger.veh_done[i] and ledger.veh_ids[i] not in self.on_copy \
                    and ledger.veh_mass[i] != new[vt]:
                ledger.veh_mass[i] = new[vt]
                st.retyped += 1
