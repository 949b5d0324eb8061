"""Which vehicles of an FCD replay have SUMO's taxi device, whose declared stops end when
the taxi is dispatched, not as planned (:mod:`sumo_drvpw.sim.fcd_stops`).

SUMO equips a vehicle with the device when the option ``device.taxi.explicit`` names it
(whatever its params say), else by its own param ``has.taxi.device`` (a flow's for its
vehicles), else its vType's, else by ``device.taxi.probability`` (> 0: which of them the FCD
cannot tell, so any may be one) (``MSDevice::equippedByDefaultAssignmentOptions``; probed
with SUMO 1.28: an explicit vehicle whose param or vType's param says false has the device). An idle taxi — no customer, the
default ``device.taxi.idle-algorithm`` stop — turns its next stop into a triggered one
(``MSIdling_Stop::idle``: ``triggered``, or ``containerTriggered`` for a vType carrying
containers) and waits there, parked, until it is dispatched: past the stop's planned end
it is still parked, not idling with its way out blocked (DLR's port_lübeck, SUMO 1.28: five
container taxis with a 10-s stop parked for up to 470 s). The replay takes such stops as
triggered by what it cannot see: their parked rows are booked parked and counted as untold
(:mod:`sumo_drvpw.sim.fcd_idle`). With ``idle-algorithm`` randomCircling the taxi drives
on and its stops end as planned. A taxi whose last rider leaves while it stands parked, with
no dispatch, stays at that stop as its idle one, one step on its lane between, booked once (the replay:
``fcd_conn._Rows._reparks``).
"""

from __future__ import annotations

from sumo_drvpw.sim.vtypes import is_true

#: the trigger a taxi's declared stop takes (fcd_stops ``_Stop.trigger``: not a person's)
DISPATCH = ("other", ())


class TaxiDevices:
    """The taxi devices of a replay's vehicles: params read from the route and additional
    files (:meth:`read`), the options from ``option`` (key → the run's SUMO option value or
    None)."""

    def __init__(self, option=None):
        opt = option or (lambda key: None)
        prob = opt("device.taxi.probability")
        try:
            some = prob is not None and float(prob) > 0
        except ValueError:
            some = False
        self.circling = (opt("device.taxi.idle-algorithm") or "").strip() == "randomCircling"
        self.all = some
        self.explicit = set((opt("device.taxi.explicit") or "").replace(",", " ").split())
        self.param: dict[str, bool] = {}  # vehicle, flow or vType id → its has.taxi.device
        #: vType id → its (boardingDuration, loadingDuration) as written [s] (:meth:`unloading_s`)
        self.durations: dict[str, tuple] = {}
        self.types: dict[str, str] = {}   # vehicle or flow id → its vType

    def read(self, el, tag: str) -> None:
        """A ``<vType>``, ``<vehicle>``, ``<trip>`` or ``<flow>`` element of the files."""
        key = el.get("id")
        if key is None:
            return
        if tag != "vType":
            self.types[key] = el.get("type", "DEFAULT_VEHTYPE")
        else:
            self.durations[key] = (el.get("boardingDuration"), el.get("loadingDuration"))
        val = next((p.get("value") for p in el if p.tag == "param" and p.get("key") == "has.taxi.device"), None)
        if val is not None:
            self.param[key] = is_true(val)

    def has(self, vid: str, declared_by: str) -> bool:
        """Whether vehicle ``vid`` (declared by the element ``declared_by``: itself or its
        flow) waits at its stops until dispatched."""
        if self.circling:
            return False
        if vid in self.explicit:
            return True
        given = self.param.get(declared_by, self.param.get(self.types.get(declared_by, "")))
        return given if given is not None else self.all

    def of(self, vid: str) -> bool:
        """Whether the replay's vehicle ``vid`` (a ``<vehicle>``/``<trip>`` of that id, else
        ``<flow id>.<n>``) has the device."""
        flow = vid.rpartition(".")[0]
        return self.has(vid, vid if vid in self.types or not flow else flow)

    def unloading_s(self, vtype: str, containers: bool) -> float:
        """How long a taxi of vType ``vtype`` stays at its stop after its last rider left it
        [s]: the vType's ``boardingDuration`` (persons; SUMO's default 0.5 s) or
        ``loadingDuration`` (containers; 90 s) — SUMO 1.28's taxi on its lane that many
        seconds after its person's or container's row left it (1-s and 0.5-s steps)."""
        val = self.durations.get(vtype, (None, None))[1 if containers else 0]
        try:
            return float(val) if val is not None else (90.0 if containers else 0.5)
        except ValueError:
            return 90.0 if containers else 0.5
