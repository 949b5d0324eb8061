"""`fcd` without --scenario takes the network, vTypes and stops of the run that recorded
the FCD from the files its header names (sim.fcd_read.recorded_inputs): found from where
the FCD is now, whatever folder SUMO was started in (real SUMO, and headers written here)."""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.sim.fcd_read import recorded_inputs

REPO = Path(__file__).resolve().parent.parent
CITY_NET = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks" / "city.net.xml"

ROUTES = """<routes>
    <vType id="lorry" vClass="truck" mass="12000"/>
    <vType id="car" vClass="passenger" mass="1400"/>
    <flow id="t" type="lorry" from="c00c10" to="c34c44" begin="0" end="30" number="3" departSpeed="0"/>
    <flow id="c" type="car" from="c40c30" to="c04c14" begin="0" end="30" number="3" departSpeed="0"/>
</routes>
"""
CONFIG = """<configuration>
    <input>
        <net-file value="../nets/city.net.xml"/>
        <route-files value="r.rou.xml"/>
    </input>
</configuration>
"""


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """A study laid out as many are: the config in scen/, the network in nets/, the FCD
    written to ../out/ (so the header's paths are relative to scen/, a folder it does not
    name)."""
    import sumolib

    d = tmp_path_factory.mktemp("study")
    (d / "nets").mkdir()
    shutil.copy(CITY_NET, d / "nets" / "city.net.xml")
    (d / "scen").mkdir()
    (d / "scen" / "r.rou.xml").write_text(ROUTES, encoding="utf-8")
    (d / "scen" / "run.sumocfg").write_text(CONFIG, encoding="utf-8")
    (d / "out").mkdir()
    # started in scen/ with a relative config: SUMO writes the paths as the config has them
    subprocess.run([sumolib.checkBinary("sumo"), "-c", "run.sumocfg", "-e", "60",
                    "--fcd-output", "../out/fcd.xml", "--no-step-log", "--no-warnings"],
                   check=True, capture_output=True, cwd=d / "scen")
    return d


@pytest.mark.sumo
def test_fcd_books_trucks_as_trucks_from_the_files_its_header_names(recorded, tmp_path,
                                                                     monkeypatch, capsys):
    """Given only the FCD (before: "give --net"), and given only --net (before: every vType
    a passenger car), the trucks are booked as trucks at their vType's mass, as with
    --vtypes, and a note names the files taken."""
    d = recorded
    monkeypatch.chdir(tmp_path)  # started anywhere
    assert cli_main(["fcd", str(d / "out" / "fcd.xml"), "--no-figures", "--out", "bare"]) == 0
    out = capsys.readouterr().out
    assert "from the run that recorded the FCD" in out and str(d / "scen" / "r.rou.xml") in out
    assert str(d / "nets" / "city.net.xml") in out
    v = pd.read_parquet(tmp_path / "bare" / "vehicles.parquet")
    lorry = v[v.vtype == "lorry"]
    assert len(lorry) and set(lorry.vclass) == {"truck"} and set(lorry.mass_kg) == {12000.0}
    assert set(v[v.vtype == "car"].vclass) == {"passenger"}
    assert cli_main(["fcd", str(d / "out" / "fcd.xml"), "--net", str(d / "nets" / "city.net.xml"),
                     "--no-figures", "--out", "net_only"]) == 0
    assert cli_main(["fcd", str(d / "out" / "fcd.xml"), "--net", str(d / "nets" / "city.net.xml"),
                     "--vtypes", str(d / "scen" / "r.rou.xml"), "--no-figures", "--out", "given"]) == 0
    same = [json.loads((tmp_path / k / "summary.json").read_text(encoding="utf-8"))["equations"]
            for k in ("bare", "net_only", "given")]
    assert same[0] == same[1] == same[2]
    trucks = same[0]["moves_single_unit_truck"]["energy_j"]
    assert trucks and any(t["total"] > 0 for t in trucks.values())


def _fcd_with_header(path: Path, inputs: dict[str, str], fcd_output: str | None) -> Path:
    opts = "".join(f'        <{k} value="{v}"/>\n' for k, v in inputs.items())
    out = f'        <fcd-output value="{fcd_output}"/>\n' if fcd_output else ""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text('<?xml version="1.0" encoding="UTF-8"?>\n\n<!-- generated on 2026-11-27 by '
                    "Eclipse SUMO sumo 1.28.0\n<sumoConfiguration>\n    <input>\n" + opts
                    + "    </input>\n    <output>\n" + out + "    </output>\n</sumoConfiguration>\n"
                    "-->\n\n<fcd-export>\n    <timestep time=\"0.00\"/>\n</fcd-export>\n", encoding="utf-8")
    return path


def _touch(*paths: Path) -> None:
    for p in paths:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text("<routes/>", encoding="utf-8")


def test_paths_are_found_from_where_the_fcd_is_now(tmp_path):
    """The header's paths, relative to a folder it does not name, are found through its
    own fcd-output path: the FCD in a subfolder of the run's folder, and beside it."""
    _touch(tmp_path / "a" / "n.net.xml", tmp_path / "a" / "r.rou.xml", tmp_path / "a" / "add" / "s.add.xml")
    inputs = {"net-file": "n.net.xml", "route-files": "r.rou.xml", "additional-files": "add/s.add.xml"}
    for out in ("res/deep/fcd.xml", "fcd.xml"):
        rec = recorded_inputs(_fcd_with_header(tmp_path / "a" / out, inputs, out), cwd="/")
        assert rec["net"] == tmp_path / "a" / "n.net.xml"
        assert rec["files"] == [tmp_path / "a" / "r.rou.xml", tmp_path / "a" / "add" / "s.add.xml"]
        assert rec["missing"] == []


def test_the_runs_own_folder_beside_the_fcds_is_the_one_holding_its_files(tmp_path):
    """../out/fcd.xml from scen/: scen/ is the folder beside out/ that holds the header's
    files; with two such folders equally good, none is guessed (the files are missing)."""
    _touch(tmp_path / "scen" / "r.rou.xml", tmp_path / "scen" / "v.add.xml", tmp_path / "other" / "r.rou.xml")
    inputs = {"route-files": "r.rou.xml,v.add.xml"}
    fcd = _fcd_with_header(tmp_path / "out" / "fcd.xml", inputs, "../out/fcd.xml")
    rec = recorded_inputs(fcd, cwd="/")
    assert rec["files"] == [tmp_path / "scen" / "r.rou.xml", tmp_path / "scen" / "v.add.xml"]
    _touch(tmp_path / "other" / "v.add.xml")  # now both folders hold both files
    rec = recorded_inputs(fcd, cwd="/")
    assert rec["files"] == [] and rec["missing"] == [("route-files", "r.rou.xml"),
                                                     ("route-files", "v.add.xml")]


def test_the_runs_folder_among_many_is_found_whatever_order_the_file_system_lists_them(tmp_path, monkeypatch):
    """The folders beside the FCD's are searched up to a cap (sim/fcd_read._SEARCH_DIRS), and
    were taken in the order the file system lists them — its own (ext4: by a hash of the
    name), another on another machine or in a copy of the same study: with more folders
    than the cap, the run's folder was found in one order and not in another. Now each
    level in name order: the same files in any listing order."""
    import pathlib

    from sumo_drvpw.sim import fcd_read

    for i in range(fcd_read._SEARCH_DIRS + 1):
        (tmp_path / f"d{i:05d}").mkdir()
    _touch(tmp_path / "a_scen" / "r.rou.xml", tmp_path / "a_scen" / "v.add.xml")
    fcd = _fcd_with_header(tmp_path / "out" / "fcd.xml", {"route-files": "r.rou.xml,v.add.xml"}, "../out/fcd.xml")
    glob, iterdir = pathlib.Path.glob, pathlib.Path.iterdir
    found = []
    for rev in (False, True):  # listings in name order, then in reverse
        monkeypatch.setattr(pathlib.Path, "glob", lambda self, pat, rev=rev: iter(sorted(glob(self, pat), reverse=rev)))
        monkeypatch.setattr(pathlib.Path, "iterdir", lambda self, rev=rev: iter(sorted(iterdir(self), reverse=rev)))
        found.append(recorded_inputs(fcd, cwd="/")["files"])
    assert found[0] == found[1] == [tmp_path / "a_scen" / "r.rou.xml", tmp_path / "a_scen" / "v.add.xml"]


def test_a_moved_fcd_falls_back_to_its_folders_and_the_working_folder(tmp_path):
    """An FCD moved or renamed on its own (its fcd-output path no longer leads to it):
    the FCD's folder, its parent and the working folder are tried; an absolute path is
    taken as written; a name found nowhere is listed missing, not guessed."""
    _touch(tmp_path / "work" / "r.rou.xml", tmp_path / "abs" / "n.net.xml")
    inputs = {"net-file": str(tmp_path / "abs" / "n.net.xml"), "route-files": "r.rou.xml,gone.rou.xml"}
    fcd = _fcd_with_header(tmp_path / "elsewhere" / "renamed.xml", inputs, "/old/place/fcd.xml")
    rec = recorded_inputs(fcd, cwd=tmp_path / "work")
    assert rec["net"] == tmp_path / "abs" / "n.net.xml"
    assert rec["files"] == [tmp_path / "work" / "r.rou.xml"]
    assert rec["missing"] == [("route-files", "gone.rou.xml")]


def test_no_header_no_inputs(tmp_path):
    """A file without SUMO's header (another tool's XML, CSV) or a header naming no input
    gives None: the replay asks for --net as before."""
    (tmp_path / "plain.xml").write_text("<fcd-export><timestep time=\"0\"/></fcd-export>", encoding="utf-8")
    assert recorded_inputs(tmp_path / "plain.xml") is None
    assert recorded_inputs(_fcd_with_header(tmp_path / "h.xml", {}, "h.xml")) is None


@pytest.mark.sumo
def test_the_recordings_battery_device_option_reaches_the_replay(tmp_path):
    """A run given SUMO's option --device.battery.probability 1 on its command line runs a
    vType that writes Energy-model parameters but no emissionClass on SUMO's Energy model,
    and the live run's vtype_energy books it. Its XML FCD's header names the option: the
    replay without a scenario books it too, the same energy (before: the replay did not see
    the option and refused, no vType of SUMO's Energy model)."""
    from sumo_drvpw.sim import run_scenario
    from sumo_drvpw.sim.fcd import process_fcd
    from test_vtype_energy_sumo_cases import HW_NET, PARAMS

    (tmp_path / "r.rou.xml").write_text(
        f'<routes><vType id="pkw" vClass="passenger" sigma="0.5">{PARAMS}</vType>\n'
        '<flow id="a" type="pkw" from="e01" to="e56" begin="0" end="30" period="10" departSpeed="0"/></routes>', encoding="utf-8")
    (tmp_path / "s.toml").write_text(
        f'equations = ["vtype_energy"]\n[sumo]\nnet = "{HW_NET}"\nroutes = ["r.rou.xml"]\nend = 60\n'
        'options = ["--no-warnings", "true"]\n[outputs]\nfigures = false\n', encoding="utf-8")
    live = run_scenario(tmp_path / "s.toml", tmp_path / "live",
                        options=["--device.battery.probability", "1", "--fcd-output",
                                 str(tmp_path / "fcd.xml"), "--precision", "6"])
    rep = process_fcd(tmp_path / "fcd.xml", net=HW_NET, vtype_files=[tmp_path / "r.rou.xml"],
                      equations=["vtype_energy"], out_dir=tmp_path / "rep", figures=False, end=60)
    assert list(live["equations"]) == list(rep["equations"]) == ["vtype_energy.pkw"]
    a = live["equations"]["vtype_energy.pkw"]["energy_j"]["highway"]["total"]
    assert a > 0 and rep["equations"]["vtype_energy.pkw"]["energy_j"]["highway"]["total"] == \
        pytest.approx(a, rel=2e-3)
    pytest.importorskip("distributed")
    from sumo_drvpw.sim.fcd_dask import process_fcd_dask

    dk = process_fcd_dask(tmp_path / "fcd.xml", tmp_path / "dask", net=HW_NET,
                          vtype_files=[tmp_path / "r.rou.xml"], equations=["vtype_energy"],
                          buckets=2, workers=1, figures=False, end=60)
    assert dk["equations"]["vtype_energy.pkw"]["energy_j"] == rep["equations"]["vtype_energy.pkw"]["energy_j"]


_NAME = st.sampled_from(["scen", "run", "out", "data", "nets", "a b", "x.y"])


@settings(max_examples=60, deadline=None)
@given(depth=st.integers(0, 2), names=st.lists(_NAME, min_size=4, max_size=4), ups=st.integers(0, 2),
       downs=st.lists(_NAME, max_size=2), where=st.lists(st.integers(0, 2), min_size=3, max_size=3),
       decoy=st.booleans())
def test_any_layout_sumo_writes_is_found_from_the_fcd(depth, names, ups, downs, where, decoy):
    """Property: the run's folder B (at some depth), the FCD written to ``../``×ups +
    downs below it, the inputs in B, in a folder below B, or in a folder beside B, all
    written relative to B as SUMO writes them: each input is found, as that file, from the
    FCD alone (no working folder to help). A decoy folder beside B holding the route file
    never gives it: B holds as many of the files the search needs, or more (a tie, when the
    route file is the only one: none is guessed, it is listed missing)."""
    import tempfile

    ups = min(ups, depth)  # SUMO's paths climb at most to the root of this tree
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(tmp)
        base = root.joinpath(*[f"{n}{i}" for i, n in enumerate(names[:depth])])
        rel_out = "/".join([".."] * ups + [f"o{i}_{d}" for i, d in enumerate(downs)] + ["fcd.xml"])
        spots = {0: "", 1: "sub/", 2: "../side/"}  # in B, below it, beside it
        files = {}
        for k, (key, fname) in enumerate(zip(("net-file", "route-files", "additional-files"),
                                             ("n.net.xml", "r.rou.xml", "s.add.xml"))):
            spot = spots[where[k]] if depth or where[k] != 2 else ""  # nothing beside the root
            files[key] = spot + fname
            _touch(base / (spot + fname))
        if decoy and depth:
            _touch(base.parent / "decoy" / files["route-files"].split("/")[-1])
        fcd = _fcd_with_header((base / rel_out).resolve(), files, rel_out)
        rec = recorded_inputs(fcd, cwd="/")
        want = {k: (base / files[k]).resolve() for k in files}
        if decoy and depth:  # never the decoy's file; where the decoy ties with B, none
            assert set(rec["missing"]) <= {("route-files", "r.rou.xml")}
            assert rec["net"] == want["net-file"]
            assert rec["files"] == [want[k] for k in ("route-files", "additional-files")
                                    if (k, files[k]) not in rec["missing"]]
            return
        assert rec["missing"] == []
        assert rec["net"] == want["net-file"]
        assert rec["files"] == [want[k] for k in ("route-files", "additional-files")]


@pytest.mark.sumo
def test_a_tabular_fcd_takes_the_files_of_the_config_that_writes_it(recorded, tmp_path, monkeypatch, capsys):
    """SUMO's Parquet and CSV outputs carry no header. When the SUMO config beside the FCD
    (or one folder up) writes it (its fcd-output is this file), fcd takes that config's
    network and route files, says so, and books the trucks as trucks (before: 'give --net',
    and with --net every vType a passenger car). Two configs naming it: none is guessed. None
    naming it (SUMO given --fcd-output on its command line): the refusal offers the config
    beside it as --scenario."""
    import sumolib

    d = tmp_path / "study"
    shutil.copytree(recorded / "nets", d / "nets")
    shutil.copytree(recorded / "scen", d / "scen")
    cfg = (d / "scen" / "run.sumocfg").read_text(encoding="utf-8").replace(
        "</input>", '</input>\n    <output>\n        <fcd-output value="fcd.parquet"/>\n    </output>')
    (d / "scen" / "run.sumocfg").write_text(cfg, encoding="utf-8")
    subprocess.run([sumolib.checkBinary("sumo"), "-c", "run.sumocfg", "-e", "60", "--no-step-log",
                    "--no-warnings"], check=True, capture_output=True, cwd=d / "scen")
    monkeypatch.chdir(tmp_path)
    assert cli_main(["fcd", str(d / "scen" / "fcd.parquet"), "--no-figures", "--out", "o"]) == 0
    out = capsys.readouterr().out
    assert "from the SUMO config that writes the FCD" in out and "run.sumocfg" in out
    v = pd.read_parquet(tmp_path / "o" / "vehicles.parquet")
    assert set(v[v.vtype == "lorry"].vclass) == {"truck"} and set(v[v.vtype == "lorry"].mass_kg) == {12000.0}
    (d / "scen" / "copy.sumocfg").write_text(cfg, encoding="utf-8")  # a second config naming it: ambiguous
    assert cli_main(["fcd", str(d / "scen" / "fcd.parquet"), "--no-figures", "--out", "o2"]) == 2
    err = capsys.readouterr().err  # both named, none said not to write it
    assert "give --net" in err and "write it (copy.sumocfg, run.sumocfg): --scenario the one that ran it" in err
    assert "no SUMO config" not in err
    # written by an --fcd-output on SUMO's command line: no config names it; the one beside
    # it is offered in the one line, and with it the run books as above
    (d / "scen" / "copy.sumocfg").unlink()
    (d / "scen" / "fcd.parquet").rename(d / "scen" / "cmdline.parquet")
    assert cli_main(["fcd", str(d / "scen" / "cmdline.parquet"), "--no-figures", "--out", "o3"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and f"if it ran it, --scenario {d / 'scen' / 'run.sumocfg'}" in err
    assert cli_main(["fcd", str(d / "scen" / "cmdline.parquet"), "--scenario", str(d / "scen" / "run.sumocfg"),
                     "--no-figures", "--out", "o3"]) == 0
    v = pd.read_parquet(tmp_path / "o3" / "vehicles.parquet")
    assert set(v[v.vtype == "lorry"].vclass) == {"truck"}


@pytest.mark.sumo
def test_process_fcd_finds_the_runs_files_as_the_command_does(recorded, tmp_path):
    """The Python API: process_fcd(FCD) with neither network nor vType files takes those
    the FCD's header names, as the fcd command does (before: 'FCD: give the network')."""
    from sumo_drvpw.sim.fcd import process_fcd

    res = process_fcd(recorded / "out" / "fcd.xml", equations=["moves_single_unit_truck", "vsp_ldv1999"],
                      out_dir=tmp_path / "o", figures=False)
    v = pd.read_parquet(tmp_path / "o" / "vehicles.parquet")
    assert set(v[v.vtype == "lorry"].vclass) == {"truck"} and set(v[v.vtype == "lorry"].mass_kg) == {12000.0}
    assert res["equations"]["moves_single_unit_truck"]["energy_j"]


@pytest.mark.sumo
@pytest.mark.parametrize("gz", [False, True])
def test_an_fcd_the_plugin_recorded_names_its_additional_files_not_their_copies(recorded, tmp_path, gz):
    """``sumo-drvpw run`` loads copies of the additional files that declare outputs (their
    outputs sent into OUT/sumo/), from a temporary folder gone after the run; an FCD the run
    records names those copies. The replay takes the originals, beside the run's other
    files (before: listed as missing, with "give --vtypes"); a gzipped one too (its copy
    is written plain, without the .gz: before, listed as missing)."""
    import gzip

    from sumo_drvpw.sim import run_scenario

    d = recorded
    name = "zipped.add.xml.gz" if gz else "stops.add.xml"  # (the study is shared by the module)
    text = ('<additional><vType id="van" vClass="delivery" mass="2500"/>'
            '<edgeData id="ed" file="ed.xml" period="30"/></additional>')
    (d / "scen" / name).write_bytes(gzip.compress(text.encode()) if gz else text.encode())
    (d / "scen" / "addrun.sumocfg").write_text(CONFIG.replace(
        "</input>", f'<additional-files value="{name}"/></input>'), encoding="utf-8")
    fcd = tmp_path / "fcd.xml"
    run_scenario(d / "scen" / "addrun.sumocfg", tmp_path / "o", figures=False, progress=False,
                 end=30, options=["--fcd-output", str(fcd)])
    assert (tmp_path / "o" / "sumo" / "ed.xml").is_file() and not (d / "scen" / "ed.xml").exists()
    got = recorded_inputs(fcd)
    assert got["missing"] == [] and (d / "scen" / name).resolve() in got["files"]
    assert got["net"] == (d / "nets" / "city.net.xml").resolve()


@pytest.mark.sumo
def test_an_fcd_with_a_header_whose_network_is_gone_is_not_said_to_lack_a_config(recorded, tmp_path, monkeypatch,
                                                                                 capsys):
    """An XML FCD with SUMO's header, moved away from the network it names, beside a config
    that writes it: the refusal asks for --net in one line and does not say that no config
    beside it writes it (before: "no SUMO config beside … writes it … an --fcd-output on
    SUMO's command line?", the offer meant for a header-less FCD)."""
    d = tmp_path / "moved"
    d.mkdir()
    shutil.copy(recorded / "out" / "fcd.xml", d / "fcd.xml")
    (d / "run.sumocfg").write_text(CONFIG.replace("</input>", '</input><output><fcd-output value="fcd.xml"/></output>'), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    assert cli_main(["fcd", str(d / "fcd.xml"), "--no-figures", "--out", "o"]) == 2
    err = capsys.readouterr().err.strip()
    assert "give --net" in err and len(err.splitlines()) == 1
    assert "no SUMO config" not in err


@pytest.mark.sumo
def test_a_config_listing_its_files_after_a_comma_and_space_is_read_whole(tmp_path, monkeypatch, capsys):
    """A config that lists its route files as "v.xml, r.rou.xml" (Hamburg's does), started by
    its path from another folder: SUMO reports the list as "scen/v.xml,scen/ r.rou.xml" (getOption,
    the FCD's header) and loads both. The Accountant and `fcd` without --scenario read the
    vTypes of the second file too (before: a rehearsal's trucks booked at SUMO's default
    mass, and every car of an electric vType as petrol)."""
    import sumolib

    from sumo_drvpw.sim import Accountant

    (tmp_path / "nets").mkdir()
    shutil.copy(CITY_NET, tmp_path / "nets" / "city.net.xml")
    scen = tmp_path / "scen"
    scen.mkdir()
    (scen / "r.rou.xml").write_text("<routes/>", encoding="utf-8")
    vtypes, flows = ROUTES.split("    <flow", 1)
    (scen / "flows.rou.xml").write_text("<routes>\n    <flow" + flows, encoding="utf-8")
    (scen / "sub").mkdir()
    (scen / "sub" / "types.xml").write_text(vtypes + "</routes>\n", encoding="utf-8")
    (scen / "run.sumocfg").write_text(CONFIG.replace('value="r.rou.xml"', 'value="r.rou.xml, sub/types.xml, flows.rou.xml"'), encoding="utf-8")
    monkeypatch.chdir(tmp_path)
    subprocess.run([sumolib.checkBinary("sumo"), "-c", "scen/run.sumocfg", "-e", "60",
                    "--fcd-output", "fcd.xml", "--no-step-log", "--no-warnings"],
                   check=True, capture_output=True)
    assert "scen/ sub/types.xml" in (tmp_path / "fcd.xml").read_text(encoding="utf-8")[:3000]  # as SUMO reports it
    assert cli_main(["fcd", "fcd.xml", "--no-figures", "--out", "replay"]) == 0
    v = pd.read_parquet(tmp_path / "replay" / "vehicles.parquet")
    assert set(v[v.vtype == "lorry"].mass_kg) == {12000.0} and set(v[v.vtype == "lorry"].vclass) == {"truck"}

    import libsumo

    libsumo.start([sumolib.checkBinary("sumo"), "-c", "scen/run.sumocfg", "--no-step-log", "--no-warnings"])
    try:
        acc = Accountant(libsumo, figures=False)
        libsumo.addStepListener(acc)
        while libsumo.simulation.getTime() < 60 - 1e-9:
            libsumo.simulationStep()
        res = acc.result()
    finally:
        libsumo.close()
    for v in (v, res.vehicles):  # (moves_passenger_car books at its source type's fixed mass)
        car = v[(v.vtype == "car") & (v.equation == "vsp_ldv1999")]
        assert set(v[v.vtype == "lorry"].mass_kg) == {12000.0} and set(car.mass_kg) == {1400.0}


@pytest.mark.sumo
def test_a_route_file_the_header_names_and_that_is_gone_is_warned_of(recorded, tmp_path, monkeypatch, capsys):
    """Its vTypes are unknown, so its trucks are booked as cars: a warning (it was a note
    among the notes), naming the file."""
    study = tmp_path / "study"
    shutil.copytree(recorded, study)
    (study / "scen" / "r.rou.xml").unlink()
    monkeypatch.chdir(tmp_path)
    assert cli_main(["fcd", str(study / "out" / "fcd.xml"), "--no-figures", "--out", "o"]) == 0
    err = capsys.readouterr().err
    assert "warning: the FCD's header names r.rou.xml, not found beside the FCD" in err
    assert "booked as passenger cars" in err
    v = pd.read_parquet(tmp_path / "o" / "vehicles.parquet")
    assert set(v[v.vtype == "lorry"].vclass) == {"passenger"}  # what the warning says


@pytest.mark.sumo
def test_a_route_file_the_header_names_and_that_is_gone_is_recorded_in_the_summary(recorded, tmp_path, monkeypatch,
                                                                                   capsys):
    """The warning that the header's route file is gone (its trucks booked as cars) was
    printed and not recorded (measured 2026-11-29: summary.json's warnings without it, as
    the replay's library call, process_fcd without vTypes, never said it at all). Now
    summary.json records it, with the file in source.inputs_not_found — from the command,
    from process_fcd and on Dask alike —, and the command prints it once, its note up front
    naming the options that give the files."""
    from sumo_drvpw.sim.fcd import process_fcd

    study = tmp_path / "study"
    shutil.copytree(recorded, study)
    (study / "scen" / "r.rou.xml").unlink()
    fcd = study / "out" / "fcd.xml"
    monkeypatch.chdir(tmp_path)
    assert cli_main(["fcd", str(fcd), "--no-figures", "--out", "o"]) == 0
    cap = capsys.readouterr()
    summary = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))
    said = [w for w in summary["warnings"] if "names r.rou.xml, not found beside the FCD" in w]
    assert len(said) == 1 and "booked as passenger cars" in said[0] and str(fcd) in said[0]
    assert summary["source"]["inputs_not_found"] == ["r.rou.xml"]
    assert "--" not in said[0]  # (library text: no command-line option)
    assert cap.err.count("names r.rou.xml, not found beside the FCD") == 1  # the summary's, once
    assert "give --vtypes (and --net) for its vTypes" in cap.out
    res = process_fcd(fcd, net=study / "nets" / "city.net.xml", out_dir=tmp_path / "api", figures=False,
                      equations=["vsp_ldv1999"])
    assert said[0] in res["warnings"]
    assert res["source"]["inputs_not_found"] == ["r.rou.xml"]
    # given the files (--vtypes), nothing of the header's is said
    (study / "types.rou.xml").write_text(ROUTES, encoding="utf-8")
    res = process_fcd(fcd, net=study / "nets" / "city.net.xml", vtype_files=[study / "types.rou.xml"],
                      out_dir=tmp_path / "given", figures=False, equations=["vsp_ldv1999"])
    assert not [w for w in res["warnings"] if "not found beside the FCD" in w]
    assert res["source"]["inputs_not_found"] == []
    pytest.importorskip("distributed")
    from sumo_drvpw.sim.fcd_dask import process_fcd_dask

    dk = process_fcd_dask(fcd, tmp_path / "dask", net=study / "nets" / "city.net.xml", equations=["vsp_ldv1999"],
                          buckets=2, workers=1, figures=False)
    assert said[0] in dk["warnings"] and dk["source"]["inputs_not_found"] == ["r.rou.xml"]
