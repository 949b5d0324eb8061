"""Planned stops in an FCD replay: the ``<stop>``s the route files declare, matched to where
a vehicle of the FCD stands, so that :class:`~sumo_drvpw.sim.shutoff.ShutOff` switches it
off at a long one as in a live run (:mod:`sumo_drvpw.sim.fcd_conn` answers SUMO's stop
getters from :class:`StopTracker`).

SUMO's FCD holds no stops. The route files do: ``<stop>`` elements of a ``<vehicle>``,
``<trip>`` or ``<flow>`` and of the ``<route>`` it drives (on a ``lane``, an ``edge``, a
``busStop``/``trainStop``, ``containerStop``, ``chargingStation`` or ``parkingArea``, the
stopping places' lanes and positions from the additional files), with their ``duration``
and ``until``. A vehicle's stops are its route's and then its own (SUMO adds them so,
``MSBaseVehicle::addStops``), ordered along the route when it has both; a flow's vehicles
``<flow id>.<n>`` take the flow's stops. SUMO shifts a stop's ``until``: a flow's own
stops by n × its spacing (``period``, 3600/``vehsPerHour``, or (end − begin)/``number``;
SUMO 1.28: ``f.1`` of a 30-s flow stops until 230 where the flow says 200), a named
route's stops by the vehicle's depart (:meth:`DeclaredStops.stops_of`).

A stop starts where SUMO's does (``MSVehicle::processNextStop``): the vehicle, on the
stop's lane (any lane of its edge for an ``edge`` stop), at most 0.1 m/s fast (SUMO's
halting speed), with its front between the stop's ``startPos`` and ``endPos`` (SUMO's
defaults: ``endPos`` the lane's end, ``startPos`` 0.2 m before it; a stopping place's
from 0 to the lane's end; negative positions from the lane's end; ±0.1 m here). SUMO
starts the stop of a vehicle queued inside a stop's range too (SUMO 1.28: a car whose
front stands at 52.5 m of a stop from 10 to 60 m behind one at 60 m). Only the first
declared stop not yet served that matches is taken, and the ones before it count as
passed: a stop is never matched out of its order, nor twice. It ends in the row the
vehicle drives off from rest, or at its planned end (the later of arrival + ``duration``
and ``until``; SUMO ends it in that row), whichever comes first: from then the vehicle is
booked standing again. A ``parking`` stop (a ``parkingArea``'s always) SUMO ends only
when the vehicle can leave its space, later when traffic blocks it (DLR's port_lübeck,
SUMO 1.28: cars parked at a bus stop until 830/870/880 s left at 836/881/887 s), and
puts the vehicle back on its lane, at its space, the step before it drives off (its
parking ends there), and ends the stop in the step it drives off (one switched off for
its stop is written at 0 in the step between; the live loop books it again from its
stop's end): the replay ends it in the row the vehicle moves in (past its planned end). A vehicle parked off the lane
(beside it, at a containerStop or parkingArea; not in a bus bay) is not booked whatever
its stop, and live no switched-off stop: with x, y written its stop starts in its first
parked row (SUMO's, as it parks it; at rest on the lane before, it manoeuvres or waits). The stop it parked at is told
(:attr:`StopTracker.parking`: arrival its first parked row, as SUMO parks a car in the
step it reaches its stop; what it waits for when ``triggered``) so that a car still parked past the
stop's planned end, its way out blocked, is booked idling there
(:mod:`sumo_drvpw.sim.fcd_idle`). An FCD without x, y cannot show a parked vehicle beside
its lane: a vehicle standing at its declared parking stop (``parking`` as SUMO reads it:
true for a ``parkingArea``, and by default for a stop waiting for a person or container;
not in a bus bay, where it dwells) is parked from the row it reaches it in until it moves
again (:meth:`StopTracker.step` ``blind``), except in its first row (SUMO inserts it on its
lane at its stop and parks it a step later). A vehicle that drives
off before a planned end was not at its stop after all (SUMO holds it there): the stop is
open to be matched again, and counted
(``stops_left_before_their_end``). At a stopping place SUMO starts the stop of a vehicle
creeping up a queue inside its range only when the vehicle reaches its stopping position,
a few steps after its first row at 0.1 m/s or slower, where the replay starts it: a stop
with a ``duration`` then ends that much earlier here (booked standing).

What the replay cannot place is booked standing, as the run would book a short stop:
stops added while the run ran (TraCI, rerouters, taxis, parking reroutes), the stops of
vehicles whose route is drawn from a ``routeDistribution`` (which member's stops is not
in the FCD) or repeats (``repeat``), a named route's stop of a vehicle whose depart is
random (a ``probability`` or ``period="exp(…)"`` flow's) or no time (``triggered``) where
``until`` alone makes the stop long, and stops on a stopping place of none of the files
read. :meth:`StopTracker.report` counts them. A taxi's stops end when it is dispatched, not as
planned (:mod:`sumo_drvpw.sim.fcd_taxi`): their end is not told.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import open_maybe_gzip
from sumo_drvpw.model.constants import STANDSTILL_MPS
from sumo_drvpw.sim.scenario_values import sumo_seconds
from sumo_drvpw.sim.fcd_taxi import DISPATCH, TaxiDevices
from sumo_drvpw.sim.sumo_outputs import INCLUDE_DEPTH

#: SUMO's default stop length on a lane [m]: ``startPos`` = ``endPos`` − 2·POSITION_EPS
#: (SUMOVehicleParserHelper::parseStop; POSITION_EPS = 0.1 m)
MIN_STOP_LENGTH_M = 0.2
#: how far a standing vehicle's front may be outside a stop's range and still be at it [m]:
#: SUMO's POSITION_EPS (it halts within that of ``endPos``: 59.995 m for 60 m, SUMO 1.28)
STOP_TOLERANCE_M = 0.1
#: the stopping places a ``<stop>`` may name (the attribute is the element's name; a
#: ``trainStop`` is named by ``busStop``)
STOPPING_PLACES = ("busStop", "trainStop", "containerStop", "chargingStation", "parkingArea")
VEHICLE_ELEMENTS = ("vehicle", "trip", "flow")
#: a stop's ``parking`` values that park the vehicle off the road (SUMO's bool spellings)
PARKING_TRUE = ("true", "1", "yes", "on", "x", "t")
#: a stop's ``triggered`` values that do not make it wait for a trigger (SUMO's false ones)
NOT_TRIGGERED = ("", "false", "0", "no", "off", "-", "f")
#: ``triggered`` values that make it wait for a person (SUMO's true ones and "person")
PERSON_TRIGGERED = ("true", "1", "yes", "on", "x", "t", "person")


def _num(val, where: str, key: str, time: bool = False) -> float | None:
    """A stop's number as written (None: not given); a time may be "h:m:s" as SUMO reads it.
    A value SUMO would refuse is a UserError naming the file, element and key."""
    if val is None or val == "":
        return None
    try:
        return float(val)
    except ValueError:
        t = sumo_seconds(val) if time else None
        if t is None:
            raise UserError(f"{where}: {key} is not a number: {val!r}") from None
        return t


class _Stop:
    """One declared stop: where (``lane`` or ``edge``, or a stopping place ``place``), its
    positions as written, and its planned ``duration`` and ``until`` [s] (None: not given)."""

    __slots__ = ("lane", "edge", "place", "bay", "start", "end", "duration", "until", "on_route", "parking", "trigger")

    def __init__(self, el, where: str, on_route: bool = False):
        a = el.attrib
        self.on_route = on_route  # a named route's stop: its until counts from the depart
        self.lane, self.edge = a.get("lane"), a.get("edge")
        self.place = next((a[k] for k in STOPPING_PLACES if a.get(k)), None)
        # at a bus (or train) stop: parked there, a vehicle dwells in its bay, booked standing
        self.bay = bool(a.get("busStop") or a.get("trainStop"))
        self.start = _num(a.get("startPos"), where, "startPos")
        self.end = _num(a.get("endPos"), where, "endPos")
        self.duration = _num(a.get("duration"), where, "duration", time=True)
        self.until = _num(a.get("until"), where, "until", time=True)
        # waits for a person, container or joining train: ends when it boards, not planned;
        # None, ("person", the ``expected`` person ids) or ("other", ())
        words = set(a.get("triggered", "").lower().replace(",", " ").split()) - set(NOT_TRIGGERED)
        if a.get("containerTriggered", "").strip().lower() not in NOT_TRIGGERED:
            words.add("container")
        # parked beside the lane (a parkingArea's always): SUMO ends the stop when the
        # vehicle can leave, which may be after its planned end. Not written: SUMO parks a
        # stop that waits for a person or a container (SUMOVehicleParserHelper::parseStop:
        # its default is triggered || containerTriggered || parkingArea; a joining train's not)
        given = a.get("parking")
        self.parking = bool(a.get("parkingArea")) or (
            given.strip().lower() in PARKING_TRUE if given is not None
            else bool(words & {*PERSON_TRIGGERED, "container"}))
        self.trigger = (None if not words else ("person", tuple(a.get("expected", "").split()))
                        if words <= set(PERSON_TRIGGERED) and not a.get("extension") else ("other", ()))

    def copy(self, **changed) -> _Stop:
        """This stop with the attributes ``changed``."""
        new = object.__new__(_Stop)
        for k in self.__slots__:
            setattr(new, k, changed.get(k, getattr(self, k)))
        return new


def _is_stop(el) -> bool:
    """A ``<stop>`` at which the vehicle halts (a waypoint, ``speed`` > 0, passes)."""
    try:
        return float(el.get("speed", 0) or 0) <= 0
    except ValueError:
        return True


class DeclaredStops:
    """The stops of the route files (:func:`read_declared_stops`): vehicle id → its stops
    in order and depart, flow id → its vehicles' stops, begin and spacing, stopping place
    id → (lane, startPos, endPos), and the vehicles whose stops cannot be known (id → why).
    ``begin``/``end``: the run's (SUMO's defaults for a flow without them; None: not set)."""

    def __init__(self, begin: float | None = None, end: float | None = None):
        self.begin, self.end = begin, end
        self.vehicles: dict[str, tuple[list[_Stop], float]] = {}
        self.flows: dict[str, tuple[list[_Stop], float, float | None]] = {}
        self.places: dict[str, tuple[str, float | None, float | None]] = {}
        self.unknown: dict[str, str] = {}         # vehicle or flow id → why
        self._routes: dict[str, tuple[list[str], list[_Stop], bool]] = {}
        self._dists: set[str] = set()             # routeDistributions with a member's stops
        #: every <vehicle>/<trip> id → its depart [s] (a time), every <flow> id → (begin,
        #: spacing, number, end) of a flow with a known spacing, and the flows without one
        #: (random, or not a time): what :meth:`departing` reads
        self.departs: dict[str, float] = {}
        self.flow_departs: dict[str, tuple[float, float, int | None, float]] = {}
        self.random_flows: list[str] = []
        #: every <vehicle>/<trip>/<flow> id → the last edge of its route (its ``to``), where
        #: the files tell it (:func:`may_return`)
        self.destinations: dict[str, str] = {}
        self.taxis = TaxiDevices()  # (read_declared_stops sets the run's options)

    def __bool__(self) -> bool:
        return bool(self.vehicles or self.flows or self.unknown)

    def stops_of(self, vid: str) -> tuple[list[_Stop] | None, list[float], str | None]:
        """A vehicle's stops (None: none declared), the shift of each one's ``until`` [s]
        (NaN: not known) and why they cannot be known (None: they can).

        SUMO 1.28 (``MSBaseVehicle::addStops``) shifts the ``until`` of a named route's
        stops by the vehicle's depart, and of its own stops (and its inner route's) by
        n × the flow's spacing for ``<flow id>.<n>``: ``period``, 3600/``vehsPerHour``
        (``perHour``), or for ``number`` alone (end − begin)/number (SUMO's
        ``parseFlowAttributes``; without an ``end`` the run's, else begin + 24 h). A flow
        by ``probability`` or ``period="exp(…)"`` has no spacing: its own stops are not
        shifted, and its vehicles' departs (a route's stops' shift) are random."""
        if vid in self.vehicles:
            stops, depart = self.vehicles[vid]
            return self._taxi(vid, vid, stops), [depart if s.on_route else 0.0 for s in stops], None
        if vid in self.unknown:
            return None, [], self.unknown[vid]
        flow, _, n = vid.rpartition(".")
        if flow and n.isdigit():
            if flow in self.flows:
                stops, begin, spacing = self.flows[flow]
                own = int(n) * spacing if spacing is not None else 0.0
                depart = begin + own if spacing is not None else np.nan
                return self._taxi(vid, flow, stops), [depart if s.on_route else own for s in stops], None
            if flow in self.unknown:
                return None, [], self.unknown[flow]
        return None, [], None

    def _taxi(self, vid: str, by: str, stops: list) -> list:
        """A taxi's stops wait for its dispatch (:mod:`sumo_drvpw.sim.fcd_taxi`)."""
        return [s.copy(trigger=s.trigger or DISPATCH) for s in stops] if self.taxis.has(vid, by) else stops

    def departing(self, t0: float, t1: float) -> dict[str, float]:
        """The vehicles the files declare to depart from ``t0`` to ``t1`` [s] (both in):
        id → depart, a flow's as ``<flow id>.<n>`` at begin + n × its spacing (flows without
        a spacing: :attr:`random_flows`)."""
        out = {v: d for v, d in self.departs.items() if t0 - 1e-9 <= d <= t1 + 1e-9}
        for f, (begin, spacing, number, end) in self.flow_departs.items():
            lo = max(0.0, np.ceil((t0 - begin) / spacing - 1e-9))
            hi = min(np.floor((min(t1, end - 1e-6) - begin) / spacing + 1e-9), np.inf if number is None else number - 1)
            if not np.isfinite(hi):  # (no end to its flow nor to the window)
                continue
            lo, hi = int(lo), int(hi)
            out.update((f"{f}.{n}", begin + n * spacing) for n in range(lo, hi + 1))
        return out

    def _departure(self, el, tag: str, vid: str) -> None:
        """Where and when ``el`` departs, for :meth:`departing`."""
        if tag != "flow":
            d = sumo_seconds(el.get("depart") or "")  # "triggered", "now": not a time
            if d is not None:
                self.departs[vid] = d
            return
        begin, spacing = self._flow_timing(el)
        if spacing is None or spacing != spacing or begin != begin or spacing <= 0:
            self.random_flows.append(vid)
            return
        try:
            number = int(el.get("number")) if el.get("number") is not None else None
        except ValueError:
            number = None
        e = sumo_seconds(el.get("end")) if el.get("end") is not None else None
        end = e if e is not None else (np.inf if number is not None else
                                       self.end if self.end is not None else begin + 86400.0)
        self.flow_departs[vid] = (begin, spacing, number, end)

    def _flow_timing(self, el) -> tuple[float, float | None]:
        """A flow's begin [s] (NaN: not a time, e.g. ``triggered``) and the spacing of its
        vehicles [s] (None: random, by ``probability`` or ``period="exp(…)"``), as SUMO 1.28
        reads them (``SUMOVehicleParserHelper::parseFlowAttributes``, in ms)."""
        b = el.get("begin")
        begin = (sumo_seconds(b) if b is not None else self.begin if self.begin is not None else 0.0)
        begin = np.nan if begin is None else begin
        per = el.get("period")
        if per is not None:
            t = sumo_seconds(per)
            return begin, (round(t * 1000) / 1000 if t is not None else None)  # exp(…): random
        for k in ("vehsPerHour", "perHour"):
            if el.get(k) is not None:
                try:
                    return begin, round(3600.0 / float(el.get(k)) * 1000) / 1000
                except (ValueError, ZeroDivisionError):
                    return begin, np.nan
        if el.get("probability") is not None:
            return begin, None
        try:
            number = int(el.get("number"))
        except (TypeError, ValueError):
            return begin, np.nan
        e = el.get("end")
        end = sumo_seconds(e) if e is not None else self.end if self.end is not None else begin + 86400.0
        if end is None or number <= 0 or begin != begin:
            return begin, np.nan
        return begin, ((round(end * 1000) - round(begin * 1000)) // number) / 1000  # SUMOTime: ms

    def _route(self, el, where: str, named: bool = False) -> tuple[list[str], list[_Stop], bool]:
        edges = (el.get("edges") or "").split()
        stops = [_Stop(s, where, named) for s in el if s.tag == "stop" and _is_stop(s)]
        return edges, stops, bool(el.get("repeat") not in (None, "", "0"))

    def _distribution(self, el, where: str) -> bool:
        """A ``<routeDistribution>``: its members are routes of their own; a vehicle that
        draws from it has stops that cannot be known when a member has any (True)."""
        stops = False
        for r in el:
            if r.tag != "route":
                continue
            if r.get("id"):
                self._routes[r.get("id")] = self._route(r, f"{where}: route '{r.get('id')}'", True)
            member = self._routes.get(r.get("refId") or r.get("id") or "")
            stops |= bool(member and member[1]) or any(s.tag == "stop" for s in r)
        if stops and el.get("id"):
            self._dists.add(el.get("id"))
        return stops

    def _vehicle(self, el, tag: str, where: str) -> None:
        vid = el.get("id")
        if vid is None:
            return
        self._departure(el, tag, vid)
        self.taxis.read(el, tag)
        where = f"{where}: {tag} '{vid}'"
        own = [_Stop(s, where) for s in el if s.tag == "stop" and _is_stop(s)]
        inner = next((r for r in el if r.tag == "route"), None)
        ref = el.get("route")
        if inner is not None:
            edges, rstops, repeat = self._route(inner, where)
        elif ref in self._routes:
            edges, rstops, repeat = self._routes[ref]
        else:
            edges, rstops, repeat = [], [], False
            dist = next((r for r in el if r.tag == "routeDistribution"), None)
            if ref in self._dists or (dist is not None and self._distribution(dist, where)):
                self.unknown[vid] = "its route is drawn from a routeDistribution with stops"
                return
        to = edges[-1] if edges else el.get("to")
        if to and el.get("arrivalEdge") is None:  # (arrivalEdge: an earlier edge of the route)
            self.destinations[vid] = to
        if not (own or rstops):
            return
        if repeat:  # SUMO serves the stops again each round, their until shifted by its cycle
            self.unknown[vid] = "its route repeats"
            return
        stops = _ordered(rstops, own, edges, self.places)
        if tag == "flow":
            self.flows[vid] = (stops, *self._flow_timing(el))
        else:
            depart = sumo_seconds(el.get("depart") or "")  # "triggered", "now": not known
            self.vehicles[vid] = (stops, np.nan if depart is None else depart)


def _edge_of(s: _Stop, places: dict) -> str | None:
    lane = s.lane or (places.get(s.place, (None,))[0] if s.place else None)
    return s.edge or (lane.rpartition("_")[0] if lane else None)


def _ordered(rstops: list, own: list, edges: list, places: dict) -> list:
    """A route's stops and a vehicle's own, in the order SUMO serves them: along the route
    (a stop on an edge the route lacks, or a route without edges: as declared)."""
    if not (rstops and own) or not edges:
        return rstops + own
    first = {}
    for i, e in enumerate(edges):
        first.setdefault(e, i)
    keyed = [(first.get(_edge_of(s, places), len(edges)), s.end if s.end is not None else np.inf, k, s)
             for k, s in enumerate(rstops + own)]
    return [s for *_, s in sorted(keyed, key=lambda x: x[:3])]


def read_declared_stops(files, depth: int = 0, out: DeclaredStops | None = None,
                        begin: float | None = None, end: float | None = None, option=None) -> DeclaredStops:
    """The stops of SUMO route/additional ``files`` (and of the files they ``<include>``),
    in load order; a bad number is a UserError naming the file, element and key. ``begin``,
    ``end``: the run's [s] (a flow without them takes them); ``option``: key → the run's SUMO
    option value or None (its taxi devices')."""
    if out is None:
        out = DeclaredStops(begin, end)
        out.taxis = TaxiDevices(option)
    for f in files:
        path = Path(f)
        try:
            with open_maybe_gzip(path) as src:
                level = 0
                for ev, el in ET.iterparse(src, events=("start", "end")):
                    if ev == "start":
                        level += 1
                        continue
                    level -= 1
                    tag = el.tag.split("}")[-1]
                    if tag in STOPPING_PLACES and el.get("id") and el.get("lane"):
                        where = f"{path}: {tag} '{el.get('id')}'"
                        out.places[el.get("id")] = (el.get("lane"), _num(el.get("startPos"), where, "startPos"),
                                                    _num(el.get("endPos"), where, "endPos"))
                    if tag == "vType":
                        out.taxis.read(el, tag)
                    if level != 1:  # inside a vehicle, route or distribution: read at its end
                        continue
                    if tag == "include" and el.get("href") and depth < INCLUDE_DEPTH:
                        read_declared_stops([path.parent / el.get("href")], depth + 1, out)
                    elif tag == "route" and el.get("id"):
                        out._routes[el.get("id")] = out._route(el, f"{path}: route '{el.get('id')}'", True)
                    elif tag == "routeDistribution" and el.get("id"):
                        out._distribution(el, str(path))
                    elif tag in VEHICLE_ELEMENTS:
                        out._vehicle(el, tag, str(path))
                    el.clear()
        except (ET.ParseError, OSError):
            continue  # the vTypes' reader names a file SUMO cannot read either
    return out


class StopTracker:
    """Which vehicles of the replay reach, and leave, a declared stop in each timestep.

    :meth:`step` takes a timestep's vehicle rows and sets ``starting`` (the vehicles whose
    stop started: SUMO's getStopStartingVehiclesIDList), ``ending`` (whose stop ended) and
    ``data`` (vehicle id → the stop it is at, as TraCI's StopData: ``duration``, ``until``,
    ``arrival``). Vehicles left (:meth:`forget`) are dropped."""

    def __init__(self, declared: DeclaredStops, net):
        self.declared, self.net = declared, net
        self.state: dict[str, list] = {}     # vehicle id → [stops, next index, shifts, current]
        self.starting: tuple = ()
        self.ending: tuple = ()
        self.data: dict[str, SimpleNamespace] = {}
        self.matched = 0
        self.vehicles = 0
        self.not_known: dict[str, int] = {}  # why → vehicles
        self.unplaced = 0                    # stops on a stopping place no file declares
        self.until_unknown = 0               # stops reached whose until could not be shifted
        self.left_early = 0                  # "stops" driven off before their planned end
        #: the vehicles that parked off the lane at a declared stop in this step: (id, row,
        #: the stop: ``duration``, ``until`` (NaN: not known), ``arrival`` its first parked
        #: row's time, ``trigger``), for telling a car idling in its space (sim/fcd_idle.py)
        self.parking: list[tuple] = []
        #: rows without x, y (:meth:`step` ``blind``): which of the step's rows are parked at a
        #: declared parking stop (the FCD cannot show it), the vehicles parked so, and their rows
        self.inferred = np.zeros(0, bool)
        self.parked_ids: set[str] = set()
        self.inferred_rows = 0

    def _state(self, vid: str):
        st = self.state.get(vid)
        if st is None:
            stops, shifts, why = self.declared.stops_of(vid)
            if why is not None:
                self.not_known[why] = self.not_known.get(why, 0) + 1
            if stops:
                self.vehicles += 1
            st = self.state[vid] = [stops or [], 0, shifts, None]
        return st

    def _span(self, s: _Stop, lane: str) -> tuple[float, float] | None:
        """The stop's [startPos, endPos] on ``lane`` [m], or None when it is not there."""
        place = None
        if s.place is not None:
            place = self.declared.places.get(s.place)
            if place is None:
                return None
            if place[0] != lane:
                return None
            a, b = place[1], place[2]
        elif s.lane is not None:
            if s.lane != lane:
                return None
            a, b = s.start, s.end
        elif s.edge is not None:
            if lane.rpartition("_")[0] != s.edge:
                return None
            a, b = s.start, s.end
        else:
            return None
        i = self.net.lane_index.get(lane)
        if i is None:
            return None
        length = float(self.net.lane_length[i])
        b = length if b is None else (b + length if b < 0 else b)
        if a is None:
            a = 0.0 if place is not None else max(0.0, b - MIN_STOP_LENGTH_M)
        elif a < 0:
            a += length
        return a, b

    def step(self, t: float, ids, lanes, pos, speed, parked=None, blind=None, fresh=None) -> None:
        """Timestep ``t`` [s] (the FCD's time) with its vehicle rows: ids, lanes (as SUMO
        wrote them, parked vehicles' too), positions [m], speeds [m/s], and which rows are
        parked (off the lane; their stop is served, not booked). ``blind``: the rows without
        x, y, which cannot show a parked vehicle beside its lane: one standing at a declared
        parking stop (``parking``, not in a bus bay, where it dwells) is parked from the row
        it reaches it in until it moves again (:attr:`inferred`), as SUMO parks it — but in a
        vehicle's first row (``fresh``), where SUMO inserts it on its lane at its stop and parks
        it in the step after."""
        starting, ending = [], []
        self.parking = []
        speed = np.asarray(speed, float)
        self.inferred = np.zeros(len(speed), bool)
        if self.parked_ids:  # parked at a declared parking stop, the FCD blind to it: until it moves
            k = np.flatnonzero(np.fromiter(map(self.parked_ids.__contains__, ids), bool, len(speed)))
            still = (speed[k] < STANDSTILL_MPS) & (blind[k] if blind is not None else False)
            self.inferred[k[still]] = True
            self.parked_ids.difference_update(np.asarray(ids, object)[k[~still]])
        if self.data:  # the vehicles at a stop: does it end in this row?
            rows = dict(zip(ids, range(len(ids))))
            for vid, cur in list(self.data.items()):
                j = rows.get(vid)
                if j is None:
                    continue
                if parked is not None and parked[j]:  # parked off the lane: served there, not
                    if cur.index >= 0:                 # booked (as if it had parked at once)
                        self._park(vid, j, cur.duration, np.nan if cur.open else cur.until, t, cur.trigger)
                    cur.end_t, cur.index = t, -1
                t_end = t
                if cur.parking and cur.index >= 0:
                    # SUMO puts a parked vehicle back on its lane, at its space, the step
                    # before it drives off (its parking ends there), but its stop ends in
                    # the step it drives off (a switched-off one is written at 0 in the
                    # step between, and the live run books it again from its stop's end)
                    over = speed[j] > 0.0 and (cur.at_rest or t >= cur.end_t - 1e-6)
                else:
                    over = t >= cur.end_t - 1e-6 or (cur.at_rest and speed[j] > 0.0)
                if over:
                    st = self.state[vid]
                    if t_end < cur.end_t - 1e-6 and np.isfinite(cur.end_t):  # not its stop after all
                        st[1] = cur.index
                        self.left_early += 1
                    st[3] = None
                    del self.data[vid]
                    ending.append(vid)
                elif speed[j] == 0.0:
                    cur.at_rest = True
        for j in np.flatnonzero(speed <= STANDSTILL_MPS):
            vid = ids[j]
            st = self.state.get(vid) or self._state(vid)
            stops, nxt = st[0], st[1]
            if st[3] is not None or nxt >= len(stops):
                continue
            for k in range(nxt, len(stops)):
                s = stops[k]
                if s.place is not None and s.place not in self.declared.places:
                    continue
                span = self._span(s, lanes[j])
                if span is None or not (span[0] - STOP_TOLERANCE_M <= pos[j] <= span[1] + STOP_TOLERANCE_M):
                    continue
                if (fresh is not None and fresh[j] and blind is not None and blind[j] and s.parking
                        and not s.bay):  # on its lane in its first row, its x, y unwritten: it parks in its next
                    break
                if (s.parking and not s.bay and parked is not None and not parked[j]
                        and not (blind is not None and blind[j])):  # SUMO starts it as it parks the vehicle:
                    break  # on its lane it manoeuvres in (parking.maneuver) or waits, idling
                st[1] = k + 1
                self.matched += 1
                until = -1.0 if s.until is None else s.until + st[2][k]
                unknown = until != until  # NaN: a depart not known (a random flow's, "triggered")
                if unknown:
                    self.until_unknown += 1
                    until = -1.0
                dur = -1.0 if s.duration is None else s.duration
                if blind is not None and blind[j] and s.parking and not s.bay and speed[j] < STANDSTILL_MPS:
                    self.inferred[j] = True  # (parked as SUMO parks it there, its x, y unwritten)
                    self.parked_ids.add(vid)
                if (parked is not None and parked[j]) or self.inferred[j]:  # parked there: not
                    self._park(vid, j, dur, np.nan if unknown else until, t, s.trigger)  # booked (but it
                    break                                                                 # may idle there)
                # SUMO ends it at the later of arrival + duration and until; neither
                # given: when the vehicle drives off
                ends = [x for x, given in ((t + dur, dur >= 0), (until, until >= 0)) if given]
                end_t = max(ends) if ends else np.inf
                cur = SimpleNamespace(duration=dur, until=until, arrival=t, end_t=end_t, at_rest=speed[j] == 0.0,
                                      index=k, parking=s.parking, trigger=s.trigger, open=unknown)
                st[3] = cur
                self.data[vid] = cur
                starting.append(vid)
                break
        self.starting, self.ending = tuple(starting), tuple(ending)
        self.inferred_rows += int(np.count_nonzero(self.inferred))

    def at_bay(self, vid: str, lane: str, pos: float) -> bool | None:
        """Whether the declared stop vehicle ``vid`` stands at on ``lane`` at ``pos`` [m] —
        its current one, else the next of its stops there — is at a bus or train stop (None:
        no declared stop of it there)."""
        st = self.state.get(vid) or self._state(vid)
        if st[3] is not None:
            return st[0][st[3].index].bay if st[3].index >= 0 else None
        for s in st[0][st[1]:]:
            if s.place is not None and s.place not in self.declared.places:
                continue
            span = self._span(s, lane)
            if span is not None and span[0] - STOP_TOLERANCE_M <= pos <= span[1] + STOP_TOLERANCE_M:
                return s.bay
        return None

    def _park(self, vid: str, j: int, dur: float, until: float, t: float, trigger) -> None:
        """Vehicle ``vid`` (row ``j``) parked off the lane at its declared stop at ``t`` [s]
        (SUMO's arrival there: it parks in the step it reaches the stop)."""
        self.parking.append((vid, int(j), SimpleNamespace(duration=dur, until=until, arrival=t,
                                                          trigger=trigger)))

    def forget(self, vids) -> None:
        for v in vids:
            self.state.pop(v, None)
            self.data.pop(v, None)
            self.parked_ids.discard(v)

    def report(self) -> dict:
        """What the replay matched and what it could not know (summary.json)."""
        d = self.declared
        lists = [*(v[0] for v in d.vehicles.values()), *(f[0] for f in d.flows.values())]
        places = sum(1 for stops in lists for s in stops if s.place is not None and s.place not in d.places)
        return {"vehicles_with_declared_stops": self.vehicles, "stops_reached": self.matched,
                "vehicles_whose_stops_are_not_known": dict(sorted(self.not_known.items())),
                "declared_stops_on_unknown_stopping_places": places,
                "stops_whose_until_is_not_known": self.until_unknown,
                "stops_left_before_their_end": self.left_early}
