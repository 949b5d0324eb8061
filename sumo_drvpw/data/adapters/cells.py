"""A vendor column's cells read as numbers: no-reading tokens as missing, anything else that is
no number (a word, a JSON or Parquet ``true``/``false`` where a number is due) refused naming the
file, the column and its first such row."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from sumo_drvpw.errors import UserError


def numeric(series: pd.Series, file, column: str, na_tokens=("-", ""), bools: bool = False) -> pd.Series:
    """Float column from a vendor column; tokens in na_tokens become NaN, anything else non-numeric
    is a UserError. A boolean cell (JSON ``true``, a Parquet bool column) is a UserError too unless
    ``bools`` (a flag or validity column: read as 1/0) — a speed ``true`` is no 1 mph."""
    if pd.api.types.is_bool_dtype(series) or pd.api.types.is_numeric_dtype(series):
        if not bools and pd.api.types.is_bool_dtype(series) and series.notna().any():
            _refuse_bool(series, file, column, int(np.flatnonzero(series.notna().to_numpy())[0]))
        return series.astype(float)
    s = series.astype(object)
    # numbers parse at once, in numpy; only the cells that do not (usually none) are tested
    # against the tokens (per-cell and per-Series work was most of a wide log's import time)
    arr = s.to_numpy()
    conv = pd.to_numeric(s, errors="coerce").to_numpy(float, copy=True)
    cand = np.flatnonzero((conv == 0) | (conv == 1)) if not bools else []  # (pandas reads True as 1.0: only
    if len(cand) and pd.api.types.infer_dtype(arr[cand]) not in ("floating", "integer", "mixed-integer-float"):
        is_bool = np.frompyfunc(lambda x: isinstance(x, (bool, np.bool_)), 1, 1)  # the cells that read as 0 or
        hit = cand[is_bool(arr[cand]).astype(bool)]  # 1 are looked at: numbers all at once, else cell by cell)
        if len(hit):
            _refuse_bool(s, file, column, int(hit[0]))
    tokens = {str(t).strip() for t in na_tokens}
    is_na = pd.isna(arr)
    check = ~is_na & (np.isnan(conv) | any(is_number(t) for t in tokens))
    for i in np.flatnonzero(check):
        x = arr[i]
        if isinstance(x, str) and x.strip() in tokens:
            is_na[i] = True
    conv[is_na] = np.nan
    bad = np.isnan(conv) & ~is_na
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        hint = ' (degrees and minutes: unit = "deg min" reads them)' if _DEG_MIN.match(str(s.iloc[i])) else ""
        raise UserError(f"{file}: column '{column}' is not numeric: data row {i} holds "
                        f"{s.iloc[i]!r}{hint}")
    return pd.Series(conv, index=series.index)


#: a position in degrees and decimal minutes, "34 11.28809", "-117 25.75793"
_DEG_MIN = re.compile(r"^\s*(-?)(\d{1,3})\s+(\d{1,2}(?:\.\d*)?)\s*$")


def degrees_minutes(series: pd.Series, file, column: str, na_tokens=("-", "")) -> pd.Series:
    """Degrees from a column of degrees and decimal minutes as text (LeafSpy's `Lat`, `Long`:
    "34 11.28809" → 34.188135, "-117 25.75793" → −117.429299; the sign is the degrees'); a
    plain number is degrees; tokens in ``na_tokens`` are missing. Anything else, or minutes
    of 60 or more, is refused naming the file, the column and its first such row."""
    tokens = {str(t).strip() for t in na_tokens}
    out = np.full(len(series), np.nan)
    for i, x in enumerate(series.astype(object).to_numpy()):
        if x is None or (isinstance(x, float) and np.isnan(x)) or str(x).strip() in tokens:
            continue
        m = _DEG_MIN.match(str(x))
        if m is None and is_number(str(x)):
            out[i] = float(x)
            continue
        if m is None or float(m.group(3)) >= 60:
            raise UserError(f"{file}: column '{column}' (unit deg min) data row {i} holds {x!r}: not degrees "
                            "and decimal minutes ('34 11.28809', minutes below 60)")
        out[i] = (-1 if m.group(1) else 1) * (int(m.group(2)) + float(m.group(3)) / 60.0)
    return pd.Series(out, index=series.index)


def _refuse_bool(s: pd.Series, file, column: str, i: int) -> None:
    raise UserError(f"{file}: column '{column}' is not numeric: data row {i} holds {str(s.iloc[i]).lower()} "
                    "(a boolean, not a number: it would read as 1 or 0)")


def is_number(text: str) -> bool:
    """Whether ``text`` reads as a number (float() takes it)."""
    try:
        float(text)
        return True
    except ValueError:
        return False


def extra_values(series: pd.Series, file, column: str, notes: list, factor: float = 1.0,
                 offset: float = 0.0, na_tokens=("-", "")) -> pd.Series:
    """A vendor column the adapter does not know: numeric (converted by factor and offset)
    where it reads as numbers (true/false as 1/0: a flag), else kept as text and noted — a
    logger's comment, driver or mode label is no reason to refuse the file (as the ``columns``
    format keeps it)."""
    try:
        return numeric(series, file, column, na_tokens, bools=True) * factor + offset
    except UserError as e:
        notes.append(f"column '{column}' is not numeric ({str(e).split(': ', 2)[-1]}): "
                     "kept as text")
        return series.astype(str)
