"""Bad values a fuzzing helper put into scenario, equation, candidate and vehicle files
(1013 mutations; 115 tracebacks or hangs, about 60 nonsense values run): each is refused in
one line naming the file and key, exit 2, nothing written. Integers beyond TOML's 64 bits
overflowed floats; a chain's sub-tables given as strings, a fuel as a list, ragged or NaN
efficiency tables crashed; SUMO options after which SUMO runs no simulation crashed or hung;
masses and winds of 1e308 booked inf litres; an edgeData period that is not a whole number
of steps labelled its intervals wrongly. And flags, drive logs and FCD files a second helper
found (674 cases, 17 crashes: --workers 1e9 started a billion processes, an FCD position of
inf indexed out of bounds, a CR-only CSV's csv.Error), with what the checks must let pass."""

from __future__ import annotations

import tomllib
from pathlib import Path

import pytest
import tomli_w

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.errors import UserError

REPO = Path(__file__).resolve().parent.parent
NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"
EQS = REPO / "sumo_drvpw" / "model" / "builtin" / "equations"
ROUTES = ('<routes><vType id="car" vClass="passenger" mass="1400"/>'
          '<flow id="c" type="car" begin="0" end="10" number="2" departSpeed="0"><route edges="c00c10 c10c20"/></flow>'
          '</routes>\n')
BASE = (f'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "{NET.as_posix()}"\nroutes = ["r.rou.xml"]\n'
        'begin = 0\nend = 20\nstep_length = 0.5\n')


def _refused(capsys, argv, out: Path, *words):
    capsys.readouterr()
    assert cli_main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err, err
    for w in words:
        assert w in err, err
    assert not out.exists()


def _run_refused(tmp_path, monkeypatch, capsys, scenario: str, more: list, *words):
    """`run` of the scenario text (with the tiny route file) and ``more`` arguments: refused."""
    monkeypatch.chdir(tmp_path)
    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    (tmp_path / "s.toml").write_text(scenario, encoding="utf-8")
    _refused(capsys, ["run", "s.toml", *more, "--no-figures", "--no-progress", "--out", "o"], tmp_path / "o", *words)


SCENARIOS = {  # name → (what replaces or adds to the base, words the message must hold)
    "huge integer": (BASE.replace("begin = 0", "begin = 1" + "0" * 400), ("sumo.begin", "64 bits")),
    "help": (BASE + 'options = ["--help"]\n', ("sumo.options", "--help")),
    "version": (BASE + 'options = ["--version"]\n', ("sumo.options", "--version")),
    "save a config": (BASE + 'options = ["--save-configuration", "x.sumocfg"]\n', ("--save-configuration",)),
    "wait for a client": (BASE + 'options = ["--remote-port", "1"]\n', ("--remote-port",)),
    "mass 1e308": (BASE + "[vtypes.car]\nmass_kg = 1e308\n", ("vtypes.car.mass_kg", "at most")),
    "wind 1000": (BASE + "[wind]\nspeed_mps = 1000\nfrom_deg = 0\n", ("wind.speed_mps", "at most")),
    "negative begin": (BASE.replace("begin = 0", "begin = -5"), ("sumo.begin", "[0, 1e+09]")),
    "end 1e308": (BASE.replace("end = 20", "end = 1e308"), ("sumo.end",)),
    "step of 0.1 ms": (BASE.replace("step_length = 0.5", "step_length = 0.0001"), ("sumo.step_length", "0.001")),
    "no vType to book": (BASE + "[vehicles]\nvtypes = []\n", ("vehicles.vtypes", "empty")),
    "period not of steps": (BASE + "[outputs]\nperiod = 0.3\n", ("s.toml: outputs.period", "0.5-s steps", "give 0.5 s")),
}


@pytest.mark.sumo
@pytest.mark.parametrize("name", SCENARIOS)
def test_a_scenario_value_is_refused_in_one_line(name, tmp_path, capsys, monkeypatch):
    text, words = SCENARIOS[name]
    _run_refused(tmp_path, monkeypatch, capsys, text, [], "s.toml", *words)


@pytest.mark.sumo
def test_the_runs_own_values_are_named_as_the_runs(tmp_path, capsys, monkeypatch):
    """A period or an end given to the run, not in the file, is named as the run's (a review:
    the file's sumo.end was blamed for --end 2e9)."""
    _run_refused(tmp_path, monkeypatch, capsys, BASE, ["--period", "0.3"], "the run's period", "give 0.5 s")
    _run_refused(tmp_path, monkeypatch, capsys, BASE, ["--end", "2e9"], "the run's end must be in [0, 1e+09]")


@pytest.mark.sumo
def test_what_the_checks_let_pass(tmp_path, monkeypatch):
    """SUMO's default --remote-port 0 and --num-clients 1, a seed of a Unix time in ms, a
    64-bit integer in TOML and an EPA road load with B below 0 are valid and pass."""
    from sumo_drvpw.model.vehicles import load_vehicle
    from sumo_drvpw.sim import run_scenario

    monkeypatch.chdir(tmp_path)
    (tmp_path / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    (tmp_path / "s.toml").write_text(BASE + 'options = ["--remote-port", "0", "--num-clients", "1"]\n'
                                     '[outputs]\nfigures = false\n', encoding="utf-8")
    assert run_scenario(tmp_path / "s.toml", tmp_path / "o")["vehicles"] == 2
    assert cli_main(["synth", "--out", "s.parquet", "--minutes", "0.01", "--seed", "1700000000000"]) == 0
    from sumo_drvpw.fileio import check_toml_integers

    check_toml_integers({"a": [2**63 - 1, -2**63]}, "x")  # the 64-bit ends: no error
    doc = tomllib.loads((REPO / "sumo_drvpw" / "model" / "builtin" / "vehicles" / "prius3.toml").read_text(encoding="utf-8"))
    doc["road_load"]["f1_N_per_mps"] = -0.5
    (tmp_path / "v.toml").write_text(tomli_w.dumps(doc), encoding="utf-8")
    assert load_vehicle(tmp_path / "v.toml").mass_kg > 0
    assert not (tmp_path / "x.sumocfg").exists()


def _chain(**change):
    doc = tomllib.loads((EQS / "epa_gasoline_car.toml").read_text(encoding="utf-8"))
    for k, v in change.items():
        doc["chain"][k] = v
    return doc


EQUATIONS = {  # name → (the equation's document, words)
    "fuel as a list": (_chain(fuel=[1, 2]), ("fuel must be one of",)),
    "std_err a string": (_chain(std_err="x"), ("'std_err' must be a table",)),
    "ragged efficiency table": (_chain(traction_efficiency={"speed_mps": [0, 10], "power_w": [0, 1000],
                                                            "values": [[0.8, 0.88], [0.84]]}),
                                ("traction_efficiency.values", "rows of one length")),
    "NaN on an axis": (_chain(traction_efficiency={"speed_mps": [0.0, float("nan")], "values": [0.8, 0.9]}),
                       ("speed_mps", "strictly increasing")),
    "auxiliary a string": (_chain(standstill_aux_w=10, aux_power_w="abc"), ("aux_power_w", "number")),
    "auxiliary 1 TW": (_chain(aux_power_w=1e12), ("aux_power_w", "beyond any road vehicle")),
    "provenance a number": ({**_chain(), "provenance": 5}, ("'provenance' must be a table",)),
}


@pytest.mark.sumo
@pytest.mark.parametrize("name", EQUATIONS)
def test_an_equation_value_is_refused_in_one_line(name, tmp_path, capsys, monkeypatch):
    doc, words = EQUATIONS[name]
    (tmp_path / "eq.toml").write_text(tomli_w.dumps(doc), encoding="utf-8")
    _run_refused(tmp_path, monkeypatch, capsys, BASE, ["--equation", "eq.toml"], "eq.toml", *words)


def test_a_candidate_files_constraints_not_a_table_and_a_huge_integer(tmp_path):
    from sumo_drvpw.fit.calibrate import resolve_candidates
    from sumo_drvpw.fit.physical import parse_constraints

    with pytest.raises(UserError, match=r"\[constraints\] must be a table"):
        parse_constraints([1], "c.toml")
    (tmp_path / "c.toml").write_text('terms = ["acc", "roll"]\nx = ' + "9" * 30 + "\n", encoding="utf-8")
    with pytest.raises(UserError, match="x = 999.*64 bits"):
        resolve_candidates(str(tmp_path / "c.toml"))
    # a key that sets nothing, and a constraint on a term the file does not offer: said
    for text, words in (('terms = ["acc", "roll"]\np_enter = 0.5\n', "unknown key 'p_enter'"),
                        ('terms = ["acc", "roll"]\n[constraints]\nwarp = { fixed = 1.0 }\n',
                         "constraints.warp constrains no term")):
        (tmp_path / "c.toml").write_text(text, encoding="utf-8")
        with pytest.raises(UserError, match=words):
            resolve_candidates(str(tmp_path / "c.toml"))


def test_a_vehicle_files_table_where_a_number_goes_and_its_road_load_aliases(tmp_path):
    from sumo_drvpw.model.vehicles import load_vehicle

    base = (REPO / "sumo_drvpw" / "model" / "builtin" / "vehicles" / "prius3.toml").read_text(encoding="utf-8")
    doc = tomllib.loads(base)
    for table, key, value, words in (("body", "frontal_area_m2", {"a": 1}, "must be a number"),
                                     ("road_load", "f0_N", -86.0, "[0, "),
                                     ("road_load", "f2_N_per_mps2", "x", "must be a number"),
                                     ("road_load", "f1_N_per_mps", 1e308, "(-10000, 10000]")):
        bad = {k: dict(v) if isinstance(v, dict) else v for k, v in doc.items()}
        bad[table] = {**bad[table], key: value}
        p = tmp_path / "v.toml"
        p.write_text(tomli_w.dumps(bad), encoding="utf-8")
        with pytest.raises(UserError) as e:
            load_vehicle(p)
        assert f"{table}.{key}" in str(e.value) and words in str(e.value), str(e.value)


def test_a_mappings_time_unit_that_is_no_time_unit(tmp_path):
    """options.time_unit = "fortnight" was reported as disagreeing with the column's unit 's'."""
    from sumo_drvpw.data.adapters.columns import load_mapping

    (tmp_path / "m.toml").write_text('[options]\ntime_unit = "fortnight"\n[columns.t]\nname = "time_s"\n'
                                     '[columns.v]\nname = "speed_mps"\n', encoding="utf-8")
    with pytest.raises(UserError, match="options.time_unit 'fortnight' is no time unit"):
        load_mapping(tmp_path / "m.toml")


def _fcd_with_pos(path: Path, pos: str) -> Path:
    path.write_text('<fcd-export>\n<timestep time="0.00">\n<vehicle id="v" x="1" y="1" angle="90" type="DEFAULT_VEHTYPE" '
                    f'speed="1.0" pos="{pos}" lane="c00c10_0" slope="0"/>\n</timestep>\n</fcd-export>\n', encoding="utf-8")
    return path


FLAGS = {  # name → (arguments, words); a second fuzzing helper's flags and files that crashed
    "seed below 0": (["synth", "--out", "s.parquet", "--minutes", "1", "--seed", "-1"], ("--seed",)),
    "0.06 s of driving": (["synth", "--out", "s.parquet", "--minutes", "0.001"], ("--minutes",)),
    "demo of inf minutes": (["demo", "--no-sumo", "--minutes", "inf", "--out", "o"], ("--minutes",)),
    "period 1e308": (["run", "city", "--end", "30", "--period", "1e308", "--out", "o"], ("--period",)),
    "fusion of 1e308 s": (["calibrate", "LOG", "--vehicle", "prius3", "--grade-source", "fused:1e308s", "--out",
                           "o.toml"], ("--grade-source", "fusion_tau_s")),
    "1e23 folds": (["diagnose", "LOG", "--vehicle", "prius3", "--folds", "100000000000000000000000", "--out", "o"],
                   ("folds",)),
    "a billion workers": (["calibrate", "LOG", "--engine", "dask", "--workers", "1000000000", "--out", "o.toml"],
                          ("--workers", "256")),
    "FCD not there": (["fcd", "nope.xml", "--out", "o"], ("FCD file not found: nope.xml",)),
    "FCD not XML": (["fcd", "junk.xml", "--out", "o"], ("junk.xml: not valid XML",)),  # (it said "give --net")
    "FCD position 1e308": (["fcd", "POS", "--net", str(NET), "--out", "o"], ("attribute pos", "1e+308")),
    "proxy correlation inf": (["diagnose", "LOG", "--vehicle", "prius3", "--proxy-corr", "inf", "--out", "o"],
                              ("proxy_corr",)),
    "vType of 1e308 kg": (["export-vtype", "vsp_ldv1999", "--mass", "1e308", "--id", "v", "--out", "v.add.xml"],
                          ("--mass",)),
    "elevation glitch": (["dynamics", "ELEV", "--out", "o"], ("elevation_m", "1e+300")),
}


@pytest.mark.parametrize("name", FLAGS)
def test_a_flag_or_file_is_refused_in_one_line(name, tmp_path, capsys, monkeypatch):
    from conftest import BUNDLED_LOG

    args, words = FLAGS[name]
    monkeypatch.chdir(tmp_path)
    pos = _fcd_with_pos(tmp_path / "pos.xml", "1e308")
    (tmp_path / "junk.xml").write_text("not XML at all\n", encoding="utf-8")
    elev = tmp_path / "elev.csv"  # one elevation of 1e300 among good ones: the grade and the fit moved silently
    elev.write_text("time_s,speed_mps,elevation_m,trip_id\n" + "".join(
        f"{t},{min(t, 10)},{1e300 if t == 20 else 100 + t},a\n" for t in range(40)), encoding="utf-8")
    args = [str(BUNDLED_LOG) if a == "LOG" else str(pos) if a == "POS" else str(elev) if a == "ELEV" else a
            for a in args]
    out = tmp_path / next((args[i + 1] for i, a in enumerate(args) if a == "--out"), "o")
    _refused(capsys, args, out, *words)


def test_a_log_whose_rows_end_in_cr_alone_is_read(tmp_path, capsys):
    """The header check split a CR-only CSV's header with the csv module: a csv.Error traceback
    in calibrate, compare, dynamics and diagnose; pandas reads such a file."""
    p = tmp_path / "cr.csv"
    p.write_text("time_s,speed_mps,trip_id\r" + "".join(f"{t},{min(t, 10)},a\r" for t in range(40)), encoding="utf-8")
    assert cli_main(["dynamics", str(p), "--out", str(tmp_path / "d")]) == 0
    from sumo_drvpw.data.log import read_log

    assert len(read_log(p).df) == 40  # every row, not one long one


def test_a_wind_direction_that_is_no_angle():
    """--wind 40@1e308 became 'from 296°' (1e308 % 360)."""
    from sumo_drvpw.data.wind import parse_wind

    with pytest.raises(UserError, match="direction must be in degrees"):
        parse_wind("40@1e308", "--wind")
    assert parse_wind("3@-90", "--wind") == (3.0, 270.0)
