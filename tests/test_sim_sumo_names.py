"""SUMO's output-prefix and output-suffix in a run: the config's outputs land in OUT/sumo/
under the names SUMO gives them (and are named so in the run's notes), the run's own
tripinfo (the emissions comparison) is found under its prefixed name, and a prefix leading
out of OUT/sumo/ is refused. Real SUMO runs."""

from __future__ import annotations

import json
import shutil
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.errors import UserError

pytest.importorskip("libsumo")

REPO = Path(__file__).resolve().parent.parent
BUILTIN = REPO / "sumo_drvpw" / "sim" / "builtin"
DEVICE = '<emissions><device.emissions.probability value="1"/></emissions>'


def _scenario(tmp_path: Path, output: str, more: str = "") -> Path:
    """The built-in city routes in a folder of their own, with a config setting ``output``
    (and ``more``) and an additional file declaring an edgeData output."""
    sc = tmp_path / "sc"
    sc.mkdir()
    for f in ("city.rou.xml", "prius3.vtype.xml"):
        shutil.copy(BUILTIN / "scenarios" / f, sc / f)
    (sc / "ed.add.xml").write_text('<additional><edgeData id="e1" file="ed_out.xml"/></additional>\n', encoding="utf-8")
    cfg = sc / "c.sumocfg"
    cfg.write_text(f"""<configuration>
    <input><net-file value="{BUILTIN / 'networks' / 'city.net.xml'}"/><route-files value="city.rou.xml"/>
           <additional-files value="prius3.vtype.xml,ed.add.xml"/></input>
    <output>{output}</output>
    {more}
    <time><begin value="0"/><end value="120"/><step-length value="0.5"/></time>
    <report><no-warnings value="true"/></report>
</configuration>
""", encoding="utf-8")
    return cfg


def _cli(args, capsys):
    code = cli_main(["run", *map(str, args), "--no-figures", "--no-progress"])
    err = capsys.readouterr().err
    assert "Traceback" not in err
    return code, err


def _files(folder: Path) -> list[str]:
    return sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file())


def test_output_prefix_names_the_outputs_and_the_comparison_reads_its_tripinfo(tmp_path, capsys):
    """output-prefix "run1_" with the config's tripinfo (which the emissions comparison
    reads back), log and an edgeData an additional file declares: before, the run failed
    ("SUMO tripinfo …/sumo/ti.xml: cannot read", exit 2) since SUMO wrote run1_ti.xml; and
    without the comparison its notes named ti.xml, sim.log.txt and ed_out.xml, files that
    are not there."""
    cfg = _scenario(tmp_path, '<tripinfo-output value="ti.xml"/><output-prefix value="run1_"/>'
                    '<log value="sim.log.txt"/>', DEVICE)
    before = _files(cfg.parent)
    out = tmp_path / "o"
    code, err = _cli([cfg, "--out", out], capsys)
    assert code == 0, err
    assert _files(out / "sumo") == ["run1_ed_out.xml", "run1_sim.log.txt", "run1_ti.xml"]
    assert "tripinfo-output (run1_ti.xml)" in err and "log (run1_sim.log.txt)" in err
    assert "ed.add.xml: run1_ed_out.xml" in err and "(ti.xml)" not in err
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["sumo_device"] and summary["sumo_device"][0]["vehicles"] > 0
    ids = {t.get("id") for t in ET.parse(out / "sumo" / "run1_ti.xml").getroot().iter("tripinfo")}
    assert summary["sumo_device"][0]["vehicles"] <= len(ids)
    assert _files(cfg.parent) == before      # inputs untouched, nothing written beside them


def test_prefix_with_folder_and_time_and_a_suffix_with_the_runs_own_tripinfo(tmp_path, capsys):
    """A prefix with a folder part and SUMO's TIME placeholder, and a suffix: the outputs
    land in OUT/sumo/res/ (the folder SUMO would need, made for it) as
    <load time>_sum_S.xml …, named so in the notes; the emissions comparison's own
    tripinfo (the config writes none) is found under the same renaming. Before: SUMO
    refused to start ("Could not build output file …/sumo/res/…")."""
    cfg = _scenario(tmp_path, '<summary value="sum.xml"/><output-prefix value="res/TIME_"/>'
                    '<output-suffix value="_S"/>', DEVICE)
    out = tmp_path / "o"
    code, err = _cli([cfg, "--out", out], capsys)
    assert code == 0, err
    files = _files(out / "sumo")
    assert len(files) == 2 and all(f.startswith("res/") for f in files), files
    summ = next(f for f in files if f.endswith("_sum_S.xml"))
    stamp = summ[len("res/"):-len("_sum_S.xml")]
    assert len(stamp) == 19 and stamp[4] == "-" and "res/" + stamp + "_ed_out_S.xml" in files
    assert f"summary ({summ})" in err and f"ed.add.xml: res/{stamp}_ed_out_S.xml" in err
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["sumo_device"] and summary["sumo_device"][0]["vehicles"] > 0


def test_a_prefix_leading_out_of_the_sumo_folder_is_refused(tmp_path, capsys):
    """"../x_" would have SUMO write the config's outputs beside OUT/sumo/ (among the run's
    own files) and its tripinfo outside the run's temporary folder: one line naming the
    config, the option and its value, exit 2, nothing written."""
    cfg = _scenario(tmp_path, '<tripinfo-output value="ti.xml"/><output-prefix value="../x_"/>')
    out = tmp_path / "o"
    code, err = _cli([cfg, "--out", out], capsys)
    assert code == 2 and err.count("\n") == 1, err
    assert f"SUMO config {cfg}: output-prefix '../x_'" in err
    assert not out.exists() and not (tmp_path / "x_ti.xml").exists()
    from sumo_drvpw.sim.sumo_outputs import naming_leaves_folder

    assert naming_leaves_folder({"output-prefix": "/abs/x_"}) is None   # SUMO: d//abs/x_…
    assert naming_leaves_folder({"output-prefix": "a/../../x_"}) == "output-prefix"


@pytest.mark.parametrize("naming", [
    {"output-prefix": "P.1_", "output-suffix": "_S"},
    {"output-suffix": "_TIME.x"},
    {"output-prefix": "TIME_", "output-suffix": "_S"}])
def test_sumo_file_name_is_what_sumo_writes(tmp_path, naming):
    """The names :func:`sumo_file_name` gives are those SUMO 1.28 writes (the suffix's
    place — before extensions of up to four characters — is SUMO's behaviour, not read
    from its source)."""
    from sumo_drvpw.sim.sumo_outputs import sumo_file_name

    sumo_bin = Path(__import__("sumo").SUMO_HOME) / "bin" / "sumo"
    outputs = {"tripinfo-output": "a.b.xml", "summary-output": "s.abcde",
               "fcd-output": "f.longpart.xml.gz", "vehroute-output": ".y.log", "log": "lg"}
    args = [str(sumo_bin), "-n", str(BUILTIN / "networks" / "city.net.xml"),
            "-r", str(BUILTIN / "scenarios" / "city.rou.xml"),
            "-a", str(BUILTIN / "scenarios" / "prius3.vtype.xml"), "--end", "5", "--no-step-log"]
    for k, v in outputs.items():
        args += [f"--{k}", v]
    for k, v in naming.items():
        args += [f"--{k}", v]
    subprocess.run(args, cwd=tmp_path, check=True, capture_output=True)
    written = sorted(p.name for p in tmp_path.iterdir())
    if any("TIME" in v for v in naming.values()):
        stamp = next(n for n in written if n[:2] == "20" or "_20" in n)
        stamp = stamp[stamp.index("20"):stamp.index("20") + 19]
    else:
        stamp = "TIME"
    assert written == sorted(sumo_file_name(v, naming, stamp) for v in outputs.values())


def test_written_file_finds_the_stamp_or_an_unprefixed_file(tmp_path):
    """written_file: "TIME" matched against the files there; a file SUMO opened without
    the prefix (its save-configuration, measured) found under its own name."""
    from sumo_drvpw.sim.sumo_outputs import written_file

    (tmp_path / "r_2026-01-02-03-04-05_ti.xml").write_text("x", encoding="utf-8")
    assert written_file(tmp_path / "ti.xml", {"output-prefix": "r_TIME_"}).name == \
        "r_2026-01-02-03-04-05_ti.xml"
    (tmp_path / "c.sumocfg").write_text("x", encoding="utf-8")
    assert written_file(tmp_path / "c.sumocfg", {"output-prefix": "P_"}).name == "c.sumocfg"
    assert written_file(tmp_path / "none.xml", {"output-prefix": "P_"}).name == "P_none.xml"


@pytest.mark.parametrize("form", ["spaced", "equals"])
def test_comparison_with_the_device_and_tripinfo_set_in_the_scenarios_options(tmp_path, capsys, form):
    """A scenario whose sumo.options enable the emissions device and write a tripinfo
    themselves, with outputs.sumo_device: the run reads SUMO's totals from that tripinfo and
    leaves the device as the options set it. Before (2026-11-27 rehearsal, port_brunswick),
    the run added both options again and SUMO refused to start ("A value for the option
    'device.emissions.probability' was already set", exit 2)."""
    cfg = _scenario(tmp_path, "")
    ti = tmp_path / "mine" / "ti.xml"
    ti.parent.mkdir()
    opts = (["--tripinfo-output", "ti.xml", "--device.emissions.probability", "1"] if form == "spaced"
            else [f"--tripinfo-output={ti}", "--device.emissions.probability=1"])
    sc = tmp_path / "s.toml"
    sc.write_text(f'equations = ["epa_gasoline_car"]\n[sumo]\nconfig = "{cfg}"\noptions = {json.dumps(opts)}\n'
                  "[outputs]\nsumo_device = true\n", encoding="utf-8")
    out = tmp_path / "o"
    code, err = _cli([sc, "--out", out], capsys)
    assert code == 0, err
    written = out / "sumo" / "ti.xml" if form == "spaced" else ti
    ids = {t.get("id") for t in ET.parse(written).getroot().iter("tripinfo")}
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["sumo_device"] and 0 < summary["sumo_device"][0]["vehicles"] <= len(ids)


@pytest.mark.parametrize("where", ["config", "spaced", "equals", "explicit"])
def test_the_device_switched_on_in_the_options_compares_as_in_the_config(tmp_path, capsys, where):
    """SUMO's emissions device switched on by the config, or by the scenario's sumo.options
    (either option form, a probability or an explicit vehicle list), without
    outputs.sumo_device: each run writes sumo_device.csv beside its own totals, the device
    settings left as given. Before (2026-11-27 rehearsal), only the config's device turned
    the comparison on: with the options' the run wrote no sumo_device.csv and said nothing."""
    more = DEVICE if where == "config" else ""
    cfg = _scenario(tmp_path, "", more)
    opts = {"config": [], "spaced": ["--device.emissions.probability", "1"],
            "equals": ["--device.emissions.probability=1"],
            "explicit": ["--device.emissions.explicit", "f0.0,f1.0"]}[where]
    sc = tmp_path / "s.toml"
    sc.write_text(f'equations = ["epa_gasoline_car"]\n[sumo]\nconfig = "{cfg}"\noptions = {json.dumps(opts)}\n', encoding="utf-8")
    code, err = _cli([sc, "--out", tmp_path / "o"], capsys)
    assert code == 0, err
    rows = (tmp_path / "o" / "sumo_device.csv").read_text(encoding="utf-8").splitlines()
    summary = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))
    assert len(rows) >= 2 and summary["sumo_device"][0]["vehicles"] > 0


def test_options_replace_the_configs_device_setting(tmp_path):
    """The options' device setting replaces the config's, as SUMO takes the command line's:
    probability 0 in the options switches the comparison off, 1 on; outputs.sumo_device
    decides over both."""
    from sumo_drvpw.sim.scenario import load_scenario

    on = _scenario(tmp_path, "", DEVICE)
    for opts, want in (([], True), (["--device.emissions.probability", "0"], False),
                       (["--device.emissions.probability=0", "--device.emissions.probability", "0.5"], True)):
        assert load_scenario(doc={"equations": ["epa_gasoline_car"],
                                  "sumo": {"config": str(on), "options": opts}}).sumo_device is want, opts
    with pytest.raises(UserError, match="'--device.emissions.probability' takes a value"):  # none: refused (40b3ad4)
        load_scenario(doc={"equations": ["epa_gasoline_car"],
                           "sumo": {"config": str(on), "options": ["--device.emissions.probability"]}})
    sc = load_scenario(doc={"equations": ["epa_gasoline_car"], "outputs": {"sumo_device": False},
                            "sumo": {"config": str(on), "options": ["--device.emissions.probability=1"]}})
    assert not sc.sumo_device


@pytest.mark.parametrize("opts", [["--device.emissions.probability", "0"],
                                  ["--device.emissions.probability=0.0", "--device.emissions.explicit", ""]])
def test_sumo_device_with_the_device_off_in_the_options_is_refused(tmp_path, capsys, opts):
    """outputs.sumo_device = true whose SUMO options switch the emissions device off for
    every vehicle (probability 0, no explicit vehicle) contradict each other: the run keeps
    the options' setting, SUMO reports for no vehicle. Refused as the other contradictory
    keys are (exit 2, one line naming the option, nothing written); before, the run wrote
    a sumo_device.csv with no row and said nothing. The same options with sumo_device at
    its default run, without the comparison."""
    cfg = _scenario(tmp_path, "")
    sc = tmp_path / "s.toml"
    body = f'equations = ["epa_gasoline_car"]\n[sumo]\nconfig = "{cfg}"\nend = 60\noptions = {json.dumps(opts)}\n'
    sc.write_text(body + "[outputs]\nsumo_device = true\n", encoding="utf-8")
    code, err = _cli([sc, "--out", tmp_path / "o"], capsys)
    assert code == 2 and not (tmp_path / "o").exists()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "outputs.sumo_device" in lines[0] and "--device.emissions.probability" in lines[0]
    sc.write_text(body, encoding="utf-8")
    code, err = _cli([sc, "--out", tmp_path / "p"], capsys)
    assert code == 0, err
    assert not (tmp_path / "p" / "sumo_device.csv").exists()


def test_a_devices_explicit_vehicles_are_the_runs_own_after_another_run_in_the_process(tmp_path):
    """libsumo keeps the explicit vehicle list of a device (``device.emissions.explicit``)
    that the first run of a process set, for the process's life (SUMO's MSDevice fills it
    once per device): a later run in the same process naming other vehicles equipped the
    first run's (`run a.toml b.toml`, one after the other: b's sumo_device.csv had no row,
    3 alone; this file's tests failed in a random order). Such a run is started in a SUMO
    process of its own and equips its own list: as the same run over TraCI does."""
    from sumo_drvpw.sim import run_scenario

    cfg = _scenario(tmp_path, "")

    def run(vehicles, name, **kw):
        return run_scenario(cfg, None, end=120, figures=False, equations=["epa_gasoline_car"],
                            options=["--device.emissions.explicit", vehicles], **kw).summary["sumo_device"]

    run("f0.0", "a")
    after = run("f1.0,f2.0,f3.0", "b")
    alone = run("f1.0,f2.0,f3.0", "b", connection="traci")   # a SUMO process of its own
    assert alone and [(r["equation"], r["vehicles"]) for r in after] == [(r["equation"], r["vehicles"]) for r in alone]
    for k in ("ours", "sumo"):
        assert [r[k] for r in after] == pytest.approx([r[k] for r in alone], rel=1e-12)
