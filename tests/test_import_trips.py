"""Trip ids a mapped trip column gives: shared by several files, or resumed within one."""
from __future__ import annotations

import numpy as np
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.adapters import read
from sumo_drvpw.data.log import read_log
from sumo_drvpw.errors import UserError

MAPPING = ('[options]\ntime_step_s = 1\n[columns."vel (mph)"]\nname = "speed_mps"\nunit = "mph"\n'
           '[columns."fuel (g/s)"]\nname = "fuel_rate_gps"\nunit = "g/s"\n'
           '[columns."phase_num"]\nname = "trip_id"\n')


def _pems(path, phases, fuel0):
    """A PEMS export without a time column (1 Hz), its test phases numbered 1, 2, … per
    vehicle, as UC Riverside's truck files are: one row per second, ``phases`` the phase of
    each run of 30 rows."""
    rows = ["vel (mph),fuel (g/s),phase_num"]
    k = 0
    for ph in phases:
        for i in range(30):
            rows.append(f"{20 + 10 * np.sin(k / 7.0):.4f},{fuel0 + k / 1000:.4f},{ph}")
            k += 1
    path.write_text("\n".join(rows) + "\n", encoding="utf-8")
    return path


def test_trips_numbered_per_file_stay_apart_and_the_log_reads(tmp_path):
    # two trucks' files, each numbering its phases 1, 2: before, both files' trip 1 were
    # written as one trip (time running 0…59 twice), which every command refused ('trip_id
    # 1 appears in more than one place'): the import's check compared the files' joined ids
    m = tmp_path / "map.toml"
    m.write_text(MAPPING, encoding="utf-8")
    a = _pems(tmp_path / "veh002.csv", [1, 2], 1.0)
    b = _pems(tmp_path / "veh003.csv", [1, 2], 5.0)
    out = tmp_path / "trucks.parquet"
    assert cli_main(["import", "columns", str(a), str(b), "--columns", str(m), "--out", str(out)]) == 0
    df = read_log(out).df
    assert sorted(df["trip_id"].unique()) == ["veh002-1", "veh002-2", "veh003-1", "veh003-2"]
    for trip, g in df.groupby("trip_id"):
        assert len(g) == 30 and np.all(np.diff(g["time_s"].to_numpy()) > 0), trip
    fuel = df.groupby("trip_id")["fuel_rate_gps"].first()
    assert fuel["veh002-1"] == pytest.approx(1.0) and fuel["veh003-1"] == pytest.approx(5.0)
    _, rep = read("columns", [a, b], m)
    assert any("also in another file" in n and "'veh003-<trip>'" in n for n in rep["files"][1]["notes"])


def test_ids_unique_across_files_are_kept_as_they_are(tmp_path):
    m = tmp_path / "map.toml"
    m.write_text(MAPPING, encoding="utf-8")
    df, rep = read("columns", [_pems(tmp_path / "a.csv", [1, 2], 1.0), _pems(tmp_path / "b.csv", [3, 4], 1.0)], m)
    assert sorted(df["trip_id"].unique()) == ["1", "2", "3", "4"]
    assert not any("also in another file" in n for f in rep["files"] for n in f["notes"])


def test_files_of_one_name_in_two_folders_import_apart(tmp_path):
    # d1/log.csv and d2/log.csv, each numbering its phases 1, …: were refused ("trip_id 'log-1'
    # comes from more than one file"): the stem cannot tell them apart, their folder does
    m = tmp_path / "map.toml"
    m.write_text(MAPPING, encoding="utf-8")
    (tmp_path / "d1").mkdir()
    (tmp_path / "d2").mkdir()
    a = _pems(tmp_path / "d1" / "log.csv", [1, 2], 1.0)
    b = _pems(tmp_path / "d2" / "log.csv", [1], 5.0)
    df, rep = read("columns", [a, b], m)
    assert sorted(df["trip_id"].unique()) == ["d1-log-1", "d1-log-2", "d2-log-1"]
    assert df.groupby("trip_id")["fuel_rate_gps"].first()["d2-log-1"] == pytest.approx(5.0)
    assert any("another folder" in n and "'d2-<trip>'" in n for n in rep["files"][1]["notes"])


def test_files_of_one_name_in_two_folders_without_a_trip_column(tmp_path):
    # each file one trip named after it: both 'log', refused before; now d1-log, d2-log
    m = tmp_path / "map.toml"
    m.write_text(MAPPING.split('[columns."phase_num"]')[0], encoding="utf-8")
    for d, f0 in (("d1", 1.0), ("d2", 5.0)):
        (tmp_path / d).mkdir()
        _pems(tmp_path / d / "log.csv", [1], f0)
    out = tmp_path / "o.parquet"
    assert cli_main(["import", "columns", str(tmp_path / "d1" / "log.csv"), str(tmp_path / "d2" / "log.csv"),
                     "--columns", str(m), "--out", str(out)]) == 0
    df = read_log(out).df
    assert df.groupby("trip_id")["fuel_rate_gps"].first().to_dict() == pytest.approx({"d1-log": 1.0, "d2-log": 5.0})


def test_files_of_one_stem_in_one_folder_sharing_a_trip_id_are_refused_saying_how_to_fix(tmp_path):
    m = tmp_path / "map.toml"
    m.write_text(MAPPING, encoding="utf-8")
    a = _pems(tmp_path / "log.csv", [1], 1.0)
    b = tmp_path / "log.parquet"
    import pandas as pd
    pd.read_csv(a).to_parquet(b)
    with pytest.raises(UserError, match=r"trip_id 'log-1' comes from more than one file: .*log.csv.*log.parquet; "
                                        r"files of one name in one folder: rename one"):
        read("columns", [a, b], m)


def test_a_trip_number_resumed_after_other_trips_is_named(tmp_path):
    # phases 1, 2, 1 in one file: the two runs of phase 1 are read as one trip (a pause
    # between them); the note names the row where it resumes and the option that splits it
    m = tmp_path / "map.toml"
    m.write_text(MAPPING, encoding="utf-8")
    df, rep = read("columns", [_pems(tmp_path / "veh.csv", [1, 2, 1], 1.0)], m)
    assert (df["trip_id"] == "1").sum() == 60
    note = [n for n in rep["files"][0]["notes"] if "resume after other trips' rows" in n]
    assert len(note) == 1 and note[0].startswith("1 trip id(s)")
    assert "trip 1 in 2 runs, again from data row 60" in note[0] and "trip_gap_s" in note[0]
    m.write_text(MAPPING.replace("time_step_s = 1\n", "time_step_s = 1\ntrip_gap_s = 5\n"), encoding="utf-8")
    df, rep = read("columns", [_pems(tmp_path / "veh.csv", [1, 2, 1], 1.0)], m)  # split: the note is moot
    assert sorted(df["trip_id"].unique()) == ["1_1", "1_2", "2"]
    assert not any("resume after other trips' rows" in n for n in rep["files"][0]["notes"])


def test_a_row_without_a_trip_id_is_refused_naming_it(tmp_path):
    # empty cells of a mapped trip column were written as a trip of their own named '' (its rows
    # scattered through the file; 'a-' beside another file), a Parquet file's nulls as 'nan'
    m = tmp_path / "map.toml"
    m.write_text(MAPPING, encoding="utf-8")
    a = _pems(tmp_path / "veh.csv", [1, 2], 1.0)
    lines = a.read_text(encoding="utf-8").splitlines()
    lines[4] = lines[4].rpartition(",")[0] + ","          # data row 3: no phase
    a.write_text("\n".join(lines) + "\n", encoding="utf-8")
    with pytest.raises(UserError, match=r"veh\.csv: column 'phase_num' \(trip_id\) data row 3 holds no trip id"):
        read("columns", [a], m)
    import pandas as pd

    df = pd.read_csv(_pems(tmp_path / "veh2.csv", [1, 2], 1.0)).astype({"phase_num": object})
    df.loc[7, "phase_num"] = None
    df.to_parquet(tmp_path / "veh2.parquet", index=False)
    with pytest.raises(UserError, match=r"veh2\.parquet: column 'phase_num' \(trip_id\) data row 7 holds no trip id \('nan'\)"):
        read("columns", [tmp_path / "veh2.parquet"], m)


def test_one_file_given_twice_is_refused_saying_so(tmp_path):
    # a file given by itself and again in its folder: f14bbb9's hint said "files of one name in
    # one folder: rename one", which renaming cannot fix
    m = tmp_path / "map.toml"
    m.write_text(MAPPING, encoding="utf-8")
    (tmp_path / "d").mkdir()
    a = _pems(tmp_path / "d" / "log.csv", [1], 1.0)
    with pytest.raises(UserError, match=r"trip_id 'log-1' comes from more than one file: .*; one file given twice"):
        read("columns", [a, tmp_path / "d"], m)
