"""A mapped column's name against its unit (``import columns``, data/adapters/unit_names.py):
names end in the SI unit the value is converted to (the drive-log spec, ../shared/spec/drive-log.md:
``speed_mps`` in m/s, ``power_w`` in W, …); a refusal says what to write, naming the mapping file
and key; a suffix that is fine is not refused, and one that says another unit than the value is
in is not accepted."""

from __future__ import annotations

import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.adapters._common import CANONICAL, DIMENSIONS, UNITS
from sumo_drvpw.data.adapters.columns import load_mapping
from sumo_drvpw.errors import UserError

BASE = '[columns."t"]\nname = "time_s"\nunit = "s"\n[columns."v"]\nname = "speed_mps"\nunit = "km/h"\n'


def _map(tmp_path, name: str, unit: str, base: str = BASE):
    p = tmp_path / "m.toml"
    p.write_text(base + f'[columns."x"]\nname = "{name}"\nunit = "{unit}"\n', encoding="utf-8")
    return p


def _other_spelling(dim: str) -> str | None:
    """A unit of ``dim`` other than its SI one that a name can end in ('kmh', 'ft', 'kw')."""
    return next((k for k, (d, f, o) in UNITS.items() if d == dim and (f, o) != (1.0, 0.0) and k.isidentifier()), None)


#: each canonical column named with another unit of its quantity: (canonical, the suffix written)
NAMED_IN_ANOTHER_UNIT = [(c, s) for c in CANONICAL if "_" in c
                         for dim in [{v: k for k, v in DIMENSIONS.items() if v}.get(c.rsplit("_", 1)[1])]
                         if dim and dim != "angle" and (s := _other_spelling(dim))]  # ('_deg': kept in degrees)


def test_every_canonical_quantity_has_a_case():
    assert {c for c, _ in NAMED_IN_ANOTHER_UNIT} >= {"speed_mps", "time_s", "elevation_m", "power_w", "mass_kg",
                                                     "ambient_c", "pressure_kpa", "accel_mps2", "battery_voltage_v",
                                                     "battery_current_a", "battery_charge_energy_j"}


@pytest.mark.parametrize("canonical, suffix", NAMED_IN_ANOTHER_UNIT)
def test_a_canonical_column_named_in_its_file_s_unit_is_told_what_to_write(tmp_path, canonical, suffix):
    """'speed_kmh' with unit km/h (and every canonical column alike: 'time_ms', 'elevation_ft',
    'power_kw', …): the one line names the file and the key and says to keep the unit under the
    canonical name — name = "speed_mps" with unit = "kmh" (before: "name it 'speed_mps'", which
    read as if the unit had to go too)."""
    stem = canonical[:canonical.rindex("_")]
    p = _map(tmp_path, f"{stem}_{suffix}", suffix, BASE if canonical not in ("speed_mps", "time_s") else
             BASE.replace('name = "time_s"', 'name = "t0_s"').replace('name = "speed_mps"', 'name = "v0_mps"'))
    with pytest.raises(UserError) as e:
        load_mapping(p)
    msg = str(e.value)
    assert str(p) in msg and "columns.x.name" in msg
    assert f'write name = "{canonical}" with unit = "{suffix}"' in msg


@pytest.mark.parametrize("canonical, unit, spelled", [("speed_mps", "kW", '"km/h"'), ("power_w", "km/h", '"kw"'),
                                                       ("elevation_m", "s", '"ft"'), ("speed_mps", "", '"m/s"')])
def test_a_canonical_column_given_a_unit_of_another_quantity_is_told_its_units(tmp_path, canonical, unit, spelled):
    """The spec's column holds its quantity: a unit of another one is the unit's mistake, and the
    line lists the units to write (before: 'use a name ending in _w' for speed_mps from kW — a
    rename that would drop the required speed)."""
    p = _map(tmp_path, canonical, unit, BASE if canonical != "speed_mps" else BASE.replace('name = "speed_mps"',
                                                                                             'name = "v0_mps"'))
    with pytest.raises(UserError) as e:
        load_mapping(p)
    msg = str(e.value)
    assert str(p) in msg and "columns.x" in msg and "write unit = one of" in msg and spelled in msg
    assert "name =" not in msg


@pytest.mark.parametrize("name, unit, factor", [
    ("speed_m_s", "m/s", 1.0),            # m/s written with '_': was refused ("ends in '_s' (time)")
    ("maf_g_s", "g/s", 1.0),              # a mass air flow in g/s: was refused the same way
    ("density_kg_m3", "kg/m3", 1.0),      # was noted "has no unit suffix"
    ("elevation_meters", "ft", 0.3048),   # a plural of the SI unit: was noted "has no unit suffix"
    ("hv_volts", "V", 1.0), ("current_amps", "A", 1.0), ("heater_watts", "kW", 1000.0),
])
def test_a_name_ending_in_its_si_unit_otherwise_spelled_is_read_unsaid(tmp_path, name, unit, factor):
    m = load_mapping(_map(tmp_path, name, unit))
    assert m["columns"]["x"]["factor"] == pytest.approx(factor, rel=1e-12)
    assert [n for n in m["notes"] if f"'{name}'" in n and "unit suffix" in n] == []


@pytest.mark.parametrize("name, unit, says", [
    # the name says one unit, the value is converted to another: were kept in SI under the name
    ("speed_km_h", "km/h", 'write name = "speed_mps" with unit = "km/h"'),
    ("speed_mi_h", "mph", 'write name = "speed_mps" with unit = "mph"'),
    ("fuel_gal_h", "gal/h", 'write name = "fuel_lph" with unit = "gal/h"'),
    ("fuel_flow_cc_s", "cc/s", 'write name = "fuel_flow_lph" with unit = "cc/s"'),  # was: "fuel_flow_cc_lph"
    ("speed_ft_s", "ft/s", 'write name = "speed_mps" with unit = "ft/s"'),          # was: "speed_ft_mps"
    # the name says one quantity, the unit another: were accepted, converted by the unit
    ("heater_kw", "km/h", 'a power in kw is written name = "heater_w" with unit = "kw"'),
    ("speed_km_h", "kW", 'a speed in km/h is written name = "speed_mps" with unit = "km/h"'),
])
def test_a_name_saying_another_unit_than_its_value_is_refused(tmp_path, name, unit, says):
    p = _map(tmp_path, name, unit)
    with pytest.raises(UserError) as e:
        load_mapping(p)
    assert str(p) in str(e.value) and "columns.x" in str(e.value) and says in str(e.value)


@pytest.mark.parametrize("name, unit, factor", [("altitude_gps", "m", 1.0), ("heading_gps", "deg", 0.017453292519943295),
                                                ("speed_ms", "m/s", 1.0), ("speed_min", "km/h", 1 / 3.6)])
def test_a_suffix_that_is_a_word_more_often_than_a_unit_is_not_refused(tmp_path, name, unit, factor):
    """'altitude_gps' (from the GPS, not in g/s; was refused: "ends in '_gps' (mass_flow)"),
    'speed_ms' (m/s, not milliseconds), 'speed_min' (a minimum): read, with the note that their
    name leaves the unit unsaid."""
    m = load_mapping(_map(tmp_path, name, unit))
    assert m["columns"]["x"]["factor"] == pytest.approx(factor, rel=1e-12)
    assert any(f"'{name}'" in n for n in m["notes"])


def test_a_speed_named_with_gps_is_said_not_to_be_read_as_a_gps_speed(tmp_path):
    (note,) = load_mapping(_map(tmp_path, "speed_gps", "km/h"))["notes"]
    assert "'speed_gps' is not read as a GPS speed" in note and "gps_speed_mps" in note
    (note,) = load_mapping(_map(tmp_path, "gps_speed_m_s", "m/s"))["notes"]
    assert "not read as a GPS speed" in note and "'gps_speed_mps'" in note


def test_the_command_line_imports_the_names_once_refused_and_refuses_the_ones_once_kept(tmp_path, capsys):
    """Round trip through ``import columns``: 'maf_g_s' and 'speed_m_s' are written as read;
    'speed_km_h' from km/h is one line naming the mapping and key, exit 2, nothing written."""
    src = tmp_path / "log.csv"
    src.write_text("t,v,maf,w\n" + "".join(f"{i},{36 + i},{2.5 + i},{10 + i}\n" for i in range(20)), encoding="utf-8")
    m = tmp_path / "ok.toml"
    m.write_text(BASE + '[columns."maf"]\nname = "maf_g_s"\nunit = "g/s"\n[columns."w"]\nname = "wheel_m_s"\n'
                 'unit = "m/s"\n', encoding="utf-8")
    assert cli_main(["import", "columns", str(src), "--columns", str(m), "--out", str(tmp_path / "ok.parquet")]) == 0
    df = pd.read_parquet(tmp_path / "ok.parquet")
    assert df["maf_g_s"].tolist() == [2.5 + i for i in range(20)]
    assert df["wheel_m_s"].tolist() == [10.0 + i for i in range(20)]
    assert df["speed_mps"].iloc[0] == pytest.approx(10.0)
    bad = tmp_path / "bad.toml"
    bad.write_text(BASE + '[columns."w"]\nname = "wheel_km_h"\nunit = "km/h"\n', encoding="utf-8")
    capsys.readouterr()
    assert cli_main(["import", "columns", str(src), "--columns", str(bad), "--out", str(tmp_path / "bad.parquet")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "bad.toml" in err[0] and "columns.w.name" in err[0]
    assert 'write name = "wheel_mps" with unit = "km/h"' in err[0]
    assert not (tmp_path / "bad.parquet").exists()


@pytest.mark.parametrize("unit", ["g/s", "kg/s", "kg/h"])
def test_a_mass_flow_named_in_kg_per_s_is_told_the_si_name(tmp_path, unit):
    """'maf_kg_s' (a mass flow whose name says kg/s, the '/' written '_'): refused, told to write
    name = "maf_gps" with the file's unit. Before, kg/s was no unit: the name's suffix read as
    '_s' (time) and the advice was name = "maf_kg_gps" — a name saying kg and g/s at once — and
    unit = "kg/s" was refused as unknown."""
    p = _map(tmp_path, "maf_kg_s", unit)
    with pytest.raises(UserError) as e:
        load_mapping(p)
    assert str(p) in str(e.value) and f'write name = "maf_gps" with unit = "{unit}"' in str(e.value), str(e.value)


def test_kg_per_s_reads_as_a_thousand_g_per_s(tmp_path):
    m = load_mapping(_map(tmp_path, "maf_gps", "kg/s"))
    assert m["columns"]["x"]["factor"] == pytest.approx(1000.0, rel=1e-12)
