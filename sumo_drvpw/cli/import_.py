"""``sumo-drvpw import FORMAT SRC... --out LOG.parquet [--columns mapping.toml]``, or
``sumo-drvpw import columns SRC... --list [--columns mapping.toml]``.

Converts vendor logs to one canonical drive log (Parquet), prints kept/dropped samples per
reason and per file, and stores that report as JSON in the Parquet schema metadata under
the key ``sumo_drvpw.import``.
"""

from __future__ import annotations

import json
from pathlib import Path

from sumo_drvpw.errors import UserError
from sumo_drvpw.data.adapters import FORMATS, read

META_KEY = b"sumo_drvpw.import"


def configure(parser) -> None:
    parser.add_argument("format", metavar="FORMAT", help="one of: " + ", ".join(FORMATS))
    parser.add_argument("src", metavar="SRC", nargs="+", help="vendor files or folders")
    parser.add_argument("--out", metavar="LOG.parquet",
                        help="canonical drive log to write (Parquet; required unless --list)")
    parser.add_argument("--list", action="store_true",
                        help="format 'columns': list what each SRC file offers — MDF channels with unit, "
                             "samples and rate (raw CAN decoded with the mapping's options.dbc), CSV/Parquet "
                             "columns with the unit their label carries — to write the mapping from; "
                             "--columns is optional then (only its [options] are read); writes nothing")
    parser.add_argument("--columns", metavar="mapping.toml",
                        help="column mapping (format 'columns' only: CSV/Parquet columns, or the "
                             "channels of ASAM MDF .mf4/.mdf files, raw CAN logs with options.dbc; "
                             "docs/adapters.md)")
    parser.add_argument("--wind", metavar="SPEED@FROM",
                        help="the day's wind (e.g. a weather station's record): speed [m/s] and the "
                             "direction it blows from [° clockwise from north], e.g. 4.2@210; writes "
                             "wind_mps (along each sample's heading, tailwind positive) so a calibration "
                             "sees the air speed. Import the trips of one wind together")


#: the terminal shows at most this many notes per file and this many characters per note;
#: the import report stored with the log (read_report) holds them whole
NOTES_SHOWN = 8
NOTE_CHARS = 400


def _notes(notes: list[str]) -> list[str]:
    out = []
    for n in notes[:NOTES_SHOWN]:
        cut = len(n) - NOTE_CHARS
        out.append(f"      note: {n[:NOTE_CHARS]} … ({cut} characters more)" if cut > 40 else f"      note: {n}")
    if len(notes) > NOTES_SHOWN:
        out.append(f"      note: … and {len(notes) - NOTES_SHOWN} more notes")
    return out


def format_report(report: dict) -> str:
    """Human-readable kept/dropped table: one line per file, then the totals (long notes
    shortened: the report stored with the log, :func:`read_report`, has them whole)."""
    parts = sum(r.get("parts", 1) for r in report["files"])
    lines = [f"import {report['format']}: {parts} file(s)"
             + (f" joined into {len(report['files'])} trip(s)" if parts != len(report["files"]) else "")]
    shortened = False
    for r in report["files"]:
        d = ", ".join(f"{k} {n}" for k, n in r["dropped"].items()) or "none"
        lines.append(f"  {Path(r['file']).name}: read {r['rows_read']}, kept {r['kept']}, dropped: {d}")
        shown = _notes(r["notes"])
        shortened |= shown != [f"      note: {n}" for n in r["notes"]]
        lines += shown
    d = ", ".join(f"{k} {n}" for k, n in report["dropped"].items()) or "none"
    lines.append(f"total: read {report['rows_read']}, kept {report['kept']}, dropped: {d}")
    lines += [f"note: {n}" for n in report["notes"]]
    lines += [f"warning: {w}" for w in report.get("warnings", [])]
    if shortened:
        lines.append("note: notes shortened here; the log's import report has them whole "
                     "(sumo_drvpw.cli.import_.read_report(LOG))")
    return "\n".join(lines)


def write_log(df, report: dict, out) -> None:
    """Write the canonical log atomically with the import report in the schema metadata."""
    import pyarrow as pa

    from sumo_drvpw.fileio import _clean, write_parquet

    table = pa.Table.from_pandas(df, preserve_index=False)
    meta = dict(table.schema.metadata or {})
    meta[META_KEY] = json.dumps(_clean(report)).encode("utf-8")
    if report.get("roles"):
        from sumo_drvpw.data.roles import to_metadata

        meta.update(to_metadata(report["roles"]))
    write_parquet(out, table.replace_schema_metadata(meta))


def read_report(path) -> dict:
    """The import report stored in a canonical log written by ``sumo-drvpw import``."""
    import pyarrow.parquet as pq

    meta = pq.read_schema(path).metadata or {}
    if META_KEY not in meta:
        raise UserError(f"{path}: no '{META_KEY.decode()}' metadata (not written by sumo-drvpw import)")
    return json.loads(meta[META_KEY])


def format_listing(files: list[dict]) -> str:
    """The terminal table of :func:`sumo_drvpw.data.adapters.listing.list_sources`."""
    lines = []
    for f in files:
        rows = f["rows"]
        lines.append(f"{f['file']} ({f['kind']}): {len(rows)} {'channels' if 'MDF' in f['kind'] else 'columns'}")
        w = max([len(r["label"]) for r in rows] + [5])
        if "MDF" in f["kind"]:
            lines.append(f"  {'label':<{w}}  {'unit':<8} {'samples':>9} {'rate Hz':>9} {'mean Hz':>9}")
            lines += [f"  {r['label']:<{w}}  {r['unit']:<8} {r['samples']:>9} {r['rate_hz']:>9.3g} "
                      f"{r.get('mean_rate_hz', float('nan')):>9.3g}" for r in rows]
        else:
            lines.append(f"  {'label':<{w}}  {'unit':<8} {'values':>7} {'numbers':>7}  first value")
            lines += [f"  {r['label']:<{w}}  {r['unit']:<8} {r['samples']:>7} {r['numbers']:>7}  {r['first'][:30]}"
                      for r in rows]
        lines += [f"  note: {n}" for n in f["notes"]]
    if files:  # the files of one listing mostly share a layout: one sketch, from the first
        lines += ["", f"# from {files[0]['file']}" + (f" (of {len(files)} files)" if len(files) > 1 else ""),
                  files[0]["sketch"]]
    return "\n".join(lines)


def main(args) -> int:
    if args.list:
        if args.format != "columns":
            raise UserError(f"--list is for format 'columns' (what a CSV, Parquet or MDF file offers to map), "
                            f"not '{args.format}'")
        from sumo_drvpw.data.adapters.listing import list_sources

        print(format_listing(list_sources(args.src, args.columns)))
        return 0
    if args.out is None:
        raise UserError("import: --out LOG.parquet is required (or --list, to see what the files offer)")
    out = Path(args.out)
    if out.suffix.lower() != ".parquet":
        raise UserError(f"--out {out}: must end in .parquet")
    from sumo_drvpw.cli import existing_paths
    from sumo_drvpw.fileio import check_output_path

    check_output_path(out, existing_paths(args.src, args.columns), "file")  # never onto an input
    wind = None
    if args.wind is not None:
        from sumo_drvpw.data.wind import parse_wind

        wind = parse_wind(args.wind, "--wind")
    df, report = read(args.format, args.src, columns=args.columns)
    if len(df) < 2:  # a drive log needs two samples (sumo_drvpw.data.log)
        why = ", ".join(f"{k} {n}" for k, n in report["dropped"].items() if n)
        raise UserError(f"{', '.join(map(str, args.src))}: {len(df)} sample(s) kept of "
                        f"{report['rows_read']} read"
                        + (f" (dropped: {why})" if why else "") + "; nothing sensible to import")
    if wind is not None:
        from sumo_drvpw.data.wind import add_wind

        df, report["wind"] = add_wind(df, *wind, where=", ".join(map(str, args.src)))
        w = report["wind"]
        report["notes"].append(
            f"wind {w['speed_mps']:g} m/s from {w['from_deg']:g}° written as wind_mps along the heading "
            f"({w['heading_source']}; {w['samples_with_heading']} of {w['samples']} samples have one, "
            "the others are taken as still air)")
    report["out"] = str(out)
    write_log(df, report, out)
    print(format_report(report))
    print(f"wrote {out} ({len(df)} samples, {df['trip_id'].nunique()} trip(s), "
          f"{df.shape[1]} columns)")
    return 0
