"""Energy per trip (issue #11 §5): traction and net energy, predicted against measured."""

import json

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from sumo_drvpw.fit.compare import compare, trip_energy, trip_net_energy
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.model.terms import Inputs


def test_hand_computed_two_trips():
    # trip a: meas 10,-5,20 W over 0.5 s -> traction 15 J; pred 12,-1,18 -> 15 J
    # trip b: meas 4,4 W over 1 s -> 8 J; pred 6,2 -> 8 J traction, error 0; net same
    meas = np.array([10.0, -5.0, 20.0, 4.0, 4.0])
    pred = np.array([12.0, -1.0, 18.0, 6.0, 2.0])
    dt = np.array([0.5, 0.5, 0.5, 1.0, 1.0])
    trip = np.array(["a", "a", "a", "b", "b"])
    out = trip_energy(pred, meas, dt, trip)
    assert list(out["trips"]) == ["a", "b"]
    assert out["trips"]["a"]["measured_j"] == pytest.approx(15.0)
    assert out["trips"]["a"]["predicted_j"] == pytest.approx(15.0)
    assert out["trips"]["b"]["error"] == pytest.approx(0.0)
    net = trip_net_energy(pred, meas, dt, trip)
    assert net["trips"]["a"]["measured_j"] == pytest.approx(12.5)   # (10-5+20)*0.5
    assert net["trips"]["a"]["predicted_j"] == pytest.approx(14.5)  # (12-1+18)*0.5
    assert net["trips"]["a"]["error"] == pytest.approx(14.5 / 12.5 - 1.0)
    assert net["max_abs_error"] == pytest.approx(14.5 / 12.5 - 1.0)
    assert net["mean_abs_error"] == pytest.approx((14.5 / 12.5 - 1.0) / 2)


def test_no_traction_trip_is_nan_and_left_out_of_summary():
    meas = np.array([-1.0, -2.0, 5.0])
    pred = np.array([1.0, -2.0, 10.0])
    out = trip_energy(pred, meas, 1.0, ["x", "x", "y"])
    assert np.isnan(out["trips"]["x"]["error"])
    assert out["mean_abs_error"] == pytest.approx(1.0)


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.floats(-5e4, 5e4), st.floats(-5e4, 5e4), st.integers(0, 3)),
                min_size=1, max_size=60))
def test_per_trip_energies_add_up_to_the_whole(rows):
    pred, meas, trip = (np.array(c) for c in zip(*rows))
    dt = 0.125
    out = trip_energy(pred, meas, dt, trip)
    tot_meas = sum(t["measured_j"] for t in out["trips"].values())
    assert tot_meas == pytest.approx(float(np.maximum(meas, 0).sum() * dt), abs=1e-6)
    net = trip_net_energy(pred, meas, dt, trip)
    assert sum(t["predicted_j"] for t in net["trips"].values()) == pytest.approx(
        float(pred.sum() * dt), abs=1e-6)


def test_report_json_carries_trip_energy_only_when_trips_known():
    n = 40
    v = np.linspace(5.0, 25.0, n)
    x = Inputs(v=v, a=np.zeros(n), theta=np.zeros(n), wind=np.zeros(n),
               mass=np.full(n, 1500.0), rho=np.full(n, 1.2))
    eq = Equation(name="aero_only", terms={"aero": 0.3})
    meas = 0.5 * 1.2 * 0.3 * v ** 3
    trip = np.repeat(["t1", "t2"], n // 2)
    doc = compare(meas, x, [eq], dt_s=0.5, trip=trip).to_json()
    te = doc["equations"]["aero_only"]["trip_energy"]
    assert set(te["trips"]) == {"t1", "t2"}
    assert te["max_abs_error"] >= 0.0
    assert "trip_net_energy" in doc["equations"]["aero_only"]
    json.dumps(doc)
    assert "trip_energy" not in compare(meas, x, [eq], dt_s=0.5).to_json()["equations"]["aero_only"]
    x.trip = trip  # the inputs carry the trips: used by default
    assert "trip_energy" in compare(meas, x, [eq], dt_s=0.5).to_json()["equations"]["aero_only"]


# ------------------------------------------------- trips that lost samples (left out)

def test_left_out_shares_by_trip_hand_computed():
    from sumo_drvpw.fit.trip_energy import left_out_by_trip, with_left_out

    # trip a: 4 samples of 1 s, P = 10, 10, 20, -5 W; the 20-W one is left out
    #   -> 1/4 of samples and time, 20/40 of traction energy, 20/35 of net energy
    # trip b: 2 samples of 2 s, the one left out has no measured power (NaN)
    meas = np.array([10.0, 10.0, 20.0, -5.0, 8.0, np.nan])
    used = np.array([True, True, False, True, True, False])
    dt = np.array([1.0, 1.0, 1.0, 1.0, 2.0, 2.0])
    left = left_out_by_trip(meas, used, dt, np.array(["a"] * 4 + ["b"] * 2))
    a, b = left["a"], left["b"]
    assert (a["samples"], a["left_out_samples"]) == (4, 1)
    assert a["left_out_time_share"] == pytest.approx(0.25)
    assert a["left_out_energy_share"] == pytest.approx(0.5)
    assert a["left_out_net_energy_share"] == pytest.approx(20.0 / 35.0)
    assert b["left_out_time_share"] == pytest.approx(0.5)
    assert b["left_out_energy_share"] == pytest.approx(0.0)  # known power: none left out
    assert b["left_out_power_unknown_samples"] == 1
    doc = trip_energy(meas[used], meas[used], dt[used], np.array(["a"] * 3 + ["b"]))
    out = with_left_out(doc, left)
    # a: 50 % of its energy; b: 50 % of its time with no measured power, energy unknown
    assert out["partial_trips"] == ["a", "b"]
    assert b["left_out_power_unknown_time_share"] == pytest.approx(0.5)
    assert out["trips"]["a"]["measured_j"] == pytest.approx(20.0)  # still the used samples (10 + 10)


def test_left_out_time_without_energy_is_not_partial():
    """Standstill left out (a tracer's minimum speed): time, but no measured energy lost."""
    from sumo_drvpw.fit.trip_energy import left_out_by_trip, with_left_out

    meas = np.array([0.0, 0.0, 0.0, 5000.0, 6000.0])  # 3 s standing, power measured: 0 W
    used = np.array([False, False, False, True, True])
    left = left_out_by_trip(meas, used, 1.0, None)
    assert left["0"]["left_out_time_share"] == pytest.approx(0.6)
    doc = with_left_out(trip_energy(meas[used], meas[used], 1.0, None), left)
    assert doc["partial_trips"] == [] and doc["trips"]["0"]["partial"] is False


def _log_with_a_gap(tmp_path):
    """Two 200-s trips at 1 Hz with logged power; trip a has 60 s flagged (brake),
    which the reader leaves out: 30 % of its time and (constant power) of its energy."""
    import pandas as pd

    rows = []
    for trip in ("a", "b"):
        t = np.arange(200.0)
        v = 10.0 + 5.0 * np.sin(t / 15.0)
        brake = (t >= 50) & (t < 110) if trip == "a" else np.zeros(200, bool)
        rows.append(pd.DataFrame({"trip_id": trip, "time_s": t, "speed_mps": v,
                                  "power_w": 8000.0 + 300.0 * v, "mass_kg": 1500.0, "brake": brake}))
    f = tmp_path / "gap.csv"
    pd.concat(rows).to_csv(f, index=False)
    return f


@pytest.mark.parametrize("engine", ["local", "memory"])
def test_compare_report_flags_a_trip_that_lost_samples(tmp_path, engine):
    from sumo_drvpw.cli import main as cli_main

    f = _log_with_a_gap(tmp_path)
    out = tmp_path / "cmp"
    assert cli_main(["compare", str(f), "--equation", "drvpw_prius3", "--engine", engine,
                     "--out", str(out)]) == 0
    doc = json.loads((out / "report.json").read_text())
    for key in ("trip_energy", "trip_net_energy"):
        te = doc["equations"]["drvpw_prius3"][key]
        a, b = te["trips"]["a"], te["trips"]["b"]
        assert a["left_out_samples"] == 60 and b["left_out_samples"] == 0
        assert a["left_out_time_share"] == pytest.approx(0.3, abs=0.01)
        assert 0.2 < a["left_out_energy_share"] < 0.4
        assert (a["partial"], b["partial"]) == (True, False)
        assert te["partial_trips"] == ["a"]
        assert {"measured_j", "predicted_j", "error"} <= set(a)  # the old keys stay
    md = (out / "report.md").read_text()
    assert "**Partial trips**" in md and "a (30 % of time" in md


@pytest.mark.parametrize("stream", ["no", "yes"])
def test_diagnose_trace_flags_a_trip_that_lost_samples(tmp_path, stream):
    from sumo_drvpw.cli import main as cli_main

    f = _log_with_a_gap(tmp_path)
    out = tmp_path / "dg"
    assert cli_main(["diagnose", str(f), "--stream", stream, "--out", str(out)]) == 0
    doc = json.loads((out / "trace.json").read_text())
    for key in ("baseline", "final"):
        te = doc[key]["trip_energy"]
        assert te["partial_trips"] == ["a"]
        assert te["trips"]["a"]["left_out_time_share"] == pytest.approx(0.3, abs=0.01)
    rows = [ln for ln in (out / "trace.md").read_text().splitlines() if ln.startswith("| a |")]
    assert rows and "partial: 30 % of time" in rows[0]


def test_chain_trace_flags_a_trip_that_lost_samples(tmp_path):
    """diagnose --target battery: the per-trip net energies of trace.json carry each trip's
    left-out shares and the partial flag, and trace.md's per-trip table says it (a 'left
    out' column and the Partial trips line), as the driving-power trace and compare do. A
    planted battery log whose trip T0 has 30 % of its samples flagged brake (left out)."""
    from sumo_drvpw.cli import main as cli_main
    from sumo_drvpw.model.equations import Equation, load_equation, save_equation
    from sumo_drvpw.synth.effects import BatteryLog, synth_trips
    from sumo_drvpw.synth.track import Noise

    b = BatteryLog(standstill_aux_w=0.0, noise_w=100.0)
    df, _ = synth_trips(n_trips=4, minutes=8.0, seed=5, effects=(b,), noise=Noise(process_w=50.0, process_rel=0.002))
    first = df["trip_id"].iloc[0]
    rows = np.flatnonzero((df["trip_id"] == first).to_numpy())
    df["brake"] = False
    df.loc[df.index[rows[int(0.4 * len(rows)):int(0.7 * len(rows))]], "brake"] = True
    log = tmp_path / "log.parquet"
    df.to_parquet(log)
    truth = load_equation("drvpw_prius3")
    decl = tmp_path / "declared.toml"
    save_equation(Equation("declared", dict(truth.terms), truth.mass_kg, chain=b.chain()), decl)
    out = tmp_path / "trace"
    assert cli_main(["diagnose", str(log), "--vehicle", "prius3", "--equation", str(decl), "--out", str(out),
                     "--quiet"]) == 0
    rep = json.loads((out / "trace.json").read_text())
    for key in ("baseline", "final"):
        te = rep[key]["trip_net_energy"]
        assert te["partial_trips"] == [str(first)]
        assert te["trips"][str(first)]["left_out_time_share"] == pytest.approx(0.3, abs=0.01)
        assert all(v["left_out_samples"] == 0 for t, v in te["trips"].items() if t != str(first))
    md = (out / "trace.md").read_text()
    row = [ln for ln in md.splitlines() if ln.startswith(f"| {first} |")]
    assert row and "partial: 30 % of time" in row[0] and "**Partial trips**" in md


def test_validation_trip_rows_carry_left_out_shares_and_the_tables_flag_partial_trips():
    """validate --chain: a per-trip row (validation/chain_common.trip_rows) says what the trip
    lost to samples left out (non-finite measured or predicted power) and whether that makes
    it partial; the report's per-trip tables (JLU, Prius, i3) name partial trips with the
    line compare's report.md has. A committed report without the keys renders as before."""
    from pathlib import Path

    from sumo_drvpw.validation.chain_common import trip_rows
    from sumo_drvpw.validation.chain_render import render

    n = 100
    trips = np.repeat(np.array(["a", "b"]), n)
    meas = np.full(2 * n, 2000.0)
    pred = np.full(2 * n, 2200.0)
    meas[20:50] = np.nan          # a: 30 % of its time without a measured power
    pred[n + 5:n + 10] = np.nan   # b: 5 % without a prediction (its energy share 5 %: not partial)
    rows = {r["trip"]: r for r in trip_rows(pred, meas, np.ones(2 * n), trips)}
    a, b = rows["a"], rows["b"]
    assert a["error"] == pytest.approx(0.1) and b["error"] == pytest.approx(0.1)
    assert a["left_out_power_unknown_time_share"] == pytest.approx(0.3) and a["partial"] is True
    assert b["left_out_energy_share"] == pytest.approx(0.05) and b["partial"] is False

    repo = Path(__file__).resolve().parents[1]
    doc = json.loads((repo / "docs" / "energy-chain-validation.json").read_text(encoding="utf-8"))

    def rows_of(d):  # every per-trip row of the report, wherever it sits
        if isinstance(d, dict):
            if "trip" in d:
                yield d
            for v in d.values():
                yield from rows_of(v)
        elif isinstance(d, list):
            for v in d:
                yield from rows_of(v)

    for r in rows_of(doc):  # a report written before the keys existed
        for k in [k for k in r if k.startswith("left_out_") or k == "partial"]:
            del r[k]
    md = render(doc, "cmd")
    assert "**Partial trips**" not in md  # rows without the keys: rendered as before
    for section, key in (("jlu", "before"), ("prius2", "rows"), ("bmw_i3", "rows")):
        row = doc[section][key][0]
        row.update({k: a[k] for k in a if k.startswith("left_out_")}, partial=True)
        flagged = render(doc, "cmd")
        assert flagged.count("**Partial trips**") == 1, section
        assert f"{row['trip']} (30 % of time" in flagged
        row["partial"] = False
