"""An FCD replay books a car whose parking is over but whose way back onto the road is
blocked as the live run books it (tests/test_parking_exit_blocked.py, sim/parking.py):
SUMO keeps it idling in its space and its emission output writes every such step at speed
0. SUMO's FCD writes it as it writes a parked car (beside the lane, speed 0); the replay
tells its idling rows from the route files' declared stop — parked from the step SUMO
ends it, by its planned end or, waiting for a person, her boarding (sim/fcd_idle.py) — or
from the FCD's blinker bits when it has them (``--fcd-output.signals``)."""

from __future__ import annotations

import pandas as pd
import pytest

from sumo_drvpw.sim import run_scenario
from sumo_drvpw.sim.fcd import process_fcd
from sumo_probe import build_net, energy_scenario
from test_parking_exit_blocked import ROUTES, sumo_electricity


def recorded(d, step=0.5, params="", stop='<stop parkingArea="pa" duration="20"/>', signals=False, extra=""):
    """The blocked-exit scenario of tests/test_parking_exit_blocked.py (the parked car's
    ``stop``, ``extra`` elements added to the routes) run live with SUMO's emission output
    and FCD at 6 decimals: (scenario, live chain_vehicles by key, SUMO's electricity per
    vehicle [Wh], the step each car parks in included: test_parking_exit_blocked.sumo_electricity)."""
    build_net(d, '<nodes><node id="a" x="0" y="0"/><node id="b" x="600" y="0"/></nodes>',
              '<edges><edge id="e" from="a" to="b" numLanes="1" speed="15"/></edges>')
    (d / "r.rou.xml").write_text(ROUTES.format(params=params).replace(
        '<stop parkingArea="pa" duration="20"/>', stop).replace("</routes>", extra + "</routes>"), encoding="utf-8")
    (d / "a.add.xml").write_text('<additional><parkingArea id="pa" lane="e_0" startPos="300" endPos="330" '
                                 'roadsideCapacity="2"/></additional>', encoding="utf-8")
    sc = energy_scenario(d, 300, step_length=step, additional="a.add.xml", fcd=True)
    if signals:
        sc.write_text(sc.read_text(encoding="utf-8").replace('"--fcd-output",', '"--fcd-output.signals", "true", "--fcd-output",'), encoding="utf-8")
    run_scenario(sc, d / "live")
    return sc, _chain(d / "live"), sumo_electricity(sc, d, dt=step)[0]


def _chain(out):
    return pd.read_csv(out / "chain_vehicles.csv").set_index("key")["net_kwh"].sort_index() * 1000.0


@pytest.mark.parametrize("step,stop,signals", [
    (0.5, '<stop parkingArea="pa" duration="20"/>', False),
    (0.5, '<stop parkingArea="pa" until="42.3"/>', False),
    (1.0, '<stop parkingArea="pa" duration="10" until="45"/>', False)])
def test_a_replay_books_a_car_blocked_in_its_parking_space_as_the_live_run(tmp_path, step, stop, signals):
    """The car parked 20 s (or until 42.3 s, between two steps; 10 s but until 45 s) is held
    ~160 s (at 1 s: ~9 s) by the queue behind a car standing near the lane's end; SUMO's
    emission output books it 100 W every idling step. The FCD has no signals: the declared
    stops tell the idling rows. Measured 2026-11-27 before the fix (step 0.5 s,
    duration 20): the replay booked 49.52 Wh against the live run's and SUMO's 53.91. Now
    every car as the live run to 1e-6, in memory, streamed in blocks of 31 rows (timesteps
    cut), and the idling rows counted."""
    sc, live, sumo = recorded(tmp_path, step, stop=stop, signals=signals)
    assert live["p"] == pytest.approx(sumo["p"], rel=1e-6)
    idle_s = 8.0 if step == 1.0 else 150.0  # booked idling at least (the row it leaves in aside)
    for rows in (None, 31):
        out = tmp_path / f"r{rows}"
        res = process_fcd(tmp_path / "fcd.xml", scenario=sc, out_dir=out, chunk_rows=rows)
        got = _chain(out)
        pd.testing.assert_series_equal(got, live, rtol=1e-6)
        assert res["source"]["idling_rows"] * step >= idle_s
        assert res["source"]["untold_parked_rows"] == 0  # the declared stops tell every row


def test_a_replay_leaves_a_car_switched_off_for_its_parking_out_while_blocked(tmp_path):
    """With ``shutOffStopDuration`` 5 s the 20-s parking switches the car off, and SUMO
    1.28 writes its idling steps at 0: the replay books none of them, as the live run."""
    sc, live, _ = recorded(tmp_path, params='<param key="shutOffStopDuration" value="5"/>')
    res = process_fcd(tmp_path / "fcd.xml", scenario=sc, out_dir=tmp_path / "r")
    pd.testing.assert_series_equal(_chain(tmp_path / "r"), live, rtol=1e-6)
    assert res["source"]["idling_rows"] == 0 and res["source"]["parked_rows"] > 300


#: a person who starts beside the parked car at 60 s and rides in it (its stop waits for her)
RIDER = '<person id="x" depart="60" departPos="316"><ride from="e" to="e" lines="p" arrivalPos="590"/></person>'


def test_a_triggered_parking_idles_from_the_step_its_person_boards(tmp_path):
    """A stop that waits for a person (``triggered``) ends when she boards, and SUMO 1.28
    keeps the car idling from that step while its way out is blocked (here from 60 s, its
    20 s long over). The FCD writes a riding person at her car's x, y and speed: the replay
    tells the boarding from those rows, and books the car as the live run to 1e-6 without
    the FCD's signals as with them. A container trigger (the recording's route file
    replaced, same FCD: the files alone decide) the FCD does not tell: its parked rows stay
    parked without signals — each 0.5 s of 100 W left out — and the blinker tells them."""
    stop = '<stop parkingArea="pa" duration="20" triggered="person"/>'
    sc, live, sumo = recorded(tmp_path, stop=stop, signals=True, extra=RIDER)
    assert live["p"] == pytest.approx(sumo["p"], rel=1e-6)
    import re
    text = (tmp_path / "fcd.xml").read_text(encoding="utf-8")
    (tmp_path / "nosig.xml").write_text(re.sub(r' signals="[^"]*"', "", text), encoding="utf-8")
    rows = {}
    for f in ("fcd.xml", "nosig.xml"):
        res = process_fcd(tmp_path / f, scenario=sc, out_dir=tmp_path / f"o_{f}", chunk_rows=31)
        pd.testing.assert_series_equal(_chain(tmp_path / f"o_{f}"), live, rtol=1e-6)
        rows[f] = res["source"]["idling_rows"]
        assert res["source"]["untold_parked_rows"] == 0  # the boarding tells them
    assert rows["fcd.xml"] == rows["nosig.xml"] > 250  # ~139 s from 60 s on
    rou = tmp_path / "r.rou.xml"
    rou.write_text(rou.read_text(encoding="utf-8").replace('triggered="person"', 'triggered="container"'), encoding="utf-8")
    res = process_fcd(tmp_path / "fcd.xml", scenario=sc, out_dir=tmp_path / "c_sig")
    pd.testing.assert_series_equal(_chain(tmp_path / "c_sig"), live, rtol=1e-6)
    assert res["source"]["untold_parked_rows"] == 0
    assert not [w for w in res["warnings"] if "parked FCD rows" in w]
    res = process_fcd(tmp_path / "nosig.xml", scenario=sc, out_dir=tmp_path / "c_nosig")
    got = _chain(tmp_path / "c_nosig")
    assert res["source"]["idling_rows"] == 0
    # its parked rows, none told, are counted and warned of (a PRT replay was silent)
    untold = res["source"]["untold_parked_rows"]
    assert untold >= rows["fcd.xml"] and res["source"]["untold_parked_vehicles"] == 1
    assert [w for w in res["warnings"] if f"{untold} parked FCD rows of 1 vehicle(s)" in w
            and "fcd-output.signals" in w]
    assert live["p"] - got["p"] == pytest.approx(rows["fcd.xml"] * 0.5 * 100.0 / 3600.0, rel=1e-6)
    pd.testing.assert_series_equal(got.drop("p"), live.drop("p"), rtol=1e-6)


def test_a_replay_on_dask_books_the_idling_as_the_serial_replay(tmp_path):
    """fcd --engine dask: the buckets' replays tell the idling rows as the serial one; the
    energies and ``source.idling_rows`` agree."""
    pytest.importorskip("distributed")
    from sumo_drvpw.sim.fcd_dask import process_fcd_dask

    sc, live, _ = recorded(tmp_path)
    serial = process_fcd(tmp_path / "fcd.xml", scenario=sc, out_dir=tmp_path / "o")
    res = process_fcd_dask(tmp_path / "fcd.xml", tmp_path / "od", scenario=sc, buckets=3, workers=1,
                           chunk_rows=50)
    pd.testing.assert_series_equal(_chain(tmp_path / "od"), live, rtol=1e-6)
    assert res["source"]["idling_rows"] == serial["source"]["idling_rows"] > 300
    assert res["source"]["parked_rows"] == serial["source"]["parked_rows"]
    assert res["source"]["untold_parked_rows"] == serial["source"]["untold_parked_rows"] == 0
    # the same FCD with the stop gone from the route files: no row of the parked car is told
    # (a stop added by a device or a script); the buckets count them as the serial replay
    rou = tmp_path / "r.rou.xml"
    rou.write_text(rou.read_text(encoding="utf-8").replace('<stop parkingArea="pa" duration="20"/>', ""), encoding="utf-8")
    serial = process_fcd(tmp_path / "fcd.xml", scenario=sc, out_dir=tmp_path / "o2")
    res = process_fcd_dask(tmp_path / "fcd.xml", tmp_path / "od2", scenario=sc, buckets=3, workers=1,
                           chunk_rows=50)
    assert res["source"]["untold_parked_rows"] == serial["source"]["untold_parked_rows"] > 300
    assert res["source"]["untold_parked_vehicles"] == serial["source"]["untold_parked_vehicles"] == 1
    assert [w for w in res["warnings"] if "parked FCD rows of 1 vehicle(s)" in w]
