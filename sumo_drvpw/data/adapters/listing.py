"""What a log file offers, to write a ``columns`` mapping from:
``sumo-drvpw import columns SRC... --list [--columns mapping.toml]``.

For an ASAM MDF file each channel's label, unit, samples and sampling rate (raw CAN frames
decoded first with the DBC files of the mapping's ``[options] dbc``,
:func:`sumo_drvpw.data.adapters.mdf.channels`); for a CSV or Parquet file each column's
label, the unit its label carries (``Speed (km/h)``, ``Speed [km/h]``), how many of the rows
read hold a value and how many of those read as numbers, and a first value. The mapping is
optional; only its ``[options]`` are read (separator, encoding, lines before the header,
DBC files), so its ``[columns]`` may still be unwritten.
"""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.data.adapters._common import expand_paths, is_number, split_header

#: rows of a CSV read for the listing (the header and a first stretch of the log)
ROWS_READ = 5000


def list_sources(paths, mapping=None) -> list[dict]:
    """Per file: {"file", "kind", "rows": [{label, unit, samples, …}], "notes"}."""
    from sumo_drvpw.data.adapters import mdf
    from sumo_drvpw.data.adapters.columns import SUFFIXES, load_options

    m = load_options(mapping) if mapping is not None else None
    out = []
    for f in expand_paths(paths, SUFFIXES + mdf.SUFFIXES, "CSV/Parquet/MDF"):
        notes: list[str] = []
        if mdf.is_mdf(f):
            rows, notes = mdf.channels(f, m or {"path": Path("(no mapping)"), "dbc": [], "isotp_layout": "css"})
            kind = "ASAM MDF" + (f", decoded with {', '.join(d.name for d in m['dbc'])}" if m and m["dbc"] else "")
        else:
            rows, kind = _table_columns(f, m or _sniffed(f, notes)), "table"
        out.append({"file": f, "kind": kind, "rows": rows, "notes": notes})
    return out


def _sniffed(path: Path, notes: list) -> dict:
    """Options to read a CSV without a mapping: UTF-8 (else Latin-1) and the separator the
    header line shows (Python's csv.Sniffer; else ','), said in ``notes``."""
    import csv

    m = {"path": Path("(no mapping)"), "sep": ",", "encoding": "utf-8", "decimal": ".", "skip_rows": 0,
         "columns": {}}
    if path.suffix.lower() in (".parquet", ".pq"):
        return m
    head = path.read_bytes()[:65536]
    try:
        text = head.decode("utf-8")
    except UnicodeDecodeError:
        text, m["encoding"] = head.decode("latin-1"), "latin-1"
    try:
        m["sep"] = csv.Sniffer().sniff(text.splitlines()[0] if text else "", delimiters=",;\t|").delimiter
    except csv.Error:
        pass
    notes.append(f"no mapping: read as {m['encoding']}, {m['sep']!r}-separated (sniffed); a mapping's "
                 "[options] sep and encoding say so when it differs")
    return m


def _table_columns(path: Path, m: dict) -> list[dict]:
    from sumo_drvpw.data.adapters.columns import _read_table

    if path.suffix.lower() in (".parquet", ".pq"):
        import pyarrow.parquet as pq

        pf = pq.ParquetFile(path)
        df = next(pf.iter_batches(batch_size=ROWS_READ)).to_pandas().astype(str) if pf.metadata.num_rows else None
    else:
        df = _read_table(path, {**m, "nrows": ROWS_READ})
    rows = []
    for c in ([] if df is None else df.columns):
        vals = [v for v in df[c].astype(str).str.strip() if v not in ("", "nan", "None", "-")]
        unit = split_header(str(c))[1]
        rows.append({"label": str(c), "unit": unit, "samples": len(vals),
                     "numbers": sum(is_number(v) for v in vals), "first": vals[0] if vals else ""})
    return rows
