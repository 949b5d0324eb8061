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
