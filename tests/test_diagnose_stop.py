"""The tracer's stop line says why it stopped: which test each candidate tried failed
(significance in the held-out block test, minimum gain, replication on held-out trips,
plausibility), in the console, trace.json (rounds[].stop_reason) and trace.md."""

import json

from sumo_drvpw.fit.diagnose.options import DiagnoseOptions, stop_reason


def test_stop_reason_groups_the_failed_tests():
    opt = DiagnoseOptions(alpha=0.05, min_gain=0.01)
    tried = [("a", "significance", 0.0846), ("b", "rejected", "passes the block test but implausible: x"),
             ("c", "significance", 1.0), ("d", "gain", 0.0052)]
    why = stop_reason(tried, 1, 63, opt)
    assert why == ("not significant in the held-out block test (Bonferroni over 63 candidates, α = 0.05): "
                   "a p = 0.0846, c p = 1; b passes the block test but implausible: x; "
                   "below the minimum gain 1 %: d 0.52 %; "
                   "replication on held-out trips not tested (1 trip(s), it needs 3)")
    assert "replication" not in stop_reason(tried, 3, 63, opt)  # three trips: it is tested
    assert stop_reason([], 5, 10, opt) == "no candidate was tried"


def test_diagnose_stop_line_names_the_failed_tests(tmp_path, capsys):
    from sumo_drvpw.cli import main as cli_main
    from test_trip_energy import _log_with_a_gap

    f = _log_with_a_gap(tmp_path)  # two trips; power linear in speed: every extra term over-fits
    out = tmp_path / "dg"
    assert cli_main(["diagnose", str(f), "--out", str(out)]) == 0
    said = capsys.readouterr()
    stop = [ln for ln in (said.out + said.err).splitlines() if "→ stop" in ln]
    assert len(stop) == 1 and "→ stop: " in stop[0]
    assert "implausible: energy share" in stop[0]
    assert "replication on held-out trips not tested (2 trip(s), it needs 3)" in stop[0]
    last = json.loads((out / "trace_details.json").read_text(encoding="utf-8"))["rounds"][-1]
    assert stop[0].endswith(last["stop_reason"])
    assert f"Stopped: {last['stop_reason']}." in (out / "trace.md").read_text(encoding="utf-8")
