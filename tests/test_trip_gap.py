"""options.trip_gap_s: a pause in logging longer than it ends a trip. A LeafSpy log holds a
day — two commutes 8.5 h apart in one file — and was one trip: its per-trip energies, held-out
folds and in-sample checks took both drives as one (the held-out per-trip errors of a
rehearsal needed the file split by hand)."""

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.data import adapters
from sumo_drvpw.errors import UserError


def _day_log(tmp_path, trip_column: bool):
    t1 = np.arange(0.0, 1200.0, 2.0)
    t2 = t1 + 1200.0 + 8.5 * 3600      # the evening commute
    t = np.r_[t1, t2]
    v = np.clip(12 + 8 * np.sin(t / 60.0), 0, None)
    df = pd.DataFrame({"epoch": 1.58e9 + t, "Speed": v * 3.6, "SOC": np.r_[np.linspace(90, 80, t1.size),
                                                                             np.linspace(95, 86, t2.size)]})
    if trip_column:
        df.insert(0, "Day", "2020-01-30")
    f = tmp_path / "day.csv"
    df.to_csv(f, index=False)
    return f


def _mapping(tmp_path, options: str, trip_column: bool):
    m = tmp_path / "map.toml"
    m.write_text(f"[options]\n{options}\n[columns.epoch]\nname = \"time_s\"\n[columns.Speed]\nname = \"speed_mps\"\n"
                 "unit = \"km/h\"\n[columns.SOC]\nname = \"soc_pct\"\n"
                 + ("[columns.Day]\nname = \"trip_id\"\n" if trip_column else ""), encoding="utf-8")
    return m


@pytest.mark.parametrize("trip_column", [False, True])
def test_a_long_pause_ends_a_trip(tmp_path, trip_column):
    f = _day_log(tmp_path, trip_column)
    df, rep = adapters.read("columns", [f], columns=_mapping(tmp_path, "trip_gap_s = 600\nsoc_capacity_kwh = 20",
                                                              trip_column))[:2]
    stem = "2020-01-30" if trip_column else "day"
    assert list(pd.unique(df["trip_id"])) == [f"{stem}_1", f"{stem}_2"]
    assert (df["trip_id"] == f"{stem}_2").sum() == 600
    notes = " ".join(rep["files"][0]["notes"])
    assert "trip_gap_s = 600" in notes and "the longest 30602 s" in notes
    # the SOC's energy per trip: the 15 % charged while parked is no trip's
    for tid, soc in ((f"{stem}_1", 10.0), (f"{stem}_2", 9.0)):
        g = df[df["trip_id"] == tid]
        spent = g["battery_discharge_energy_j"].iloc[-1] - g["battery_discharge_energy_j"].iloc[0]
        assert spent == pytest.approx(soc / 100 * 20 * 3.6e6, rel=1e-6)
        assert g["battery_charge_energy_j"].iloc[-1] == g["battery_charge_energy_j"].iloc[0]


def test_without_the_option_or_below_it_one_trip(tmp_path):
    f = _day_log(tmp_path, False)
    for opt in ("", "trip_gap_s = 40000"):
        df = adapters.read("columns", [f], columns=_mapping(tmp_path, opt, False))[0]
        assert list(pd.unique(df["trip_id"])) == ["day"]
    for bad in ("trip_gap_s = 0", "trip_gap_s = \"10 min\"", "trip_gap_s = true"):
        with pytest.raises(UserError, match="options.trip_gap_s"):
            adapters.read("columns", [f], columns=_mapping(tmp_path, bad, False))


def test_a_part_is_not_named_as_another_trip_of_the_file(tmp_path):
    """A file with trip A (two drives an hour apart) and trip A_2 (a third drive): A's second
    part was named A_2 and merged with the other drive into one trip of 1,200 samples spanning
    2 h (no word); the parts take names no other trip of the file has."""
    t1 = np.arange(0.0, 600.0, 1.0)
    t2, t3 = t1 + 4200.0, t1 + 12000.0
    v = np.clip(12 + 8 * np.sin(np.r_[t1, t2, t3] / 60.0), 0, None) * 3.6
    f = tmp_path / "day.csv"
    pd.DataFrame({"Trip": ["A"] * 1200 + ["A_2"] * 600, "t": np.r_[t1, t2, t3], "Speed": v}).to_csv(f, index=False)
    m = tmp_path / "map.toml"
    m.write_text('[options]\ntrip_gap_s = 600\n[columns.t]\nname = "time_s"\n[columns.Speed]\nname = "speed_mps"\n'
                 'unit = "km/h"\n[columns.Trip]\nname = "trip_id"\n', encoding="utf-8")
    df = adapters.read("columns", [f], columns=m)[0]
    sizes = df.groupby("trip_id", sort=False)["time_s"].agg(["size", "min"])
    assert len(sizes) == 3 and (sizes["size"] == 600).all(), sizes
    assert list(sizes["min"]) == [0.0, 4200.0, 12000.0]
    assert "A_2" in sizes.index and sizes.loc["A_2", "min"] == 12000.0   # the file's own A_2 keeps its id


def test_a_gap_not_longer_than_the_time_step_is_refused(tmp_path):
    """A gap at or below the log's 2-s step (0.5 written for half an hour, say) made every sample
    a trip of its own — 1,200 one-sample trips, written, said only in a note; refused naming the
    mapping, the file and the step. Just above the step only the real pause splits."""
    f = _day_log(tmp_path, False)
    for bad in ("0.5", "2"):
        with pytest.raises(UserError, match=rf"map\.toml: options\.trip_gap_s = {bad} s .*day\.csv \(2 s"):
            adapters.read("columns", [f], columns=_mapping(tmp_path, f"trip_gap_s = {bad}", False))
    df = adapters.read("columns", [f], columns=_mapping(tmp_path, "trip_gap_s = 2.5", False))[0]
    assert list(pd.unique(df["trip_id"])) == ["day_1", "day_2"]
