"""Plausible ranges of a drive log's physical columns (data/ranges.py): a value no road
vehicle's powertrain gives is refused as the log is read, in one line naming the file, the
column, the row and the value, in memory and streamed."""

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.log import bundled_log, read_log
from sumo_drvpw.data.ranges import RANGES, SHAFT_SPEED_MAX_RPM, SHAFT_TORQUE_MAX_NM
from sumo_drvpw.errors import UserError

ROW = 321


@pytest.fixture(scope="module")
def prius_log() -> pd.DataFrame:
    """The bundled Prius 3 test-track log (power-split columns)."""
    return pd.read_parquet(bundled_log())


def _motor_log(prius: pd.DataFrame) -> pd.DataFrame:
    """A single-motor log: the Prius log's MG2 as a BEV's motor (shaft speed and torque)."""
    return prius.drop(columns=["ice_speed_rpm", "mg1_speed_rpm", "mg1_torque_nm"]).rename(
        columns={"mg2_speed_rpm": "motor_speed_rpm", "mg2_torque_nm": "motor_torque_nm"})


#: (column, an absurd value): a logger's garbage, or a unit wrong by far
ABSURD = [("mg2_speed_rpm", 1e9), ("mg1_speed_rpm", -1e6), ("ice_speed_rpm", 1e6),
          ("mg1_torque_nm", 1e7), ("mg2_torque_nm", -5e4), ("motor_speed_rpm", 4e4),
          ("motor_torque_nm", 2.5e4)]


@pytest.mark.parametrize("engine", ["memory", "local"])
@pytest.mark.parametrize("column,value", ABSURD)
def test_an_absurd_shaft_speed_or_torque_is_refused_naming_file_column_row_and_value(
        tmp_path, capsys, prius_log, column, value, engine):
    df = (_motor_log(prius_log) if column.startswith("motor") else prius_log).copy()
    df.loc[ROW, column] = value
    p = tmp_path / "log.csv"
    df.to_csv(p, index=False)
    out = tmp_path / "eq.toml"
    code = cli_main(["calibrate", str(p), "--vehicle", "prius3", "--engine", engine, "--out", str(out)])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    assert str(p) in err and f"column '{column}'" in err and f"row {ROW}" in err and f"{value:g}" in err, err
    assert not out.exists()


def test_the_bounds_cover_every_shaft_column_and_real_machines(tmp_path, prius_log):
    for c in ("ice_speed_rpm", "mg1_speed_rpm", "mg2_speed_rpm", "motor_speed_rpm"):
        assert RANGES[c][:2] == (-SHAFT_SPEED_MAX_RPM, SHAFT_SPEED_MAX_RPM)
    for c in ("mg1_torque_nm", "mg2_torque_nm", "motor_torque_nm"):
        assert RANGES[c][:2] == (-SHAFT_TORQUE_MAX_NM, SHAFT_TORQUE_MAX_NM)
    # what real machines reach is read: a Prius 3 MG2 at 13,500 rpm, a heavy truck engine's
    # 3,700 N·m (Scania's 770-hp V8), a motor spinning backwards (reversing)
    df = prius_log.copy()
    df.loc[10, "mg2_speed_rpm"] = 13_500.0
    df.loc[11, "mg2_speed_rpm"] = -13_500.0
    df.loc[12, "mg2_torque_nm"] = 3_700.0
    p = tmp_path / "ok.parquet"
    df.to_parquet(p)
    assert len(read_log(p)) == len(df)
    # ... and the bound itself, not only far beyond it
    df.loc[13, "mg1_speed_rpm"] = np.nextafter(SHAFT_SPEED_MAX_RPM, np.inf)
    df.to_parquet(p)
    with pytest.raises(UserError, match="mg1_speed_rpm' is 30000 at row 13"):
        read_log(p)


# ------------------------------------------- power, battery, fuel and air flows, loads

def _refused(capsys, code, path, *needles):
    """Exit 2, one line naming the file and every needle, no traceback."""
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2 and len(lines) == 1 and "Traceback" not in err, err
    for n in (str(path.name), *needles):
        assert n in err, err


def _base() -> pd.DataFrame:
    from corpus import base_log

    return base_log()


def _battery() -> pd.DataFrame:
    """The corpus log with the battery's V·I for its power (discharge positive)."""
    df = _base()
    return df.assign(battery_voltage_v=350.0, battery_current_a=df["power_w"] / 350.0).drop(columns="power_w")


@pytest.mark.parametrize("engine", ["memory", "local"])
@pytest.mark.parametrize("column,value", [("power_w", 1e12), ("battery_voltage_v", 1e9),
                                          ("battery_voltage_v", -1.0), ("battery_current_a", -2e4)])
def test_an_absurd_power_or_battery_value_is_refused(tmp_path, capsys, column, value, engine):
    df = _base() if column == "power_w" else _battery()
    df.loc[ROW, column] = value
    p = tmp_path / "log.csv"
    df.to_csv(p, index=False)
    args = ["--target", "battery", "--vehicle", "jlu_bev", "--equation", "roadload_spec"] \
        if column != "power_w" else []
    code = cli_main(["calibrate", str(p), *args, "--engine", engine, "--out", str(tmp_path / "eq.toml")])
    _refused(capsys, code, p, f"column '{column}'", f"row {ROW}", f"{value:g}")
    assert not (tmp_path / "eq.toml").exists()


def _fuel_log(column: str) -> pd.DataFrame:
    df = _base()
    if column == "fuel_rate_gps":
        return df.assign(fuel_rate_gps=0.3 + df["power_w"].clip(lower=0) / 40000.0)
    if column == "fuel_rate_lph":
        return df.assign(fuel_rate_lph=0.6 + df["power_w"].clip(lower=0) / 9000.0)
    # a petrol car's mass air flow and its fuel trim (no fuel flow): the fuel estimated from the air
    return df.assign(maf_gps=3.0 + df["power_w"].clip(lower=0) / 3000.0, short_term_fuel_trim_bank_1_pct=2.0)


@pytest.mark.parametrize("engine", ["memory", "local"])
@pytest.mark.parametrize("column,value", [
    ("fuel_rate_gps", "n/a?"), ("fuel_rate_gps", np.inf), ("fuel_rate_gps", 1e9),
    ("fuel_rate_lph", "x"), ("fuel_rate_lph", np.inf), ("fuel_rate_lph", 5e4),
    ("maf_gps", "x"), ("maf_gps", -np.inf), ("maf_gps", 1e7),
    ("short_term_fuel_trim_bank_1_pct", "x"), ("short_term_fuel_trim_bank_1_pct", np.inf),
    ("short_term_fuel_trim_bank_1_pct", 250.0)])
def test_a_fuel_or_air_flow_that_is_text_infinite_or_absurd_is_refused(tmp_path, capsys, column, value, engine):
    # text was a traceback (ValueError), an infinity or 1e9 g/s a fuel power taken as read
    df = _fuel_log(column)
    if isinstance(value, str):
        df[column] = df[column].astype(object)
    df.loc[ROW, column] = value
    p = tmp_path / "log.csv"
    df.to_csv(p, index=False)
    code = cli_main(["calibrate", str(p), "--target", "fuel", "--engine", engine, "--out", str(tmp_path / "eq.toml")])
    shown = value if isinstance(value, str) else f"{value:g}"
    _refused(capsys, code, p, f"column '{column}'", f"row {ROW}", shown)
    assert not (tmp_path / "eq.toml").exists()


@pytest.mark.parametrize("engine", ["memory", "local"])
@pytest.mark.parametrize("value", [np.inf, 1e12])
def test_an_infinite_or_absurd_load_is_refused(tmp_path, capsys, value, engine):
    df = _battery().assign(heater_w=1500.0)
    df.loc[ROW, "heater_w"] = value
    p = tmp_path / "log.parquet"
    df.to_parquet(p)
    code = cli_main(["calibrate", str(p), "--target", "battery", "--vehicle", "jlu_bev", "--equation",
                     "roadload_spec", "--load", "heater_w", "--engine", engine, "--out", str(tmp_path / "eq.toml")])
    _refused(capsys, code, p, "load column 'heater_w'", f"row {ROW}", f"{value:g}")


@pytest.mark.parametrize("engine", ["memory", "local"])
@pytest.mark.parametrize("column,value", [("gps_speed_mps", "abc"), ("gps_speed_mps", 1e306),
                                          ("gps_speed_mps", np.inf), ("gps_speed_phone_mps", -20.0)])
def test_a_gps_speed_that_is_text_infinite_or_absurd_is_refused(tmp_path, capsys, column, value, engine):
    """A GPS speed column beside the speed (read for the speedometer's note, data/conditions.py)
    was a traceback when text (ValueError) or huge (1e306: OverflowError summing it), and a
    negative or infinite one was passed over unsaid: refused as the speed is, in memory and streamed."""
    df = _base()
    df[column] = df["speed_mps"].astype(object)
    df.loc[ROW, column] = value
    p = tmp_path / "log.csv"
    df.to_csv(p, index=False)
    code = cli_main(["calibrate", str(p), "--engine", engine, "--out", str(tmp_path / "eq.toml")])
    _refused(capsys, code, p, f"column '{column}'", f"row {ROW}", value if isinstance(value, str) else f"{value:g}")
    assert not (tmp_path / "eq.toml").exists()


def test_a_gps_speed_in_range_is_read(tmp_path):
    df = _base()
    df["gps_speed_mps"] = df["speed_mps"] * 0.98
    p = tmp_path / "log.csv"
    df.to_csv(p, index=False)
    assert cli_main(["calibrate", str(p), "--out", str(tmp_path / "eq.toml")]) == 0
