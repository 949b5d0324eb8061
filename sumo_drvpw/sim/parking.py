"""Parked vehicles in the live loop: not booked while parked, booked again when they leave,
and booked idling while they wait in their space for a gap to leave by.

SUMO takes a parking vehicle off its lane (``MSVehicleTransfer``): engine off, no auxiliary
power, not in its emission output. The loop tells it once, when a read finds it without a
lane and its stop state says parking — the step in which SUMO moved it into its stop and
parked it, booked as driven (:meth:`Parking.started`) — and does not read it again until its parking ends
(``getParkingEndingVehiclesIDList``): a parked fleet costs no getter calls. A vehicle
parked at a bus stop (a bus bay: ``parking="true"`` at a busStop) dwells there in service:
it is booked standing on the stop's lane (time, auxiliary power), as at a stop on the lane.

**The step a parking ends in** is not booked: SUMO puts the car back on its lane at speed 0
after the step's moves (``MSVehicleTransfer::checkInsertions``), and its emissions device
books nothing there (its emission output writes it); the car stays parked for the loop one
step more (:attr:`Parking.waking`) and is booked from the step it drives off in — as the device
counts a parking: the step it parks in, its idle steps, not this one (before 2026-11-30 one
standing step more per parking). A car idling from the step it parks in (its parking over
when it got there, its way blocked) is the exception: the device books that step twice
(its move and an idle step), so its end is booked (:attr:`Parking.at_once`).

**A way out that is blocked.** When the parking time is over but the lane has no gap at the
space (``MSVehicleTransfer::checkInsertions``: insertion failed), SUMO keeps the vehicle in
its space *idling* — "blocked from entering the road, engine assumed to be idling" — and
switches on its blinker to signal the wish to re-enter. Its emission output writes every
such step (``isOnRoad() || isIdling()``) at speed 0 on the parking lane, and its emissions
device books them (``notifyIdle``). The loop books them standing in the space (the stop's
lane, the position SUMO gives), with the grade there, as the emission output does (the
emissions device's tripinfo takes slope 0: the two differ only for a car on SUMO's MMPEVEM
parked on a slope, by its holding torque). The grade is the slope SUMO gives the car in its
space, read once when it starts to idle (``getSlope``: a parking area's ``<space>`` may
have a ``slope`` of its own; beside the lane, the car's front-to-back slope there), and
once in the step its parking ends when that step is booked (below), back on the lane but
still at its stop, where SUMO still takes that slope — not the plug-in's robust profile of the lane, which parts
from it on a lot's sloped space or where the lane's grade changes within a car length (a
probe, 2026-11-27, SUMO's MMPEVEM BMW i3: idling 158 s in a space of ``slope="6"`` beside
a flat lane, −17 % of the car before, 5e-7 after; at 315 m, where a 7.0° ramp of the lane's
shape ends, SUMO 0.326 Wh/s against 0.164 at the profile's 3.7°, −14 % before; a car
leaving the sloped space at once, its one step back on the lane, −8.2e-4 before, 2e-9 after;
that step is not booked since 2026-11-30, below.
Its stop ended by a script, SUMO takes the lane's slope, and the loop the profile. A car
standing on the lane at such a grade change — at a stop, in a queue — is still booked at
the profile: an i3 stopping on the lane at 315 m, −11 %). A parked vehicle is asked for its signals
(one getter) only from its parking's earliest planned end on (its arrival plus the
remaining ``duration``, or its ``until``; every step for a stop with neither, as a
triggered one), so a parked fleet still costs nothing until it is due to leave (a probe,
2026-11-27, 300 s at 0.5-s steps: 40 cars parked for 5000 s — 20 of SUMO's MMPEVEM i3,
never switched off, and 20 on the Energy model, switched off — cost no getSignals call; 20
cars at ``triggered="person"`` stops without a duration, whom no person boards, cost one
per car and step from their arrival, 7,901). A car
whose parking is over when it gets there (its ``until`` passed while it drove) is tried
in the step it parks, and idles from that very step when the way is blocked: booked then
at the speed SUMO still gives it (the last of its creep into the space) and, from the next
step, braking from it to 0, as the emission output books them. A parked car whose stop
a script ends (``vehicle.resume``) leaves SUMO's id list until it is back on the road (SUMO
1.28: its getters answer "no value", −2³⁰, its emission output books it idling in its
space): the loop tells it by the id list's count (one getLoadedIDList, as for a removed
vehicle), asks for its signals from then on, and reads it, idling, from the space it
parked in (:meth:`Parking.resume`); a bus in a bay whose stop a script ends leaves the
list alike and is booked dwelling there until it is back on the road (its FCD has no rows
for that time, so a replay books none). A stop that a script shortens (``setStop``,
``setParkingAreaStop`` with a shorter duration) after it started is due at the end planned
when it started: idling before then is not booked (a probe, 2026-11-27: the car of
tests/test_parking_exit_blocked.py cut from ``until`` 40 s to 1 s at 30 s idles 19 steps
the loop misses, 0.26 Wh of SUMO's 54.23). A vehicle switched off for
its stop (planned longer than its vType's ``shutOffStopDuration``: sim/shutoff.py) stays
off while it idles — its stop is still SUMO's current one — and is not booked (SUMO 1.28
writes it at 0), nor in the step it is back on the road (SUMO writes that one off too: the
stop's duration its emission model reads is that of the step before): booked from the step
after, when its stop ends. Its stop ended by a script, it stays off all the same (SUMO
1.28 writes 0 while it idles out of the id list). Persons who boarded while it was parked
(a ``triggered="person"`` stop) are read when it starts to idle, and every step while it
idles (its stop is still the current one): SUMO's MMPEVEM books their mass in the holding
torque on a slope. The FCD replay tells an idling car by the FCD's blinker, or by its
declared stop (:mod:`sumo_drvpw.sim.fcd_idle`).

Not reproduced (probes of 2026-11-27 with SUMO 1.28): a car whose parking starts and ends
in one step (its ``until`` passed, the way free) is written by SUMO at speed 0 with the
acceleration of its last move into the space (getAcceleration −0.25 m/s² where its speed
fell from 0.33 to 0 in the 1-s step), which the loop books as (0 − 0.33)/Δt: for SUMO's
MMPEVEM i3, whose holding torque takes the acceleration at speed 0, −1.1e-5 of that car.
"""

from __future__ import annotations

import heapq

import numpy as np

from sumo_drvpw.sim.reader import known_to_sumo
from sumo_drvpw.sim.shutoff import planned_duration_s

#: vehicle.getStopState bit: the vehicle stops at a bus (or train) stop (TraCI's stop
#: state: 1 stopped, 2 parking, 4/8 triggered, 16 at a busStop, 32 containerStop, 64
#: chargingStation, 128 parkingArea)
STOP_AT_BUS_STOP = 16
#: vehicle.getStopState bit: the vehicle is parking (off the lane)
STOP_PARKING = 2
#: vehicle.getSignals bits: blinker right (1) and left (2); SUMO switches on the one
#: towards the road (left; right in a left-hand network) while a parked vehicle waits to
#: re-enter the road
BLINKERS = 1 | 2
#: TraCI's "not set" for a stop's time fields (INVALID_DOUBLE_VALUE, −2³⁰)
UNSET = -1e9


class Parking:
    """Which vehicles of a run are parked, dwelling at a bus stop, or idling in their space
    (see the module docstring); ``on`` when the connection can tell parking."""

    def __init__(self, conn, net, lane_index: dict, shutoff=None, riders=None):
        self.conn, self.net, self.lane_index, self.shutoff = conn, net, lane_index, shutoff
        self.riders = riders  # sim/riders.py: who rides in a car that starts to idle
        sim, veh = conn.simulation, conn.vehicle
        self.ends = getattr(sim, "getParkingEndingVehiclesIDList", None)
        self.on = self.ends is not None and hasattr(veh, "getStopState") and hasattr(veh, "getStops")
        self.signals = getattr(veh, "getSignals", None) if self.on else None
        #: vehicle id → (lane number, lane position) where it is booked standing off the
        #: lane: dwelling at a bus stop, or idling in its parking space
        self.dwell: dict[str, tuple[int, float]] = {}
        #: parked vehicle id → simulation time [s] from which it may leave; a heap of
        #: (time, id) gives those due in a step without a look at the others, which move to
        #: ``polling`` (their signals read each step until they idle or leave)
        self.due: dict[str, float] = {}
        self.heap: list[tuple[float, str]] = []
        self.polling: set[str] = set()
        self.idling: set[str] = set()  # parked vehicles idling in their space, waiting to leave
        self.idle_starts = 0  # times a parked vehicle began to idle
        self.idle_vehicle_s = 0.0  # time booked idling [s]
        self.dt = float(sim.getDeltaT())
        #: parked vehicle id → (lane number, lane position) of its space, read when it parks
        self.space: dict[str, tuple[int, float]] = {}
        #: parked vehicles whose stop a script ended (``vehicle.resume``): out of SUMO's id
        #: list until they are back on the road, read all the same (:meth:`with_resumed`)
        self.resumed: set[str] = set()
        #: vehicles switched off at their stop (sim/shutoff.py) whose parking ended in the
        #: last step: SUMO writes them off in the step they are back on the road too
        self.waking: set[str] = set()
        self.off: set[str] = set()  # parked vehicles switched off for their stop (shutoff.py)
        #: idling vehicle id → the slope SUMO gives it in its space [rad] (getSlope at its
        #: idle start: a parking area's space may have its own ``slope``; the car's front-to-
        #: back slope on the lane), which its emission output takes (MMPEVEM's holding torque)
        self.grade: dict[str, float] = {}
        self.slope = getattr(veh, "getSlope", None)
        #: vehicle id → its slope [rad] in the step its parking ended (back on its lane, its
        #: stop not yet over, SUMO still gives it its space's) or began (read once)
        self.once: dict[str, float] = {}
        #: vehicles idling from the step they parked in, whose device booked that step's move
        #: and an idle step (MSVehicleTransfer::checkInsertions): the step they leave is booked
        self.at_once: set[str] = set()

    def _standing(self, vid: str, stops=None) -> tuple[int, float] | None:
        """The lane number and position of vehicle ``vid`` at its current stop (``stops``:
        its getStops(vid, 1) when read already), or None."""
        if stops is None:
            stops = self.conn.vehicle.getStops(vid, 1)
        lane = self.lane_index.get(stops[0].lane, -1) if stops else -1
        if lane < 0:
            return None
        pos = float(self.conn.vehicle.getLanePosition(vid))
        return lane, min(max(pos, 0.0), float(self.net.lane_length[lane]))

    def started(self, ledger, vid: str, i: int, now: float, moved_in: bool = True) -> tuple[int, float] | None:
        """Vehicle ``vid`` (slot ``i``), just read without a lane: parked (not read until its
        parking ends), dwelling at a bus stop (booked standing there), or neither (a
        teleport: read again next step). Returns the lane number and position to book this
        step at, or None: where it dwells or idles, and — ``moved_in``: it was on the road
        in the step before — the move into its space: SUMO parks a car in the step it comes
        to rest at its stop (below 0.1 m/s), after moving it there on the lane (its speed
        from the last step's to this one's, its distance, engine on: SUMO's emissions device
        books that move), so this step is booked as driven, on the stop's lane at the
        position SUMO gives it, and the car is parked from the next (before 2026-11-29 it was
        not booked: the kinetic energy of the car's last speed on the lane, up to 7.6 m/s at
        1-s steps, was lost from the acceleration term)."""
        st = int(self.conn.vehicle.getStopState(vid))
        if not st & STOP_PARKING:
            return None
        if st & STOP_AT_BUS_STOP:
            d = self._standing(vid)
            if d is not None:
                self.dwell[vid] = d
                return d
        ledger.veh_parked[i] = True
        stops = self.conn.vehicle.getStops(vid, 1)
        entry = self._standing(vid, stops) if moved_in else None
        if entry is not None and self.slope is not None:  # at the slope SUMO gives it then: its space's
            s = float(self.slope(vid))
            if -90.0 <= s <= 90.0:
                self.once[vid] = np.radians(s)
        # switched off for a stop longer than its vType's shutOffStopDuration, it stays
        # off while it idles (its stop is still SUMO's current one): nothing to book
        if stops and self.shutoff is not None and planned_duration_s(stops[0]) \
                > self.shutoff.limit_of(ledger.veh_type[i]):
            self.off.add(vid)
        elif self.signals is not None:
            d = self._standing(vid, stops)
            if d is not None:  # where it idles should a script end its stop (resume)
                self.space[vid] = d
            self.due[vid] = due = self._earliest_end(stops, now)
            heapq.heappush(self.heap, (due, vid))
            # over already when it arrives (an ``until`` it came too late for): SUMO
            # tries to put it back on the road in the step it parks, and idles it there
            # at once when the road is blocked: booked from this step, at the speed SUMO
            # gives it (the last of its creep into the space, in its emission output too)
            if due <= now + 1e-9 and int(self.signals(vid)) & BLINKERS:
                ledger.veh_parked[i] = False
                self.at_once.add(vid)  # (SUMO's device books this step twice: its end is booked)
                # its grade: the slope at the space, as SUMO's (SUMO set it into the space
                # farther than its speed took it: the rise since its last read is no grade)
                ledger.veh_at[i, 2] = np.nan
                self.idle_vehicle_s += self.dt  # (step() counted this step's before)
                return self.dwell[vid] if self._idle(ledger, {vid: i}, vid) else None
        return entry

    def _idle(self, ledger, vmap, vid: str) -> bool:
        """Parked vehicle ``vid`` idles in its space from this step (its blinker shows it):
        booked standing there, with whoever rides in it. True when it is."""
        self.due.pop(vid, None)
        self.polling.discard(vid)
        d = self.space.get(vid) if vid in self.resumed else self._standing(vid)
        if d is None:
            return False
        self.dwell[vid] = d
        self.idling.add(vid)
        self.idle_starts += 1
        if self.slope is not None and vid not in self.resumed:  # (out of its stop SUMO takes
            s = float(self.slope(vid))                           # the lane's: the profile's)
            if -90.0 <= s <= 90.0:
                self.grade[vid] = np.radians(s)
        r = self.riders
        if r is not None and r.on:  # persons who boarded while it was parked (not read then)
            r.at_stop.add(vid)      # and those boarding while it idles: its stop is not over
            r.update(ledger, vmap, [vid])
        return True

    @staticmethod
    def _earliest_end(stops, now: float) -> float:
        """The earliest time the parking at ``stops[0]`` can end [s] (never later than
        SUMO's: the remaining duration counts down, so arrival + remaining is at most the
        planned end)."""
        if not stops:
            return now
        s = stops[0]
        dur, until, arrival = (float(getattr(s, k, UNSET)) for k in ("duration", "until", "arrival"))
        start = arrival if arrival > UNSET else now
        ends = [start + dur] if dur > UNSET else []
        if until > UNSET:
            ends.append(until)
        return max(ends) if ends else now

    def _unpark(self, ledger, i: int) -> None:
        ledger.veh_parked[i] = False
        ledger.veh_lane[i] = -2          # read its lane and position again
        ledger.veh_prev_speed[i] = 0.0   # from standstill
        ledger.veh_at[i, 2] = np.nan
        ledger.veh_prev_angle[i] = np.nan  # (no turn: one idling out of SUMO's list read angle 0)

    def step(self, ledger, vmap, now: float, dt: float) -> bool:
        """Once per step, before the vehicles are read: those whose parking ended are read
        and booked again, from standstill; parked ones now idling in their space, waiting
        to leave, are booked standing there from this step. True when the selection of
        vehicles read changes."""
        changed = False
        self.once = {}
        waking, self.waking = self.waking, set()
        for vid in waking:  # back on the road a step ago (not booked then): booked from now
            i = vmap.get(vid)
            if i is not None and ledger.veh_parked[i] and not ledger.veh_done[i]:
                self._unpark(ledger, i)
                changed = True
        for vid in self.ends():
            parked_off = vid in self.off  # switched off for its stop, parked off the lane
            off = parked_off or (self.shutoff is not None and vid in self.shutoff.off)  # (a bay)
            idled, at_once = vid in self.idling, vid in self.at_once
            self.forget(vid)
            i = vmap.get(vid)
            if i is not None and (ledger.veh_parked[i] or idled) and not at_once:
                # back on its lane at speed 0 (MSVehicleTransfer::checkInsertions, after the
                # step's moves): SUMO's emissions device books nothing in this step (its
                # emission output writes it), so it is booked from the next — also one
                # switched off for its stop (SUMO writes 0 here too); one dwelling in a bus
                # bay switched off by ShutOff stays with ShutOff, whose own it is
                if off and not parked_off:
                    continue
                ledger.veh_parked[i] = True
                self.waking.add(vid)
                changed = changed or idled
            if i is not None and at_once and self.slope is not None:  # booked now, at its space's slope
                s = float(self.slope(vid))
                if -90.0 <= s <= 90.0:
                    self.once[vid] = np.radians(s)
        heap, due = self.heap, self.due
        while heap and heap[0][0] <= now + 1e-9:
            t, vid = heapq.heappop(heap)
            if due.get(vid) == t:  # (else forgotten, or parked again since: a newer entry)
                self.polling.add(vid)
        for vid in list(self.polling):
            i = vmap.get(vid)
            if i is None or not ledger.veh_parked[i] or ledger.veh_done[i]:
                self.forget(vid)
            elif int(self.signals(vid)) & BLINKERS and self._idle(ledger, vmap, vid):
                self._unpark(ledger, i)
                changed = True
        self.idle_vehicle_s += len(self.idling) * dt
        return changed

    def forget(self, vid: str) -> None:
        """Vehicle ``vid`` left the simulation, or its parking ended."""
        self.dwell.pop(vid, None)
        self.due.pop(vid, None)
        self.polling.discard(vid)
        self.idling.discard(vid)
        self.space.pop(vid, None)
        self.resumed.discard(vid)
        self.waking.discard(vid)
        self.off.discard(vid)
        self.grade.pop(vid, None)
        self.at_once.discard(vid)

    def resume(self, ledger, vmap, vids, now: float) -> list:
        """Vehicles ``vids`` left SUMO's id list without leaving the simulation: those
        parked are out of their stop, which a script ended (``vehicle.resume``), and SUMO
        tries to put them back on the road from the next step, idling them in their space
        while the way is blocked — out of its id list until they are back on the road
        (probed with SUMO 1.28: getIDList leaves such a car out, its emission output books
        it idling). Their signals are read from now on. A bus dwelling in a bay leaves the
        list alike: read, dwelling there, until it is back on the road. Returns those
        parked or dwelling."""
        out = []
        for vid in vids:
            i = vmap.get(vid)
            if i is None:
                continue
            if not ledger.veh_parked[i]:
                if vid in self.dwell:  # a bus in a bay: dwelling there until back on the road
                    self.resumed.add(vid)
                    out.append(vid)
                continue
            if vid in self.off:  # switched off for its stop: off while it idles (SUMO 1.28
                continue           # writes 0), on a step after it is back on the road
            if vid in self.space:
                self.resumed.add(vid)
                self.due[vid] = now
                heapq.heappush(self.heap, (now, vid))
                out.append(vid)
        return out

    def with_resumed(self, ids):
        """SUMO's id list ``ids`` and the parked vehicles whose stop a script ended, which
        it leaves out (:meth:`resume`): those still in the simulation (one getter each; one
        a script removed is forgotten, and retired by the loop as removed)."""
        live, extra = set(ids), []
        for vid in list(self.resumed):
            if vid in live:
                continue
            if known_to_sumo(self.conn.vehicle.getStopState, vid):
                extra.append(vid)
            else:
                self.forget(vid)
        return (*ids, *extra) if extra else ids

    def tilt(self, kids, tilt, once=None):
        """``tilt`` ((n,) slopes [rad] over ``kids``, NaN where the lane's; None: none yet)
        with the slopes of the vehicles whose parking ended or began in this step (:attr:`once`;
        ``once``: others, vehicle id → slope [rad])."""
        for vid, g in (self.once if once is None else once).items():
            try:
                j = kids.index(vid)
            except ValueError:  # not read (a vType not booked)
                continue
            tilt = np.full(len(kids), np.nan) if tilt is None else tilt
            tilt[j] = g
        return tilt

    def at_rest(self, kids, values) -> None:
        """The state read of vehicles ``kids`` (``values``: arrays of speed, acceleration,
        angle, slope, or None; in place) for those idling out of SUMO's id list
        (:meth:`resume`), for which SUMO answers its "no value", −2³⁰: standing (speed and
        acceleration 0; its angle 0, its slope unknown: the lane's is booked)."""
        idx = [j for j, k in enumerate(kids) if k in self.resumed]
        for x, rest in zip(values, (0.0, 0.0, 0.0, np.nan)):
            if x is not None and idx:
                x[idx] = rest

    def summary(self) -> dict:
        return {"idle_starts": self.idle_starts, "idle_vehicle_s": self.idle_vehicle_s,
                "rule": "a parked vehicle whose parking is over but whose way back onto the road "
                        "is blocked idles in its space (SUMO: engine on, blinker on), booked standing "
                        "there until it leaves, unless switched off for its stop (shutOffStopDuration)"}
