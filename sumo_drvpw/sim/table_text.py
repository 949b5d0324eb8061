"""A run's tables written without pandas: Arrow arrays made from NumPy arrays and lists of
text, and CSV text as pandas' ``DataFrame(...).to_csv(index=False)`` writes it.

pyarrow's ``pa.array`` imports pandas on its first call (to ask whether its input is a pandas
object), and a run's outputs wrote their CSV files through pandas: its import was about a
fifth of a second, a twentieth of a small run's wall time (benchmarks/run_ratio.py). Here
the arrays are built from their buffers and the CSV text with the csv module in pandas'
dialect, each column's values formatted as pandas formats that column's dtype (a float
column by NumPy's ``astype(str)``, NaN as an empty field). A column this module cannot tell
the dtype pandas would give (mixed kinds) goes through pandas itself, so the text is
pandas' in every case (tests/test_table_text.py holds the two together).
"""

from __future__ import annotations

import csv
import io
from numbers import Integral, Real

import numpy as np
import pyarrow as pa

_NUMERIC = {np.dtype(t): pa.from_numpy_dtype(np.dtype(t)) for t in
            (np.float64, np.float32, np.int64, np.int32, np.int16, np.int8,
             np.uint64, np.uint32, np.uint16, np.uint8)}


def _strings(values) -> pa.Array | None:
    """A string array of ``values`` (every one a str), else None. Their text joined and
    encoded at once where it is ASCII (one C call each, not one per value)."""
    try:
        joined = "".join(values)
    except TypeError:  # (a value that is no str: pa.array's to read)
        return None
    if joined.isascii():
        data = joined.encode("ascii")
        lens = np.fromiter(map(len, values), np.int64, len(values))
    else:
        enc = [x.encode("utf-8") for x in values]
        data = b"".join(enc)
        lens = np.fromiter(map(len, enc), np.int64, len(enc))
    if len(data) >= 2**31:  # (pa.array makes a chunked large column then: left to it)
        return None
    off = np.zeros(len(lens) + 1, np.int32)
    np.cumsum(lens, out=off[1:])
    return pa.Array.from_buffers(pa.string(), len(lens), [None, pa.py_buffer(off), pa.py_buffer(data)])


def arrow_array(values) -> pa.Array:
    """``pa.array(values)`` for a NumPy array of numbers or bools (no nulls: NaN stays NaN, as
    ``pa.array`` keeps it), a list of floats, of ints, of bools or of str, or an object array
    of str, made from its buffers; any other input through ``pa.array`` itself."""
    if type(values) is np.ndarray and values.ndim == 1:
        if values.dtype in _NUMERIC:
            a = np.ascontiguousarray(values)
            if not a.dtype.isnative:
                a = a.astype(a.dtype.newbyteorder("="))
            return pa.Array.from_buffers(_NUMERIC[values.dtype], len(a), [None, pa.py_buffer(a)])
        if values.dtype == np.bool_:
            return pa.Array.from_buffers(pa.bool_(), len(values),
                                         [None, pa.py_buffer(np.packbits(values, bitorder="little"))])
        if values.dtype == object and len(values):
            got = _strings(values.tolist())
            if got is not None:
                return got
    elif type(values) is list and values:
        kinds = set(map(type, values))
        if kinds <= {float, np.float64}:  # (NaN a value, as pa.array keeps it)
            return arrow_array(np.array(values, np.float64))
        if kinds == {bool}:
            return arrow_array(np.array(values, np.bool_))
        if kinds == {int} and -2**63 <= min(values) and max(values) < 2**63:
            return arrow_array(np.array(values, np.int64))
        got = _strings(values) if kinds == {str} else None
        if got is not None:
            return got
    return pa.array(values)


def _missing(x) -> bool:
    return x is None or (isinstance(x, float) and x != x)


def _column_text(values: list) -> list | None:
    """One column's fields as pandas writes the dtype it infers from ``values`` (a list), or
    None where that dtype is not one of: bool, integer, float (numbers with None or NaN), str
    (with None)."""
    present = [x for x in values if not _missing(x)]
    if all(isinstance(x, (bool, np.bool_)) for x in present):
        if len(present) == len(values) and present:
            return ["True" if x else "False" for x in values]
        return None if present else [""] * len(values)  # (bools with missing: object; none: float)
    if all(isinstance(x, str) for x in present):
        return ["" if _missing(x) else x for x in values]
    if any(isinstance(x, np.floating) and type(x) is not np.float64 for x in present):
        return None  # (float32 items: pandas may keep a float32 column, written by its own repr)
    if all(isinstance(x, Real) and not isinstance(x, (bool, np.bool_)) for x in present):
        if len(present) == len(values) and all(isinstance(x, Integral) for x in present):
            return [str(int(x)) for x in values]
        arr = np.array([np.nan if _missing(x) else x for x in values], float)
        return _float_text(arr)
    return None


def _float_text(arr: np.ndarray) -> list:
    """A float64 column's fields as pandas writes them: ``astype(str)``, NaN empty."""
    out = arr.astype(str).astype(object)
    out[np.isnan(arr)] = ""
    return out.tolist()


def _write(header: list | None, columns: list[list]) -> str:
    buf = io.StringIO()  # (pandas' csv dialect: CSVFormatter)
    w = csv.writer(buf, lineterminator="\n", delimiter=",", quoting=csv.QUOTE_MINIMAL,
                   doublequote=True, escapechar=None, quotechar='"')
    if header is not None:
        w.writerow(header)
    w.writerows(zip(*columns))
    return buf.getvalue()


def rows_csv(rows: list[dict], columns: list | None = None, header: bool = True) -> str:
    """``pd.DataFrame(rows, columns=columns).to_csv(index=False, header=header)`` (also as
    ``pd.DataFrame(rows).reindex(columns=columns)`` writes it): the columns in their first
    row's order then any new key's (or ``columns``), a key a row lacks left empty."""
    names = list(dict.fromkeys(k for r in rows for k in r)) if columns is None else list(columns)
    if not names or not all(isinstance(c, str) for c in names):  # (no column, or a name no str)
        import pandas as pd

        return pd.DataFrame(rows, columns=columns).to_csv(index=False, header=header)
    return columns_csv({c: [r.get(c) for r in rows] for c in names}, header)


def columns_csv(cols: dict, header: bool = True) -> str:
    """``pd.DataFrame(cols).to_csv(index=False, header=header)`` of columns of equal length
    (lists or 1-D NumPy arrays)."""
    fields = []
    for name, val in cols.items():
        if type(val) is np.ndarray and val.dtype == np.float64:
            fields.append(_float_text(val))
            continue
        if type(val) is np.ndarray and val.dtype.kind in "iub":
            fields.append([str(x) for x in val.tolist()])
            continue
        got = None if type(val) is np.ndarray and val.dtype != object else _column_text(list(val))
        if got is None:  # (a float32 column, mixed kinds …: pandas' own text)
            return _by_pandas(cols, header)
        fields.append(got)
    if not fields or len({len(f) for f in fields}) != 1:
        return _by_pandas(cols, header)
    return _write(list(cols) if header else None, fields)


def table_csv(table: pa.Table) -> str:
    """``table.to_pandas().to_csv(index=False)`` of an Arrow table without nulls whose columns
    are strings, bools or 64-bit numbers (any other through pandas)."""
    cols = {}
    for name, col in zip(table.column_names, table.columns):
        t = col.type
        if col.null_count or not (pa.types.is_string(t) or pa.types.is_boolean(t)
                                  or t in (pa.float64(), pa.int64())):
            return table.to_pandas().to_csv(index=False)
        cols[name] = col.to_pylist()  # (to_numpy asks for pandas)
    return columns_csv(cols) if cols else table.to_pandas().to_csv(index=False)


def _by_pandas(cols: dict, header: bool = True) -> str:
    import pandas as pd

    return pd.DataFrame(cols).to_csv(index=False, header=header)
