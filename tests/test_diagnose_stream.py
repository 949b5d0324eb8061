"""The streamed residual tracer (fit/diagnose/stream_run.py) equals the in-memory one (#14).

Synthetic logs of the virtual test track (truth drvpw_prius3) with planted effects, split
over three files, read in small chunks so every trip lands in its own batch and every
statistic is gathered over many batches. With fewer rows than the first-look sample the
screening sees the same samples, so every number of the report must equal the in-memory
tracer's: coefficients, standard errors, metrics, p-values, trip energies, per-trip lags
to 1e-9 relative; the relative RMSE gains (one minus the square root of a ratio of two
nearly equal held-out SSEs) to 1e-9 absolute.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import sumo_drvpw.synth.effects as E
from sumo_drvpw.data.measured import load_measured
from sumo_drvpw.fit.diagnose import DiagnoseOptions, diagnose
from sumo_drvpw.fit.diagnose.stream_run import diagnose_stream
from sumo_drvpw.model.equations import load_equation
from sumo_drvpw.synth.track import Noise

NOISE = Noise(process_w=200.0, process_rel=0.01)
DETAILS = ("samples", "signals_offered", "signals_skipped", "candidates_dropped", "rounds", "timing",
           "not_replicated", "candidates_scored", "final_std_err", "structural", "candidates_per_round")


def _logs(tmp_path, effects, n_trips=6, seed=11):
    df, _ = E.synth_trips(n_trips, 8.0, seed=seed, effects=list(effects) + [E.LogPower()], noise=NOISE)
    df["noise_0"] = np.random.default_rng(0).normal(0, 1, len(df))
    trips = df["trip_id"].unique()
    cuts = np.array_split(np.arange(len(trips)), 3)
    paths = []
    for i, c in enumerate(cuts):
        p = tmp_path / f"log{i}.parquet"
        df[df["trip_id"].isin(trips[c])].to_parquet(p)
        paths.append(p)
    return paths


def _compare(a, b, path=""):
    """Differences between two JSON-like documents beyond the tolerances (list of str)."""
    bad = []
    if isinstance(a, dict):
        if set(a) != set(b):
            return [f"{path}: keys {sorted(set(a) ^ set(b))}"]
        for k in a:
            bad += _compare(a[k], b[k], f"{path}/{k}")
    elif isinstance(a, (list, tuple)):
        if len(a) != len(b):
            return [f"{path}: length {len(a)} != {len(b)}"]
        for i, (u, v) in enumerate(zip(a, b)):
            bad += _compare(u, v, f"{path}[{i}]")
    elif isinstance(a, float) or isinstance(b, float):
        if math.isnan(a) and math.isnan(b):
            return []
        if path.endswith("rmse_gain"):
            ok = abs(a - b) <= 1e-9
        else:
            ok = abs(a - b) <= 1e-9 * max(abs(a), abs(b))
        if not ok:
            bad.append(f"{path}: {a!r} != {b!r}")
    elif a != b:
        bad.append(f"{path}: {a!r} != {b!r}")
    return bad


def _both(tmp_path, effects, opt, rows=2500, cache_mb=768.0, **kw):
    paths = _logs(tmp_path, effects, **kw)
    eq = load_equation("drvpw_prius3")
    mem = diagnose(load_measured(paths, "prius3"), eq, DiagnoseOptions(**opt))
    st = diagnose_stream(paths, "prius3", eq, DiagnoseOptions(**opt), rows=rows, cache_mb=cache_mb)
    return mem, st


def _assert_equal(mem, st):
    bad = _compare(mem.report, st.report, "report")
    bad += _compare({k: mem.details.get(k) for k in DETAILS}, {k: st.details.get(k) for k in DETAILS},
                    "details")
    bad += _compare(mem.equation.terms, st.equation.terms, "equation")
    assert not bad, "\n".join(bad[:20])


def test_streamed_equals_in_memory_planted_load_many_batches(tmp_path):
    mem, st = _both(tmp_path, [E.AuxLoad(), E.Distractors()], {})
    assert [f["term"] for f in mem.report["findings"]] == ["[ac_power_w]"]
    _assert_equal(mem, st)
    r = st.details["resources"]
    assert r["passes"] > 3 and r["sample_rows"] == r["rows"] and not r["batches_on_disk"]


def test_streamed_equals_in_memory_batches_on_disk(tmp_path):
    # a cache of 0.2 MB: all but the first prepared batch go to the temporary folder
    mem, st = _both(tmp_path, [E.TermScaledBySignal(), E.Distractors()], {"max_findings": 2}, cache_mb=0.2)
    assert st.details["resources"]["batches_on_disk"]
    assert any("tyre_temp_c" in f["signals"] for f in mem.report["findings"])
    _assert_equal(mem, st)


def test_streamed_equals_in_memory_lag_and_per_trip_mass(tmp_path):
    # a power lag (the lag step: shifted powers per trip, on samples finite at every
    # shift) and a per-trip mass (per-trip columns, the composite rebuilt from refits)
    mem, st = _both(tmp_path, [E.PowerLag(1.5), E.PerTripMass()], {"max_findings": 3})
    terms = [f["term"] for f in mem.report["findings"]]
    assert terms[0].startswith("lag +1.5") and any(t.startswith("trip=ID*(") for t in terms), terms
    _assert_equal(mem, st)


def test_streamed_finds_nothing_when_nothing_is_planted(tmp_path):
    mem, st = _both(tmp_path, [E.Distractors()], {}, seed=5)
    assert st.report["findings"] == [] and mem.report["findings"] == []
    _assert_equal(mem, st)


def test_cli_streams_above_the_row_limit_and_prints_resources(tmp_path, capsys, monkeypatch):
    import json

    from sumo_drvpw.cli import main
    from sumo_drvpw.cli import diagnose as cli

    paths = _logs(tmp_path, [E.AuxLoad()], n_trips=3)
    # standstill noise the reader clips (its note is printed, streamed as in memory)
    import pyarrow.parquet as pq

    t = pq.read_table(paths[-1])
    meta = t.schema.metadata
    df = t.to_pandas()
    stand = df.index[df["speed_mps"] == 0][:7]
    df.loc[stand, "speed_mps"] = -0.05
    import pyarrow as pa

    pq.write_table(pa.Table.from_pandas(df, preserve_index=False).replace_schema_metadata(
        {**(meta or {}), **(pa.Table.from_pandas(df).schema.metadata or {})}), paths[-1])
    assert not cli.should_stream(paths)
    monkeypatch.setattr(cli, "STREAM_ROWS", 1000)
    assert cli.should_stream(paths) and not cli.should_stream(paths, "no")
    out = tmp_path / "out"
    rc = main(["diagnose", *map(str, paths), "--vehicle", "prius3", "--equation", "drvpw_prius3",
               "--out", str(out), "--quiet"])
    assert rc == 0
    cap = capsys.readouterr()
    err = cap.err
    assert "streamed" in err and "rows/s" in err and "peak RSS" in err
    assert "note: 7 speed sample(s) in [-0.1, 0) m/s clipped to 0" in cap.out
    details = json.loads((out / "trace_details.json").read_text(encoding="utf-8"))
    assert details["resources"]["passes"] > 0
    assert json.loads((out / "trace.json").read_text(encoding="utf-8"))["findings"][0]["term"] == "[ac_power_w]"
    assert not list(out.glob("*.png"))      # streamed runs draw no figures


def test_streamed_bad_input_is_a_user_error(tmp_path):
    from sumo_drvpw.errors import UserError

    paths = _logs(tmp_path, [], n_trips=3)
    with pytest.raises(UserError, match="needs the log column 'no_such_col'"):
        from sumo_drvpw.model.equations import Equation

        diagnose_stream(paths, "prius3", Equation("x", {"acc": 1.0, "[no_such_col]": 1.0}), DiagnoseOptions())


def test_streamed_equals_in_memory_calibrated_on_the_spot(tmp_path):
    # no declared equation: both calibrate indt-var-1 on the spot (the streamed tracer on its
    # first-look sample, here all rows), then trace
    paths = _logs(tmp_path, [E.AuxLoad()], n_trips=4)
    mem = diagnose(load_measured(paths, "prius3"), None, DiagnoseOptions(structural=False))
    st = diagnose_stream(paths, "prius3", None, DiagnoseOptions(structural=False), rows=3000)
    assert mem.details["calibrated_on_the_spot"] and st.details["calibrated_on_the_spot"]
    _assert_equal(mem, st)


def test_streamed_lag_on_block_folds_equals_in_memory(tmp_path):
    # validation over blocks (folds by block rank within each trip, gathered per chunk of
    # whole trips and carried over between batches) instead of over trips
    mem, st = _both(tmp_path, [E.PowerLag(1.5)], {"validation": "blocks", "max_findings": 1}, n_trips=4)
    assert mem.report["findings"][0]["term"].startswith("lag +1.5")
    assert st.report["validation"].startswith("5-fold cross-validation over contiguous 60-s blocks")
    _assert_equal(mem, st)


def _held_bytes(obj) -> int:
    """Bytes of the NumPy arrays reachable through dicts, lists and tuples."""
    if isinstance(obj, np.ndarray):
        return obj.nbytes
    if isinstance(obj, dict):
        return sum(_held_bytes(v) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return sum(_held_bytes(v) for v in obj)
    return 0


def test_lag_search_memory_does_not_grow_with_rows(tmp_path, monkeypatch):
    # the same trips read 4 times (copies of the files, each copy's trips under ids of their
    # own, same rows otherwise: a trip id in two files is refused): the lag search keeps
    # per-fold sums — the same arrays of the same sizes, 4 × the sums — and per-trip sums,
    # each copy's those of its original, and nothing per block or per row (issue #14: memory
    # flat in rows)
    import pandas as pd

    from sumo_drvpw.fit.diagnose import stream_run

    seen = []

    class Spy(stream_run.LagSums):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            seen.append(self)

    monkeypatch.setattr(stream_run, "LagSums", Spy)
    paths = _logs(tmp_path, [E.PowerLag(1.5)], n_trips=3)
    copies = []
    for r in range(3):
        for p in paths:
            copies.append(tmp_path / f"copy{r}_{p.name}")
            df = pd.read_parquet(p)
            df["trip_id"] = df["trip_id"].astype(str) + f"-copy{r}"
            df.to_parquet(copies[-1])
    eq, opt = load_equation("drvpw_prius3"), DiagnoseOptions(max_findings=1)
    diagnose_stream(paths, "prius3", eq, opt, rows=2500)
    diagnose_stream(paths + copies, "prius3", eq, opt, rows=2500)
    one, four = seen

    def folds(s):
        return [s.fzy, s.fyy]

    def per_trip(s):  # the trips' sums, in an order that does not depend on their ids
        return sorted((s.trips[t] for t in s.trips), key=lambda v: (v[0], float(v[3][0])))

    assert list(one.lags) == list(four.lags) and len(four.trips) == 4 * len(one.trips) > 0
    assert [a.shape for a in folds(one)] == [a.shape for a in folds(four)]
    for a, b in zip(folds(one), folds(four)):
        np.testing.assert_allclose(b, 4 * a, rtol=1e-12, atol=0)
    mine, theirs = per_trip(one), per_trip(four)
    for i, s in enumerate(mine):  # each trip four times, its copies' sums its own
        for c in theirs[4 * i:4 * i + 4]:
            assert c[0] == s[0]
            for u, v in zip(s[1:], c[1:]):
                np.testing.assert_allclose(v, u, rtol=1e-12, atol=0)
    # every array it holds: the fold sums, and per trip the same bytes however many rows
    rest = {k: v for k, v in vars(four).items() if k != "trips"}
    assert _held_bytes(rest) == _held_bytes({k: v for k, v in vars(one).items() if k != "trips"}) > 0
    assert _held_bytes(four.trips) == 4 * _held_bytes(one.trips) > 0


def test_a_trip_id_in_two_files_is_refused_streamed_as_in_memory(tmp_path):
    """Two files holding the same trip ids (a log and its copy): the in-memory reader refuses
    them in one line; the streamed tracer took them (exit 0, each trip's sums and lag twice
    under one id) and now refuses them with the same line."""
    import shutil

    from sumo_drvpw.errors import UserError

    paths = _logs(tmp_path, [], n_trips=3)
    shutil.copy(paths[0], tmp_path / "copy.parquet")
    logs = paths + [tmp_path / "copy.parquet"]
    with pytest.raises(UserError) as mem:
        load_measured(logs, "prius3")
    with pytest.raises(UserError) as st:
        diagnose_stream(logs, "prius3", load_equation("drvpw_prius3"), DiagnoseOptions(), rows=2500)
    assert str(st.value) == str(mem.value) and "is also in" in str(st.value)


def test_a_declared_term_zero_on_the_logs_is_held_at_its_coefficient(tmp_path):
    """Logs with no grade (no grade or elevation column: a flat road, said by the reader)
    and an equation with a grade term: diagnose ran into "term 'grade' is zero" and refused
    (found by a sweep). The term is now held at its declared coefficient, not fitted, back in
    the final equation (it serves SUMO's hills) and reported; in memory and streamed alike."""
    import pandas as pd

    paths = _logs(tmp_path, [], n_trips=4)
    for p in paths:
        pd.read_parquet(p).drop(columns=["grade_rad", "gps_elevation_m"]).to_parquet(p)
    eq = load_equation("drvpw_prius3")
    mem = diagnose(load_measured(paths, "prius3"), eq, DiagnoseOptions())
    st = diagnose_stream(paths, "prius3", eq, DiagnoseOptions(), rows=2500)
    _assert_equal(mem, st)
    assert mem.report["held_terms"]["grade"]["coefficient"] == eq.terms["grade"]
    assert mem.equation.terms["grade"] == eq.terms["grade"] and set(eq.terms) <= set(mem.equation.terms)
    assert mem.report["baseline"]["terms"][0] == "grade"
    assert mem.equation.terms["acc"] != eq.terms["acc"]  # the others refitted


def test_a_term_zero_only_in_the_first_rows_is_fitted_streamed_as_in_memory(tmp_path):
    """A folder of a flat log and hilly ones: the streamed tracer's first-look sample (the
    flat log) has grade 0; later batches have it ≠ 0, so it reads again and fits it, as the
    in-memory tracer does (it held grade at its declared coefficient: baseline RMSE 13 kW
    against 585 W; found by a review)."""
    import pandas as pd

    paths = _logs(tmp_path, [], n_trips=6)
    flat = pd.read_parquet(paths[0]).drop(columns=["grade_rad", "gps_elevation_m"])
    flat.to_parquet(paths[0])
    eq = load_equation("drvpw_prius3")
    mem = diagnose(load_measured(paths, "prius3"), eq, DiagnoseOptions())
    st = diagnose_stream(paths, "prius3", eq, DiagnoseOptions(), rows=2500, sample_rows=len(flat))
    assert "held_terms" not in mem.report and "held_terms" not in st.report
    assert mem.report["n_samples"] == st.report["n_samples"]  # the flat trips read flat in both
    # the declared fit alike (the screening differs: the streamed one sees the first file only)
    assert not _compare(mem.report["baseline"], st.report["baseline"], "baseline")


def test_the_sample_and_the_trace_do_not_depend_on_the_chunk_size(tmp_path):
    """A log larger than the first-look sample, read in chunks of 2,500 rows and of whole
    files: the sample ends at the end of the trip that holds row ``sample_rows`` − 1, the
    batches after it read only the columns the trace uses, and every number of the report
    is the same (to 1e-9). Before, the sample ended where the first batch past
    ``sample_rows`` did: the first trip (3,840 rows) in chunks of 2,500, the first file's
    first two trips (7,680 rows) read in one chunk, and the first look differed with it."""
    paths = _logs(tmp_path, [E.AuxLoad(), E.Distractors()], n_trips=9)
    eq = load_equation("drvpw_prius3")
    sample = 3000  # inside the first trip (3,840 rows a trip, three a file): the sample is that trip
    a = diagnose_stream(paths, "prius3", eq, DiagnoseOptions(), rows=2500, sample_rows=sample)
    b = diagnose_stream(paths, "prius3", eq, DiagnoseOptions(), rows=10 ** 6, sample_rows=sample)
    assert a.details["resources"]["sample_rows"] == b.details["resources"]["sample_rows"] == 3840
    assert [f["term"] for f in a.report["findings"]] == ["[ac_power_w]"]
    _assert_equal(a, b)


def test_batches_are_bounded_by_values_and_narrow_to_the_columns_asked_for(tmp_path, monkeypatch):
    """read_batches: a wide log's chunks hold at most BATCH_VALUES values of the columns read
    (rows_for of its width; here scaled down), each batch whole trips; once the columns are
    narrowed (after the first look), the rest of a Parquet file is read from the next trip
    on with only those columns, every row read once."""
    import pandas as pd

    import sumo_drvpw.data.stream as S
    from sumo_drvpw.fit.diagnose.source import read_batches

    monkeypatch.setattr(S, "BATCH_VALUES", 60_000)
    monkeypatch.setattr(S, "MIN_BATCH_ROWS", 100)
    rng = np.random.default_rng(1)
    frames = []
    for k in range(30):  # 30 trips of 200 rows, 4 canonical and 40 extra columns
        t = np.arange(200) * 0.5
        v = 10.0 + 3.0 * np.sin(t / 9.0 + k)
        frames.append(pd.DataFrame({"trip_id": f"k{k:02d}", "time_s": t, "speed_mps": v,
                                    "power_w": 150.0 * v + 0.4 * v ** 3, "mass_kg": 1500.0,
                                    **{f"x{j:02d}": rng.normal(size=200) for j in range(40)}}))
    f = tmp_path / "wide.parquet"
    pd.concat(frames, ignore_index=True).to_parquet(f, row_group_size=1000)
    chunk = S.rows_for(45)  # 60,000 / (45 + 10) = 1,090 rows: five trips
    assert chunk == 60_000 // 55
    want = {"columns": None}
    seen, cols = [], []
    for m in read_batches([f], want=want, rows=10 ** 6, sample_rows=1500):
        seen += list(m.log.df["trip_id"].astype(str).unique())
        cols.append(set(m.log.df.columns))
        assert len(m.power_w) <= chunk and len(m.power_w) % 200 == 0
        if len(seen) == 8:  # the first look is over: only x03 of the extras from now on
            want["columns"] = frozenset(S.CANONICAL | {"x03"})
    assert seen == [f"k{k:02d}" for k in range(30)]  # every trip once, in order
    first, later = cols[0], cols[-1]
    assert {"x00", "x03", "x39"} <= first and "x03" in later and not ({"x00", "x39"} & later)
