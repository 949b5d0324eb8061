"""Streamed reading says where its inputs came from as the in-memory reader does, whatever
batch or file comes first: the acceleration's source over logs that differ (one with
``accel_mps2``, one without), and the fuel-flow column chosen once per file, not per batch.

Batches are made small (``rows``) so every file is read in several, and the files are named
so that either kind of log comes first.
"""

from functools import partial

import numpy as np
import pandas as pd
import pytest

import corpus
from sumo_drvpw.data.measured import load_measured, resolve_equations
from sumo_drvpw.fit.engine import run
from sumo_drvpw.fit.stream import CalibrationStats
from sumo_drvpw.fit.stream_compare import CompareStats
from sumo_drvpw.model.equations import load_equation

ROWS = 700  # rows per streamed batch: each file below takes several
ACCEL_KEYS = ("accel_source", "accel_derived_rows", "accel_window_s", "accel_derivation")


def _drive(trip, hz, n_s=150.0, seed=0, kmh_steps=False):
    """A trip of smooth stop-and-go driving at ``hz``, its wheel power from a road load
    (so every sample is usable); the speed in whole km/h when ``kmh_steps``."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, n_s, 1.0 / hz)
    v = 12.0 + 6.0 * np.sin(2 * np.pi * t / 40.0 + rng.uniform(0, 6)) + 2.0 * np.sin(2 * np.pi * t / 7.0)
    if kmh_steps:
        v = np.round(v * 3.6) / 3.6
    a = np.gradient(v, t)
    p = 1500.0 * v * a + 150.0 * v + 0.4 * v ** 3
    return pd.DataFrame({"trip_id": trip, "time_s": t, "speed_mps": v, "power_w": p, "mass_kg": 1500.0,
                         "_a": a})


def _accel_logs(d, column_first: bool):
    """Three files: one whose trips carry accel_mps2, two without it (one of them logged in
    whole km/h, so its window is widened); ``column_first``: the file with the column sorts
    first."""
    d.mkdir()
    with_col = pd.concat([_drive("A1", 10.0, seed=1), _drive("A2", 10.0, seed=2)], ignore_index=True)
    with_col = with_col.rename(columns={"_a": "accel_mps2"})
    fine = pd.concat([_drive("B1", 10.0, seed=3), _drive("B2", 5.0, seed=4, kmh_steps=True)], ignore_index=True)
    slow = _drive("C1", 1.0, n_s=900.0, seed=5)
    first, last = ("a", "z") if column_first else ("z", "a")
    with_col.to_csv(d / f"{first}_column.csv", index=False)
    fine.drop(columns="_a").to_parquet(d / f"{last}_derived.parquet", row_group_size=300)
    slow.drop(columns="_a").to_csv(d / "m_derived.csv", index=False)
    return d


@pytest.mark.parametrize("column_first", [True, False])
def test_acceleration_source_of_logs_that_differ_is_the_in_memory_one(tmp_path, column_first):
    """Found by review: the streamed paths kept the first batch's acceleration source, so a
    folder with one logger writing accel_mps2 and another not was reported as all 'accel_mps2
    column' (or all derived), without the rows derived. Now every streamed path — calibrate,
    compare, diagnose — reports what the in-memory reader reports for the same logs."""
    from sumo_drvpw.fit.diagnose.stream_run import diagnose_stream

    d = _accel_logs(tmp_path / "logs", column_first)
    m = load_measured([d])
    ref = {k: m.counts[k] for k in ACCEL_KEYS if k in m.counts}
    # the reference says both sources and the rows each has
    assert ref["accel_source"].startswith("accel_mps2 column; derived: central difference of speed")
    n_derived = int((~m.log.df["trip_id"].isin(["A1", "A2"])).sum())
    assert ref["accel_derived_rows"] == n_derived
    assert ref["accel_derivation"]["column_rows"] == len(m.log.df) - n_derived
    assert "widened from 0.5 s on 1 of 3 trips" in ref["accel_source"]

    eqs = resolve_equations(["vsp_ldv1999"])
    cs, _ = run([d], partial(CompareStats, eqs, None), None, rows=ROWS)
    st, _ = run([d], partial(CalibrationStats, ("acc", "roll", "aero")), None, rows=ROWS)
    res = diagnose_stream([d], None, load_equation("vsp_ldv1999"), rows=ROWS, sample_rows=ROWS)
    for got in (cs.counts, st.counts, res.details["reader_counts"]):
        corpus.assert_close_documents(ref, {k: got[k] for k in ACCEL_KEYS if k in got}, 1e-12)
    # and the numbers: every sample's acceleration as the in-memory reader's (the comparison)
    from sumo_drvpw.fit.compare import compare

    u = m.usable
    mem = compare(m.power_w[u], m.inputs.take(u), eqs, dt_s=m.log.df["dt_s"].to_numpy()[u],
                  trip=m.inputs.trip[u]).to_json()
    corpus.assert_close_documents(mem, cs.comparison().to_json(), 1e-9, same_keys=False)


def test_a_trip_with_the_column_keeps_the_least_window_read_with_trips_without(tmp_path):
    """The window of the smoothed derivative (shaft accelerations of a power-split log) of a
    trip that has accel_mps2 is the least one whether or not a file without the column is
    read with it (in memory it took the window its speed would need if derived)."""
    from sumo_drvpw.data.log import read_log

    d = tmp_path / "logs"
    d.mkdir()
    col = _drive("A", 5.0, seed=7, kmh_steps=True).rename(columns={"_a": "accel_mps2"})
    col.to_csv(d / "a.csv", index=False)
    _drive("B", 10.0, seed=8).drop(columns="_a").to_csv(d / "b.csv", index=False)
    both, alone = read_log(d), read_log(d / "a.csv")
    y = both.df["speed_mps"].to_numpy()
    a_rows = (both.df["trip_id"] == "A").to_numpy()
    np.testing.assert_allclose(both.derivative(y)[a_rows], alone.derivative(alone.df["speed_mps"].to_numpy()),
                               rtol=0, atol=1e-12)


# ------------------------------------------------------- the fuel flow, once per file

def _fuel_log(d, empty_trip: str | None):
    """The planted fuel log of test_stream_chain (five trips, a hybrid battery's V·I) with a
    second fuel flow, fuel_rate_lph, logged 25 % high (another sensor), and the preferred
    fuel_rate_gps empty over the whole trip ``empty_trip`` (a stretch of a batch or more)."""
    from test_stream_chain import _fuel_frame

    from sumo_drvpw.model.constants import FUELS

    df = _fuel_frame()
    df["fuel_rate_lph"] = 1.25 * df["fuel_rate_gps"] / 1000.0 * 3600.0 / FUELS["gasoline"]["density_kg_per_l"]
    if empty_trip:
        df.loc[df["trip_id"] == empty_trip, "fuel_rate_gps"] = np.nan
    d.mkdir()
    df.to_parquet(d / "fuel.parquet", row_group_size=500)
    return d / "fuel.parquet", df


@pytest.mark.parametrize("empty_trip", ["F0", "F2"])
def test_a_batch_without_the_chosen_fuel_flow_is_missing_samples_not_another_flow(tmp_path, empty_trip):
    """Found by review: the streamed paths chose the fuel-flow column per batch, so a batch in
    which fuel_rate_gps was empty (a trip, or any stretch of whole trips) took fuel_rate_lph —
    another sensor, here 25 % high — for that batch only, and the first batch's choice named
    the source. In memory the whole file chooses fuel_rate_gps and that trip's samples are left
    out (counted as non-finite power). The streamed compare and diagnose now choose once per
    file: the same comparison, source and counts."""
    from test_stream_chain import FUEL_EQ, _eq

    from sumo_drvpw.fit.compare import compare
    from sumo_drvpw.fit.diagnose.stream_run import diagnose_stream
    from sumo_drvpw.fit.trip_energy import left_out_by_trip

    path, df = _fuel_log(tmp_path / "logs", empty_trip)
    eqs = [_eq(FUEL_EQ)]
    m = load_measured([path], target="fuel")
    u = m.usable
    n_empty = int((df["trip_id"] == empty_trip).sum())
    assert m.source.startswith("fuel flow fuel_rate_gps") and m.counts["excluded_nonfinite_power"] == n_empty
    comp = compare(m.power_w[u], m.inputs.take(u), eqs, dt_s=m.log.df["dt_s"].to_numpy()[u],
                   target="fuel", battery_w=m.battery_w[u])
    comp.left_out = left_out_by_trip(m.power_w, u, m.log.df["dt_s"].to_numpy(), m.inputs.trip)
    ref = comp.to_json()
    assert empty_trip not in ref["equations"]["hev"]["trip_energy"]["trips"]
    cs, _ = run([path], partial(CompareStats, eqs, None, target="fuel"), rows=ROWS)
    assert cs.source == m.source
    assert cs.counts["excluded_nonfinite_power"] == n_empty and cs.counts["usable"] == m.counts["usable"]
    got = cs.comparison().to_json()
    got["settings"].pop("percentiles")
    corpus.assert_close_documents(ref, got, 1e-9)
    res = diagnose_stream([path], None, eqs[0], target="fuel", rows=ROWS, sample_rows=8 * ROWS)
    assert res.details["reader_counts"]["excluded_nonfinite_power"] == n_empty
    assert res.details["reader_counts"]["power_source"] == m.source


def test_a_file_whose_flow_is_empty_throughout_is_still_refused_streamed(tmp_path):
    """The choice by the whole file changes nothing for a file that has no fuel flow at all:
    refused as in memory, naming the columns it needs."""
    from sumo_drvpw.errors import UserError

    path, df = _fuel_log(tmp_path / "logs", None)
    df.drop(columns=["fuel_rate_lph"]).assign(fuel_rate_gps=np.nan).to_parquet(path)
    with pytest.raises(UserError, match="needs a fuel-flow column"):
        load_measured([path], target="fuel")
    with pytest.raises(UserError, match="needs a fuel-flow column"):
        run([path], partial(CompareStats, resolve_equations(["epa_gasoline_car"]), None, target="fuel"), rows=ROWS)
