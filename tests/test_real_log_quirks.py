"""Quirks of real public drive logs a new user met (docs/adapters.md "Data quirks"),
each reproduced on a small synthetic file: an app's title lines above the CSV header,
header labels with a leading space copied into the mapping, …"""

from __future__ import annotations

import numpy as np
import pytest

from sumo_drvpw.data.adapters import read
from sumo_drvpw.errors import UserError

# BlueDriver's export (and others): title lines above the header, labels after ', '
TITLED = ("BlueDriver Data Log,,\n"
          "07/16/2017, 2017 2:47:57 PM,\n"
          "Time (s), Engine RPM (rpm), Vehicle Speed (km/h)\n"
          "0, , \n"
          "1.5,838,36\n"
          "3,814,72\n")
MAP = ('[columns."Time (s)"]\nname = "time_s"\n'
       '[columns." Vehicle Speed (km/h)"]\nname = "speed_mps"\nunit = "km/h"\n')


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def test_mapping_label_with_the_headers_leading_space_names_the_column(tmp_path):
    """A label copied verbatim from a ', '-separated header (' Vehicle Speed (km/h)') is the
    column the reader sees stripped ('Vehicle Speed (km/h)'), not a missing one."""
    src = _write(tmp_path, "log.csv", TITLED.split("\n", 2)[2])
    df, rep = read("columns", [src], columns=_write(tmp_path, "m.toml", MAP))
    np.testing.assert_allclose(df["speed_mps"], [10.0, 20.0])   # 36, 72 km/h
    assert rep["dropped"] == {"NaN speed": 1}                   # the row of blank ' ' cells
    both = MAP + '[columns."Vehicle Speed (km/h)"]\nname = "gps_speed_mps"\nunit = "km/h"\n'
    with pytest.raises(UserError, match="name the same source column"):
        read("columns", [src], columns=_write(tmp_path, "m2.toml", both))


def test_title_lines_above_the_header_skip_rows_and_the_hint(tmp_path):
    src = _write(tmp_path, "log.csv", TITLED)
    with pytest.raises(UserError, match=r"on line 3.*set options.skip_rows = 2 in .*m.toml"):
        read("columns", [src], columns=_write(tmp_path, "m.toml", MAP))
    df, _ = read("columns", [src], columns=_write(tmp_path, "s.toml", "[options]\nskip_rows = 2\n" + MAP))
    np.testing.assert_allclose(df["time_s"], [1.5, 3.0])
    np.testing.assert_allclose(df["engine_rpm_rpm"], [838, 814])
    one_wide = _write(tmp_path, "one.csv", "My logger v2\nTime (s),Vehicle Speed (km/h)\n0,36\n1,72\n")
    with pytest.raises(UserError, match=r"set options.skip_rows = 1"):  # a parser error, hinted
        read("columns", [one_wide], columns=_write(tmp_path, "m.toml", MAP))
    for bad in ("-1", "true", "1.5", '"2"'):
        with pytest.raises(UserError, match="options.skip_rows must be a whole number"):
            read("columns", [src], columns=_write(tmp_path, "b.toml", f"[options]\nskip_rows = {bad}\n" + MAP))


# A petrol car's Torque Pro log (yudhi-chen/OBD_viewer): speed and the app's fuel flow, no
# driving power; the user first runs the wheel-level commands on it
def _fuel_log(tmp_path):
    t = np.arange(0.0, 120.0, 1.0)
    v = 10.0 + 5.0 * np.sin(t / 10.0)
    rows = "\n".join(f"trip,{a:g},{b:.3f},{1.0 + 0.2 * b:.3f}" for a, b in zip(t, v))
    return _write(tmp_path, "fuel.csv", "trip_id,time_s,speed_mps,fuel_flow_rate_hour_lph\n" + rows + "\n")


@pytest.mark.parametrize("argv,want", [
    (["calibrate"], "calibrate its fuel chain with `sumo-drvpw calibrate LOG --vehicle V --target fuel"),
    (["compare", "--equation", "vsp_spec"], "then compare or diagnose with --target fuel"),
    (["diagnose"], "calibrate its fuel chain with"),
    (["calibrate", "--target", "fuel"], "give it with --equation (vsp_spec"),
    (["calibrate", "--target", "fuel", "--engine", "memory"], "give it with --equation (vsp_spec"),
])
def test_a_fuel_log_without_driving_power_is_told_what_it_can_do(tmp_path, capsys, argv, want):
    from sumo_drvpw.cli import main as cli_main

    log = _fuel_log(tmp_path)
    out = tmp_path / ("o.toml" if argv[0] == "calibrate" else "o")
    code = cli_main([argv[0], str(log), *argv[1:], "--vehicle", "prius3", "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert "no measured power" in err and "it holds fuel_flow_rate_hour_lph" in err and want in err
    assert not out.exists()


def test_no_driving_power_crosses_a_task_boundary_whole():
    """A Dask task's refusal is pickled to the driver: it stays a NoDrivingPower with its targets."""
    import pickle

    from sumo_drvpw.errors import NoDrivingPower
    from sumo_drvpw.fit.engine import guarded, unguarded

    def refuse():
        raise NoDrivingPower("x.csv: no measured power", ("fuel",))

    with pytest.raises(NoDrivingPower) as e:
        unguarded(pickle.loads(pickle.dumps(guarded(refuse))))
    assert e.value.targets == ("fuel",) and str(e.value) == "x.csv: no measured power"
    assert pickle.loads(pickle.dumps(e.value)).targets == ("fuel",)
