"""Column roles (drive-log spec "Roles", issue #11 §1): declared, stored, inferred, used."""

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.data import roles
from sumo_drvpw.errors import UserError


@pytest.mark.parametrize("name,role", [
    ("ambient_c", "condition"), ("winter", "condition"), ("wiper_on", "condition"),
    ("heater_power_w", "load"), ("aircon_power_w", "load"), ("ac_power_w", "load"),
    ("throttle_pct", "response"), ("accel_pedal_pct", "response"), ("mg2_torque_exec_nm", "response"),
    ("soc_max_pct", "response"), ("tot_char", "response"), ("battery_discharge_energy_j", "response"), ("battery_current_ib_a", "response"),
    ("random_walk", "unknown"), ("tyre_temp_c", "unknown"),
])
def test_roles_inferred_from_clear_names(name, role):
    assert roles.infer_role(name) == role


def test_metadata_round_trip_and_bad_role():
    md = roles.to_metadata({"pedal": "response", "amb": "condition"})
    assert roles.from_metadata({k.decode(): v.decode() for k, v in md.items()}) == {
        "amb": "condition", "pedal": "response"}
    with pytest.raises(UserError, match="role must be one of"):
        roles.to_metadata({"x": "cause"})
    res = roles.resolve(["pedal", "random_walk", "ambient_c"], {"pedal": "condition"})
    assert res["pedal"] == {"role": "condition", "source": "declared"}   # declared wins
    assert res["random_walk"]["role"] == "unknown"
    assert res["ambient_c"]["source"] == "inferred from the name"


def test_mapping_role_reaches_the_log(tmp_path):
    """A role in the mapping TOML is stored with the imported log and read back with it."""
    from sumo_drvpw.cli import main
    from sumo_drvpw.data.log import read_log

    n = 50
    pd.DataFrame({"t": np.arange(n) * 0.5, "v": np.full(n, 36.0), "pos": np.linspace(0, 50, n),
                  "foo": np.arange(n) % 7}).to_csv(tmp_path / "a.csv", index=False)
    (tmp_path / "m.toml").write_text(
        '[columns.t]\nname = "time_s"\nunit = "s"\n[columns.v]\nname = "speed_mps"\nunit = "km/h"\n'
        '[columns.pos]\nname = "pedal_pct"\nunit = "%"\nrole = "response"\n'
        '[columns.foo]\nname = "foo"\nrole = "condition"\n', encoding="utf-8")
    out = tmp_path / "log.parquet"
    assert main(["import", "columns", str(tmp_path / "a.csv"), "--columns", str(tmp_path / "m.toml"),
                 "--out", str(out)]) == 0
    r = roles.of_log(read_log([out]))
    assert r["pedal_pct"] == {"role": "response", "source": "declared"}
    assert r["foo"] == {"role": "condition", "source": "declared"}
    (tmp_path / "bad.toml").write_text(
        '[columns.t]\nname = "time_s"\n[columns.v]\nname = "speed_mps"\nunit = "km/h"\nrole = "cause"\n', encoding="utf-8")
    assert main(["import", "columns", str(tmp_path / "a.csv"), "--columns", str(tmp_path / "bad.toml"),
                 "--out", str(tmp_path / "x.parquet")]) == 2
    assert not (tmp_path / "x.parquet").exists()
