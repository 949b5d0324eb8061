"""Multi-frame diagnostic responses (ISO-TP) in raw CAN logs (sumo_drvpw/data/adapters/isotp.py):
reassembled as CSS Electronics publishes it, on any segmentation, and decoded with a real
UDS DBC from a real CANedge log of a Hyundai Kona Electric."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

pytest.importorskip("asammdf")

from sumo_drvpw.cli import main as cli_main  # noqa: E402
from sumo_drvpw.data.adapters import read  # noqa: E402
from sumo_drvpw.data.adapters.columns import load_mapping  # noqa: E402
from sumo_drvpw.data.adapters.isotp import reassemble  # noqa: E402
from sumo_drvpw.data.adapters.mdf import _open  # noqa: E402

HERE = Path(__file__).resolve().parent / "data" / "mdf"

#: CSS Electronics' api-examples, examples/data-processing/README.md ("UDS example"): nine raw
#: frames of one Kona BMS response on 0x7EC (2028) and the single frame they publish as its
#: reassembly (the response from the service id on)
README_FRAMES = [[16, 62, 98, 1, 1, 255, 247, 231], [33, 255, 100, 0, 0, 0, 0, 131], [34, 0, 3, 13, 244, 10, 9, 9],
                 [35, 9, 9, 10, 0, 0, 10, 182], [36, 35, 182, 50, 0, 0, 146, 0], [37, 0, 1, 197, 0, 0, 4, 112],
                 [38, 0, 0, 0, 155, 0, 0, 1], [39, 143, 0, 2, 157, 31, 9, 1], [40, 101, 0, 0, 0, 0, 11, 184]]
README_RESPONSE = [98, 1, 1, 255, 247, 231, 255, 100, 0, 0, 0, 0, 131, 0, 3, 13, 244, 10, 9, 9, 9, 9, 10, 0, 0, 10,
                   182, 35, 182, 50, 0, 0, 146, 0, 0, 1, 197, 0, 0, 4, 112, 0, 0, 0, 155, 0, 0, 1, 143, 0, 2, 157,
                   31, 9, 1, 101, 0, 0, 0, 0, 11, 184]


def test_the_published_kona_response_is_reassembled_in_both_layouts():
    t = 0.01 * np.arange(len(README_FRAMES))
    data, n = np.array(README_FRAMES, np.uint8), np.full(len(README_FRAMES), 8)
    times, resp, broken = reassemble(t, data, n, "payload")
    assert list(resp[0]) == README_RESPONSE and len(resp) == 1 and broken == 0 and times[0] == 0.0
    times, resp, broken = reassemble(t, data, n, "css")  # the layout CSS's DBC files number bytes in
    assert list(resp[0]) == [62] + README_RESPONSE
    # its last consecutive frame lost as the log ends: nothing decoded, one incomplete
    assert reassemble(t[:-1], data[:-1], n[:-1], "css")[1:] == ([], 1)


def _segment(payload: bytes) -> list[list[int]]:
    """ISO 15765-2 frames (8 bytes, padded with 0xAA) of one response."""
    if len(payload) <= 7:
        return [[len(payload), *payload] + [0xAA] * (7 - len(payload))]
    frames = [[0x10 | (len(payload) >> 8), len(payload) & 0xFF, *payload[:6]]]
    rest, seq = payload[6:], 1
    while rest:
        frames.append([0x20 | seq, *rest[:7]] + [0xAA] * (7 - len(rest[:7])))
        rest, seq = rest[7:], (seq + 1) & 0x0F
    return frames


@settings(max_examples=60, deadline=None)
@given(st.lists(st.binary(min_size=1, max_size=300), min_size=1, max_size=12),
       st.lists(st.integers(0, 11), max_size=3), st.booleans())
def test_any_segmentation_is_reassembled_and_a_lost_frame_drops_its_response(payloads, lose, flow_control):
    """Responses of 1–300 bytes (single frames, first frames with up to 42 consecutive frames,
    sequence numbers wrapping) come back byte for byte in the payload layout; a consecutive
    frame lost drops its response only, and is counted; flow-control frames are skipped."""
    frames, owner = [], []
    for k, p in enumerate(payloads):
        for j, f in enumerate(_segment(p)):
            frames.append(f)
            owner.append((k, j))
        if flow_control:
            frames.append([0x30, 0, 0, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA])
            owner.append((k, -1))
    lost = {k for k in lose if k < len(payloads) and len(payloads[k]) > 7}  # a consecutive frame of k
    keep = [i for i, (k, j) in enumerate(owner) if not (k in lost and j == 1)]
    data = np.array([frames[i] for i in keep], np.uint8)
    times, resp, broken = reassemble(np.arange(len(keep), dtype=float), data, np.full(len(keep), 8), "payload")
    assert resp == [p for k, p in enumerate(payloads) if k not in lost]
    assert broken == len(lost)
    css = reassemble(np.arange(len(keep), dtype=float), data, np.full(len(keep), 8), "css")[1]
    assert css == [bytes([len(p) & 0xFF]) + p for k, p in enumerate(payloads) if k not in lost]


def test_a_real_kona_uds_log_decodes_with_css_dbc(tmp_path):
    """The CANedge log (5 min, 2010 frames) of a Hyundai Kona Electric: the BMS answers DID
    0x0101 on 0x7EC every 2 s in 62 bytes (a first frame and 8 consecutive frames), the
    climate unit DID 0x0100 on 0x7BB. Decoded with CSS's UDS DBC in its layout: the state of
    charge byte reads 100 → 50.0 % (0.5 %/bit), the outside air 7.0 °C (a December day); at
    the log's end the BMS sends 30 first frames the logger no longer asked to continue."""
    m = load_mapping(_mapping(tmp_path), mdf=True)
    notes = []
    mdf = _open(HERE / "kona_uds.MF4", m, notes=notes)
    try:
        soc = mdf.get("M_SID_0x220101_StateOfChargeBMS")
        out = mdf.get("M_SID_0x220100_OutdoorTemp")
        assert len(soc.samples) == 120 and np.all(soc.samples == 50.0) and soc.unit == "%"
        np.testing.assert_allclose(np.median(np.diff(soc.timestamps)), 2.0, atol=0.01)
        assert len(out.samples) == 150 and np.all(out.samples == 7.0)
        assert mdf.get("Battery.response").samples.tolist() == [0x0101] * 120   # the DID, by MESSAGE.Signal
    finally:
        mdf.close()
    assert notes == ["ISO-TP responses reassembled (options.isotp_layout = 'css'): Temperature 150, Battery 120 "
                     "(30 incomplete, left out: a first frame without its consecutive frames — no flow control, "
                     "or a frame lost)"]
    # in the other layout the DBC's bytes are one off: the service id is read from the DID's byte
    m["isotp_layout"] = "payload"
    mdf = _open(HERE / "kona_uds.MF4", m)
    try:
        assert "M_SID_0x220101_StateOfChargeBMS" not in mdf.channels_db
    finally:
        mdf.close()


def _mapping(tmp_path: Path, layout: str | None = None) -> Path:
    """This log has no vehicle speed: the state of charge stands in as the time base's
    channel (mapped to speed_mps) so that the import runs end to end."""
    p = tmp_path / "map.toml"
    p.write_text(f'[options]\ndbc = ["{HERE / "tp_uds.dbc"}"]\n'
                 + (f'isotp_layout = "{layout}"\n' if layout else "")
                 + '[columns.M_SID_0x220101_StateOfChargeBMS]\nname = "speed_mps"\nunit = "m/s"\n'
                 + '[columns.M_SID_0x220100_OutdoorTemp]\nname = "ambient_c"\nunit = "degC"\n', encoding="utf-8")
    return p


def test_the_import_carries_the_reassembled_signals(tmp_path, capsys):
    df, rep = read("columns", HERE / "kona_uds.MF4", _mapping(tmp_path))
    assert len(df) == 120 and np.all(df["ambient_c"] == 7.0)
    assert any(n.startswith("ISO-TP responses reassembled") for n in rep["files"][0]["notes"])
    assert cli_main(["import", "columns", str(HERE / "kona_uds.MF4"), "--columns", str(_mapping(tmp_path, "bogus")),
                     "--out", str(tmp_path / "k.parquet")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "options.isotp_layout must be one of 'css', 'payload', got 'bogus'" in err[0]
    assert not (tmp_path / "k.parquet").exists()


def test_a_real_leaf_log_with_gnss_speed_imports_its_battery_responses(tmp_path):
    """A CANedge log (64 s) of a Nissan Leaf with its GNSS module: the speed from the module's
    DBC, the state of charge and pack temperature from the Li-ion battery controller's
    responses on 0x7BB (service 0x61, 55 bytes over eight frames), decoded with CSS's Nissan
    UDS DBC: a drive log whose battery columns came over ISO-TP. The car stands (GNSS speed
    below 0.5 m/s), at 89.1–89.2 % charge, its pack at 2 °C on a January day."""
    p = tmp_path / "map.toml"
    p.write_text(f'[options]\ndbc = ["{HERE / "tp_uds_nissan.dbc"}", "{HERE / "canmod-gps.dbc"}"]\n'
                 '[columns.Speed]\nname = "speed_mps"\n'
                 '[columns.SoC]\nname = "soc_pct"\nunit = "%"\n'
                 '[columns.BatPackTemp1]\nname = "battery_temp_c"\nunit = "degC"\n', encoding="utf-8")
    out = tmp_path / "leaf.parquet"
    assert cli_main(["import", "columns", str(HERE / "leaf_uds_gnss.MF4"), "--columns", str(p),
                     "--out", str(out)]) == 0
    df = pd.read_parquet(out)
    assert len(df) == 44 and df["speed_mps"].max() < 0.5
    soc = df["soc_pct"].dropna()
    assert len(soc) >= 40 and 89.0 < soc.min() <= soc.max() < 89.3
    assert set(df["battery_temp_c"].dropna()) == {2.0}
    df2, rep = read("columns", HERE / "leaf_uds_gnss.MF4", p)
    assert "ISO-TP responses reassembled (options.isotp_layout = 'css'): SoC_Temp 26" in rep["files"][0]["notes"]
