"""A wide log streamed in bounded memory: every chunk the streamed reader holds has at most
``BATCH_VALUES`` values (rows × (columns read + ``DERIVED_VALUES``)) whatever the log's
width, and streamed `calibrate` and `compare` still give what the in-memory engine gives
(1e-9 relative).

The log is a planted synthetic one (three 3-minute trips of the virtual track, Prius 3)
with 150 extra float columns, as a fleet log has; the budget is made small so the few
thousand rows are read in many chunks, each trip crossing several.
"""

from functools import partial

import numpy as np
import pandas as pd
import pytest

import corpus
import sumo_drvpw.data.stream as stream
from sumo_drvpw.data.measured import load_measured, resolve_equations
from sumo_drvpw.data.stream import Part, iter_measured
from sumo_drvpw.fit.calibrate import CANDIDATES, calibrate
from sumo_drvpw.fit.compare import compare
from sumo_drvpw.fit.engine import run
from sumo_drvpw.fit.stream import CalibrationStats, calibrate_from_stats
from sumo_drvpw.fit.stream_compare import CompareStats
from sumo_drvpw.model.vehicles import load_vehicle
from sumo_drvpw.synth.effects import synth_trips

RTOL = 1e-9
EXTRA = 150
#: values per chunk: small, so a log of a few thousand rows is read in many chunks
BUDGET = 20_000


@pytest.fixture(scope="module")
def wide(tmp_path_factory):
    df, _ = synth_trips(n_trips=3, minutes=3.0, seed=11)
    df = df.drop(columns=["phase"])
    rng = np.random.default_rng(5)
    extra = pd.DataFrame(rng.normal(size=(len(df), EXTRA)), columns=[f"extra_{i:03d}" for i in range(EXTRA)])
    p = tmp_path_factory.mktemp("wide") / "wide.parquet"
    pd.concat([df, extra], axis=1).to_parquet(p, row_group_size=1000)
    return p


@pytest.fixture
def chunks(monkeypatch):
    """A small value budget; the shape of every chunk the streamed reader reads is recorded."""
    monkeypatch.setattr(stream, "BATCH_VALUES", BUDGET)
    monkeypatch.setattr(stream, "MIN_BATCH_ROWS", 10)
    seen = []
    read = stream._chunks

    def spy(part, rows, columns=None, categorical=False):
        for df in read(part, rows, columns, categorical):
            seen.append(df.shape)
            yield df

    monkeypatch.setattr(stream, "_chunks", spy)
    return seen


def _bounded(shapes) -> None:
    assert len(shapes) > 3  # read in many chunks
    for rows, cols in shapes:
        assert rows * (cols + stream.DERIVED_VALUES) <= BUDGET, (rows, cols)


def test_every_column_read_in_chunks_bounded_by_values(wide, chunks):
    """All 170 columns read (as a battery or fuel target reads them): fewer rows per chunk,
    and the measured power and inputs of the batches are the in-memory reader's."""
    veh = load_vehicle("prius3")
    got = list(iter_measured(Part(str(wide)), veh, columns=None))
    _bounded(chunks)
    assert max(c for _, c in chunks) == len(pd.read_parquet(wide).columns)
    ref = load_measured([wide], "prius3")
    for a in ("power_w", "usable"):
        np.testing.assert_allclose(np.concatenate([getattr(m, a) for m in got]), getattr(ref, a),
                                   rtol=RTOL)
    for a in ("v", "a", "theta", "mass"):
        np.testing.assert_allclose(np.concatenate([getattr(m.inputs, a) for m in got]),
                                   getattr(ref.inputs, a), rtol=RTOL)


def test_streamed_calibrate_and_compare_of_a_wide_log_bounded_and_equal_to_memory(wide, chunks):
    """The engines' own columns (the reader's and the terms'): chunks bounded by values,
    the calibration and the whole comparison document equal to the in-memory path's."""
    veh = load_vehicle("prius3")
    m = load_measured([wide], "prius3")
    cands = CANDIDATES["indt-var-2"]
    ref = calibrate(m.inputs, m.power_w, cands, mask=m.usable, counts=m.counts,
                    reference_mass_kg=float(m.inputs.mass[m.usable].mean()))
    st, _ = run([wide], partial(CalibrationStats, cands), veh)
    _bounded(chunks)
    assert max(c for _, c in chunks) < 30  # only the columns the reader and the terms need
    got = calibrate_from_stats(st)
    assert got.terms == ref.terms and got.n == ref.n
    for k in ("params", "std_err", "p_values"):
        for t in ref.terms:
            assert getattr(got, k)[t] == pytest.approx(getattr(ref, k)[t], rel=RTOL, abs=1e-300)
    assert got.r2 == pytest.approx(ref.r2, rel=RTOL)
    chunks.clear()
    eqs = resolve_equations(["drvpw_prius3", "vsp_spec"], veh)
    u = m.usable
    want = compare(m.power_w[u], m.inputs.take(u), eqs, dt_s=m.log.df["dt_s"].to_numpy()[u],
                   reference="drvpw_prius3", trip=m.inputs.trip[u]).to_json()
    cs, _ = run([wide], partial(CompareStats, eqs, "drvpw_prius3"), veh)
    _bounded(chunks)
    doc = cs.comparison().to_json()
    corpus.assert_close_documents(want, doc, RTOL, same_keys=False)
    assert doc["settings"]["percentiles"] == "exact"


def test_reservoir_is_the_bottom_k_of_every_batch_added():
    """compare's reservoir selects once per k/4 waiting samples, not per batch: read at any
    point, it is the k smallest keys of all batches added so far, with their columns."""
    from sumo_drvpw.fit.stream_compare import _Reservoir

    rng = np.random.default_rng(2)
    res, keys = _Reservoir(100, np.zeros(0), {}), []
    for i, n in enumerate(rng.integers(0, 40, 60)):
        key = rng.random(n)
        keys.append(key)
        res = res.add(key, {"x": key * 2.0, "ok": key < 0.5})
        if i % 7 == 0:  # read midway: the waiting batches are selected first
            assert np.array_equal(np.sort(res.key), np.sort(np.concatenate(keys))[:100])
    want = np.sort(np.concatenate(keys))[:100]
    assert np.array_equal(np.sort(res.key), want)
    assert np.array_equal(res.cols["x"], res.key * 2.0) and np.array_equal(res.cols["ok"], res.key < 0.5)
