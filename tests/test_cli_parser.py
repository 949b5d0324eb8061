"""The command line's parser (sumo_drvpw/cli/_parser.py): an option holding one value given
twice with different values is refused in one line, exit 2 (argparse keeps the last one
silently: `run --end 600 … --end 900` ran 900 s while the user read 600 in the command)."""

import argparse

import pytest

from sumo_drvpw.cli import build_parser, main


def _single_valued_options():
    """(command, option, two values that parse) for every store option of every command."""
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    out = []
    for name, p in sub.choices.items():
        for a in p._actions:
            if not a.option_strings or not isinstance(a, argparse._StoreAction) or a.nargs not in (None, 1):
                continue
            if a.choices:
                if len(list(a.choices)) < 2:
                    continue
                values = [str(c) for c in list(a.choices)[:2]]
            else:
                values = ["1", "2"]
            try:
                [a.type(v) if a.type else v for v in values]
            except (TypeError, ValueError, argparse.ArgumentTypeError):
                continue
            out.append((name, a.option_strings[-1], values))
    return out


CASES = _single_valued_options()


def test_the_introspection_finds_the_options_users_repeat():
    opts = {(c, o) for c, o, _ in CASES}
    assert {("run", "--end"), ("fcd", "--period"), ("calibrate", "--out")} <= opts
    assert len(CASES) > 50


@pytest.mark.parametrize("command,option,values", CASES, ids=[f"{c} {o}" for c, o, _ in CASES])
def test_an_option_given_twice_differently_is_refused_in_one_line(command, option, values, capsys, tmp_path):
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args([command, option, values[0], option, values[1]])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{option} given twice" in err, err
    assert f"{option} {values[0]}" in err and f"{option} {values[1]}" in err


def test_the_same_value_twice_and_a_flag_twice_are_no_contradiction(capsys, tmp_path):
    out = tmp_path / "o"
    rc = main(["synth", "--out", str(out / "a.parquet"), "--minutes", "0.05", "--minutes", "0.05",
               "--seed", "3", "--seed", "3"])
    assert rc == 0, capsys.readouterr().err
    assert (out / "a.parquet").exists()
    args = build_parser().parse_args(["calibrate", "x.parquet", "--out", "o", "--force", "--force"])
    assert args.force is True


def test_a_refused_repetition_writes_nothing(capsys, tmp_path):
    out = tmp_path / "o"
    with pytest.raises(SystemExit) as e:
        main(["synth", "--out", str(out / "a.parquet"), "--minutes", "0.05", "--minutes", "0.1"])
    assert e.value.code == 2
    assert "--minutes given twice (--minutes 0.05, then --minutes 0.1)" in capsys.readouterr().err
    assert not out.exists()


_PROBE = """
import sys
from sumo_drvpw.cli import main
try:
    rc = main(sys.argv[1:])
except SystemExit as e:
    rc = e.code
print("RC", rc, "pandas" in sys.modules, "sumo_drvpw.sim.loop" in sys.modules)
"""


@pytest.mark.parametrize("argv,rc", [
    (["--help"], 0),
    (["run", "--help"], 0),
    (["run", "x.sumocfg", "--out", "o", "--end", "abc"], 2),  # a bad SUMO time (read by sim/scenario_values)
    (["run", "x.sumocfg", "--out", "o", "--jobs", "2", "--jobs", "3"], 2),
    (["runn", "x"], 2),
], ids=["help", "run help", "run bad time", "run option twice", "no such command"])
def test_help_and_refused_options_load_no_pandas(argv, rc, tmp_path):
    """The command line's start: only the command given is configured, and its options read
    without the sim package's loop or pandas (about half a second of every start); the
    refusal's one line and exit 2 are those of any refusal."""
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-c", _PROBE, *argv], capture_output=True, text=True, cwd=tmp_path)
    assert p.stdout.splitlines()[-1] == f"RC {rc} False False", (p.stdout[-500:], p.stderr)
    if rc == 2:
        assert p.stderr.count("\n") == 1 and "error:" in p.stderr, p.stderr
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("argv", [
    ["run", "no-such.sumocfg", "--out", "o"],
    ["calibrate", "x.parquet", "--out", "o.toml", "--p-enter", "2"],
    ["calibrate", "no-such.parquet", "--out", "o.toml", "--p-enter", "0.1", "--p-remove", "0.05"],
], ids=["run of a missing config", "calibrate bad p-enter", "calibrate p-enter over p-remove"])
def test_refusals_past_the_parser_load_no_pandas(argv, tmp_path):
    """A run of a config that is not there is refused by the scenario's reading, after the
    loop's modules are imported (sim/run.py), and calibrate's option checks come before its
    fit: neither loads pandas (a quarter to half a second of CPU on every refusal; the run's
    reader imported data/wind.py, which loads pandas, for a wind only some runs have, and
    cli/calibrate.py the log's modules at its import)."""
    import subprocess
    import sys

    p = subprocess.run([sys.executable, "-c", _PROBE, *argv], capture_output=True, text=True, cwd=tmp_path)
    assert p.stdout.splitlines()[-1].startswith("RC 2 False"), (p.stdout[-500:], p.stderr)
    assert p.stderr.count("\n") == 1 and "error:" in p.stderr, p.stderr
    assert not (tmp_path / "o").exists() and not (tmp_path / "o.toml").exists()


def test_the_sim_package_still_names_its_public_api():
    """The lazily imported names of sumo_drvpw.sim (README: ``from sumo_drvpw.sim import
    Accountant`` in a user's TraCI script) are the modules' own, ``import *`` gives them, and
    ``dir()`` (help, tab completion) lists them as before the lazy imports."""
    import sumo_drvpw.sim as sim
    from sumo_drvpw.sim.accountant import Accountant

    assert sim.Accountant is Accountant
    ns: dict = {}
    exec("from sumo_drvpw.sim import *", ns)
    assert set(sim.__all__) <= set(ns) and set(sim.__all__) <= set(dir(sim))
    with pytest.raises(AttributeError, match="no attribute 'nope'"):
        sim.nope


def test_the_sim_package_s_modules_are_its_attributes_as_before_the_lazy_names():
    """Before the lazy names, ``import sumo_drvpw.sim`` loaded its modules, so a script could
    write ``sim.chain.ChainLedger`` (docs/energy-chain.md names that dotted path); then it
    raised AttributeError. A fresh process (this one has loaded them all already)."""
    import subprocess
    import sys

    code = ("import sumo_drvpw.sim as s; from sumo_drvpw.sim.chain import ChainLedger; "
            "assert s.chain.ChainLedger is ChainLedger and s.network.__name__ == 'sumo_drvpw.sim.network'\n"
            "try:\n    s.no_such_module\nexcept AttributeError:\n    print('ok')")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "ok", out.stderr


@pytest.mark.parametrize("command", ["calibrate", "compare", "diagnose"])
def test_a_switch_and_its_opposite_together_are_refused_in_one_line(command, capsys):
    """--exclude-dropouts --no-exclude-dropouts set one setting two ways: refused naming both
    (argparse kept the last silently: the dropouts kept); the same switch twice is no contradiction."""
    with pytest.raises(SystemExit) as e:
        build_parser().parse_args([command, "x.parquet", "--out", "o", "--equation", "e.toml", "--exclude-dropouts",
                                   "--no-exclude-dropouts"])
    assert e.value.code == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--exclude-dropouts and --no-exclude-dropouts" in err, err
    args = build_parser().parse_args([command, "x.parquet", "--out", "o", "--equation", "e.toml",
                                      "--no-exclude-dropouts", "--no-exclude-dropouts"])
    assert args.exclude_dropouts is False
