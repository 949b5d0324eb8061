"""A CSV file cut short: it ends inside its last row (a logger that lost power, a copy
that was interrupted).

Loggers and writers end every row with a line break, so a file whose last line has none
was cut inside that row: some of its fields are missing, or its last field is cut (a
number cut off is still a number, only a wrong one). The readers leave that row out and
say so, naming the file and the row; the complete rows before it are read as they are.
A row in the middle of a file with fewer fields than the header is no cut: its missing
fields are empty (NaN), as the schema's rules for empty values say (one with more fields
than the header is refused by the CSV parser).

Used by the canonical reader (:mod:`sumo_drvpw.data.log`, :mod:`sumo_drvpw.data.stream`)
and by the import's vendor CSVs (:mod:`sumo_drvpw.data.adapters._common`).
"""

from __future__ import annotations

import io
from pathlib import Path

import pandas as pd

#: bytes read from the end of a file to find its last line break
TAIL_BYTES = 65536


def complete_bytes(path, encoding: str = "utf-8") -> int | None:
    """The length [bytes] of a CSV file up to the end of its last complete line, when the
    file ends inside a row; None when it ends with a line break (``\\n`` or ``\\r``), when
    only blanks follow its last line break (CSV readers skip a blank line), when it holds no
    line break at all (a header alone: nothing was cut from the data), or when its text is
    UTF-16 or UTF-32 (its line breaks are not single bytes)."""
    if str(encoding).lower().replace("-", "").replace("_", "").startswith(("utf16", "utf32")):
        return None
    with open(path, "rb") as f:
        f.seek(0, 2)
        size = f.tell()
        at = size
        while at > 0:  # the last line break, reading back in blocks (a long last line)
            start = max(0, at - TAIL_BYTES)
            f.seek(start)
            block = f.read(at - start)
            if at == size and (not block or block.endswith((b"\n", b"\r"))):
                return None
            k = max(block.rfind(b"\n"), block.rfind(b"\r"))
            if k >= 0:
                end = start + k + 1
                f.seek(end)
                return None if not f.read(size - end).strip(b" \t") else end
            at = start
    return None


class _Head(io.RawIOBase):
    """The first ``size`` bytes of an open binary file, as a file."""

    def __init__(self, f, size: int):
        self._f, self._left = f, int(size)

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        if self._left <= 0:
            return 0
        n = self._f.readinto(memoryview(b)[:min(len(b), self._left)])
        self._left -= n
        return n

    def close(self) -> None:
        self._f.close()
        super().close()


def open_complete(path, size: int):
    """The file ``path`` read up to ``size`` bytes (:func:`complete_bytes`): its complete
    rows, for a CSV reader (pandas.read_csv takes it; close it after reading)."""
    return io.BufferedReader(_Head(open(path, "rb"), size))


def cut_message(path, complete_rows: int) -> str:
    """What is said of a file cut inside row ``complete_rows`` (0-based: the rows before it
    are complete)."""
    return (f"{path}: the file is cut short (truncated): it ends inside row {complete_rows}, its last "
            f"line (no line break at its end), which is left out; the {complete_rows} complete row(s) "
            "before it are read")


def refuse_if_too_short(path, complete_rows: int) -> None:
    """UserError when a file cut inside a row holds fewer than 2 complete rows (a drive log
    needs at least 2 samples), naming the file and the cut."""
    from sumo_drvpw.errors import UserError

    if complete_rows < 2:
        raise UserError(f"{Path(path)}: the file is cut short (truncated inside row {complete_rows}, its "
                        f"last line) and holds {complete_rows} complete row(s); a drive log needs at least "
                        "2 samples")


def read_complete_csv(path, **kw) -> tuple[pd.DataFrame, int | None]:
    """pandas.read_csv of the complete rows of a CSV file (``kw`` passed on) and, when the
    file ends inside a row, that row's number (0-based: the number of complete rows; the cut
    row is never parsed, so it changes no column's type); None when the file is whole.
    A cut file with fewer than 2 complete rows is refused (:func:`refuse_if_too_short`)."""
    size = complete_bytes(path, kw.get("encoding") or "utf-8")
    if size is None:
        return pd.read_csv(path, **kw), None
    with open_complete(path, size) as fh:
        try:
            df = pd.read_csv(fh, **kw)
        except pd.errors.EmptyDataError:  # (a header cut inside its own line: no line break)
            df = pd.DataFrame()
    refuse_if_too_short(path, len(df))
    return df, len(df)
