"""Vehicles a user's TraCI script removes between steps: retired by the Accountant without
SUMO or the TraCI client printing errors about them, also when the removal coincides with
a teleport's end. Real SUMO (libsumo in process, traci as a server process)."""

from __future__ import annotations

from pathlib import Path

import pytest

from sumo_drvpw.sim import Accountant, close_sumo, start_sumo
from sumo_drvpw.sim.scenario import load_scenario

pytestmark = pytest.mark.sumo

REPO = Path(__file__).resolve().parent.parent
CITY = REPO / "scenarios" / "city.toml"


@pytest.mark.parametrize("connection", ["libsumo", "traci"])
def test_a_removed_car_is_retired_without_error_lines(connection, capfd):
    """Before: through traci, each removed car cost 13 error lines — SUMO answered the six
    variables of the car's subscription with "Error: Answered with error to command 0xa4:
    Vehicle '…' is not known." (TraCIServer drops a vehicle's subscription only when it
    arrives in the step), the traci client printed "Error! Vehicle '…' is not known." for
    each, and the ledger's getTypeID probe added one more. The car is still retired at once."""
    conn = start_sumo(load_scenario(CITY, end=60).sumo_args, connection)
    try:
        acc = Accountant(conn, equations=["vsp_ldv1999"])
        for _ in range(30):
            conn.simulationStep()
            acc.step()
        ids = conn.vehicle.getIDList()
        conn.vehicle.remove(ids[0])
        for _ in range(3):
            conn.simulationStep()
            acc.step()
        assert acc.ledger.veh_done[acc.stepper.vmap[ids[0]]]
        still = [acc.stepper.vmap[v] for v in ids[1:] if v in conn.vehicle.getIDList()]
        assert still and not acc.ledger.veh_done[still].any()
        res = acc.result()
    finally:
        close_sumo(conn)
    out, err = capfd.readouterr()
    said = [x for x in (out + err).splitlines() if ids[0] in x or "rror" in x]
    assert not said, said
    assert ids[0] in set(res.vehicles.vehicle)


def _spanning_teleport(sc, options):
    """(vehicle, the time its teleport ends) of the first teleport that lasts more than a
    step in a run of ``sc`` with ``options``, or None."""
    conn = start_sumo(list(sc.sumo_args) + options)
    try:
        start = {}
        while conn.simulation.getTime() < sc.end - 1e-9:
            conn.simulationStep()
            t = conn.simulation.getTime()
            for v in conn.simulation.getStartingTeleportIDList():
                start[v] = t
            for v in conn.simulation.getEndingTeleportIDList():
                if start.get(v, t) < t:
                    return v, t
    finally:
        close_sumo(conn)
    return None


def test_a_removal_in_the_step_a_teleport_ends_is_seen():
    """A car removed between steps while another car's teleport ends in the next step: the
    id list loses one and gains one, so the counts the ledger compared (last step's ids −
    arrived + departed) balanced and the removed car's row was held as running to the end.
    The count now takes the vehicles back from a teleport."""
    sc = load_scenario(CITY, end=300)
    options = ["--time-to-teleport", "3", "--no-warnings", "true"]
    found = _spanning_teleport(sc, options)
    assert found is not None, "no teleport lasting more than a step: the scenario changed?"
    back, t_end = found
    conn = start_sumo(list(sc.sumo_args) + options)
    try:
        acc = Accountant(conn, equations=["vsp_ldv1999"])
        dt = conn.simulation.getDeltaT()
        while conn.simulation.getTime() < t_end - dt - 1e-9:
            conn.simulationStep()
            acc.step()
        ids = conn.vehicle.getIDList()
        assert back not in ids          # teleporting now
        gone = ids[-1]
        conn.vehicle.remove(gone)
        conn.simulationStep()
        assert back in conn.simulation.getEndingTeleportIDList()   # ends in this step
        acc.step()
        assert acc.ledger.veh_done[acc.stepper.vmap[gone]]
        assert not acc.ledger.veh_done[acc.stepper.vmap[back]]
    finally:
        close_sumo(conn)


def test_a_script_dropping_the_context_subscription_is_warned():
    """Through traci the plug-in reads every vehicle from one context subscription on the
    simulation. A script that unsubscribes the simulation's context drops it: every vehicle
    is then read by getters, correct but a call each; the run now says so instead of only
    slowing down. (A script's own subscribeContext with a small range, tried too, left every
    vehicle in the results: SUMO keeps the larger.)"""
    conn = start_sumo(load_scenario(CITY, end=200).sumo_args, "traci")
    try:
        acc = Accountant(conn, equations=["vsp_ldv1999"])
        for _ in range(20):
            conn.simulationStep()
            acc.step()
        assert acc.stepper.reader.subscribed and acc.stepper.reader.fallback_reads == 0
        conn.simulation.subscribeContext("", 0xa4, 1.0, [0x40])  # the script's own, 1 m around ""
        for _ in range(50):
            conn.simulationStep()
            acc.step()
        assert acc.stepper.reader.fallback_reads == 0
        conn.simulation.unsubscribeContext("", 0xa4, 1.0)
        for _ in range(100):
            conn.simulationStep()
            acc.step()
        res = acc.result()
    finally:
        close_sumo(conn)
    assert acc.stepper.reader.fallback_reads > 100
    assert any("missing from the plug-in's traci context subscription" in w for w in res.summary["warnings"])
