"""The streamed compare (fit/stream_compare.py) carries a chain's per-trip state through each
trip of a batch: a plug-in hybrid starts every trip charged and its sustaining hybrid's battery
window empty, whatever other trips share its batch or however many chunks the trip was read in."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.data.measured import load_measured
from sumo_drvpw.data.stream import Part, iter_measured
from sumo_drvpw.fit.stream_compare import CompareStats
from sumo_drvpw.model.chain import EnergyChain
from sumo_drvpw.model.equations import equation_from_dict

#: a plug-in hybrid whose battery one trip spends about half of (each trip alone never runs dry)
CHAIN = {"predicts": "fuel", "fuel": "gasoline", "marginal_efficiency": 0.4, "idle_fuel_power_w": 5000.0,
         "engine_off_below_w": 8000.0, "charge_sustaining": True, "aux_power_w": 500.0,
         "recuperation_round_trip": 0.64, "recuperation_limit_w": 30000.0, "battery_usable_j": 50e3,
         "depleting": {"usable_j": 1.0e6, "traction_efficiency": 0.85, "recuperation_efficiency": 0.6}}
#: rows of the trips; read in chunks of ROWS: T1 and T2 share the first batch, T3 is read in two
#: chunks and shares the second batch with T4, T5 is the third
LENGTHS = {"T1": 100, "T2": 100, "T3": 300, "T4": 100, "T5": 100}
ROWS = 250


def _log(path) -> None:
    """1-Hz trips: speed v̄ + 0.6·v̄·sin(t/15 s) m/s (a braking every 90 s; v̄ 14 m/s, the long T3
    9 m/s), 1500 kg; the fuel flow of a conventional engine on it (the measured side, not what is
    checked)."""
    frames = []
    for k, (trip, n) in enumerate(LENGTHS.items()):
        t = np.arange(n, dtype=float)
        vm = 9.0 if trip == "T3" else 14.0
        v = vm * (1.0 + 0.6 * np.sin(t / 15.0 + k))
        frames.append(pd.DataFrame({"trip_id": trip, "time_s": t, "speed_mps": v, "mass_kg": 1500.0,
                                    "fuel_flow_rate_hour_lph": 3.0 + 0.2 * v}))
    pd.concat(frames, ignore_index=True).to_csv(path, index=False)


def test_each_trip_of_a_batch_starts_with_its_own_charged_battery(tmp_path):
    log = tmp_path / "phev.csv"
    _log(log)
    eq = equation_from_dict({"equation": {"name": "phev"}, "terms": {"acc": 1.0, "roll": 0.009, "aero_rho": 0.62},
                             "chain": CHAIN})
    stats = CompareStats([eq], target="fuel")
    batches = []
    for m in iter_measured(Part(str(log)), rows=ROWS, target="fuel"):
        batches.append(list(dict.fromkeys(m.log.df["trip_id"].astype(str))))
        stats.add(m)
    assert batches == [["T1", "T2"], ["T3", "T4"], ["T5"]]   # several trips a batch; T3 over two chunks
    got = {t: e[3] for t, e in stats.eq["phev"].trip_e.items()}   # each trip's predicted net fuel energy [J]
    # each trip alone, one series from a charged battery, on the samples compare uses
    m = load_measured([log], target="fuel")
    trips = m.log.df["trip_id"].astype(str).to_numpy()
    dt = m.log.df["dt_s"].to_numpy(float)
    ch: EnergyChain = eq.chain
    for t in LENGTHS:
        idx = np.flatnonzero((trips == t) & m.usable)
        x = m.inputs.take(idx)
        alone = ch.evaluate(eq.power(x), x.v, dt[idx])
        assert alone["spent_j"][-1] < ch.depleting.usable_j   # alone, a trip never runs its battery dry
        assert got[t] == pytest.approx(float(alone["power_w"] @ dt[idx]), rel=1e-9, abs=1.0)
    # carried from one trip into the next of its batch, T2 and T4 would start half spent and run dry
    for first, second in (("T1", "T2"), ("T3", "T4")):
        idx = np.flatnonzero(np.isin(trips, [first, second]) & m.usable)
        x = m.inputs.take(idx)
        run_on = ch.evaluate(eq.power(x), x.v, dt[idx])
        on_second = trips[idx] == second
        assert float(run_on["power_w"][on_second] @ dt[idx][on_second]) > got[second] + 1e5
