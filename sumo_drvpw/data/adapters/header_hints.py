"""Where a mapped label is missing from a file: what its header shows instead — the header
on a line below a title (options.skip_rows), a first line of data (a logger's continuation
file), a label written in another case, spacing or encoding — each a hint the error of
:mod:`sumo_drvpw.data.adapters.columns` adds, and the header's cells as written."""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from sumo_drvpw.data.adapters._common import is_number

#: lines of a CSV searched for a mapped label that is not in the header (the hint of the error)
HEADER_SEARCH_LINES = 50


def skip_hint(path: Path, m: dict) -> str:
    """' (… set options.skip_rows = N)' when a mapped label sits on a line below the one read
    as the header, else ''."""
    for label in m["columns"]:
        line = header_line_of(path, m, label)
        if line is not None and line != m.get("skip_rows", 0) + 1:
            return (f" ('{label}' is on line {line}: the header is there, below {line - 1} other "
                    f"line(s); set options.skip_rows = {line - 1} in {m['path']})")
    return ""


def no_header_hint(raw: pd.DataFrame) -> str:
    """' (… no header …)' when what was read as the header is mostly numbers or dates (a
    logger's continuation file, written without the header of its first file), else ''."""
    cells = [str(c) for c in raw.columns]
    data = sum(is_number(c) or not pd.isna(pd.to_datetime(c, errors="coerce", format="mixed")) for c in cells)
    if len(cells) < 2 or data < 0.5 * len(cells):
        return ""
    return (f" (its first line is data, not a header: '{','.join(cells[:3])[:60]},…' — a logger's "
            "continuation file? put the header line of its other files above it)")


def header_line_of(path: Path, m: dict, label: str) -> int | None:
    """The 1-based line among the first :data:`HEADER_SEARCH_LINES` of a CSV whose cells hold
    ``label`` (a header below an app's title lines), or None."""
    if path.suffix.lower() in (".parquet", ".pq"):
        return None
    try:
        with open(path, encoding=m["encoding"], errors="replace") as f:
            for i, line in enumerate(f, 1):
                if i > HEADER_SEARCH_LINES:
                    break
                cells = [c.strip().strip('"').strip().lstrip("\ufeff") for c in line.split(m["sep"])]
                if label in cells:
                    return i
    except (OSError, ValueError, LookupError):  # unreadable in that encoding: reading it says why
        return None
    return None


def close_label(label: str, labels: list[str], encoding: str) -> str:
    """A hint naming the file's label that differs from ``label`` only by case, spacing or
    a mis-decoded character ('°C' as 'Â°C': UTF-8 read as Latin-1, or written so), else ""."""
    def key(x: str) -> str:
        return "".join(str(x).replace("Â", "").replace("Ã", "").lower().split())
    near = [c for c in labels if key(c) == key(label)]
    if not near:
        return ""
    if not any("Â" in c or "Ã" in c for c in near):
        return f" — the file has '{near[0]}': map that label"
    latin = encoding.lower().replace("_", "-") in ("latin-1", "latin1", "iso-8859-1", "cp1252", "windows-1252")
    return (f" — the file has '{near[0]}' (" + ("UTF-8 read as Latin-1: [options] encoding = \"utf-8\", or map "
                                                "that label" if latin else
                                                "its UTF-8 written twice over: map that label as it reads") + ")")


def header_cells(path: Path, m: dict) -> list[str]:
    """A CSV's header line as written, each label stripped ([] for Parquet, or where it cannot
    be read so: reading the table says why)."""
    if path.suffix.lower() in (".parquet", ".pq"):
        return []
    try:
        row = pd.read_csv(path, sep=m["sep"], encoding=m["encoding"], header=None, nrows=1, dtype=str,
                          keep_default_na=False, na_filter=False, skiprows=m.get("skip_rows", 0) or None)
    except (ValueError, OSError, pd.errors.ParserError, pd.errors.EmptyDataError):
        return []
    return [str(c).strip().lstrip("\ufeff").strip() for c in row.iloc[0]] if len(row) else []
