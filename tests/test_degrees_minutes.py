"""Positions logged as degrees and decimal minutes in text — LeafSpy's `Lat`, `Long`
("34 11.28809", "-117 25.75793") — are read with the mapping unit "deg min". Before, such a
column was refused as not numeric with no way to read it (three public LeafSpy logs so far:
docs/adapters.md), so `import --wind` had no GPS positions to take the heading from. Rows of
a 2020 Nissan Leaf's log (ericthobbs/TripViewer @ a58aa42, examples/Log.csv; columns cut)."""
from __future__ import annotations

import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.errors import UserError

ROWS = ("epoch time,Lat,Long,Speed\n"
        "1751256576.729,34 11.28809,-117 25.75793,68\n"
        "1751256581.865,34 11.23628,-117 25.8311,64\n"
        "1751256587.000,34 11.18604,-117 25.90262,63\n"
        "1751256592.135,34 11.13772,-117 25.97647,63\n")


def test_degrees_and_minutes_read_as_degrees():
    from sumo_drvpw.data.adapters.cells import degrees_minutes

    s = pd.Series(["34 11.28809", "-117 25.75793", "0 0.5", "-", "12.5", " 8 05 "])
    x = degrees_minutes(s, "f.csv", "Lat")
    assert x[0] == pytest.approx(34 + 11.28809 / 60, abs=1e-12)
    assert x[1] == pytest.approx(-(117 + 25.75793 / 60), abs=1e-12)  # the sign is the degrees'
    assert x[2] == pytest.approx(0.5 / 60)
    assert pd.isna(x[3])  # a no-reading token
    assert x[4] == 12.5 and x[5] == pytest.approx(8 + 5 / 60)  # a plain number is degrees


@pytest.mark.parametrize("cell", ["34 61.5", "N34 11.2", "34° 11.2'"])
def test_what_is_no_degrees_and_minutes_is_refused_naming_the_row(cell):
    from sumo_drvpw.data.adapters.cells import degrees_minutes

    with pytest.raises(UserError, match=r"f.csv: column 'Lat' \(unit deg min\) data row 1 holds"):
        degrees_minutes(pd.Series(["34 11.2", cell]), "f.csv", "Lat")


def _mapping(tmp_path, unit):
    m = tmp_path / "m.toml"
    m.write_text('[columns."epoch time"]\nname = "time_s"\nunit = "s"\n'
                 '[columns."Speed"]\nname = "speed_mps"\nunit = "mph"\n'
                 f'[columns."Lat"]\nname = "latitude_deg"\nunit = "{unit}"\n'
                 f'[columns."Long"]\nname = "longitude_deg"\nunit = "{unit}"\n', encoding="utf-8")
    return m


def test_a_leafspy_log_imports_its_positions_and_takes_the_wind_along_them(tmp_path, capsys):
    f = tmp_path / "Log.csv"
    f.write_text(ROWS, encoding="utf-8")
    out = tmp_path / "leaf.parquet"
    assert cli_main(["import", "columns", str(f), "--columns", str(_mapping(tmp_path, "deg min")),
                     "--out", str(out), "--wind", "3@270"]) == 0
    d = pd.read_parquet(out)
    assert d["latitude_deg"].iloc[0] == pytest.approx(34.1881348, abs=1e-7)
    assert d["longitude_deg"].iloc[0] == pytest.approx(-117.4292988, abs=1e-7)
    # west-south-west (longitude and latitude fall) into a west wind: a headwind, negative,
    # where the positions 20 m apart give a heading (the others still air, as the note says)
    w = d["wind_mps"]
    assert (w <= 0).all() and (w < -2).sum() >= 2, w  # (heading WSW: 3·cos 40°)


def test_mapped_in_degrees_the_error_says_the_unit_that_reads_them(tmp_path, capsys):
    f = tmp_path / "Log.csv"
    f.write_text(ROWS, encoding="utf-8")
    rc = cli_main(["import", "columns", str(f), "--columns", str(_mapping(tmp_path, "deg")),
                   "--out", str(tmp_path / "o.parquet")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1
    assert "column 'Lat' is not numeric: data row 0 holds '34 11.28809'" in err
    assert 'unit = "deg min" reads them' in err
    assert not (tmp_path / "o.parquet").exists()


@pytest.mark.parametrize("name, said", [
    ("speed_mps", "unit 'deg min' is an angle, but 'speed_mps' holds a speed"),
    ("lat_kmh", "unit 'deg min' is an angle, but name 'lat_kmh' ends in '_kmh', a speed unit"),
    ("heading_s", "unit 'deg min' is an angle, but name 'heading_s' ends in '_s'"),
])
def test_deg_min_is_an_angle_checked_against_the_name_as_deg_is(tmp_path, capsys, name, said):
    """'deg min' is an angle's unit: a name that says another quantity is refused as with 'deg'
    (one line naming the mapping file and key, exit 2, nothing written). Before, 'deg min' was
    returned ahead of the name checks: `Lat` mapped as speed_mps was written as a speed of
    0.597 m/s (34.19° in radians)."""
    f = tmp_path / "Log.csv"
    f.write_text(ROWS, encoding="utf-8")
    m = tmp_path / "m.toml"
    m.write_text('[columns."epoch time"]\nname = "time_s"\nunit = "s"\n'
                 + ('' if name == "speed_mps" else '[columns."Speed"]\nname = "speed_mps"\nunit = "mph"\n')
                 + f'[columns."Lat"]\nname = "{name}"\nunit = "deg min"\n', encoding="utf-8")
    rc = cli_main(["import", "columns", str(f), "--columns", str(m), "--out", str(tmp_path / "o.parquet")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1, err
    assert f"{m}: columns.Lat: {said}" in err
    assert not (tmp_path / "o.parquet").exists()


def test_deg_min_under_a_radian_name_reads_radians(tmp_path):
    """'latitude_rad' from 'deg min' is the same position in radians as 'latitude_deg' in degrees."""
    f = tmp_path / "Log.csv"
    f.write_text(ROWS, encoding="utf-8")
    m = tmp_path / "m.toml"
    m.write_text(_mapping(tmp_path, "deg min").read_text(encoding="utf-8").replace("latitude_deg", "latitude_rad"),
                 encoding="utf-8")
    assert cli_main(["import", "columns", str(f), "--columns", str(m), "--out", str(tmp_path / "o.parquet")]) == 0
    d = pd.read_parquet(tmp_path / "o.parquet")
    assert d["latitude_rad"].iloc[0] == pytest.approx(34.1881348 * 3.141592653589793 / 180, abs=1e-9)
    assert d["longitude_deg"].iloc[0] == pytest.approx(-117.4292988, abs=1e-7)
