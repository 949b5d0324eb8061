"""What an FCD replay answers in place of SUMO (:mod:`sumo_drvpw.sim.fcd`): the subset of
the libsumo API the loop reads (time, vehicles, getters, departures and arrivals, riders)
and what SUMO's FCD rows say beyond the vehicles' own columns — parked vehicles (beside
their lane: :class:`ParkedTest`; those idling in their space, their way out blocked, booked
there: :mod:`sumo_drvpw.sim.fcd_idle`), buses dwelling at their stops (:func:`bus_stops`), and
persons riding in vehicles (at the vehicle's x, y and speed: :class:`_Rows`) —, with what
the route files add: their vTypes' shut-off params and their vehicles' planned stops
(:mod:`sumo_drvpw.sim.fcd_stops`), so that :class:`~sumo_drvpw.sim.shutoff.ShutOff`
switches vehicles off as in a live run."""

from __future__ import annotations

import numpy as np
import pandas as pd

from sumo_drvpw.model.constants import STANDSTILL_MPS
from sumo_drvpw.sim.network import off_lane
from sumo_drvpw.sim.sumo_outputs import additional_elements
from sumo_drvpw.sim.vtypes import SUMO_DEFAULT_TYPE_MASS_KG


class _Domain:
    """A TraCI domain of the replay: its getters read the replay ``r``."""

    def __init__(self, r):
        self.r = r


class _Sim(_Domain):
    def getTime(self):  # noqa: N802 (SUMO's names)
        return self.r.t

    def getDeltaT(self):  # noqa: N802
        return self.r.dt

    def getMinExpectedNumber(self):  # noqa: N802
        return self.r.remaining()

    def getDepartedIDList(self):  # noqa: N802
        return self.r.departed

    def getArrivedIDList(self):  # noqa: N802
        return self.r.arrived

    def getEndingTeleportIDList(self):  # noqa: N802 (a vehicle back after steps without a row)
        return getattr(self.r, "back", ())

    def getStopEndingVehiclesIDList(self):  # noqa: N802 (and the vehicles whose riders changed)
        stops = self.r.stops
        return self.r.load_changed + stops.ending if stops is not None else self.r.load_changed

    def getStopStartingVehiclesIDList(self):  # noqa: N802 (the route files' stops: fcd_stops)
        return self.r.stops.starting if self.r.stops is not None else ()

    def getDepartedPersonIDList(self):  # noqa: N802
        return self.r.departed_persons if self.r.count_persons else ()

    def getOption(self, key):  # noqa: N802 (the recording's, where the replay knows it)
        return self.r.options[key]


class _Person(_Domain):
    def getIDCount(self):  # noqa: N802
        return self.r.person_count

    def getTypeID(self, pid):  # noqa: N802
        return self.r.person_types[pid]


class _Veh(_Domain):
    def getIDList(self):  # noqa: N802
        return self.r.ids

    def getTypeID(self, vid):  # noqa: N802
        return self.r.types[vid]

    def getPersonIDList(self, vid):  # noqa: N802 (persons at the vehicle's x, y and speed)
        return self.r.riders.get(vid, ())

    def getParameter(self, vid, key):  # noqa: N802 (its containers: those at its x, y and speed)
        if key == "has.container.device":
            return "true" if vid in self.r.boxes else "false"
        return " ".join(self.r.boxes.get(vid, ())) if key == "device.container.IDList" else ""

    def getStops(self, vid, limit=0):  # noqa: N802 (the declared stop it is at: fcd_stops)
        cur = self.r.stops.data.get(vid) if self.r.stops is not None else None
        return [cur] if cur is not None else []

    def _col(self, k):
        return lambda vid: self.r.state[vid][k]

    def __getattr__(self, name):
        k = {"getSpeed": 0, "getAcceleration": 1, "getAngle": 2, "getLaneID": 3,
             "getLanePosition": 4, "getSlope": 5}.get(name)
        if k is None:
            raise AttributeError(name)
        return self._col(k)


class _VType(_Domain):
    def getVehicleClass(self, vt):  # noqa: N802 (not in FCD: the route files say)
        return ""

    def getParameter(self, vt, key):  # noqa: N802 (SUMO's shut-off params of the route files)
        return (self.r.type_params.get(vt) or {}).get(key, "")

    def getEmissionClass(self, vt):  # noqa: N802 (the route files', as the recorded run read them)
        return self.r.type_eclass.get(vt, self.r.default_eclass)

    def getActionStepLength(self, vt):  # noqa: N802 (the route files', else the step length)
        return self.r.type_asl.get(vt, self.r.dt)

    def getMass(self, vt):  # noqa: N802 (a person's or container's type: SUMO's mass of the route
        m = self.r.type_mass.get(vt)  # files' vType or SUMO's own type: sumo_type_mass)
        if m is None:  # (a vType of no file read: SUMO's default person's or container's)
            box = vt in self.r.container_types
            m = SUMO_DEFAULT_TYPE_MASS_KG["DEFAULT_CONTAINERTYPE" if box else "DEFAULT_PEDTYPE"]
        return m

    def getIDList(self):  # noqa: N802 (as SUMO's: the route files' vTypes, loaded from the start —
        seen = self.__dict__.setdefault("_seen", set())  # a setType to one read when live reads it —
        seen.update(self.r.type_mass)  # and those the rows named so far; a vehicle's own copy
        now = self.r.types  # <type>@<id> while its vehicle is on it: SUMO drops it at a setType or the end
        copies = {t for v, t in now.items() if t.endswith("@" + v)}
        seen.update(set(now.values()) - copies)
        return tuple(seen | copies)

    def getIDCount(self):  # noqa: N802
        return len(self.getIDList())


class _Calib(_Domain):
    def getIDList(self):  # noqa: N802 (the scenario files' calibrators: set by replay_fcd)
        return list(self.r.calibrators)

    def getEdgeID(self, c):  # noqa: N802
        return self.r.calibrators[c]


class _Rows:
    """What the FCD replays share: a timestep's rows → the vehicles' columns, with parked
    vehicles off their lane (:func:`_unpark`) and the persons riding in each vehicle. SUMO's
    FCD writes riding persons at their vehicle's x, y and speed, without naming the vehicle:
    a person whose x, y and speed equal one vehicle's rides in it (as the live loop reads
    with vehicle.getPersonIDList; their vTypes' masses from the route files)."""

    #: an FCD replay, not SUMO (the Accountant's messages say so)
    is_replay = True

    def _init_rows(self):
        self.parked_rows = 0
        self.riders: dict = {}
        self.person_types: dict = {}
        self.person_count = 0
        self.departed_persons: tuple = ()
        self.load_changed: tuple = ()
        self.rider_rows = 0
        #: person rows of timesteps without x, y (persons or vehicles): no rider told (matched
        #: by place and speed), their mass not booked
        self.unplaced_person_rows = 0
        #: vType → SUMO's mass [kg] of the route files' vTypes and SUMO's own (set by replay_fcd:
        #: sumo_type_mass), what a rider of that vType adds to its vehicle
        self.type_mass: dict = dict(SUMO_DEFAULT_TYPE_MASS_KG)
        #: the route files' containers' vTypes (set by replay_fcd): SUMO's tabular FCD writes a
        #: container as a person, the reader the XML's <container> rows too; told apart by them
        #: (and SUMO's DEFAULT_CONTAINERTYPE), and matched to vehicles as riding persons are
        self.container_types: set = set()
        self.boxes: dict = {}  # vehicle id → the containers at its x, y and speed
        self.boxes_before: dict = {}  # (those of the last timestep)
        self.box_of: dict = {}  # container id → its vType (as its rows write it)
        #: vType → its shut-off params as the route files write them (set by replay_fcd)
        self.type_params: dict = {}
        self.type_eclass: dict = {}
        #: vType → its actionStepLength [s] as the route files write it (set by replay_fcd)
        self.type_asl: dict = {}
        #: vType → the speed gain per second [m/s²] its driving cannot exceed (set by replay_fcd:
        #: sim/dynamics.accel_bounds), which tells a placement (sim/reader.reinserted)
        self.type_accel: dict = {}
        #: vehicle id → depart [s] of the route files' vehicles not yet in a row (set by
        #: replay_fcd for rows sparser than the steps; emptied as they appear: fcd_warn.missed_vehicles)
        self.unseen: dict = {}
        self.default_eclass = ""  # (a vType the files do not hold: sim/vtype_energy.replay_emission_classes)
        #: the route files' stops matched to where vehicles stand (fcd_stops.StopTracker;
        #: set by replay_fcd, None: no file declares a stop)
        self.stops = None
        #: which parked rows idle in their space, their way out blocked (fcd_idle.Idling;
        #: set by replay_fcd, None: none told), and the rows booked so
        self.idling, self.idle_rows = None, 0
        self.count_persons = True
        #: the vehicles' kinetic energy gained row to row (fcd_warn.KineticGain; set by replay_fcd
        #: for rows sparser than the run's steps, None: not measured)
        self.kinetic = None
        #: a timestep with vehicles but no angle column (no yaw rate for the radial factor)
        self.no_angle = False
        #: the step length [s] of the run that recorded the FCD (its header; set by replay_fcd,
        #: None: unknown): SUMO booked its radial drag per step of it, whatever the rows' interval
        self.recorded_step_s = None
        #: vehicle rows on a lane of the network, on a lane it lacks, and the first of
        #: those (lane, time) (with the column ``lane_ok`` of ParkedTest.mark)
        self.lane_rows, self.unknown_rows, self.first_unknown = 0, 0, None
        #: calibrator id → its edge, of the scenario's files (set by replay_fcd): where SUMO
        #: changes vTypes, read every step there as the live run does (sim/reader.calibrator_lanes)
        self.calibrators: dict = {}
        #: the vehicles whose last row was on their lane (not parked): one of them parked in
        #: this row moved into its space in this step (:func:`_parks_now`)
        self.on_lane_ids: set = set()
        self.entry_slope: dict = {}  # vehicle id → the FCD's slope [rad] of the row it parks in
        self.riders_before: dict = {}  # the riders of the last timestep (vehicle id → persons)
        self.riders_told = True  # persons matched to vehicles (their rows and the vehicles' have x, y)
        self.last_ids: set = set()  # the vehicles of the last timestep
        #: vehicle rows without x, y: parked vehicles told only by the route files' parking stops
        self.blind_rows = 0
        #: vehicles parked beside a bus stop's span at a declared stop of theirs that is no bus
        #: stop (a parkingArea there): parked, not dwelling, while they stand there (:meth:`_bays`)
        self.not_bay: set = set()
        #: the route files' taxi devices (fcd_taxi.TaxiDevices; set by replay_fcd, None: none
        #: read), and the parked taxis whose last rider left → when their stop ends [s] (:meth:`_reparks`)
        self.taxis, self.emptied, self.reparked = None, {}, set()
        self.at_once: set = set()  # vehicles idling from the row they parked in (:meth:`_vehicles`)
        self.person, self.vehicletype, self.calibrator = _Person(self), _VType(self), _Calib(self)

    def saw(self, ids) -> None:
        """Vehicles ``ids`` are in a row: not among :attr:`unseen`."""
        for v in ids if self.unseen else ():
            self.unseen.pop(v, None)

    def _vehicles(self, c: dict, nxt: dict | None) -> dict:
        """The vehicles' rows of timestep ``c`` (next timestep ``nxt``, None at the end)."""
        self.riders_before = self.riders  # (a car's riders in its row before: who boards at a stop)
        person = c.get("person")
        boxes = None
        if person is not None and person.any():
            box = person & np.isin(c["type"], [*self.container_types, "DEFAULT_CONTAINERTYPE"])
            if box.any():
                boxes = {k: v[box] for k, v in c.items()}
                c = {k: v[~box] for k, v in c.items()}
                person = c["person"]
        if person is not None and person.any():
            veh = ~person
            self._ride({k: v[person] for k, v in c.items()}, {k: v[veh] for k, v in c.items()})
            c = {k: v[veh] for k, v in c.items()}
        elif self.riders or self.person_count:
            self._ride(None, c)
        self.boxes_before = self.boxes
        if boxes is not None or self.boxes:
            self._carry(boxes, c)
        if self.kinetic is not None:
            self.kinetic.add(c["id"], c["speed"])
        if self.idling is not None:
            self.idling.forget(self.arrived)
        if "bay" in c:  # beside a bus stop: parked where its declared stop there is no bus stop
            c = self._bays(c)
        blind = ~_placed(c)  # rows without x, y: a parked vehicle is told by its declared stop
        self.blind_rows += int(np.count_nonzero(blind))
        if self.stops is not None:  # (lanes as written: a parked vehicle serves its stop too)
            self.stops.forget(self.arrived)
            fresh = ~np.fromiter(map(self.last_ids.__contains__, c["id"]), bool, len(c["id"]))
            self.stops.step(self.t - self.dt, c["id"], c["lane"], c["pos"], c["speed"], c.get("off"),
                            blind if blind.any() else None, fresh)
            if self.stops.inferred.any():
                c = dict(c, off=c["off"] | self.stops.inferred)
            self.last_ids = set(c["id"])
        ok = c.get("lane_ok")
        if ok is not None and len(ok):
            self.lane_rows += int(np.count_nonzero(ok > 0))
            bad = ok < 0
            if bad.any():
                self.unknown_rows += int(np.count_nonzero(bad))
                if self.first_unknown is None:
                    j = int(np.argmax(bad))
                    self.first_unknown = (str(c["lane"][j]), float(c["time"][j]))
        if self.taxis is not None and "off" in c:  # an idle taxi parking again where it stands
            c = self._reparks(c, nxt)
        entry = None
        if "off" in c:  # the row a vehicle parks in: its move into the space, booked as driven
            entry, self.on_lane_ids = _parks_now(c["id"], c["off"], self.on_lane_ids)
            if self.reparked:  # (on its lane in this row, not booked: parking again in the next, booked)
                self.on_lane_ids, self.reparked = self.on_lane_ids | self.reparked, set()
            # at the slope SUMO gave it then, its space's, as live (where the FCD has slopes)
            self.entry_slope = (dict(zip(c["id"][entry], np.radians(np.asarray(c["slope"], float)[entry])))
                                if "slope" in c and entry.any() else {})
        if "off" in c and len(c["id"]):  # parked vehicles (ParkedTest.mark)
            if nxt is not None:  # (next rows without x, y: standing is parked, moving is not)
                keep = ~nxt["person"] if "person" in nxt else np.ones(len(nxt["id"]), bool)
                nb = nxt["bay"] & np.fromiter(map(self.not_bay.__contains__, nxt["id"]), bool, len(nxt["id"])) \
                    if "bay" in nxt and self.not_bay else False
                nxt = {"id": nxt["id"][keep], "off": (nxt["off"] | nb | (~_placed(nxt) & (np.asarray(
                    nxt["speed"], float) < STANDSTILL_MPS)))[keep]}
            lanes, n, back = _unpark(c["lane"], c["id"], c["off"] & ~entry, nxt["id"] if nxt else None,
                                     nxt["off"] if nxt else None)
            if self.idling is not None:  # idling in its space, its way out blocked: booked there
                idle = self.idling.rows(self.t - self.dt, c["id"], c["type"], c["off"], c.get("signals"),
                                        self.riders, entry, self.riders_before, self.riders_told)
                if (idle & entry).any():  # idling from the row it parks in: SUMO's device books that
                    self.at_once.update(c["id"][idle & entry])  # step twice, and its end is booked
                if self.at_once and back.any():  # (as live: sim/parking.py Parking.at_once)
                    k = back & np.fromiter(map(self.at_once.__contains__, c["id"]), bool, len(back))
                    self.at_once.difference_update(c["id"][k])
                    back &= ~k
                    lanes[k] = c["lane"][k]
                    n -= int(np.count_nonzero(k))
                idle &= (lanes == "") & ~back
                if idle.any():
                    lanes[idle] = c["lane"][idle]
                    k = int(np.count_nonzero(idle))
                    self.idle_rows += k
                    n -= k
            c = dict(c, lane=lanes)
            self.parked_rows += n
        return c

    def _reparks(self, c: dict, nxt: dict | None) -> dict:
        """Rows ``c`` with an idle taxi's one step on its lane where it stands parked: when its
        last rider leaves at a parking stop and no dispatch follows, SUMO keeps that stop as
        the idle one (``MSIdling_Stop::idle``: triggered, parking) once its unloading is over
        (:meth:`TaxiDevices.unloading_s`), and libsumo reads the taxi on its lane, standing, in
        that step, parked again from the next — while SUMO's FCD writes it at its space all
        along (SUMO 1.28: a person at 1-s and 0.5-s steps, a container at 1-s steps). SUMO
        books the re-park once: its emissions device the next step (a parking entry,
        :meth:`sumo_drvpw.sim.parking.Parking.started`), not the step on the lane (a parking's
        end, :func:`_unpark`), which its emission output writes instead. That row stays
        parked, the next is booked as the row the taxi parks in. Rows written every step only
        (not sparser: :attr:`kinetic` None)."""
        if self.kinetic is not None or not self.riders_told:
            return c
        ids, off, now = c["id"], c["off"], self.t - self.dt
        for load, load_before, box in ((self.riders, self.riders_before, False), (self.boxes, self.boxes_before, True)):
            for v in [v for v, r in load_before.items() if r and not load.get(v)]:
                if self.taxis.of(v):  # (its vType: as its last row names it)
                    k = np.flatnonzero(ids == v)
                    if len(k) and off[k[0]]:
                        self.emptied[v] = now + self.taxis.unloading_s(str(c["type"][k[0]]), box)
        if not self.emptied:
            return c
        due = {v for v, t in self.emptied.items() if t <= now + 1e-6}
        if not due:
            return c
        for v in due:
            del self.emptied[v]
        parked = set(np.asarray(nxt["id"], object)[np.asarray(nxt["off"], bool)]) if nxt is not None else set()
        k = np.flatnonzero(off & np.fromiter(((v in due and v in parked) for v in ids), bool, len(ids)))
        if len(k):  # (else driven off, or dispatched: its stop ended as SUMO's dispatch says)
            self.reparked = set(ids[k])
        return c

    def _bays(self, c: dict) -> dict:
        """Rows ``c`` with the ones :class:`ParkedTest` took for a vehicle dwelling in a bus
        bay (``bay``) marked parked (``off``) where the route files' stops say the vehicle
        stands at a stop of its own there that is no bus stop (a parkingArea whose span
        touches the bus stop's), and it stays parked while it stands there; without such a
        stop (none declared, or one at the bus stop) it dwells, as before."""
        bay = c["bay"]
        if not bay.any():
            self.not_bay = set()
            return c
        k = np.flatnonzero(bay)
        ids, lanes, pos = c["id"], c["lane"], np.asarray(c["pos"], float)
        sure = np.array([ids[j] in self.not_bay or (self.stops is not None and self.stops.at_bay(
            ids[j], lanes[j], pos[j]) is False) for j in k], bool)
        self.not_bay = set(np.asarray(ids, object)[k[sure]])
        if not sure.any():
            return c
        off = c["off"].copy()
        off[k[sure]] = True
        return dict(c, off=off)

    def _carry(self, b: dict | None, v: dict) -> None:
        """Containers per vehicle from the containers' rows ``b`` at a vehicle's x, y and speed
        (SUMO writes them there, as riding persons), and the vehicles whose load changed."""
        boxes: dict = {}
        if b is not None and len(v["id"]) and all(k in b and k in v for k in ("x", "y")):
            at = dict(zip(zip(v["x"], v["y"], v["speed"]), v["id"]))
            for q, vt, key in zip(b["id"], b["type"], zip(b["x"], b["y"], b["speed"])):
                vid = at.get(key)
                if vid is not None:
                    boxes.setdefault(vid, []).append(q)
                    self.box_of[q] = vt
        changed = {vid for vid in set(self.boxes) | set(boxes) if self.boxes.get(vid) != boxes.get(vid)}
        if changed:
            self.load_changed = tuple(set(self.load_changed) | changed)
        self.boxes = boxes

    def _ride(self, p: dict | None, v: dict) -> None:
        """Riders per vehicle from the persons' rows ``p`` and the vehicles' rows ``v``."""
        riders: dict = {}
        if p is not None:  # memory: the persons of this timestep (as for the vehicles)
            self.person_count = len(p["id"])
            before = self.person_types
            self.person_types = dict(zip(p["id"], p["type"]))
            self.departed_persons = tuple(q for q in self.person_types if q not in before)
            self.riders_told = "x" in p and "y" in p and "x" in v and "y" in v
            if not self.riders_told:
                self.unplaced_person_rows += len(p["id"])
            elif len(v["id"]):
                at = dict(zip(zip(v["x"], v["y"], v["speed"]), v["id"]))
                for q, key in zip(p["id"], zip(p["x"], p["y"], p["speed"])):
                    vid = at.get(key)
                    if vid is not None:
                        riders.setdefault(vid, []).append(q)
        else:
            self.person_count, self.departed_persons, self.person_types = 0, (), {}
        old = self.riders
        # persons board and leave as SUMO's emission models count them (sim/riders.py): the
        # riders of each row, standing or not
        self.load_changed = tuple(vid for vid in set(old) | set(riders)
                                  if old.get(vid) != riders.get(vid))
        self.riders = riders
        self.rider_rows += sum(len(r) for r in riders.values())


class ParkedTest:
    """Which FCD rows show a parked vehicle: standing (below ``STANDSTILL_MPS``) beside its
    lane (:func:`~sumo_drvpw.sim.network.off_lane`). SUMO's FCD writes a parked vehicle
    with its lane, at speed 0, at the parking space's x, y; libsumo gives it no lane, and
    the live loop books nothing for it (engine off; SUMO's emission output leaves it out
    too) — unless its parking is over and its way out blocked: SUMO keeps it idling in its
    space, booked standing there (:mod:`sumo_drvpw.sim.fcd_idle`, applied per timestep in
    ``_Rows._vehicles``). Applied once per block of rows (:meth:`mark`), not per timestep. A bus parked at
    one of ``bus_stops`` (lane id → [(start, end)] positions, :func:`bus_stops`) dwells
    there in service and stays on its lane (booked standing), as in the live loop. ``coords``:
    the rows' x, y into the network's (:class:`~sumo_drvpw.sim.fcd_geo.NetCoordinates`; an
    FCD written in geo or UTM coordinates), applied in :meth:`mark`."""

    def __init__(self, net, bus_stops: dict | None = None, coords=None):
        self.net = net
        self.bus_stops = bus_stops or {}
        self.coords = coords

    def __call__(self, cols: dict) -> np.ndarray:
        """Rows (``speed``, ``lane``, ``pos``, ``x``, ``y``) → off their lane, standing."""
        return self.marks(cols)[0]

    def marks(self, cols: dict) -> tuple[np.ndarray, np.ndarray]:
        """Rows → (off their lane, standing; and ``bay``: off it within a bus stop's span,
        taken for a vehicle dwelling in its bay, not parked — unless the route files say its
        stop there is none: ``_Rows._bays``)."""
        off = np.asarray(cols["speed"], float) < STANDSTILL_MPS
        bay = np.zeros(len(off), bool)
        if "x" not in cols or "y" not in cols:
            return np.zeros(len(off), bool), bay
        k = np.flatnonzero(off)  # only a standing vehicle can be parked
        if len(k):
            codes, uniq = pd.factorize(np.asarray(cols["lane"], object)[k])
            idx = self.net.lane_index
            lane = np.array([idx.get(u, -1) for u in uniq], np.int64)[codes]
            off[k] = off_lane(self.net, lane, np.asarray(cols["pos"], float)[k],
                              np.asarray(cols["x"], float)[k], np.asarray(cols["y"], float)[k])
        if self.bus_stops and off.any():  # dwelling at a bus stop: standing, not parked
            lanes, pos = np.asarray(cols["lane"], object), np.asarray(cols["pos"], float)
            k = np.flatnonzero(off)
            for i in k[np.isin(lanes[k], list(self.bus_stops))]:  # parked on a stop's lane
                if any(a - 1.0 <= pos[i] <= b + 1.0 for a, b in self.bus_stops.get(lanes[i], ())):
                    off[i], bay[i] = False, True
        return off, bay

    def lane_ok(self, cols: dict) -> np.ndarray:
        """Rows' lanes (``lane``) → 1 a lane of the network, 0 none (a person; ""), −1 a
        lane the network lacks (int8)."""
        codes, uniq = pd.factorize(np.asarray(cols["lane"], object))
        idx = self.net.lane_index
        st = np.array([1 if u in idx else (0 if u == "" else -1) for u in uniq] + [0], np.int8)
        return st[codes]  # code −1 (no value): the 0 appended

    def mark(self, blocks):
        """The blocks (:func:`iter_fcd_blocks`) with the columns ``off`` (this test's rows)
        and ``lane_ok`` (:meth:`lane_ok`)."""
        for b in blocks:
            if self.coords is not None:
                self.coords.convert(b.cols, self.net)
            b.cols["off"], b.cols["bay"] = self.marks(b.cols)
            b.cols["lane_ok"] = self.lane_ok(b.cols)
            yield b


def bus_stops(files) -> dict[str, list[tuple[float, float]]]:
    """Bus and train stops of SUMO additional files (and of the files they ``<include
    href>``): lane id → [(startPos, endPos)] [m] (SUMO's defaults: 0 and the lane's end;
    negative positions count from the end, read as 0 / the end here). Unreadable files are
    left to SUMO."""
    out: dict[str, list[tuple[float, float]]] = {}
    for _, el in additional_elements(files):
        if el.tag in ("busStop", "trainStop") and el.get("lane"):
            try:
                a = float(el.get("startPos", 0.0))
                b = float(el.get("endPos", np.inf))
            except ValueError:
                continue
            out.setdefault(el.get("lane"), []).append((max(a, 0.0), b if b >= 0 else np.inf))
    return out


def calibrators(files) -> dict[str, str]:
    """Calibrators of SUMO additional files (and of the files they ``<include href>``):
    id → edge (its ``edge``, else its ``lane``'s edge). Unreadable files are left to SUMO."""
    return {el.get("id", ""): el.get("edge") or el.get("lane").rsplit("_", 1)[0]
            for _, el in additional_elements(files)
            if el.tag == "calibrator" and (el.get("edge") or el.get("lane"))}


def _placed(c: dict) -> np.ndarray:
    """Which rows of columns ``c`` have x, y (an FCD written without them has neither)."""
    if "x" not in c or "y" not in c:
        return np.zeros(len(c["id"]), bool)
    return np.isfinite(np.asarray(c["x"], float)) & np.isfinite(np.asarray(c["y"], float))


def _parks_now(ids, off, on_lane_before: set) -> tuple[np.ndarray, set]:
    """Which rows of a timestep (``ids``, ``off``: parked, :class:`ParkedTest`) are the one a
    vehicle parks in — parked now, on its lane in its row before (``on_lane_before``) — and
    the vehicles on their lane now. SUMO parks a car in the step it comes to rest at its stop
    (below 0.1 m/s), after moving it there on its lane, and its FCD writes that row at the
    space with the step's speed: the replay books it driven on its lane, as the live loop
    books that step (:meth:`sumo_drvpw.sim.parking.Parking.started`)."""
    ids = np.asarray(ids, object)
    entry = np.zeros(len(ids), bool)
    if on_lane_before and off.any():
        k = np.flatnonzero(off)
        entry[k] = np.fromiter(map(on_lane_before.__contains__, ids[k]), bool, len(k))
    return entry, set(ids[~off])


def _unpark(lanes, ids, off, nxt_ids, nxt_off) -> tuple[np.ndarray, int, np.ndarray]:
    """The lanes of a timestep's rows with "" for the parked vehicles (``off``: off the
    lane), their number, and which of them are back on their lane in the next timestep
    (``nxt_*``; None: none). libsumo's getLaneID reads "" from the step a vehicle parks to
    the one before it drives off; in that one SUMO puts it back on its lane at speed 0
    (``MSVehicleTransfer::checkInsertions``, after the step's moves), where FCD still
    shows it at the parking space: its emissions device books nothing there (its emission
    output writes it), so that row is booked parked too, as the live loop leaves it
    (:meth:`sumo_drvpw.sim.parking.Parking.step`)."""
    back = np.zeros(len(off), bool)
    if not off.any():
        return lanes, 0, back
    if nxt_ids is not None and len(nxt_ids):
        on = set(np.asarray(nxt_ids, object)[~nxt_off])
        back = off & np.fromiter((v in on for v in ids), bool, len(ids))
    lanes = np.array(lanes, dtype=object)
    lanes[off] = ""
    return lanes, int(np.count_nonzero(off)), back
