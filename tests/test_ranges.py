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
