"""A trip's signature (data/trips.py: trip_signatures, same_trips) tells the same samples
re-read from another file — re-exported, rounded, renamed, cut by a row — from another
drive of the same route or cycle, so `compare` can say an equation's errors are in sample."""

import numpy as np
import pandas as pd
from hypothesis import given, settings, strategies as st

from sumo_drvpw.data.trips import same_trips, signature_texts, trip_signatures


def _drive(seed: int, n: int, dt: float = 0.1) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    t = np.arange(n) * dt
    v = np.clip(12 + 8 * np.sin(2 * np.pi * t / 300) + np.cumsum(rng.normal(0, 0.05, n)), 0, None)
    v[:20] = v[-20:] = 0.0  # starts and ends standing
    return pd.DataFrame({"trip_id": f"trip{seed}", "time_s": t, "speed_mps": v})


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(300, 20_000), cut=st.integers(0, 2),
       digits=st.sampled_from([None, 3, 6]), kmh=st.booleans())
def test_the_same_samples_re_read_match(seed, n, cut, digits, kmh):
    d = _drive(seed, n)
    e = d.iloc[: n - cut].copy()
    e["trip_id"] = "renamed"
    if kmh:  # through km/h and back, as a mapping reads a km/h column
        e["speed_mps"] = (e["speed_mps"] * 3.6) / 3.6
    if digits is not None:
        e["speed_mps"] = e["speed_mps"].round(digits)
    ref = list(trip_signatures(d).values())
    assert same_trips(ref, trip_signatures(e)) == ["renamed"]


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(300, 20_000), err_kmh=st.floats(0.1, 2.0))
def test_a_repeat_of_the_same_cycle_does_not_match(seed, n, err_kmh):
    """The same trace driven again (the same samples, a driver's trace error of 0.1–2 km/h
    rms, slowly varying as a driver's is) is another drive."""
    d = _drive(seed, n)
    rng = np.random.default_rng(seed + 1)
    k = max(n // 50, 2)  # an error that drifts over ~50 samples
    err = np.interp(np.arange(n), np.linspace(0, n - 1, k), rng.normal(0, err_kmh / 3.6, k))
    e = d.copy()
    e["trip_id"] = "again"
    e["speed_mps"] = np.clip(d["speed_mps"] + err, 0, None)
    assert same_trips(list(trip_signatures(d).values()), trip_signatures(e)) == []


def test_trips_are_told_apart_in_a_mixed_file():
    a, b, c = _drive(1, 5000), _drive(2, 5000), _drive(3, 4000)
    ref = list(trip_signatures(pd.concat([a, b])).values())
    assert same_trips(ref, trip_signatures(pd.concat([c, b, a]))) == ["trip2", "trip1"]
    assert same_trips([], trip_signatures(a)) == []


def test_kept_as_lines_of_numbers_and_a_hand_edited_one_is_passed_over():
    a = _drive(4, 3000)
    kept = signature_texts(trip_signatures(a))
    assert len(kept) == 1 and len(kept[0].split()) == 4 + 3  # blocks ending at 64, 256, 1024 (4096 > 3000)
    assert same_trips(kept, trip_signatures(a)) == ["trip4"]
    assert same_trips(["not numbers", "1 2", None, 7] + kept, trip_signatures(a)) == ["trip4"]
    assert same_trips(["not numbers"], trip_signatures(a)) == []


def test_a_parked_session_is_not_taken_for_another_of_the_same_length():
    """Two parked sessions (an EV's cabin pre-conditioned, the battery logged: speed 0 at
    every sample) of the same length had the same signature, so a battery `compare` said an
    equation calibrated on one was 'calibrated on' the other. Speed that never changes tells
    nothing; a trip that moves is still found."""
    parked = pd.DataFrame({"trip_id": "p1", "time_s": np.arange(1800) * 0.1, "speed_mps": 0.0})
    other = parked.assign(trip_id="p2")
    cruise = parked.assign(trip_id="c1", speed_mps=20.0)  # one speed throughout: the same
    ref = signature_texts(trip_signatures(pd.concat([parked, cruise, _drive(5, 3000)])))
    assert same_trips(ref, trip_signatures(pd.concat([other, cruise.assign(trip_id="c2"),
                                                      _drive(5, 3000)]))) == ["trip5"]


def _battery(d: pd.DataFrame, seed: int) -> pd.DataFrame:
    rng = np.random.default_rng(seed)
    v = d["speed_mps"].to_numpy()
    return d.assign(battery_voltage_v=np.round(398 - 0.002 * np.cumsum(v) + rng.normal(0, 0.3, len(d)), 2),
                    battery_current_a=np.round(2.5 * v + rng.normal(0, 3, len(d)), 2))


def test_two_tests_whose_speed_was_logged_alike_are_told_by_the_battery():
    """The shared JLU dynamometer's UDDS_01 and UDDS_02 hold the same speed samples (every
    one equal) but two tests' battery data (1.29 and 1.22 kWh): a battery `compare` on
    UDDS_02 of an equation calibrated on UDDS_01 said it was 'calibrated on' it. The battery
    power (V·I: mean and rms) is part of the signature now: the same speed with another
    test's battery is another trip; the same samples re-read (V and I to 10 mV and 10 mA, the
    current's sign the other way round, two rows cut) still match, and a signature kept
    without the power (or a log without the battery) is judged by the speed alone."""
    d = _drive(8, 6000)
    one, two = _battery(d, 1), _battery(d, 2).assign(trip_id="other_test")
    ref = signature_texts(trip_signatures(one))
    assert same_trips(ref, trip_signatures(two)) == []
    again = one.iloc[:-2].assign(trip_id="again", battery_current_a=lambda x: -x["battery_current_a"])
    again[["battery_voltage_v", "battery_current_a"]] = again[["battery_voltage_v", "battery_current_a"]].round(2)
    assert same_trips(ref, trip_signatures(again)) == ["again"]
    speed_only = [" ".join(r.split()[:4 + 4]) for r in ref]  # n, duration, mean, rms, 4 blocks
    assert same_trips(speed_only, trip_signatures(two)) == ["other_test"]
    assert same_trips(ref, trip_signatures(d.assign(trip_id="no_battery"))) == ["no_battery"]


def test_each_trip_is_held_in_detail_only_to_signatures_near_it(monkeypatch):
    """same_trips compared every trip with every kept signature in Python (3,000 trips of
    30 min at 8 Hz against as many signatures: 16.5 s, growing with the square): the samples,
    duration, mean and rms speed are now compared with all signatures at once, and the blocks
    and power only with those that agree. Counted here (not timed): the signatures are
    split into their parts once each, and each trip once, not once per pair."""
    import sumo_drvpw.data.trips as trips_mod

    drives = [_drive(s, 1500) for s in range(40)]  # the same length, another drive each
    ref = signature_texts(trip_signatures(pd.concat(drives[:20])))
    seen = trip_signatures(pd.concat(drives[10:]))
    calls = []
    real = trips_mod._parts
    monkeypatch.setattr(trips_mod, "_parts", lambda sig: calls.append(1) or real(sig))
    assert same_trips(ref, seen) == [f"trip{s}" for s in range(10, 20)]
    assert len(calls) <= len(ref) + len(seen)
