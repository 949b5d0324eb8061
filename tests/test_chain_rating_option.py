"""`calibrate --target fuel --engine-max profile`: the engine's rated output (``engine_max_w``)
profiled by the command, as the library's ``calibrate_fuel(engine_max_w="profile")`` does
(fit/chain_fuel.py profile_cap, through fit/chain.py ``calibrate_on(rating="profile")``); before,
only a rating declared in the --equation file reached a calibration from the command line.

On the planted truck of tests/test_chain_engine_stream.py (300-kW rating reached on 2 % of the
samples) it is recovered within 2 %, the same through the local engine (fitted in memory, said
so); a rating the equation file declares and a battery target are refused in one line."""

from __future__ import annotations

import tomllib

import pytest

from sumo_drvpw.cli import main as cli_main
from test_chain_engine_stream import CAP_W, MOVING_W, V1, V3, _truck_log


def _run(capsys, *argv):
    rc = cli_main(["calibrate", *map(str, argv)])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err.strip()


@pytest.fixture
def truck(tmp_path):
    """The planted truck's log and an equation file that declares the moving zero-output fuel
    only (no rating)."""
    log, _, beyond = _truck_log(tmp_path)
    assert beyond > 0.01
    eq = tmp_path / "plain.toml"
    eq.write_text(f'[equation]\nname = "rl"\n[terms]\nacc = 1.0\nv1 = {V1}\nv3 = {V3}\n'
                  '[chain]\npredicts = "fuel"\nmoving_idle_fuel_power_w = 0.0\n', encoding="utf-8")
    return log, eq, tmp_path


def test_the_command_profiles_the_rated_output(truck, capsys):
    log, eq, tmp = truck
    chains = {}
    for engine in ("memory", "local"):
        out = tmp / f"{engine}.toml"
        rc, said, err = _run(capsys, log, "--target", "fuel", "--equation", eq, "--engine-max", "profile",
                             "--engine", engine, "--name", "truck", "--out", out)
        assert rc == 0, err
        assert ("fitted in memory" in said) == (engine == "local")
        chains[engine] = tomllib.loads(out.read_text(encoding="utf-8"))["chain"]
    ch = chains["memory"]
    assert ch["engine_max_w"] == pytest.approx(CAP_W, rel=0.02)
    assert ch["moving_idle_fuel_power_w"] == pytest.approx(MOVING_W, rel=0.05)
    assert "rated output" in ch["reading"]["engine_max_w"]
    for k in ("engine_max_w", "idle_fuel_power_w", "moving_idle_fuel_power_w", "marginal_efficiency"):
        assert chains["local"][k] == ch[k]
    # without the option: no rating (none declared)
    rc, _, err = _run(capsys, log, "--target", "fuel", "--equation", eq, "--engine", "memory", "--out", tmp / "d.toml")
    assert rc == 0, err
    assert "engine_max_w" not in tomllib.loads((tmp / "d.toml").read_text(encoding="utf-8"))["chain"]


def test_profile_is_refused_where_a_rating_is_declared_or_no_engine(truck, capsys):
    log, eq, tmp = truck
    declared = tmp / "rated.toml"
    declared.write_text(eq.read_text(encoding="utf-8") + "engine_max_w = 250000.0\n", encoding="utf-8")
    for argv, words in (((log, "--target", "fuel", "--equation", declared), ("rated.toml", "engine_max_w", "declared")),
                        ((log, "--target", "battery", "--equation", eq), ("--engine-max profile", "--target fuel")),
                        # a cap profiled on windowed means reads low (the review's 300-kW truck: 191–299 kW)
                        ((log, "--target", "fuel", "--equation", eq, "--fit-window", 30),
                         ("--fit-window 30", "--engine-max profile", "--engine-max declared"))):
        out = tmp / "o.toml"
        rc, _, err = _run(capsys, *argv, "--engine-max", "profile", "--engine", "memory", "--out", out)
        assert rc == 2 and len(err.splitlines()) == 1 and not out.exists(), err
        assert all(w in err for w in words), err


@pytest.mark.parametrize("values", [[0.85, 0.85, 0.85], [0.7, 0.85, 0.9]])
def test_a_declared_rating_through_an_efficiency_table_is_kept_where_the_engine_reaches_it(values):
    """A rating declared beside a traction-efficiency table over power is kept at the driving power P
    where P/η_t(P) + P_aux reaches it (before: the table's chain kept P_max itself, 300 kW where a
    constant 0.85 keeps (300 − 10)·0.85 = 246.5 kW)."""
    import numpy as np

    from sumo_drvpw.fit.chain_fuel import declared_engine
    from sumo_drvpw.model.chain_toml import chain_from_dict
    from sumo_drvpw.model.equations import Equation

    doc = {"predicts": "fuel", "engine_max_w": 300e3, "aux_power_w": 1e4}
    table = chain_from_dict({**doc, "traction_efficiency": {"power_w": [0.0, 1e5, 4e5], "values": values}})
    cap = declared_engine(Equation("e", {"v1": 1.0}, chain=table))["engine_max_w"]
    eta = float(np.ravel(table.traction_efficiency(0.0, cap))[0])
    assert cap / eta + 1e4 == pytest.approx(300e3, rel=1e-9)
    if len(set(values)) == 1:
        flat = chain_from_dict({**doc, "traction_efficiency": values[0]})
        assert cap == pytest.approx(declared_engine(Equation("e", {"v1": 1.0}, chain=flat))["engine_max_w"], rel=1e-9)


@pytest.mark.parametrize("extra, words", [
    ({"traction_efficiency": {"speed_mps": [0.0, 30.0], "values": [0.8, 0.9]}}, ("traction_efficiency", "speed")),
    ({"aux_power_w": 5000.0, "engine_max_w": 4000.0}, ("aux_power_w", "engine_max_w"))])
def test_a_declared_rating_with_no_one_driving_power_is_refused(extra, words):
    from sumo_drvpw.errors import UserError
    from sumo_drvpw.fit.chain_fuel import declared_engine
    from sumo_drvpw.model.chain_toml import chain_from_dict
    from sumo_drvpw.model.equations import Equation

    ch = chain_from_dict({"predicts": "fuel", "engine_max_w": 300e3, **extra}, "rated.toml")
    with pytest.raises(UserError) as e:
        declared_engine(Equation("e", {"v1": 1.0}, chain=ch))
    msg = str(e.value)
    assert "rated.toml" in msg and "\n" not in msg and all(w in msg for w in words), msg
