"""``sumo-drvpw import columns SRC --list``: what a file offers, to write its mapping from
(sumo_drvpw/data/adapters/listing.py) — MDF channels with unit, samples and rate (raw CAN
decoded with the mapping's DBC files, ISO-TP responses reassembled), CSV columns with the
unit their label carries; nothing written; misuse in one line with exit 2."""

from __future__ import annotations

from pathlib import Path

import pytest

from sumo_drvpw.cli import main as cli_main

HERE = Path(__file__).resolve().parent / "data" / "mdf"


def _lines(capsys) -> list[str]:
    return capsys.readouterr().out.splitlines()


def _row(lines, label):
    return next(line.split() for line in lines if line.split() and line.split()[0] == label)


def test_a_raw_can_log_lists_its_frames_then_its_signals_with_the_dbc(tmp_path, capsys):
    pytest.importorskip("asammdf")
    assert cli_main(["import", "columns", str(HERE / "canmod_gps.MF4"), "--list"]) == 0
    out = _lines(capsys)
    assert out[0].endswith("(ASAM MDF): 11 channels") and _row(out, "CAN_DataFrame.ID")[1] == "5477"
    assert any("name the vehicle's DBC files as options.dbc" in line for line in out)
    # a mapping with its [options] alone (the [columns] not yet written) gives the DBC
    m = tmp_path / "map.toml"
    m.write_text(f'[options]\ndbc = ["{(HERE / "canmod-gps.dbc").as_posix()}"]\n')
    assert cli_main(["import", "columns", str(HERE / "canmod_gps.MF4"), "--list", "--columns", str(m)]) == 0
    out = _lines(capsys)
    assert "decoded with canmod-gps.dbc): 39 channels" in out[0]
    assert _row(out, "Speed") == ["Speed", "m/s", "41", "1"]                 # the GNSS at 1 Hz
    assert _row(out, "AccelerationX") == ["AccelerationX", "m/s^2", "4518", "100"]  # the IMU at 100 Hz
    assert sorted(p.name for p in tmp_path.iterdir()) == ["map.toml"]        # nothing written


def test_iso_tp_responses_are_listed_as_signals(tmp_path, capsys):
    pytest.importorskip("asammdf")
    m = tmp_path / "map.toml"
    m.write_text(f'[options]\ndbc = ["{(HERE / "tp_uds.dbc").as_posix()}"]\n')
    assert cli_main(["import", "columns", str(HERE / "kona_uds.MF4"), "--list", "--columns", str(m)]) == 0
    out = _lines(capsys)
    assert _row(out, "M_SID_0x220101_StateOfChargeBMS") == ["M_SID_0x220101_StateOfChargeBMS", "%", "120", "0.5"]
    assert any("ISO-TP responses reassembled" in line and "Battery 120" in line for line in out)


def test_a_csv_without_mapping_is_sniffed_and_its_units_read_from_the_labels(tmp_path, capsys):
    f = tmp_path / "log.csv"
    f.write_bytes("Zeit [s];Geschwindigkeit [km/h];Außentemperatur (°C);Fahrer\n0;0;3;A\n0.1;1.5;3;A\n"
                  "0.2;;3;A\n".encode("latin-1"))
    assert cli_main(["import", "columns", str(f), "--list"]) == 0
    out = _lines(capsys)
    assert out[0].endswith("(table): 4 columns")
    assert _row(out, "Geschwindigkeit") == ["Geschwindigkeit", "[km/h]", "km/h", "2", "2", "0"]
    assert _row(out, "Außentemperatur")[2:5] == ["°C", "3", "3"]
    assert _row(out, "Fahrer") == ["Fahrer", "3", "0", "A"]                  # text: no unit, no numbers
    assert any("read as latin-1, ';'-separated (sniffed)" in line for line in out)


@pytest.mark.parametrize("args, says", [
    (["import", "jlu-road", "x.parquet", "--list"], "--list is for format 'columns'"),
    (["import", "columns", "x.csv", "--columns", "m.toml"], "--out LOG.parquet is required"),
])
def test_misuse_in_one_line(tmp_path, capsys, monkeypatch, args, says):
    monkeypatch.chdir(tmp_path)
    assert cli_main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and says in err[0]
