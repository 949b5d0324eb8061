"""One mapping for files from several loggers: a column's candidate source labels (``also``,
or several tables of one name), the first a file holds read; two in one file refused unless
``first_wins`` (sumo_drvpw/data/adapters/labels.py, columns.load_mapping)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.adapters import read
from sumo_drvpw.errors import UserError

KMH = np.array([36.0, 54.0, 72.0, 50.0])
MPH_PER_MPS = 3600.0 / 1609.344  # 1 mph = 1609.344 m / 3600 s (exact)

ALSO = """
[columns."Time (s)"]
name = "time_s"
also = ["Zeit"]
[columns."Speed (km/h)"]
name = "speed_mps"
unit = "km/h"
role = "condition"
also = [" GPS Speed [km/h] ", "v_kmh"]
"""


def write(d: Path, name: str, text: str) -> Path:
    p = d / name
    p.write_text(text, encoding="utf-8")
    return p


def csv(d: Path, name: str, time: str, speed: str, values, extra: str = "") -> Path:
    rows = "".join(f"{i},{v:g}{',1' if extra else ''}\n" for i, v in enumerate(values))
    return write(d, name, f"{time},{speed}{',' + extra if extra else ''}\n{rows}")


def test_two_loggers_labels_read_through_one_mapping(tmp_path):
    a = csv(tmp_path, "logger_a.csv", "Time (s)", "Speed (km/h)", KMH)
    b = csv(tmp_path, "logger_b.csv", "Zeit", "GPS Speed [km/h]", KMH[::-1])
    c = csv(tmp_path, "logger_c.csv", "Zeit", "v_kmh", KMH)
    m = write(tmp_path, "map.toml", ALSO)
    df, rep = read("columns", [a, b, c], columns=m)
    for trip, kmh in (("logger_a", KMH), ("logger_b", KMH[::-1]), ("logger_c", KMH)):
        g = df[df["trip_id"] == trip]
        np.testing.assert_allclose(g["speed_mps"], kmh / 3.6, rtol=1e-12)  # the table's unit for every label
        np.testing.assert_allclose(g["time_s"], np.arange(len(kmh)))
    # no label's generic extra beside the canonical column, and the table's role for all
    assert not any(c.startswith("gps_speed") or c.startswith("v_kmh") for c in df.columns)
    assert rep["roles"]["speed_mps"] == "condition"


def test_several_tables_of_one_name_each_with_its_unit(tmp_path):
    m = write(tmp_path, "map.toml", """
[columns.t]
name = "time_s"
[columns."Speed (km/h)"]
name = "speed_mps"
unit = "km/h"
[columns."Speed (mph)"]
name = "speed_mps"
unit = "mph"
role = "condition"
""")
    a = csv(tmp_path, "kmh.csv", "t", "Speed (km/h)", KMH)
    b = csv(tmp_path, "mph.csv", "t", "Speed (mph)", KMH)
    df, rep = read("columns", [a, b], columns=m)
    np.testing.assert_allclose(df.loc[df["trip_id"] == "kmh", "speed_mps"], KMH / 3.6, rtol=1e-12)
    np.testing.assert_allclose(df.loc[df["trip_id"] == "mph", "speed_mps"], KMH / MPH_PER_MPS, rtol=1e-12)
    assert rep["roles"]["speed_mps"] == "condition"


def test_a_file_with_two_labels_of_a_column_is_refused_in_one_line(tmp_path, capsys):
    src = csv(tmp_path, "both.csv", "Time (s)", "Speed (km/h)", KMH, extra="GPS Speed [km/h]")
    m = write(tmp_path, "map.toml", ALSO)
    with pytest.raises(UserError) as e:
        read("columns", src, columns=m)
    msg = str(e.value)
    assert str(src) in msg and "'Speed (km/h)'" in msg and "'GPS Speed [km/h]'" in msg
    assert "first_wins" in msg and str(m) in msg
    out = tmp_path / "out.parquet"
    assert cli_main(["import", "columns", str(src), "--columns", str(m), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "'GPS Speed [km/h]'" in err and "Traceback" not in err
    assert not out.exists()


def test_first_wins_reads_the_first_listed_and_leaves_the_other_out(tmp_path):
    src = write(tmp_path, "both.csv", "Time (s),GPS Speed [km/h],Speed (km/h)\n0,10,36\n1,10,54\n2,10,72\n")
    m = write(tmp_path, "map.toml", ALSO.replace('role = "condition"', 'first_wins = true'))
    df, rep = read("columns", src, columns=m)
    np.testing.assert_allclose(df["speed_mps"], KMH[:3] / 3.6, rtol=1e-12)  # the table's own label, listed first
    assert list(df.columns) == ["trip_id", "time_s", "speed_mps"]           # the other left out, not an extra
    assert any("'GPS Speed [km/h]'" in n and "left out" in n for n in rep["files"][0]["notes"])


def test_a_column_none_of_whose_labels_is_in_the_file_names_them_all(tmp_path):
    src = csv(tmp_path, "x.csv", "Zeit", "Tempo", KMH)
    with pytest.raises(UserError, match=r"x.csv: missing column 'Speed \(km/h\)' named in .*map.toml "
                                        r"\(nor its other labels 'GPS Speed \[km/h\]', 'v_kmh'\)"):
        read("columns", src, columns=write(tmp_path, "map.toml", ALSO))


def test_an_existing_mapping_reads_as_before_from_parquet_too(tmp_path):
    src = tmp_path / "p.parquet"
    pd.DataFrame({"Zeit": [0.0, 1.0, 2.0], "GPS Speed [km/h]": [36.0, 54.0, 72.0], "Other": [1, 2, 3]}).to_parquet(src)
    plain = write(tmp_path, "plain.toml", '[columns.Zeit]\nname = "time_s"\n[columns."GPS Speed [km/h]"]\n'
                                          'name = "speed_mps"\nunit = "km/h"\n')
    df0, _ = read("columns", src, columns=plain)
    df1, _ = read("columns", src, columns=write(tmp_path, "map.toml", ALSO))
    pd.testing.assert_frame_equal(df0, df1)
    assert list(df1.columns) == ["trip_id", "time_s", "speed_mps", "other"]


BASE = '[columns.t]\nname = "time_s"\n'


@pytest.mark.parametrize("text, key, what", [
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nalso = []\n', "columns.v.also", "non-empty list"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nalso = "w"\n', "columns.v.also", "non-empty list"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nalso = ["w", 3]\n', "columns.v.also", "non-empty texts, got 3"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nalso = ["w", " "]\n', "columns.v.also", "non-empty texts"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nalso = ["w", "w "]\n', "columns.v.also", "'w' twice"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nalso = ["v"]\n', "columns.v.also", "'v' twice"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nalso = ["t"]\n', "columns.v.also", "table of its own"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nalso = ["w"]\n[columns.x]\nname = "gps_speed_mps"\n'
     'also = ["w"]\n', "columns.x.also", "columns.v.also lists too"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nalso = ["w"]\nfirst_wins = "yes"\n', "columns.v.first_wins",
     "true or false"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nfirst_wins = true\n', "columns.v.first_wins", "several labels"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nrole = "condition"\n[columns.w]\nname = "speed_mps"\nunit = "m/s"\n'
     'role = "response"\n', "columns.w.role", "one role"),
    (BASE + '[columns.v]\nname = "speed_mps"\nunit = "m/s"\nfirst_wins = true\n[columns.w]\nname = "speed_mps"\nunit = "m/s"\n'
     'first_wins = false\n', "columns.w.first_wins", "disagree"),
])
def test_bad_candidate_labels_are_refused_naming_the_file_and_key(tmp_path, capsys, text, key, what):
    m = write(tmp_path, "map.toml", text)
    src = write(tmp_path, "x.csv", "t,v\n0,1\n1,2\n")
    with pytest.raises(UserError) as e:
        read("columns", src, columns=m)
    msg = str(e.value)
    assert msg.startswith(f"{m}: ") and key in msg and what in msg and "\n" not in msg
    out = tmp_path / "out.parquet"
    assert cli_main(["import", "columns", str(src), "--columns", str(m), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and key in err and not out.exists()


def test_mdf_channels_of_two_loggers_through_one_mapping(tmp_path):
    pytest.importorskip("asammdf")
    from asammdf import MDF, Signal

    t = np.arange(0, 10, 0.1)
    for name, ch in (("a.mf4", "VehSpd"), ("b.mf4", "WheelBasedVehicleSpeed"), ("c.mf4", "Speed")):
        mdf = MDF(version="4.10")
        mdf.append([Signal(36.0 + t, t, name=ch, unit="km/h")])
        mdf.save(tmp_path / name, overwrite=True)
        mdf.close()
    m = write(tmp_path, "map.toml", '[columns.VehSpd]\nname = "speed_mps"\nalso = ["WheelBasedVehicleSpeed"]\n')
    df, _ = read("columns", [tmp_path / "a.mf4", tmp_path / "b.mf4"], columns=m)
    assert set(df["trip_id"]) == {"a", "b"}
    np.testing.assert_allclose(df["speed_mps"], np.tile((36.0 + t) / 3.6, 2), rtol=1e-12)
    with pytest.raises(UserError, match=r"c.mf4: no channel 'VehSpd' named in .*\(nor its other labels "
                                        r"'WheelBasedVehicleSpeed'\)"):
        read("columns", tmp_path / "c.mf4", columns=m)


def test_a_missing_column_s_hints_look_at_all_its_labels(tmp_path):
    """A file of the second logger whose header sits below a title line, or whose label differs
    from the mapped one by case: the hint names the line and the near label as for a plain
    mapping of that logger's labels. Before, only the table's own label was looked for: 'only
    one column … wrong sep?' and no hint at all."""
    rows = "".join(f"{i},{v:g}\n" for i, v in enumerate(KMH))
    m = write(tmp_path, "map.toml", ALSO)
    titled = write(tmp_path, "titled.csv", "Logger B v2.1\nZeit,GPS Speed [km/h]\n" + rows)
    with pytest.raises(UserError, match=r"'Zeit' is on line 2.*skip_rows = 1"):
        read("columns", titled, columns=m)
    near = write(tmp_path, "near.csv", "Zeit,gps speed [km/h]\n" + rows)
    with pytest.raises(UserError, match=r"missing column 'Speed \(km/h\)'.*the file has 'gps speed \[km/h\]'"):
        read("columns", near, columns=m)


@pytest.mark.parametrize("header, mapping", [
    ("t,v,v", BASE + '[columns.v]\nname = "speed_mps"\nunit = "km/h"\n'),                    # a plain mapping
    ("Zeit,w,w", ALSO),                                                                       # another logger's label
    ("Zeit,GPS Speed [km/h],GPS Speed [km/h]", ALSO),
])
def test_a_mapped_label_written_twice_exactly_is_refused(tmp_path, capsys, header, mapping):
    """Two columns labelled alike, character for character: pandas reads the second as 'v.1',
    so the check for two columns of one label (which caught them alike but for a space) did
    not see them; the first was read as the speed and the second kept as an extra 'v_1'."""
    ALSO_W = ALSO.replace('"v_kmh"', '"w"')
    src = write(tmp_path, "x.csv", header + "\n" + "".join(f"{i},{v:g},{v + 5:g}\n" for i, v in enumerate(KMH)))
    m = write(tmp_path, "map.toml", ALSO_W if mapping is ALSO else mapping)
    label = header.split(",")[1]
    with pytest.raises(UserError, match=rf"x.csv: 2 columns are labelled '{re.escape(label)}'.*cannot tell them apart"):
        read("columns", src, columns=m)
    out = tmp_path / "out.parquet"
    assert cli_main(["import", "columns", str(src), "--columns", str(m), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err and not out.exists()


def test_a_label_ending_in_dot_one_is_its_own_column(tmp_path):
    """A file whose labels are 'v' and 'v.1' (two labels, not one written twice) reads as before."""
    src = write(tmp_path, "x.csv", "t,v,v.1\n" + "".join(f"{i},{v:g},{v + 5:g}\n" for i, v in enumerate(KMH)))
    df, _ = read("columns", src, columns=write(tmp_path, "map.toml", BASE + '[columns.v]\nname = "speed_mps"\nunit = "km/h"\n'))
    np.testing.assert_allclose(df["speed_mps"], KMH / 3.6, rtol=1e-12)
    assert "v_1" in df.columns


def test_a_missing_column_of_many_labels_names_a_few(tmp_path):
    """A column with many labels (a fleet's loggers): the 'missing column' line names the first
    few of its other labels and how many more, not all (5,000 labels: a 44-kB line before)."""
    also = ", ".join(f'"speed_{i}"' for i in range(5000))
    m = write(tmp_path, "map.toml", BASE + f'[columns.v]\nname = "speed_mps"\nunit = "km/h"\nalso = [{also}]\n')
    src = csv(tmp_path, "x.csv", "t", "Tempo", KMH)
    with pytest.raises(UserError) as e:
        read("columns", src, columns=m)
    msg = str(e.value)
    assert "(nor its other labels 'speed_0', 'speed_1', 'speed_2', 'speed_3', 'speed_4' or 4,995 more)" in msg
    assert len(msg) < 500
