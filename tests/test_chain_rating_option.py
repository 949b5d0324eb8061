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
                        ((log, "--target", "battery", "--equation", eq), ("--engine-max profile", "--target fuel"))):
        out = tmp / "o.toml"
        rc, _, err = _run(capsys, *argv, "--engine-max", "profile", "--engine", "memory", "--out", out)
        assert rc == 2 and len(err.splitlines()) == 1 and not out.exists(), err
        assert all(w in err for w in words), err
