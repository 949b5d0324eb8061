"""A CSV drive log cut short inside its last row (data/truncated.py): read up to that row,
in memory and streamed, and said naming the file and the row; a row in the middle with
fewer fields than the header is no cut."""

import numpy as np
import pandas as pd
import pytest

from corpus import base_log
from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.data.adapters import read as import_read
from sumo_drvpw.data.log import read_log
from sumo_drvpw.data.stream import Part, iter_measured
from sumo_drvpw.data.truncated import complete_bytes
from sumo_drvpw.errors import UserError


def _log() -> pd.DataFrame:
    df = base_log(n=800)
    df["heater_w"] = 1500.0 + 100.0 * np.sin(np.arange(len(df)) / 50.0)  # an extra signal
    return df


def _cut_text(df: pd.DataFrame, keep) -> str:
    """The CSV text of ``df`` with its last line cut to ``keep(line)`` characters."""
    lines = df.to_csv(index=False).splitlines()
    last = lines[-1]
    return "\n".join(lines[:-1]) + "\n" + last[:keep(last)]


#: where a logger's last row may be cut: inside a middle field (fewer fields than the
#: header), inside the last field (the field count whole), inside time (a time that goes
#: backwards), or right after the trip id (no time, no speed)
CUTS = {
    "middle field": lambda s: s.index(",", s.index(",") + 1) + 3,
    "last field": lambda s: len(s) - 4,
    "time": lambda s: s.index(",") + 2,
    "after the trip id": lambda s: s.index(",") + 1,
}


@pytest.mark.parametrize("where", sorted(CUTS))
def test_read_log_leaves_the_cut_row_out_and_counts_it(tmp_path, where):
    df = _log()
    cut = tmp_path / "cut.csv"
    cut.write_text(_cut_text(df, CUTS[where]), encoding="utf-8")
    whole = tmp_path / "whole.csv"
    df.iloc[:-1].to_csv(whole, index=False)
    a, b = read_log(cut), read_log(whole)
    assert a.counts["truncated_rows"] == {str(cut): len(df) - 1}
    assert "truncated_rows" not in b.counts
    # the complete rows as the file without the cut row gives them, with the same types
    # (a cut number in the last row never turns its column into text)
    pd.testing.assert_frame_equal(a.df.drop(columns="trip_id"), b.df.drop(columns="trip_id"))
    assert a.df["heater_w"].dtype == float


def test_streamed_batches_say_the_cut_row_once_in_the_last(tmp_path):
    df = _log()
    p = tmp_path / "cut.csv"
    p.write_text(_cut_text(df, CUTS["middle field"]), encoding="utf-8")
    ms = list(iter_measured(Part(str(p)), rows=150))
    assert len(ms) == 1 or sum("truncated_rows" in m.counts for m in ms) == 1
    assert ms[-1].counts["truncated_rows"] == {str(p): len(df) - 1}
    assert sum(len(m.power_w) for m in ms) == len(df) - 1


@pytest.mark.parametrize("engine", ["memory", "local"])
@pytest.mark.parametrize("command", ["calibrate", "compare"])
def test_cli_warns_of_the_cut_row_and_fits_the_complete_rows(tmp_path, capsys, engine, command):
    df = _log()
    cut = tmp_path / "cut.csv"
    cut.write_text(_cut_text(df, CUTS["time"]), encoding="utf-8")  # time '0'..: went backwards
    whole = tmp_path / "whole.csv"
    df.iloc[:-1].to_csv(whole, index=False)
    outs = {}
    for p in (cut, whole):
        out = tmp_path / f"{p.stem}.toml" if command == "calibrate" else tmp_path / f"{p.stem}-cmp"
        args = [command, str(p), "--engine", engine, "--out", str(out)]
        if command == "compare":
            args += ["--equation", "vsp_ldv1999"]
        code = cli_main(args)
        cap = capsys.readouterr()
        assert code == 0, cap.err
        outs[p.stem] = (cap.out, out)
    said = [ln for ln in outs["cut"][0].splitlines() if "cut short" in ln]
    assert len(said) == 1 and said[0].startswith("warning: ") and str(cut) in said[0] \
        and f"row {len(df) - 1}" in said[0], outs["cut"][0]
    assert "cut short" not in outs["whole"][0]
    if command == "calibrate":  # the same equation as from the complete rows
        import tomllib

        terms = [tomllib.loads(o.read_text(encoding="utf-8"))["terms"] for _, o in outs.values()]
        assert terms[0] == pytest.approx(terms[1], rel=1e-9)


def test_a_cut_file_with_fewer_than_two_complete_rows_is_refused_naming_the_cut(tmp_path, capsys):
    p = tmp_path / "cut.csv"
    p.write_text(_cut_text(_log().iloc[:2], CUTS["middle field"]), encoding="utf-8")
    with pytest.raises(UserError, match="cut short.*1 complete row"):
        read_log(p)
    code = cli_main(["calibrate", str(p), "--engine", "local", "--out", str(tmp_path / "e.toml")])
    err = capsys.readouterr().err
    assert code == 2 and str(p) in err and "cut short" in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "e.toml").exists()


def test_a_short_row_in_the_middle_is_no_cut_and_blanks_after_the_last_line_break_neither(tmp_path):
    df = _log()
    lines = df.to_csv(index=False).splitlines()
    lines[101] = ",".join(lines[101].split(",")[:3])  # row 100: trip, time and speed only
    p = tmp_path / "ragged.csv"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    log = read_log(p)
    assert "truncated_rows" not in log.counts and len(log.df) == len(df)
    assert np.isnan(log.df["power_w"].iloc[100]) and np.isnan(log.df["heater_w"].iloc[100])
    # blanks after the last line break: the CSV reader skips that blank line; no row is cut
    q = tmp_path / "blank_tail.csv"
    q.write_text(df.to_csv(index=False) + "   ", encoding="utf-8")
    assert complete_bytes(q) is None
    assert len(read_log(q).df) == len(df)
    r = tmp_path / "nul_tail.csv"  # a logger that lost power may leave NUL bytes: a cut row
    r.write_bytes(df.to_csv(index=False).encode() + b"\0\0\0\0")
    assert read_log(r).counts["truncated_rows"] == {str(r): len(df)}


def test_import_keeps_a_complete_last_row_followed_by_blanks(tmp_path):
    # the import's cut rule is the reader's: blanks after the last line break are no cut row
    src = tmp_path / "src.csv"
    src.write_text("t,v\n" + "".join(f"{i / 8},{20 + i % 7}\n" for i in range(80)) + "  ", encoding="utf-8")
    m = tmp_path / "map.toml"
    m.write_text('[columns."t"]\nname = "time_s"\nunit = "s"\n[columns."v"]\nname = "speed_mps"\n'
                 'unit = "km/h"\n', encoding="utf-8")
    df, report = import_read("columns", [src], columns=m)
    assert len(df) == 80
    assert "truncated last row" not in str(report)
