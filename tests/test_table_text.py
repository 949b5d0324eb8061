"""A run's tables without pandas (sim/table_text.py): the Arrow arrays are pa.array's (type,
values, Parquet bytes) and the CSV text is pandas' to_csv(index=False) of the same data,
for any values (hypothesis); and a whole `sumo-drvpw run` imports no pandas (its import
was a fifth of a second of a small run: benchmarks/run_ratio.py)."""

from __future__ import annotations

import io
import json
import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sumo_drvpw.sim.table_text import arrow_array, columns_csv, rows_csv, table_csv

FLOATS = st.floats(allow_nan=True, allow_infinity=True, width=64) | st.sampled_from(
    [0.0, -0.0, 1e16, 1e-5, 1e-4, 123456789012345.6, 0.1, 5e-324, 1.7976931348623157e308, 3.0])
TEXT = st.text(alphabet=st.sampled_from(list('ab,"\n\r é€ 0.5') + ["\u00e4"]), max_size=6)
INTS = st.integers(min_value=-2**63, max_value=2**63 - 1)


def _parquet(t: pa.Table) -> bytes:
    buf = io.BytesIO()
    pq.write_table(t, buf)
    return buf.getvalue()


@settings(max_examples=150, deadline=None)
@given(st.one_of(
    st.lists(FLOATS, max_size=12).map(lambda x: np.array(x, float)),
    st.lists(INTS, max_size=12).map(lambda x: np.array(x, np.int64)),
    st.lists(st.booleans(), min_size=0, max_size=20).map(lambda x: np.array(x, bool)),
    st.lists(FLOATS, min_size=1, max_size=12),
    st.lists(INTS, min_size=1, max_size=12),
    st.lists(st.booleans(), min_size=1, max_size=12),
    st.lists(TEXT, min_size=1, max_size=12),
    st.lists(TEXT, min_size=1, max_size=12).map(lambda x: np.array(x, object)),
    st.lists(FLOATS, min_size=2, max_size=12).map(lambda x: np.array(x, float)[::2]),  # a strided view
))
def test_arrow_array_is_pa_array(values):
    ours, theirs = arrow_array(values), pa.array(values)
    assert ours.type == theirs.type
    assert ours.null_count == theirs.null_count == 0
    if pa.types.is_floating(ours.type):  # NaN a value, bit for bit
        assert np.array_equal(np.asarray(ours.to_pylist(), float).view(np.int64),
                              np.asarray(theirs.to_pylist(), float).view(np.int64))
    else:
        assert ours.to_pylist() == theirs.to_pylist()
    schema = pa.schema([pa.field("x", ours.type, metadata={"unit": "J"})])
    assert _parquet(pa.Table.from_arrays([ours], schema=schema)) == \
        _parquet(pa.Table.from_arrays([theirs], schema=schema))


CELL = st.one_of(FLOATS, st.integers(-10**6, 10**6), st.booleans(), TEXT, st.none())
COLUMN = st.one_of(
    st.lists(FLOATS, min_size=3, max_size=3),
    st.lists(st.integers(-10**18, 10**18), min_size=3, max_size=3),
    st.lists(st.one_of(FLOATS, st.integers(-99, 99), st.none()), min_size=3, max_size=3),
    st.lists(st.booleans(), min_size=3, max_size=3),
    st.lists(st.one_of(TEXT, st.none()), min_size=3, max_size=3),
    st.lists(CELL, min_size=3, max_size=3),  # mixed kinds: pandas' own text
    st.lists(FLOATS, min_size=3, max_size=3).map(lambda x: np.array(x, float)),
    st.lists(st.integers(-99, 99), min_size=3, max_size=3).map(lambda x: np.array(x, np.int64)),
    st.lists(st.booleans(), min_size=3, max_size=3).map(lambda x: np.array(x, bool)),
    st.lists(TEXT, min_size=3, max_size=3).map(lambda x: np.array(x, object)),
)


@settings(max_examples=200, deadline=None)
@given(st.dictionaries(st.sampled_from(["a", "b,c", 'q"', "é", "x y"]), COLUMN, min_size=1, max_size=4))
def test_columns_csv_is_pandas_to_csv(cols):
    assert columns_csv(cols) == pd.DataFrame(cols).to_csv(index=False)
    assert columns_csv(cols, header=False) == pd.DataFrame(cols).to_csv(index=False, header=False)


@settings(max_examples=150, deadline=None)
@given(st.lists(st.dictionaries(st.sampled_from(["key", "fuel_l", "ok", "n"]), CELL, max_size=4), max_size=5),
       st.sampled_from([None, ["n", "key", "fuel_l", "ok", "absent"]]))
def test_rows_csv_is_pandas_to_csv(rows, columns):
    assert rows_csv(rows, columns) == pd.DataFrame(rows, columns=columns).to_csv(index=False)
    if columns is not None:  # the streamed chain parts: DataFrame(rows).reindex(columns=…), no header
        assert rows_csv(rows, columns, header=False) == \
            pd.DataFrame(rows).reindex(columns=columns).to_csv(index=False, header=False)


def test_table_csv_is_to_pandas_to_csv():
    t = pa.table({"class": ["motorway", "urban,x"], "term": ["acc", 'a"b'], "share": [0.25, math.nan],
                  "n": pa.array([3, -1], pa.int64()), "ok": [True, False], "e_j": [1e16, -0.0]})
    assert table_csv(t) == t.to_pandas().to_csv(index=False)
    nulls = pa.table({"x": pa.array([1.5, None]), "s": pa.array(["a", None])})  # (through pandas)
    assert table_csv(nulls) == nulls.to_pandas().to_csv(index=False)


@pytest.mark.sumo
def test_a_run_imports_no_pandas(tmp_path):
    """The bundled highway scenario (wind, elevation, a difference of two equations) run
    from the command line in a fresh process, its network table in the cache (a run's usual
    case; the first run of a network reads it with pandas, sim/lane_spread.py): its outputs
    written, pandas never imported. Before: pyarrow's pa.array, the CSV outputs (to_csv),
    data/wind.py and sim/fcd_conn.py (a rider's SUMO mass, checked at the start) each did."""
    import os

    out = tmp_path / "o"
    code = ("import sys, sumo_drvpw.cli as c; r = c.main(['run', 'highway', '--out', sys.argv[1], "
            "'--no-figures', '--no-progress', '--end', '300']); print('PANDAS', 'pandas' in sys.modules); sys.exit(r)")
    env = dict(os.environ, SUMO_DRVPW_CACHE=str(tmp_path / "cache"))
    for _ in range(2):  # (the first fills the cache)
        r = subprocess.run([sys.executable, "-c", code, str(out)], capture_output=True, text=True, timeout=300, env=env)
        assert r.returncode == 0, r.stderr
    assert "PANDAS False" in r.stdout
    summary = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert summary["vehicles"] > 0 and {"shares.csv", "difference.csv", "vehicles.parquet"} <= set(summary["files"].values())


@pytest.mark.parametrize("values", [
    [np.float32(0.1), np.float32(2.5), np.float32(3.0)],   # a float32 array's items (pandas: float32)
    [np.float16(0.1), np.float16(1.0), np.float16(-2.0)],
    [np.float32(0.1), None, np.float32(1.0)],
    [np.float32(0.1), 0.2, 1],                               # mixed with Python numbers
    [np.longdouble(0.1), 0.5, 1.0],
])
def test_narrow_or_wide_float_scalars_are_written_as_pandas_writes_them(values):
    """A column of NumPy float scalars other than float64 (a float32 array's items in a chain row)
    is pandas' text too: before, it was widened to float64 and written 0.10000000149011612 where
    pandas writes the float32 column 0.1."""
    cols = {"x": values, "n": [1, 2, 3]}
    assert columns_csv(cols) == pd.DataFrame(cols).to_csv(index=False)
    rows = [{"x": x, "n": k} for k, x in enumerate(values)]
    assert rows_csv(rows) == pd.DataFrame(rows).to_csv(index=False)
