"""Bad scenario and equation input found by a fuzz run: each is refused in one line naming
the file and the key (or option) and the offending value; through the CLI: exit 2, one
stderr line, no traceback, no output folder.

1. ``[road_class]`` values of the wrong type (``types`` as a list: a ValueError traceback);
2. string booleans (``trace = "no"`` counted as true), strings for lists
   (``sumo.options = "--seed 7"``) and other values of the wrong type;
3. unknown SUMO vClass names (``[vclasses.spaceship]``, an equation's ``vclasses``);
4. unknown keys in an equation file's ``[equation]``;
5. a log-only term of an ``--equation`` file blamed on the scenario;
6. a truncated ``.rou.xml.gz`` (an EOFError traceback in read_vtypes).
"""

from __future__ import annotations

import glob
import gzip
import tomllib
from pathlib import Path

import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.errors import UserError
from sumo_drvpw.model.equations import (DEPRECATED_VCLASSES, EQUATION_KEYS, SUMO_VCLASSES,
                                        builtin_names, equation_from_dict, load_equation)
from sumo_drvpw.sim.scenario import load_scenario
from sumo_drvpw.sim.vtypes import read_vtypes

REPO = Path(__file__).resolve().parent.parent
BUILTIN = REPO / "sumo_drvpw" / "sim" / "builtin"
CFG = (BUILTIN / "scenarios" / "city.sumocfg").as_posix()
HEAD = f'equations = ["vsp_ldv1999", "drvpw_prius3"]\n[sumo]\nconfig = "{CFG}"\n'


def _write(tmp_path, text, name="s.toml") -> Path:
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


def _refused(path: Path, *needles: str, **overrides) -> str:
    """load_scenario refuses ``path`` in one line naming it and every needle."""
    with pytest.raises(UserError) as e:
        load_scenario(path, **overrides)
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg, msg
    for n in needles:
        assert n in msg, (n, msg)
    return msg


def _cli_refused(capsys, argv: list[str], out: Path, *needles: str) -> str:
    """The CLI: exit 2, one stderr line naming every needle, no traceback, no --out."""
    capsys.readouterr()
    rc = cli_main([*argv, "--out", str(out)])
    err = capsys.readouterr().err.strip()
    assert rc == 2, err
    assert "Traceback" not in err and len(err.splitlines()) == 1, err
    for n in needles:
        assert n in err, (n, err)
    assert not out.exists()
    return err


def _equation(tmp_path, body: str, name="eq.toml") -> Path:
    return _write(tmp_path, '[equation]\nname = "e1"\n' + body, name)


# --- 1. [road_class] ------------------------------------------------------------------

@pytest.mark.parametrize("body,key,value", [
    ('types = ["a", "b"]', "road_class.types", "['a', 'b']"),
    ('types = "highway.primary"', "road_class.types", "'highway.primary'"),
    ('types = { "highway.primary" = 3 }', "road_class.types.highway.primary", "3"),
    ('edges = ["e1"]', "road_class.edges", "['e1']"),
    ('edges = { "e1" = "" }', "road_class.edges.e1", "''"),
    ('edges = { "e1" = ["highway"] }', "road_class.edges.e1", "['highway']"),
    ('highway_types = "highway.motorway, highway.trunk"', "road_class.highway_types",
     "'highway.motorway, highway.trunk'"),
    ('highway_types = [1, 2]', "road_class.highway_types", "[1, 2]"),
    ('highway_min_speed_kmh = "80"', "road_class.highway_min_speed_kmh", "'80'"),
    ('highway_min_speed_kmh = true', "road_class.highway_min_speed_kmh", "True"),
])
def test_road_class_values_of_the_wrong_type_are_named(tmp_path, body, key, value):
    _refused(_write(tmp_path, f"{HEAD}[road_class]\n{body}\n"), f"'{key}'", value)


def test_road_class_tables_still_read(tmp_path):
    p = _write(tmp_path, HEAD + '[road_class]\nhighway_min_speed_kmh = 70\nhighway_types = '
               '["highway.motorway"]\ntypes = { "highway.primary" = "arterial" }\n'
               'edges = { "e12" = "highway" }\n')
    rule = load_scenario(p).road_class
    assert rule.types == {"highway.primary": "arterial"} and rule.edges == {"e12": "highway"}
    assert rule.highway_types == ("highway.motorway",)
    assert rule.classify("x", "highway.primary", 30.0) == "arterial"


# --- 2. booleans and other values of the wrong type ------------------------------------

@pytest.mark.parametrize("table,key,value", [
    ("outputs", "trace", '"no"'), ("outputs", "edgedata", '"false"'),
    ("outputs", "figures", "1"), ("outputs", "progress", '"no"'),
    ("outputs", "sumo_device", "0"), ("sumo", "gui", '"yes"'),
    ("vehicles", "default_masses", '"no"'), ("vehicles", "transportable_mass", '"false"'),
    ("vehicles", "default_carrier", "1"),
])
def test_string_and_number_booleans_are_refused(tmp_path, table, key, value):
    text = HEAD + (f"{key} = {value}\n" if table == "sumo" else f"[{table}]\n{key} = {value}\n")
    _refused(_write(tmp_path, text), f"'{table}.{key}' must be true or false", value.strip('"'))


@pytest.mark.parametrize("text,needles", [
    (HEAD + 'options = "--seed 7"\n', ("'sumo.options'", "'--seed 7'", "must be a list of strings")),
    (HEAD + 'options = ["--seed", true]\n', ("'sumo.options'",)),
    (HEAD.replace('["vsp_ldv1999", "drvpw_prius3"]', '"vsp_ldv1999"'),
     ("'equations'", "'vsp_ldv1999'")),
    (HEAD + '[vehicles]\nvtypes = "prius3"\n', ("'vehicles.vtypes'", "'prius3'")),
    (HEAD + '[vtypes.prius3]\nequations = "vsp_ldv1999"\n', ("'vtypes.prius3.equations'",)),
    (HEAD + '[outputs]\ndifference = "vsp_ldv1999 drvpw_prius3"\n', ("'outputs.difference'",)),
    (HEAD + '[outputs]\ndifference = 3\n', ("'outputs.difference'", "3")),
    (HEAD + '[outputs]\nperiod = "300"\n', ("'outputs.period'", "'300'")),
    (HEAD + '[wind]\nspeed_mps = "4"\n', ("'wind.speed_mps'", "'4'")),
    (HEAD + '[slope]\nwindow_m = "20"\n', ("'slope.window_m'", "'20'")),
    (HEAD + '[air]\ndensity_kgm3 = "1.2"\n', ("'air.density_kgm3'", "'1.2'")),
    (HEAD + '[air]\npressure_kpa = 90.0\n', ("air.pressure_kpa", "air.temperature_c")),
    (HEAD + '[air]\ndensity_kgm3 = 1.2\npressure_kpa = 90.0\n', ("air.pressure_kpa",)),
    (HEAD + 'connection = 1\n', ("'sumo.connection'", "1")),
    (HEAD + 'additional = ["x.add.xml"]\n', ("sumo.config", "sumo.additional")),
    ('equations = ["vsp_ldv1999"]\n[sumo]\nconfig = 3\n', ("'sumo.config'", "3")),
    ('equations = ["vsp_ldv1999"]\n[sumo]\nnet = ["a.net.xml"]\n', ("'sumo.net'",)),
    ('vtypes = ["prius3"]\n' + HEAD, ("'vtypes'", "['prius3']")),
    ('vclasses = "bus"\n' + HEAD, ("'vclasses'", "'bus'")),
    (HEAD + '[vtypes.prius3]\nmass_kg = "1625"\n', ("'vtypes.prius3.mass_kg'", "'1625'")),
    (HEAD + '[air]\ndensity_kgm3 = 1e6\n', ("'air.density_kgm3'", "1e+06", "0.6 … 1.6")),
    (HEAD + '[air]\ntemperature_c = 80.0\n', ("'air.temperature_c'", "80")),
    (HEAD + '[air]\ntemperature_c = 10.0\npressure_kpa = 101325\n', ("'air.pressure_kpa'", "101325")),
    (HEAD + '[vtypes.prius3]\ncold_start = 1.5\n', ("'vtypes.prius3.cold_start'", "1.5", "share from 0 to 1")),
    (HEAD + '[vclasses.passenger]\ncold_start = "yes"\n', ("'vclasses.passenger.cold_start'", "'yes'")),
])
def test_values_of_the_wrong_type_are_named(tmp_path, text, needles):
    _refused(_write(tmp_path, text), *needles)


def test_difference_of_the_wrong_type_with_equations_replaced(tmp_path):
    """The file's pair is checked before the run's --equation drops it (was a TypeError)."""
    _refused(_write(tmp_path, HEAD + "[outputs]\ndifference = 3\n"), "'outputs.difference'",
             equations=["vsp_ldv1999"])


@pytest.mark.parametrize("value,share", [("true", 1.0), ("false", 0.0), ("0.3", 0.3), ("1", 1.0)])
def test_cold_start_is_a_switch_or_a_share(tmp_path, value, share):
    assert load_scenario(_write(tmp_path, HEAD + f"[vehicles]\ncold_start = {value}\n")).cold_start == share


@pytest.mark.parametrize("value", ['"yes"', "1.5", "-0.1", "nan"])
def test_cold_start_beyond_a_share_is_refused(tmp_path, value):
    _refused(_write(tmp_path, HEAD + f"[vehicles]\ncold_start = {value}\n"),
             "'vehicles.cold_start' must be true, false or a share from 0 to 1", value.strip('"'))


def test_real_booleans_and_lists_still_read(tmp_path):
    p = _write(tmp_path, HEAD + 'options = ["--seed", "7"]\n[outputs]\ntrace = true\n'
               'edgedata = false\nfigures = false\nprogress = false\n')
    sc = load_scenario(p)
    assert (sc.trace, sc.edgedata, sc.figures, sc.progress) == (True, False, False, False)
    # a number among the SUMO options is written as SUMO reads it
    assert load_scenario(_write(tmp_path, HEAD + 'options = ["--seed", 7]\n')).sumo_args[-2:] == ["--seed", "7"]
    assert sc.sumo_args[-2:] == ["--seed", "7"]


def test_string_boolean_through_the_cli_writes_nothing(tmp_path, capsys):
    p = _write(tmp_path, HEAD + '[outputs]\ntrace = "no"\nedgedata = "false"\n')
    _cli_refused(capsys, ["run", str(p), "--no-figures"], tmp_path / "out", str(p),
                 "outputs.trace", "'no'")


# --- 3. SUMO vClass names ---------------------------------------------------------------

def test_unknown_vclass_table_of_a_scenario_is_refused(tmp_path):
    msg = _refused(_write(tmp_path, HEAD + "[vclasses.spaceship]\nmass_kg = 100\n"),
                   "vclasses.spaceship", "'spaceship'", "not a SUMO vClass", "passenger")
    assert "ship" in msg  # the nearest name


def test_deprecated_vclass_name_says_what_sumo_reads_it_as(tmp_path):
    _refused(_write(tmp_path, HEAD + "[vclasses.public_transport]\nmass_kg = 12000\n"),
             "vclasses.public_transport", "'public_transport'", "'bus'")


def test_known_vclass_tables_still_read(tmp_path):
    sc = load_scenario(_write(tmp_path, HEAD + "[vclasses.bus]\nmass_kg = 14000\n"
                              '[vclasses.custom1]\nequations = ["vsp_ldv1999"]\n'))
    assert sc.vclass_data == {"bus": {"mass_kg": 14000.0}, "custom1": {"equations": ["vsp_ldv1999"]}}


@pytest.mark.parametrize("value", ['["spaceship"]', '["passenger", "spaceship"]', '"passenger, taxi"',
                                   '["cityrail"]'])
def test_unknown_vclass_of_an_equation_is_refused(tmp_path, value):
    p = _equation(tmp_path, f"vclasses = {value}\n[terms]\nacc = 1.0\naero = 0.3\n")
    with pytest.raises(UserError) as e:
        load_equation(p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg and "equation.vclasses" in msg
    bad = "cityrail" if "cityrail" in value else "spaceship" if "spaceship" in value else "passenger, taxi"
    assert repr(bad) in msg


def test_unknown_vclass_of_an_equation_through_the_cli(tmp_path, capsys):
    p = _equation(tmp_path, 'vclasses = ["spaceship"]\n[terms]\nacc = 1.0\naero = 0.3\n')
    _cli_refused(capsys, ["run", "city", "--equation", str(p), "--end", "30", "--no-figures"],
                 tmp_path / "out", str(p), "equation.vclasses", "'spaceship'", "passenger")


def test_every_sumo_vclass_and_every_shipped_equation_is_accepted(tmp_path):
    for vc in SUMO_VCLASSES:
        assert equation_from_dict({"equation": {"name": "e", "vclasses": [vc]},
                                   "terms": {"acc": 1.0}}).vclasses == (vc,)
    assert not set(DEPRECATED_VCLASSES) & set(SUMO_VCLASSES)
    for name in builtin_names():
        load_equation(name)
    files = glob.glob(str(REPO / "docs" / "**" / "*.toml"), recursive=True)
    for f in files:
        doc = tomllib.loads(Path(f).read_text(encoding="utf-8"))
        if "equation" in doc:
            equation_from_dict(doc, f)


# --- 4. unknown [equation] keys -----------------------------------------------------------

def test_unknown_equation_key_is_refused_naming_file_key_and_known_keys(tmp_path):
    p = _equation(tmp_path, "bogus = 3\n[terms]\nacc = 1.0\n")
    with pytest.raises(UserError) as e:
        load_equation(p)
    msg = str(e.value)
    assert "\n" not in msg and str(p) in msg and "'bogus'" in msg and "[equation]" in msg
    assert all(k in msg for k in EQUATION_KEYS)


def test_every_equation_key_is_read(tmp_path):
    p = _equation(tmp_path, 'description = "d"\nsource = "s"\nmass_kg = 1500\nreference_mass_kg = 1500\n'
                  'vclasses = ["passenger"]\npredicts = "wheel"\nspeed_range_mps = [0, 30]\n'
                  "accel_range_mps2 = [-3, 2]\n[beta]\nacc = 1500.0\n")
    eq = load_equation(p)
    assert eq.mass_kg == 1500.0 and eq.speed_range_mps == (0.0, 30.0) and eq.vclasses == ("passenger",)


@pytest.mark.parametrize("key,value", [("description", "3"), ("source", "[1]"), ("name", "true")])
def test_equation_text_keys_must_be_strings(tmp_path, key, value):
    body = f"{key} = {value}\n[terms]\nacc = 1.0\n"
    text = ('[equation]\n' + body) if key == "name" else ('[equation]\nname = "e1"\n' + body)
    p = _write(tmp_path, text, "eq.toml")
    with pytest.raises(UserError, match=rf"equation\.{key} must be a string"):
        load_equation(p)


def test_unknown_equation_key_through_the_cli(tmp_path, capsys):
    p = _equation(tmp_path, "bogus = 3\n[terms]\nacc = 1.0\n")
    _cli_refused(capsys, ["run", "city", "--equation", str(p), "--end", "30", "--no-figures"],
                 tmp_path / "out", str(p), "'bogus'")


# --- 5. a log-only term names the equation file -------------------------------------------

def test_log_only_term_of_an_equation_file_names_that_file(tmp_path, capsys):
    p = _equation(tmp_path, '[terms]\nacc = 1.0\naero = 0.3\n"[ambient_c]" = 2.0\n')
    err = _cli_refused(capsys, ["run", "city", "--equation", str(p), "--end", "30", "--no-figures"],
                       tmp_path / "out", str(p), "[ambient_c]", "ambient_c")
    assert "city.toml" not in err
    assert err.split("error: ", 1)[1].startswith(str(p))


def test_unknown_equation_name_says_where_it_was_written(tmp_path, capsys):
    """A misspelt equation name in a route file's vType param, in a scenario's list, or given
    to the run: the message names the file and vType or key (it named none; found by a
    sweep)."""
    net = BUILTIN / "networks" / "city.net.xml"
    rou = _write(tmp_path, '<routes><vType id="t" vClass="passenger"><param key="drvpw.equation" '
                 'value="vsp_ldv199"/></vType><vehicle id="v" type="t" depart="0">'
                 '<route edges="c00c10 c10c20"/></vehicle></routes>', "typo.rou.xml")
    cfg = _write(tmp_path, f'<configuration><input><net-file value="{net}"/><route-files value="{rou}"/>'
                 '</input></configuration>', "typo.sumocfg")
    _cli_refused(capsys, ["run", str(cfg), "--end", "10", "--no-figures"], tmp_path / "o1",
                 str(rou), "vType 't'", "'vsp_ldv199'")
    sc = _write(tmp_path, 'equations = ["vsp_ldv1999", "moves_pasenger_car"]\n[sumo]\n'
                f'config = "{cfg}"\n', "s.toml")
    _cli_refused(capsys, ["run", str(sc), "--end", "10", "--no-figures"], tmp_path / "o2",
                 f"{sc}: equations", "'moves_pasenger_car'")
    err = _cli_refused(capsys, ["run", "city", "--equation", "nosuch", "--end", "10", "--no-figures"],
                       tmp_path / "o3", "the equations given to the run", "'nosuch'")
    assert "city.toml" not in err
    fcd = _write(tmp_path, '<fcd-export><timestep time="0.00"/></fcd-export>', "fcd.xml")
    _cli_refused(capsys, ["fcd", str(fcd), "--net", str(net), "--equation", "nosuch"], tmp_path / "o4",
                 "the equations given to the run", "'nosuch'")


def test_missing_equation_file_says_which_key_named_it_and_where_it_was_looked_for(tmp_path, capsys):
    """An equation file a scenario names that is not there: the message names the scenario,
    the key and the path looked for (it said only 'equation file not found: nofile.toml';
    rehearsal 2026-11-29)."""
    net = BUILTIN / "networks" / "city.net.xml"
    sc = _write(tmp_path, 'equations = ["vsp_ldv1999", "mine/bus.toml"]\n[sumo]\n'
                f'net = "{net}"\n', "s.toml")
    _cli_refused(capsys, ["run", str(sc), "--end", "10", "--no-figures"], tmp_path / "o1",
                 f"{sc}: equations", "mine/bus.toml", str(tmp_path / "mine" / "bus.toml"))
    sc = _write(tmp_path, 'equations = ["vsp_ldv1999"]\n[sumo]\n'
                f'net = "{net}"\n[vtypes.BUS]\nequations = ["nofile.toml"]\n', "s2.toml")
    _cli_refused(capsys, ["run", str(sc), "--end", "10", "--no-figures"], tmp_path / "o2",
                 f"{sc}: vtypes.BUS.equations", str(tmp_path / "nofile.toml"))


def test_a_vtype_table_naming_no_vtype_of_the_files_is_refused_before_sumo_starts(tmp_path, capsys):
    """`[vtypes.BUSS]` where the route files define BUS: refused before the run, with the
    nearest id (it was warned of after the whole run, exit 0, the buses booked on the
    defaults; rehearsal 2026-11-29). SUMO's own types pass; a vTypeDistribution's id is
    refused too (its vehicles take its members' ids: its settings would book none)."""
    net = BUILTIN / "networks" / "city.net.xml"
    rou = _write(tmp_path, '<routes><vType id="BUS" vClass="bus"/><vTypeDistribution id="mix">'
                 '<vType id="a" probability="1"/></vTypeDistribution><vehicle id="v" type="BUS" depart="0">'
                 '<route edges="c00c10 c10c20"/></vehicle></routes>', "r.rou.xml")
    head = f'equations = ["vsp_ldv1999"]\n[sumo]\nnet = "{net}"\nroutes = ["{rou}"]\n'
    sc = _write(tmp_path, head + '[vtypes.BUSS]\nmass_kg = 14000\n', "s.toml")
    _cli_refused(capsys, ["run", str(sc), "--end", "10", "--no-figures"], tmp_path / "o1",
                 f"{sc}: [vtypes.BUSS]", "did you mean 'BUS'?", "BUS, a, mix")
    sc = _write(tmp_path, head + '[vtypes.mix]\nmass_kg = 3000\n', "s.toml")
    _cli_refused(capsys, ["run", str(sc), "--end", "10", "--no-figures"], tmp_path / "o2",
                 f"{sc}: [vtypes.mix] names a vTypeDistribution", "per member")
    row = '<vehicle id="v" x="0" y="0" angle="0" type="BUS" speed="0" pos="1" lane="c00c10_0" slope="0"/>'
    fcd = _write(tmp_path, f'<fcd-export><timestep time="0.00">{row}</timestep><timestep time="1.00">{row}'
                 '</timestep></fcd-export>', "fcd.xml")
    sc = _write(tmp_path, head + '[vtypes.BUSS]\nmass_kg = 14000\n', "s.toml")
    _cli_refused(capsys, ["fcd", str(fcd), "--scenario", str(sc), "--no-figures"], tmp_path / "o3",
                 f"{sc}: [vtypes.BUSS]", "did you mean 'BUS'?")  # a replay as a run
    for vt in ("BUS", "DEFAULT_VEHTYPE"):
        sc = _write(tmp_path, head + f'[vtypes.{vt}]\nmass_kg = 14000\n', "s.toml")
        assert load_scenario(sc) and cli_main(["run", str(sc), "--end", "2", "--no-figures",
                                               "--out", str(tmp_path / vt)]) == 0


# --- 6. a truncated .gz among the SUMO inputs ---------------------------------------------

def _truncated_gz(path: Path, text: str) -> Path:
    data = gzip.compress(text.encode("utf-8"))
    path.write_bytes(data[: len(data) // 2])
    return path


@pytest.mark.parametrize("damage", ["truncated", "corrupt"])
def test_read_vtypes_names_a_damaged_gzip_file(tmp_path, damage):
    text = (BUILTIN / "scenarios" / "city.rou.xml").read_text(encoding="utf-8")
    text = text.replace("<routes>", '<routes>\n<vType id="car" mass="1500"/>\n' + "<!-- x -->\n" * 200)
    p = tmp_path / "r.rou.xml.gz"
    if damage == "truncated":
        _truncated_gz(p, text)
    else:
        data = bytearray(gzip.compress(text.encode("utf-8")))
        data[20:60] = b"\xff" * 40
        p.write_bytes(bytes(data))
    with pytest.raises(UserError) as e:
        read_vtypes([p])
    assert str(p) in str(e.value) and "gzip" in str(e.value) and "\n" not in str(e.value)


@pytest.mark.sumo
def test_truncated_route_file_of_a_sumo_config_through_the_cli(tmp_path, capsys):
    """The fuzz run's case: a SUMO config whose .rou.xml.gz is cut short after the trips
    a short run loads (SUMO reads routes ahead by --route-steps, 200 s, so it runs; the
    vType reader reads the whole file)."""
    scen = BUILTIN / "scenarios"
    late = "".join(f'    <trip id="late{i}" type="prius3" depart="{1000 + i}" from="c00c10" '
                   'to="c34c44"/>\n' for i in range(3000))
    text = (scen / "city.rou.xml").read_text(encoding="utf-8").replace("</routes>", late + "</routes>")
    gz = _truncated_gz(tmp_path / "city.rou.xml.gz", text)
    cfg = tmp_path / "c.sumocfg"
    cfg.write_text(f'<configuration><input><net-file value="{BUILTIN / "networks" / "city.net.xml"}"/>'
                   f'<route-files value="{gz.name}"/><additional-files value="'
                   f'{scen / "prius3.vtype.xml"}"/></input></configuration>', encoding="utf-8")
    _cli_refused(capsys, ["run", str(cfg), "--end", "30", "--no-figures", "--no-progress"],
                 tmp_path / "out", str(gz), "not a readable gzip file")


@pytest.mark.parametrize("options, named", [
    ('["-r"]', "'-r' takes a value (SUMO's FILE) and is given none"),
    ('["--time-to-teleport"]', "'--time-to-teleport' takes a value (SUMO's TIME)"),
    ('["--seed", "--time-to-teleport", "5"]', "'--seed' takes a value (SUMO's INT) and is given none before "
                                              "'--time-to-teleport'"),
])
def test_a_sumo_option_without_its_value_is_named(tmp_path, capsys, options, named):
    """SUMO said only "The parameter 'true' is not allowed in this context" (exit 2, the
    option unnamed): refused before SUMO starts, in one line naming the option."""
    p = _write(tmp_path, HEAD + f"options = {options}\n")
    _refused(p, "sumo.options", named)
    _cli_refused(capsys, ["run", str(p), "--no-figures"], tmp_path / "out", str(p), named)


def test_sumo_options_with_their_values_still_read(tmp_path):
    """A negative number is a value; a true/false flag alone or with its value; --k=v."""
    opts = ['--time-to-teleport', '-1', '--verbose', '--no-warnings', 'false', '--seed=3', '-b', '0']
    p = _write(tmp_path, HEAD + f"options = {opts!r}\n".replace("'", '"'))
    assert load_scenario(p).sumo_args[-len(opts):] == opts


def test_an_output_option_naming_an_input_is_refused(tmp_path, capsys):
    """sumo.options' outputs at an absolute path are kept where they are: one naming the
    scenario file itself (exit 0, the scenario overwritten by SUMO's tripinfo) or the run's
    route file (--vehroute-output onto -r's file: the file destroyed, SUMO failing half-read)
    is refused before SUMO starts, naming the option and the file; the inputs stay as they were."""
    routes = tmp_path / "r.rou.xml"
    routes.write_text((BUILTIN / "scenarios" / "city.rou.xml").read_text(encoding="utf-8"), encoding="utf-8")
    for name, opts in (("s.toml", ["--tripinfo-output", str(tmp_path / "s.toml")]),
                       ("s2.toml", ["-r", str(routes), f"--vehroute-output={routes}"])):
        p = _write(tmp_path, HEAD + f"options = {opts!r}\n".replace("'", '"'), name)
        before = (p.read_bytes(), routes.read_bytes())
        _refused(p, f"sumo.options: --{opts[-2 if len(opts) == 2 else -1][2:].split('=')[0]}",
                 "a file the run reads")
        _cli_refused(capsys, ["run", str(p), "--no-figures"], tmp_path / "out", str(p), "a file the run reads")
        assert (p.read_bytes(), routes.read_bytes()) == before


@pytest.mark.sumo
def test_an_output_option_given_with_equals_goes_into_the_output_folder(tmp_path, monkeypatch):
    """'--tripinfo-output=ti.xml' was written into the working folder (only '--tripinfo-output
    ti.xml' went into OUT/sumo/, as docs/scenario.md says of a relative path), so '=s.toml' wrote
    over the scenario there, exit 0; now both forms go into OUT/sumo/."""
    monkeypatch.chdir(tmp_path)
    p = _write(tmp_path, HEAD + 'options = ["--tripinfo-output=s.toml"]\n')
    before = p.read_bytes()
    assert cli_main(["run", str(p), "--end", "5", "--no-figures", "--out", str(tmp_path / "out")]) == 0
    assert p.read_bytes() == before and (tmp_path / "out" / "sumo" / "s.toml").is_file()


@pytest.mark.parametrize("options, named", [
    ('["--time-to-teleprot", "5"]', "'--time-to-teleprot' is no option of SUMO's"),
    ('["--seed 7"]', "give each option and value an item of its own"),
    ('["seed", "7"]', "'seed' is neither a SUMO option nor an option's value"),
    ('[""]', "'' is neither a SUMO option"),
])
def test_a_misspelt_sumo_option_or_a_stray_value_is_named(tmp_path, capsys, options, named):
    """SUMO said "On processing option '--time-to-teleprot': The parameter '5' is not allowed
    in this context" (or only "The parameter 'seed' is not allowed …"), naming no typo."""
    p = _write(tmp_path, HEAD + f"options = {options}\n")
    _refused(p, "sumo.options", named)
    _cli_refused(capsys, ["run", str(p), "--no-figures"], tmp_path / "out", str(p), named)
