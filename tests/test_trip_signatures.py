"""A trip's signature (data/trips.py: trip_signatures, same_trips) tells the same samples
re-read from another file — re-exported, rounded, renamed, cut by a row — from another
drive of the same route or cycle, so `compare` can say an equation's errors are in sample."""

import numpy as np
import pandas as pd
import pytest
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
    nums = kept[0].split()  # samples, duration, mean, rms, blocks ending at 64, 256, 1024 (4096 > 3000),
    assert len(kept) == 1 and nums[7:10] == ["0", "0", "3"]  # no battery power, then the anchors, three numbers each
    assert 3 <= (len(nums) - 10) // 3 <= 64 and (len(nums) - 10) % 3 == 0
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


def _city(seed: int, n: int, dt: float = 0.1) -> pd.DataFrame:
    """A stop-and-go drive: accelerations of up to ±2.5 m/s² held for seconds, stops of
    some seconds, noise of a wheel-speed sensor (0.02 m/s)."""
    rng = np.random.default_rng(seed)
    k = int(np.ceil(n * dt / 4.0)) + 1  # a new acceleration every 4 s
    a = np.repeat(rng.uniform(-2.5, 2.5, k), int(round(4.0 / dt)))[:n]
    v = np.zeros(n)
    for i in range(1, n):  # (a test's drive: bounded, standing at 0 and capped at 25 m/s)
        v[i] = min(max(v[i - 1] + a[i] * dt, 0.0), 25.0)
    v = np.clip(v + rng.normal(0, 0.02, n), 0, None)
    return pd.DataFrame({"trip_id": f"city{seed}", "time_s": np.arange(n) * dt, "speed_mps": v})


def _pieces(d: pd.DataFrame, start: int, stop: int):
    return d.iloc[start:stop].assign(trip_id="part")


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(3000, 30_000), a=st.floats(0.0, 0.7), b=st.floats(0.0, 0.7),
       battery=st.booleans(), kept=st.booleans())
def test_a_part_of_a_calibration_trip_is_found(seed, n, a, b, battery, kept):
    """A trip cut at its start (its first rows dropped), at its end, or one of two files it
    was split into was not found (the signature's samples, duration and mean speed are the
    whole trip's): 0 of 6 parts of each shared trip. Its anchors are the whole trip's,
    shifted by the rows dropped before it: at least 30 % of the trip, anywhere in it, is
    found — against the signature as an equation file keeps it or as read."""
    d = _city(seed, n)
    if battery:
        d = _battery(d, seed)
    ref = signature_texts(trip_signatures(d)) if kept else list(trip_signatures(d).values())
    start = int(a * n)
    stop = n - int(b * max(n - start - int(0.3 * n), 0) / 0.7)  # at least 30 % of the trip
    assert stop - start >= 0.3 * n - 2
    assert same_trips(ref, trip_signatures(_pieces(d, start, stop))) == ["part"]


@pytest.mark.parametrize("split", [0.2, 0.5, 0.8])
def test_both_files_of_a_split_trip_are_found(split):
    d = _city(7, 12_000)
    cut = int(split * len(d))
    ref = signature_texts(trip_signatures(d))
    first = _pieces(d, 0, cut).assign(trip_id="first")
    second = _pieces(d, cut, len(d)).assign(trip_id="second")
    assert same_trips(ref, trip_signatures(pd.concat([first, second]))) == ["first", "second"]


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 10_000), other=st.integers(1, 10_000), a=st.floats(0.0, 0.6), err_kmh=st.floats(0.1, 1.0))
def test_a_part_of_another_drive_is_not_found(seed, other, a, err_kmh):
    """A part of another drive, or of the same drive driven again (a driver's trace error
    of 0.1–1 km/h rms, drifting over ~5 s) is not a part of the calibration trip."""
    d = _city(seed, 8000)
    ref = signature_texts(trip_signatures(d))
    start = int(a * len(d))
    assert same_trips(ref, trip_signatures(_pieces(_city(seed + other, 8000), start, start + 3000))) == []
    rng = np.random.default_rng(other)
    err = np.interp(np.arange(len(d)), np.arange(0, len(d) + 50, 50), rng.normal(0, err_kmh / 3.6, len(d) // 50 + 1))
    again = d.assign(speed_mps=np.clip(d["speed_mps"] + err, 0, None))
    assert same_trips(ref, trip_signatures(_pieces(again, start, start + 3000))) == []


def test_a_part_of_a_test_whose_speed_was_logged_alike_is_told_by_the_battery():
    """As for the whole tests (UDDS_01 and UDDS_02 of the shared JLU dynamometer): a half of
    the other test, the same speed samples, is not a part of this one; a half of this one,
    its current logged the other way round, is."""
    d = _city(8, 9000)
    one, two = _battery(d, 1), _battery(d, 2)
    ref = signature_texts(trip_signatures(one))
    assert same_trips(ref, trip_signatures(_pieces(two, 4500, 9000))) == []
    mine = _pieces(one, 4500, 9000).assign(battery_current_a=lambda x: -x["battery_current_a"])
    assert same_trips(ref, trip_signatures(mine)) == ["part"]


def test_many_trips_keep_fewer_anchors_each_and_their_halves_are_still_found():
    """An equation file kept 64 anchors of every trip (some 1.6 kB a line): a calibration on
    thousands of trips would write megabytes of them. Past KEPT_ANCHORS_TOTAL // trips each
    keeps fewer (at least KEPT_ANCHORS_MIN): 1,000 signatures of long city drives keep at most
    8 anchors each, and each drive's halves are still found in it alone."""
    from sumo_drvpw.data.trips import KEPT_ANCHORS_MIN, _split

    d = _city(11, 12_000)
    sig = next(iter(trip_signatures(d).values()))
    assert len(_split(sig)[1]) > 64  # a drive with more anchors than any file keeps
    others = {f"other{k}": list(sig[:6]) + [1.0e6 + k] for k in range(999)}  # elsewhere, unmatched
    few, alone = signature_texts({"d": sig} | others)[0], signature_texts({"d": sig})[0]
    assert len(_split([float(x) for x in few.split()])[1]) == KEPT_ANCHORS_MIN
    assert len(_split([float(x) for x in alone.split()])[1]) == 64 and len(few) < len(alone) / 4
    first, second = _pieces(d, 0, 6000).assign(trip_id="first"), _pieces(d, 6000, 12_000).assign(trip_id="second")
    assert same_trips([few], trip_signatures(pd.concat([first, second]))) == ["first", "second"]


def test_a_signature_written_before_the_anchors_is_read_and_matched_as_before():
    """An equation file written before the anchors keeps [samples, duration, mean, rms, the
    blocks, the power's mean and rms where logged]: the same trips re-read are found as
    before, their parts are not (those signatures cannot tell them)."""
    d = _battery(_city(9, 6000), 3)
    for frame, power in ((d, 2), (d[["trip_id", "time_s", "speed_mps"]], 0)):
        new = signature_texts(trip_signatures(frame))[0].split()
        old = " ".join(new[:4 + 4 + power])  # blocks ending at 64, 256, 1024, 4096
        assert new[8:10] == (new[8:10] if power else ["0", "0"])
        whole = trip_signatures(frame.iloc[:-1].assign(trip_id="again"))
        assert same_trips([old], whole) == ["again"] == same_trips([" ".join(new)], whole)
        part = trip_signatures(_pieces(frame, 1000, 6000))
        assert same_trips([old], part) == [] and same_trips([" ".join(new)], part) == ["part"]


def test_parts_of_the_shared_trips_are_found_in_their_own_trip_only(shared_data):
    """Every trip of the shared logs (BMW i3, Prius Gen-2, JLU dynamometer and road: 104),
    read as `calibrate` reads them: its start cut by 100 rows and its two halves against the
    kept signatures of all. Before the anchors none was found (1 of 832 planted parts, a
    row cut); no part is taken for another trip, and nearly all are found in their own (the
    few not: halves of constant-speed tests, whose speed crosses no level)."""
    from sumo_drvpw.data import adapters
    from sumo_drvpw.data.log import from_frame

    frames = []
    for folder, fmt in (("bmw_i3_tum", "bmw-i3-tum"), ("prius_gen2_torquepro", "torquepro-prius2"),
                        ("jlu_bev_dyno", "jlu-dyno"), ("jlu_bev_road", "jlu-road")):
        df, _ = adapters.read(fmt, shared_data / folder)
        d = from_frame(df, None, name=folder).df
        frames.append(d[[c for c in ("trip_id", "time_s", "speed_mps", "battery_voltage_v", "battery_current_a")
                         if c in d]].assign(trip_id=folder + "/" + d["trip_id"].astype(str)))
    d = pd.concat(frames, ignore_index=True)
    kept = trip_signatures(d)
    texts = dict(zip(kept, signature_texts(kept)))
    assert len(texts) == d["trip_id"].nunique() >= 100
    found = total = 0
    for tid, g in d.groupby("trip_id", sort=False):
        n = len(g)
        parts = pd.concat([g.iloc[100:].assign(trip_id="cut"), g.iloc[: n // 2].assign(trip_id="first"),
                           g.iloc[n // 2:].assign(trip_id="second")])
        sigs = trip_signatures(parts)
        assert same_trips([t for k, t in texts.items() if k != tid], sigs) == [], tid
        found += len(same_trips([texts[tid]], sigs))
        total += len(sigs)
    assert found >= 0.9 * total, (found, total)


@pytest.mark.parametrize("engine", ["local", "memory"])
def test_compare_says_a_split_or_cut_calibration_trip_is_in_sample(tmp_path, capsys, engine):
    """`calibrate` on a synthetic drive, `compare` on its trip split in two files (each
    renamed) and on the trip with its first 500 rows dropped: said in sample, as the whole
    trip re-exported was; another drive beside them is not."""
    from sumo_drvpw.cli import main as cli_main

    a, b = tmp_path / "a.parquet", tmp_path / "b.parquet"
    assert cli_main(["synth", "--out", str(a), "--minutes", "6", "--seed", "1"]) == 0
    assert cli_main(["synth", "--out", str(b), "--minutes", "6", "--seed", "7"]) == 0
    eq = tmp_path / "eq.toml"
    assert cli_main(["calibrate", str(a), "--vehicle", "prius3", "--out", str(eq), "--engine", engine]) == 0
    da = pd.read_parquet(a)
    half = len(da) // 2
    one, two, cut = tmp_path / "one.csv", tmp_path / "two.csv", tmp_path / "cut.csv"
    da.iloc[:half].assign(trip_id="first").to_csv(one, index=False)
    da.iloc[half:].assign(trip_id="second").to_csv(two, index=False)
    da.iloc[500:].assign(trip_id="late").to_csv(cut, index=False)
    capsys.readouterr()
    for logs, said in (([one, two, b], "2 of these 3 trip(s) (first, second;"), ([cut, b], "1 of these 2 trip(s) (late;")):
        assert cli_main(["compare", *map(str, logs), "--vehicle", "prius3", "--equation", str(eq),
                         "--out", str(tmp_path / "c"), "--engine", engine, "--force"]) == 0
        notes = [x for x in capsys.readouterr().out.splitlines() if "in sample" in x]
        assert len(notes) == 1 and f"eq was calibrated on {said}" in notes[0], notes
