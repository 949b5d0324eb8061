"""Input files from what the user named: files, and the matching files inside folders.

The one ``expand_paths`` of the package: the drive-log reader and every adapter list
their inputs through it, so a folder, a file and a wrong name behave alike everywhere.
``parquet_frame`` reads a Parquet file into a pandas frame at about the frame's memory.
"""

from __future__ import annotations

from pathlib import Path

from sumo_drvpw.errors import UserError


#: CSS Electronics CANedge log files that are MF4 packed by the logger (its converters read
#: them: canlogger.csselectronics.com, "CANedge MF4 converters"); no MDF reader opens them
PACKED_MF4 = {".mfc": "compressed", ".mfe": "encrypted", ".mfm": "compressed and encrypted"}


def files_in_common(named, files) -> list[str]:
    """The ``files`` that ``named`` names too — files, or folders holding them, as an
    equation's provenance lists the logs it was calibrated on; compared as resolved paths."""
    seen = set()
    for x in named:
        p = Path(x)
        if p.is_dir():
            seen |= {q.resolve() for q in p.rglob("*") if q.is_file()}
        elif p.exists():
            seen.add(p.resolve())
    return [f for f in files if Path(f).resolve() in seen]


def folders_in_order(base, depth: int, most: int) -> list[Path]:
    """The first ``most`` folders ``depth`` levels below ``base``, each level in name order:
    the same on every machine (a file system lists a folder in an order of its own — ext4 by
    a hash of the name —, so a search capped in that order saw other folders elsewhere)."""
    out: list[Path] = []

    def walk(d: Path, k: int) -> None:
        if k == 0:
            out.append(d)
            return
        try:
            subs = sorted(p for p in d.iterdir() if p.is_dir())
        except OSError:
            return
        for sub in subs:
            if len(out) >= most:
                return
            walk(sub, k - 1)

    walk(Path(base), depth)
    return out[:most]


def refuse_packed(p: Path) -> None:
    """UserError for a CANedge MF4 that the logger compressed or encrypted (:data:`PACKED_MF4`),
    naming the file and what unpacks it; else nothing."""
    how = PACKED_MF4.get(p.suffix.lower())
    if how:
        raise UserError(f"{p}: a CANedge log file {how} by the logger ({p.suffix}), not a plain MF4: "
                        "unpack it to .MF4 first with CSS Electronics' MF4 converters (e.g. the MDF "
                        "converter, mdf2finalized; an encrypted file needs its passwords.json), then "
                        "read the .MF4")


def expand_paths(paths, suffixes: tuple[str, ...], what: str,
                 check_files: bool = False) -> list[Path]:
    """Files named in ``paths`` plus, for each folder named, its files with one of
    ``suffixes`` (sorted by name).

    Parameters
    ----------
    paths : a path or a list of paths (str or Path) to files or folders
    suffixes : lower-case suffixes with the dot, e.g. ``(".parquet", ".csv")``
    what : what the files are, for messages ("drive log", "TUM trip CSV")
    check_files : also refuse a named file whose suffix is not in ``suffixes``

    Raises :class:`UserError` naming the path for a missing path, an empty folder, a file
    of the wrong type (``check_files``), or no input at all.
    """
    if isinstance(paths, (str, Path)):
        paths = [paths]
    out: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            found = sorted(f for f in p.iterdir() if f.is_file() and f.suffix.lower() in suffixes)
            if not found:
                for f in sorted(p.iterdir()):
                    refuse_packed(f)
                raise UserError(f"{p}: folder holds no {what} file ({', '.join(suffixes)})"
                                + subfolder_hint(p, suffixes))
            out.extend(found)
        elif p.is_file():
            refuse_packed(p)
            if check_files and p.suffix.lower() not in suffixes:
                raise UserError(f"{p}: unknown file type '{p.suffix}' (a {what} is "
                                f"{' or '.join(suffixes)}, or a folder of them)")
            out.append(p)
        else:
            raise UserError(f"{p}: no such file or folder")
    if not out:
        raise UserError(f"no {what} given")
    return out


def subfolder_hint(folder: Path, suffixes: tuple[str, ...], skip=("overview.csv",)) -> str:
    """'; its sub-folders hold N such files (…): name those folders …' when files with one of
    ``suffixes`` lie below ``folder`` (a folder is read flat, its sub-folders are not
    searched), else ''."""
    from itertools import islice

    below = sorted(f for f in islice(Path(folder).rglob("*"), 20000)  # an error message: bounded
                   if f.is_file() and f.suffix.lower() in suffixes and f.parent != Path(folder)
                   and f.name not in skip)
    if not below:
        return ""
    dirs = sorted({str(f.parent) for f in below})
    return (f"; its sub-folders hold {len(below)} such file(s) (e.g. {below[0]}): name those "
            f"folders ({', '.join(dirs[:3])}{' …' if len(dirs) > 3 else ''}), sub-folders are not searched")


#: at most this many columns are read one block each (pandas warns beyond 100 blocks)
SPLIT_COLUMNS_MAX = 90


def parquet_frame(p: Path, meta_prefixes: tuple[bytes, ...] = ()) -> tuple:
    """A Parquet file as a pandas frame, and the schema's key-value metadata whose keys start
    with one of ``meta_prefixes`` (decoded).

    Arrow's buffers are freed as each column is converted and handed back to the system after
    (the peak is about the frame, not the frame and the Arrow table); each column keeps its own
    block unless there are so many that pandas would call the frame fragmented."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    table = pq.read_table(p)
    meta = {k.decode(): v.decode() for k, v in (table.schema.metadata or {}).items()
            if k.startswith(meta_prefixes)} if meta_prefixes else {}
    df = table.to_pandas(split_blocks=table.num_columns <= SPLIT_COLUMNS_MAX, self_destruct=True)
    del table
    pa.default_memory_pool().release_unused()
    return df, meta
