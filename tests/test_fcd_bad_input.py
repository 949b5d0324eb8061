"""`sumo-drvpw fcd` on bad input: one line naming the file, column, attribute or option and
the first offending row or value, exit 2, no output folder, inputs untouched (findings of
a fuzz run: truncated gzip, a vehicle without type or lane, a --net that is no network,
date-typed times, implausible speeds, FCD of another network, an empty time window)."""

from __future__ import annotations

import gzip
import hashlib
import json
import re
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.errors import UserError
from sumo_drvpw.model.equations import Equation
from sumo_drvpw.sim.fcd_read import iter_fcd_blocks, read_fcd

REPO = Path(__file__).resolve().parent.parent
NETS = REPO / "sumo_drvpw" / "sim" / "builtin" / "networks"
CITY_NET = NETS / "city.net.xml"
PHYS = Equation("phys", {"acc": 1.0, "grade": 1.0, "aero_rho": 0.25 * 2.23, "roll": 0.01})
TABULAR = {"time": "timestep_time", "id": "vehicle_id", "type": "vehicle_type",
           "speed": "vehicle_speed", "lane": "vehicle_lane", "pos": "vehicle_pos",
           "angle": "vehicle_angle", "slope": "vehicle_slope", "x": "vehicle_x", "y": "vehicle_y"}
ROW = re.compile(r"<(?:vehicle|person) [^>]*/>")


@pytest.fixture(scope="module")
def fcd(tmp_path_factory):
    """A minute of the city scenario's FCD (XML, --precision 6) and its text."""
    from sumo_drvpw.sim import run_scenario

    d = tmp_path_factory.mktemp("fcd")
    path = d / "fcd.xml"
    run_scenario(REPO / "scenarios" / "city.toml", None, end=60, equations=[PHYS],
                 figures=False, options=["--fcd-output", str(path), "--precision", "6"])
    text = path.read_text(encoding="utf-8")
    assert len(ROW.findall(text)) > 100
    return path, text


def _digest(paths) -> dict:
    return {p: hashlib.sha256(Path(p).read_bytes()).hexdigest() for p in paths}


def _refused(capsys, tmp_path, fcd_file, *names, net=CITY_NET, extra=()) -> str:
    """`fcd FCD_FILE --net NET ...`: exit 2, one line on stderr without a traceback naming
    each of ``names``, no output folder, the inputs unchanged; returns the line."""
    out = tmp_path / "out"
    before = _digest([fcd_file, net])
    capsys.readouterr()
    code = cli_main(["fcd", str(fcd_file), "--net", str(net), "--equation", "vsp_ldv1999",
                     "--no-figures", *extra, "--out", str(out)])
    err = capsys.readouterr().err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert code == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    for n in names:
        assert n in lines[0], (n, lines[0])
    assert not out.exists()
    assert _digest([fcd_file, net]) == before
    return lines[0]


def _edit_row(text: str, n: int, fn) -> str:
    """``text`` with its ``n``-th vehicle/person row (0-based, file order) replaced by
    ``fn(row)``."""
    m = list(ROW.finditer(text))[n]
    return text[:m.start()] + fn(m.group(0)) + text[m.end():]


def _tabular(fcd_xml: Path) -> pd.DataFrame:
    """The FCD as SUMO's tabular output (column names ``vehicle_*``)."""
    df = read_fcd(fcd_xml)
    df = df[[k for k in TABULAR if k in df.columns]].rename(columns=TABULAR)
    df.attrs = {}  # the timesteps read_fcd keeps there: not Parquet metadata
    return df.reset_index(drop=True)


@pytest.mark.sumo
def test_a_truncated_gzip_is_named(fcd, tmp_path, capsys):
    """Finding 1: a .xml.gz cut short (a copy interrupted, a run killed) was an EOFError."""
    path, text = fcd
    blob = gzip.compress(text.encode())
    bad = tmp_path / "trunc.xml.gz"
    bad.write_bytes(blob[:len(blob) // 2])
    _refused(capsys, tmp_path, bad, str(bad), "truncated or corrupt")
    bad.write_bytes(b"\x1f\x8b" + b"no gzip stream at all" * 10)  # gzip magic, no gzip
    _refused(capsys, tmp_path, bad, str(bad), "cannot read")


@pytest.mark.sumo
def test_a_vehicle_without_type_is_refused_on_both_engines(fcd, tmp_path, capsys):
    """Finding 2: a vehicle row without ``type`` (SUMO always writes it) was a TypeError
    (local) or a 45-line ArrowInvalid (dask); the reader refuses it, naming the row."""
    path, text = fcd
    bad = tmp_path / "no_type.xml"
    bad.write_text(_edit_row(text, 4, lambda r: re.sub(r' type="[^"]*"', "", r)), encoding="utf-8")
    _refused(capsys, tmp_path, bad, str(bad), "attribute type", "vehicle row 5")
    _refused(capsys, tmp_path, bad, bad.name, "attribute type", "vehicle row 5",
             extra=("--engine", "dask", "--workers", "1"))
    df = _tabular(path)
    df.loc[7, "vehicle_type"] = None
    df.to_parquet(tmp_path / "no_type.parquet")
    _refused(capsys, tmp_path, tmp_path / "no_type.parquet", "column vehicle_type",
             "vehicle row 8")


@pytest.mark.sumo
def test_fcd_without_lanes_is_refused(fcd, tmp_path, capsys):
    """Finding 3: FCD written without ``lane`` was an IndexError."""
    _, text = fcd
    bad = tmp_path / "no_lane.xml"
    bad.write_text(re.sub(r' lane="[^"]*"', "", text), encoding="utf-8")
    _refused(capsys, tmp_path, bad, str(bad), "attribute lane", "vehicle row 1")
    # a mesoscopic run writes the edge instead of the lane: the message says why that FCD
    # carries no driving power (it said only that SUMO writes a lane for every vehicle)
    meso = tmp_path / "meso.xml"
    meso.write_text(re.sub(r' lane="([^"]*)_\d+"', r' edge="\1"', text), encoding="utf-8")
    _refused(capsys, tmp_path, meso, str(meso), "attribute lane", "mesoscopic")


@pytest.mark.sumo
def test_a_row_without_time_or_a_vehicle_twice_in_a_step_is_refused(fcd, tmp_path, capsys):
    """A fuzz run's findings: a tabular row with an empty timestep_time was dropped without
    a word (its distance lost), and a vehicle written twice in one timestep was booked
    twice; both are refused, naming the row."""
    path, text = fcd
    df = _tabular(path)
    df.loc[500, "timestep_time"] = np.nan
    df.to_csv(tmp_path / "no_time.csv", index=False)
    _refused(capsys, tmp_path, tmp_path / "no_time.csv", "column timestep_time", "row 501")
    df = _tabular(path)
    df = pd.concat([df.iloc[:501], df.iloc[500:501], df.iloc[501:]], ignore_index=True)
    df.to_csv(tmp_path / "twice.csv", index=False)
    _refused(capsys, tmp_path, tmp_path / "twice.csv", "appears twice", "row 502")
    bad = tmp_path / "twice.xml"
    bad.write_text(_edit_row(text, 4, lambda r: r + r), encoding="utf-8")
    _refused(capsys, tmp_path, bad, "appears twice", "vehicle row 6")


@pytest.mark.sumo
def test_a_tabular_fcd_with_a_byte_order_mark_is_read(fcd, tmp_path, capsys):
    """A CSV saved by Excel starts with a UTF-8 byte-order mark: its first column read as
    '\ufefftimestep_time' and the file was refused for lacking timestep_time. It is read,
    and books what the XML books."""
    path, _ = fcd
    csv = tmp_path / "bom.csv"
    csv.write_bytes(b"\xef\xbb\xbf" + _tabular(path).to_csv(index=False).encode())
    runs = []
    # the vTypes given: an XML FCD's header names the run's own files, a CSV has no header
    vt = REPO / "sumo_drvpw" / "sim" / "builtin" / "scenarios" / "prius3.vtype.xml"
    for f, out in ((path, "x"), (csv, "c")):
        code = cli_main(["fcd", str(f), "--net", str(CITY_NET), "--equation", "vsp_ldv1999",
                         "--vtypes", str(vt), "--no-figures", "--out", str(tmp_path / out)])
        assert code == 0, capsys.readouterr().err
        runs.append(json.loads((tmp_path / out / "summary.json").read_text(encoding="utf-8")))
    assert runs[1]["vehicles"] == runs[0]["vehicles"] > 0
    assert runs[1]["equations"] == runs[0]["equations"]


@pytest.mark.sumo
def test_a_gap_in_the_fcd_is_named_as_one(fcd, tmp_path, capsys):
    """Timesteps missing from an FCD (a gap, or FCD written every n-th step) are not booked;
    the warning said to call simulationStep() without a target time — advice for a TraCI
    script, not for a file. It now names the gap."""
    path, _ = fcd
    df = _tabular(path)
    t = df["timestep_time"]
    df[(t < 10) | (t > 20)].to_csv(tmp_path / "gap.csv", index=False)
    code = cli_main(["fcd", str(tmp_path / "gap.csv"), "--net", str(CITY_NET), "--equation",
                     "vsp_ldv1999", "--no-figures", "--out", str(tmp_path / "o")])
    assert code == 0, capsys.readouterr().err
    s = json.loads((tmp_path / "o" / "summary.json").read_text(encoding="utf-8"))
    w = [x for x in s["warnings"] if "timesteps of 0.5 s are missing" in x]
    assert s["missed_steps"] == 21 and len(w) == 1 and "simulationStep" not in w[0]


def test_a_net_that_is_no_network_is_named(tmp_path, capsys):
    """Finding 4: ``--net`` given a file with no edges (here: an FCD file) was a
    ValueError."""
    fcd_file = tmp_path / "fcd.xml"
    fcd_file.write_text('<fcd-export><timestep time="0.00"><vehicle id="v" type="t" '
                        'speed="1" pos="1" lane="a_0"/></timestep></fcd-export>\n', encoding="utf-8")
    _refused(capsys, tmp_path, fcd_file, str(fcd_file), "not a SUMO network", net=fcd_file)


@pytest.mark.sumo
def test_a_time_column_of_dates_is_refused(fcd, tmp_path, capsys):
    """Finding 5: a Parquet time column of timestamps was read as nanoseconds (a step of
    5e8 s); SUMO writes seconds. A time span column alike; seconds as numbers are read."""
    path, _ = fcd
    df = _tabular(path)
    ok = tmp_path / "ok.parquet"
    df.to_parquet(ok)
    assert len(read_fcd(ok)) == len(df)
    for name, conv in (("dt", lambda t: pd.to_datetime(t, unit="s")),
                       ("td", lambda t: pd.to_timedelta(t, unit="s"))):
        bad = tmp_path / f"t_{name}.parquet"
        df.assign(timestep_time=conv(df["timestep_time"])).to_parquet(bad)
        _refused(capsys, tmp_path, bad, str(bad), "column timestep_time", "not numbers")
    # the parts of a partitioned FCD are sorted by their first time: refused there too
    parts = tmp_path / "parts"
    parts.mkdir()
    half = len(df) // 2
    for i, part in enumerate((df.iloc[:half], df.iloc[half:])):
        part.assign(timestep_time=pd.to_datetime(part["timestep_time"], unit="s")) \
            .to_parquet(parts / f"part-{i}.parquet")
    with pytest.raises(UserError, match="column timestep_time holds timestamp"):
        list(iter_fcd_blocks(parts))


@pytest.mark.sumo
def test_implausible_speeds_are_refused_naming_the_files_row(fcd, tmp_path, capsys):
    """Finding 6: an infinite speed (distance inf) or 1e9 m/s (4.6e26 J) was booked; a speed
    must be finite, 0 to the drive logs' bound (100 m/s). Read in blocks, the row
    named is the file's."""
    path, text = fcd
    n = len(ROW.findall(text))
    k = n - 3  # in the last block of a read in blocks of 10 rows
    for value in ("1e9", "inf", "100.5", "-5"):
        bad = tmp_path / f"speed_{value}.xml"
        bad.write_text(_edit_row(text, k, lambda r: re.sub(r' speed="[^"]*"',
                                                           f' speed="{value}"', r)), encoding="utf-8")
        _refused(capsys, tmp_path, bad, str(bad), "attribute speed", f"vehicle row {k + 1}",
                 "100 m/s")
        with pytest.raises(UserError, match=f"vehicle row {k + 1} "):
            list(iter_fcd_blocks(bad, chunk_rows=10))
    df = _tabular(path)
    df.loc[k, "vehicle_speed"] = np.inf
    bad = tmp_path / "speed_inf.parquet"
    df.to_parquet(bad)
    _refused(capsys, tmp_path, bad, str(bad), "column vehicle_speed", f"vehicle row {k + 1}",
             "inf")
    with pytest.raises(UserError, match=f"vehicle row {k + 1} "):
        list(iter_fcd_blocks(bad, chunk_rows=10))
    # a partitioned FCD names the part and its own row
    parts = tmp_path / "parts"
    parts.mkdir()
    df.iloc[:k - 5].to_parquet(parts / "part-0.parquet")
    df.iloc[k - 5:].to_parquet(parts / "part-1.parquet")
    with pytest.raises(UserError, match=r"part-1\.parquet: column vehicle_speed is inf at "
                                        r"vehicle row 6 "):
        list(iter_fcd_blocks(parts, chunk_rows=4))


@pytest.mark.sumo
def test_fcd_of_another_network_is_refused_and_unknown_lanes_warned(fcd, tmp_path, capsys):
    """Finding 7: FCD on the wrong network booked nothing with exit 0, a row on a lane the
    network lacks was dropped silently. None of the lanes in the network: refused naming
    the FCD, the network and the first lane; some: booked without them, with a warning
    counting the rows left out (no lane, as the live loop: persons, parked vehicles)."""
    path, text = fcd
    first = re.search(r' lane="([^"]*)"', text).group(1)
    line = _refused(capsys, tmp_path, path, str(path), str(NETS / "highway.net.xml"),
                    repr(first), "another network", net=NETS / "highway.net.xml")
    assert "none of its vehicles' lanes" in line
    out = {}
    for name, t in (("ok", text),
                    ("one", _edit_row(text, 20, lambda r: re.sub(r' lane="[^"]*"',
                                                                 ' lane="nowhere_0"', r)))):
        f = tmp_path / f"{name}.xml"
        f.write_text(t, encoding="utf-8")
        capsys.readouterr()
        assert cli_main(["fcd", str(f), "--net", str(CITY_NET), "--equation", "vsp_ldv1999",
                         "--no-figures", "--out", str(tmp_path / name)]) == 0
        out[name] = json.loads((tmp_path / name / "summary.json").read_text(encoding="utf-8"))
    warned = [w for w in out["one"]["warnings"] if "lanes the network" in w]
    assert len(warned) == 1 and warned[0].startswith("1 FCD row ") and "'nowhere_0'" in warned[0]
    assert not [w for w in out["ok"]["warnings"] if "lanes the network" in w]
    assert out["one"]["samples"] == out["ok"]["samples"] - 1


@pytest.mark.sumo
def test_an_empty_time_window_is_refused(fcd, tmp_path, capsys):
    """Finding 8: ``--begin 100 --end 50`` and ``--end -1`` wrote an empty result with exit
    0; refused as `run` refuses them."""
    path, _ = fcd
    _refused(capsys, tmp_path, path, "--end 50", "--begin 100", extra=("--begin", "100",
                                                                       "--end", "50"))
    _refused(capsys, tmp_path, path, "--end -1", extra=("--end", "-1"))
    _refused(capsys, tmp_path, path, "--end 5", "--begin 5", extra=("--begin", "5", "--end", "5"))


def test_a_file_without_timesteps_or_a_begin_after_its_end_is_refused(fcd, tmp_path, capsys):
    """Rehearsal 2026-11-27: `fcd ti.xml --scenario city.sumocfg` (SUMO's tripinfo given for
    its FCD, the step length known from the scenario) and `fcd FCD --begin 5000` on a file
    ending at 60 s wrote an empty result with exit 0 (0 steps, 0 vehicles); refused in one
    line naming the file."""
    path, _ = fcd
    ti = tmp_path / "ti.xml"
    ti.write_text('<tripinfos>\n    <tripinfo id="a" depart="0.00" routeLength="10.0"/>\n</tripinfos>\n', encoding="utf-8")
    city = str(REPO / "scenarios" / "city.sumocfg")
    _refused(capsys, tmp_path, ti, "ti.xml", "no timestep", extra=("--scenario", city))
    _refused(capsys, tmp_path, path, "fcd.xml", "no timestep", extra=("--scenario", city,
                                                                      "--begin", "5000"))


def test_a_file_without_timesteps_is_refused_on_the_in_memory_path_too(fcd, tmp_path):
    """`process_fcd(..., chunk_rows=None)` (the whole file read first, the reference path)
    refuses a file without timesteps and a --begin after its end as the streamed path does;
    it returned an empty result (0 steps, 0 vehicles) before."""
    from sumo_drvpw.sim.fcd import process_fcd

    path, _ = fcd
    ti = tmp_path / "ti.xml"
    ti.write_text('<tripinfos>\n    <tripinfo id="a" depart="0.00" routeLength="10.0"/>\n</tripinfos>\n', encoding="utf-8")
    city = REPO / "scenarios" / "city.sumocfg"
    for f, kw in ((ti, {}), (path, {"begin_s": 5000})):
        with pytest.raises(UserError, match="no timestep"):
            process_fcd(f, scenario=city, equations=[PHYS], chunk_rows=None, **kw)


@pytest.mark.sumo
@pytest.mark.parametrize("flag", [[], ["--no-progress"]], ids=["bar", "no-progress"])
def test_the_replay_shows_its_progress_on_a_terminal(fcd, tmp_path, capsys, monkeypatch, flag):
    """`fcd` on a terminal counts the timesteps it replays (tqdm, no total: a streamed file's
    length is not known ahead), as `run` shows its steps; `--no-progress` leaves stderr to
    the messages. Before, an FCD replay showed nothing however long it ran."""
    path, text = fcd
    monkeypatch.setattr(sys.stderr, "isatty", lambda: True, raising=False)
    code = cli_main(["fcd", str(path), "--net", str(CITY_NET), "--equation", "vsp_ldv1999",
                     "--no-figures", "--out", str(tmp_path / "o"), *flag])
    err = capsys.readouterr().err
    assert code == 0, err
    steps = len(re.findall(r"<timestep ", text))
    shown = re.findall(r"(?:^|\r)(\d+)step \[", err)  # tqdm: "\r120step [00:00, …]"
    if flag:
        assert not shown
    else:
        assert shown and int(shown[-1]) == steps


@pytest.mark.sumo
def test_an_fcd_of_part_of_the_run_says_so(fcd, tmp_path, capsys):
    """An FCD recorded for a share of the vehicles (device.fcd.probability 0.5, which its
    header writes) was booked as if it were the fleet's, without a note (a rehearsal); now
    a warning names the share, and one recorded on part of the network says that."""
    path, text = fcd
    head = re.search(r"<!--.*?-->", text, re.S)
    assert head and "Configuration" in head.group(0)
    for opt, said in (('<device.fcd.probability value="0.5"/>', "records a share of the vehicles "
                       "(device.fcd.probability 0.5)"),
                      ('<fcd-output.filter-edges.input-file value="edges.txt"/>', "records part of the network")):
        f = tmp_path / f"part{len(said)}.xml"
        f.write_text(text.replace("</libsumoConfiguration>", f"<device>{opt}</device></libsumoConfiguration>", 1), encoding="utf-8")
        out = tmp_path / f"o{len(said)}"
        assert cli_main(["fcd", str(f), "--net", str(CITY_NET), "--equation", "vsp_ldv1999",
                         "--no-figures", "--out", str(out)]) == 0, capsys.readouterr().err
        warn = json.loads((out / "summary.json").read_text(encoding="utf-8")).get("warnings", [])
        assert any(said in w for w in warn), warn
