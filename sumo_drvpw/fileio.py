"""Atomic output and small file helpers (outputs: temporary name, then rename)."""

from __future__ import annotations

import contextlib
import glob
import json
import os
import stat
import tempfile
from pathlib import Path
from typing import Iterator


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

    An interrupted writer leaves either the old file or the new one, never a partial one.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as e:  # read-only, permission denied, disk full: the user's to fix
        from sumo_drvpw.errors import UserError

        raise UserError(f"{path}: cannot write here: {e.strerror or e}") from None
    os.close(fd)
    tmp = Path(tmp)
    umask = os.umask(0)
    os.umask(umask)
    try:
        yield tmp
        # mkstemp creates 0600; give the output the mode a plain open() would
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()


def write_text(path, text: str) -> None:
    """Write text atomically (UTF-8)."""
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


def write_json(path, obj) -> None:
    """Write JSON atomically, indented, NaN written as null."""
    write_text(path, json.dumps(plain(obj), indent=2, sort_keys=False) + "\n")


def plain(o, toml: bool = False):
    """The one cleaner of documents for JSON and TOML: plain Python values only.

    Keys become str, tuples and arrays lists, NumPy scalars int/float/bool, paths str.
    For JSON (default) a NaN or infinite float becomes None (null); for TOML
    (``toml=True``), which has no null, dict entries whose value is None are left out and
    floats are kept as they are (TOML writes nan and inf).
    """
    import math

    import numpy as np

    if isinstance(o, dict):
        return {str(k): plain(v, toml) for k, v in o.items() if not (toml and v is None)}
    if isinstance(o, (list, tuple)):
        return [plain(v, toml) for v in o]
    if isinstance(o, np.ndarray):
        return plain(o.tolist(), toml)
    if isinstance(o, (bool, np.bool_)):
        return bool(o)
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, (np.floating, float)):
        f = float(o)
        return f if toml or math.isfinite(f) else None
    if isinstance(o, Path):
        return str(o)
    return o


#: former name of :func:`plain` (JSON mode)
_clean = plain


def write_parquet(path, table) -> None:
    """Write a pyarrow Table or pandas DataFrame to Parquet atomically."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    if not isinstance(table, pa.Table):
        table = pa.Table.from_pandas(table, preserve_index=False)
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp)


def write_figure(path, fig) -> None:
    """Save a matplotlib figure as PNG atomically and close it."""
    import matplotlib.pyplot as plt

    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=110, bbox_inches="tight")
    plt.close(fig)


def open_maybe_gzip(path):
    """A file opened for binary reading, decompressed when it is gzipped (by its magic
    bytes, not its name: SUMO writes *.gz outputs, and users rename files)."""
    import gzip

    with open(path, "rb") as f:
        magic = f.read(2)
    return gzip.open(path, "rb") if magic == b"\x1f\x8b" else open(path, "rb")


def repo_root() -> Path:
    """The project checkout this package runs from (editable install)."""
    return Path(__file__).resolve().parent.parent


@contextlib.contextmanager
def signals_blocked(*signums):
    """``signums`` held back in this thread while the block runs, then delivered; threads
    started meanwhile keep them blocked, and so do the processes those start (a blocked
    signal stays blocked across fork and exec). Where the platform cannot block signals, the
    block runs as it is."""
    import signal

    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, set(signums))
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def folder_given(p: Path, what: str, suffixes: tuple[str, ...]) -> str:
    """The message for a folder given where a file is read: its files of those suffixes
    (the first few), or that it has none."""
    names = sorted(f.name for f in p.iterdir() if f.is_file() and f.suffix in suffixes)
    listed = ", ".join(names[:6]) + (", …" if len(names) > 6 else "")
    return (f"{p} is a folder; the {what} is a file in it" + (f": {listed}" if names else
            f", and it has no {' or '.join('*' + x for x in suffixes)} file"))


def read_toml(path, what: str) -> dict:
    """Parse a TOML file; a missing or invalid file is a UserError naming it.

    Parameters
    ----------
    path : file path
    what : what the file is, for the message (e.g. "equation file", "--columns mapping")
    """
    import tomllib

    from sumo_drvpw.errors import UserError

    p = Path(path)
    if p.is_dir():
        raise UserError(folder_given(p, what, (".toml",)))
    if not p.is_file():
        raise UserError(f"{what} not found: {p}")
    try:
        text = p.read_text(encoding="utf-8-sig")  # a byte-order mark (Notepad, Excel) is no TOML
    except UnicodeDecodeError as e:
        raise UserError(f"{p}: not a valid TOML {what}: not UTF-8 text (byte {e.start}); "
                        "save it as UTF-8") from None
    except OSError as e:  # PermissionError, I/O error
        raise UserError(f"{p}: cannot read the {what}: {e.strerror or e}") from None
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise UserError(f"{p}: not a valid TOML {what}: {e}") from None
    check_toml_integers(doc, p)
    return doc


def check_toml_integers(doc, where) -> None:
    """UserError naming the first integer beyond TOML's 64 bits (Python's reader keeps any
    size, which no number of the project means: an integer of 400 digits overflowed a float
    with a traceback), by its key path."""
    from sumo_drvpw.errors import UserError

    def walk(x, key):
        if isinstance(x, dict):
            for k, v in x.items():
                walk(v, f"{key}.{k}" if key else str(k))
        elif isinstance(x, list):
            for i, v in enumerate(x):
                walk(v, f"{key}[{i}]")
        elif isinstance(x, int) and not isinstance(x, bool) and not -2**63 <= x < 2**63:
            raise UserError(f"{where}: {key} = {str(x)[:12]}… ({len(str(x).lstrip('-'))} digits): an integer "
                            "beyond TOML's 64 bits; give a number")

    walk(doc, "")


# ------------------------------------------------------------------ whole output sets

#: The command line of the running CLI invocation (set by ``sumo_drvpw.cli.main``);
#: written into every output set's ``manifest.json`` when no ``command`` is given.
CURRENT_COMMAND: list[str] | None = None

MANIFEST = "manifest.json"
_NO_SPACE = {28, 122}  # ENOSPC, EDQUOT


def _version() -> str:
    from sumo_drvpw import __version__

    return __version__


def _is_within(a: Path, b: Path) -> bool:
    """True when ``a`` is ``b`` or lies inside the tree of ``b`` (resolved paths)."""
    return a == b or b in a.parents


def check_output_path(out, inputs=(), kind: str = "folder") -> Path:
    """Refuse an output path that is, holds or lies inside an input; return it resolved.

    Parameters
    ----------
    out : the output file or folder
    inputs : input files and folders of the command (never written to)
    kind : "folder" (an output set) or "file" (a single output file)

    Raises :class:`sumo_drvpw.errors.UserError` when ``out`` equals an input, lies inside
    an input folder, or (a folder replaced whole) contains an input; when a folder output
    has no name of its own ('', '.', '..': the working folder or a parent); when a folder output
    is an existing file or a file output is an existing folder.
    """
    from sumo_drvpw.errors import UserError

    if kind == "folder" and Path(out).name in ("", ".."):  # ('', '.', '..', 'a/..': no name of its own)
        raise UserError(f"{str(out)!r}: names the working folder or one above it, not an output folder of "
                        "its own (an output set replaces its folder whole): give the folder's name")
    out = Path(out)
    res = out.resolve()
    for i in inputs:
        if i is None:
            continue
        ri = Path(i).resolve()
        if _is_within(res, ri):
            raise UserError(f"{out}: output is {'the input' if res == ri else 'inside the input'} "
                            f"{i}; inputs are never overwritten, choose another output path")
        if kind == "folder" and _is_within(ri, res):
            raise UserError(f"{out}: output folder holds the input {i}, and an output folder "
                            "is replaced whole; choose another output path")
    try:  # one stat: a folder another run moves aside meanwhile is not "a file"
        mode = out.stat().st_mode
    except (FileNotFoundError, NotADirectoryError):
        mode = None
    if kind == "folder" and mode is not None and not stat.S_ISDIR(mode):
        raise UserError(f"{out}: exists and is a file, not a folder; choose a folder path")
    if kind == "file" and out.is_dir():
        raise UserError(f"{out}: is a folder; give a file name")
    base = next((d for d in res.parents if d.exists()), None)  # where the file or sibling goes
    if base is not None and not os.access(base, os.W_OK | os.X_OK):
        raise UserError(f"{out}: cannot write in {base} (read-only or permission denied)")
    return res


def no_space_message(path, e: OSError) -> str:
    """One line for a full disk (ENOSPC/EDQUOT) while writing under ``path``."""
    where = e.filename or path
    return f"{path}: disk full (no space left on the device) while writing {where}; nothing written"


@contextlib.contextmanager
def output_set(out_dir, *, force: bool = False, command=None, inputs=(),
               meta: dict | None = None) -> Iterator[Path]:
    """Write a whole set of outputs: into a temporary sibling folder, then move into place.

    Usage::

        with output_set(out, force=args.force, inputs=args.logs) as tmp:
            write_json(tmp / "report.json", doc)      # every file of the set under tmp
            write_text(tmp.parent / f"{tmp.name}.md", md)  # optional companion beside it

    The yielded folder has the same name as ``out_dir`` (it lives in a hidden temporary
    folder beside ``out_dir``), so code that derives names from the folder's name works
    unchanged; files written beside it in ``tmp.parent`` are companions moved beside
    ``out_dir`` (e.g. ``validation.md`` beside ``validation/``).

    On success ``manifest.json`` (files with sizes, command line, version, UTC time and
    ``meta``) is written into the set, an existing ``out_dir`` is replaced whole and the
    temporary folder removed. On any exception (KeyboardInterrupt included) the temporary
    folder is removed and ``out_dir`` stays as it was; a full disk becomes a UserError.

    Parameters
    ----------
    out_dir : final output folder
    force : replace an existing non-empty folder that is not an earlier output set
        (a folder with a sumo-drvpw ``manifest.json``, or an empty one, is always replaced)
    command : command line for the manifest (default: the running CLI's argv)
    inputs : input paths; ``out_dir`` may neither be nor lie inside nor contain one
    meta : extra manifest fields; the caller may fill it inside the block (e.g.
        ``meta["interrupted"] = True`` for a run stopped by Ctrl-C that writes what it has)
    """
    import shutil
    import signal

    from sumo_drvpw.errors import OutputExists, UserError

    out = Path(out_dir)
    check_output_path(out, inputs, "folder")
    if not force and _foreign_folder(out):
        raise OutputExists(f"{out}: folder exists, is not empty and was not written by "
                           "sumo-drvpw (no manifest.json); it is left untouched")
    extra = [] if force else unlisted_files(out)
    if extra:
        raise OutputExists(f"{out}: an earlier output set holds {len(extra)} file(s) it did not write "
                           f"(first: {extra[0]}), which replacing the set would delete; they are left "
                           "untouched — move them out")
    parent = out.parent if str(out.parent) else Path(".")
    made = [d for d in [parent, *parent.parents] if not d.exists()]
    try:
        parent.mkdir(parents=True, exist_ok=True)
        remove_abandoned(parent, out.name)
        stage = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".tmp", dir=parent))
        _own(stage)
    except PermissionError:
        raise UserError(f"{out}: cannot write in {made[-1].parent if made else parent} "
                        "(permission denied)") from None
    except OSError as e:
        if e.errno in _NO_SPACE:
            raise UserError(no_space_message(out, e)) from None
        raise UserError(f"{out}: cannot create the output folder: {e.strerror}") from None
    tmp = stage / out.name
    tmp.mkdir()
    info = meta if meta is not None else {}
    done = False
    try:
        try:
            yield tmp
            companions = sorted(p.name for p in stage.iterdir() if p.name not in (out.name, OWNER))
            write_manifest(tmp, info, command, [(c, (stage / c).stat().st_size) for c in companions])
        except OSError as e:
            if e.errno in _NO_SPACE:
                raise UserError(no_space_message(out, e)) from None
            raise
        with signals_blocked(signal.SIGINT, signal.SIGTERM):  # publish: no signal may split the moves
            olds = []
            try:
                _publish(tmp, out, parent, olds)
                for c in companions:
                    os.replace(stage / c, parent / c)
                done = True
            finally:
                for o in olds:  # earlier sets moved aside
                    shutil.rmtree(o, ignore_errors=True)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
        if not done:
            for d in made:  # folders created for this set only
                try:
                    d.rmdir()
                except OSError:
                    pass


def write_manifest(folder: Path, meta: dict | None = None, command=None, companions=(), kept=()) -> None:
    """``manifest.json`` of an output set in ``folder``: every file in it with its size (but
    ``kept``, a user's files the set was written beside), the command line, version, UTC time
    and ``meta`` (``companions``: (name, bytes) beside it)."""
    import datetime

    folder = Path(folder)
    files = sorted(str(p.relative_to(folder)) for p in folder.rglob("*")
                   if p.is_file() and p != folder / MANIFEST and str(p.relative_to(folder)) not in set(kept))
    write_json(folder / MANIFEST, {
        "tool": "sumo-drvpw", "version": _version(),
        "command": list(command if command is not None else (CURRENT_COMMAND or [])),
        "created_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "interrupted": False, **(meta or {}),
        "files": [{"path": f, "bytes": (folder / f).stat().st_size} for f in files],
        "companions": [{"path": f"../{c}", "bytes": b} for c, b in companions]})


def in_output_set(folder) -> bool:
    """Whether ``folder`` is (or lies in) the staging folder an :func:`output_set` yielded:
    the set is then written whole by it."""
    return any((p / OWNER).is_file() for p in Path(folder).absolute().parents)


def check_earlier_set(out, force: bool = False) -> tuple[list[str], list[str]]:
    """Check ``out`` for an output set written in place (the Python API's
    ``run_scenario(out_dir=…)`` and ``RunResult.write``, as :func:`output_set` is for the
    commands), before anything is written or removed: refused (:class:`OutputExists`)
    unless ``force`` — a non-empty folder that is no output set, and files a user added to
    an earlier set (``force``: left in place). Returns (the earlier set's files, the files
    left in place), for :func:`remove_stale` and :func:`write_manifest`."""
    from sumo_drvpw.errors import OutputExists, UserError

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise UserError(f"{out}: is a file; give a folder to write the outputs into")
    if not out.exists():
        return [], []
    if _foreign_folder(out):
        if force:
            return [], sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file())
        raise OutputExists(f"{out}: folder exists, is not empty and was not written by sumo-drvpw "
                           "(no manifest.json); it is left untouched (force=True writes into it)")
    extra = unlisted_files(out)
    if extra and not force:
        raise OutputExists(f"{out}: an earlier output set holds {len(extra)} file(s) it did not write "
                           f"(first: {extra[0]}), which writing the new set would leave beside it; "
                           "move them out (force=True keeps them there)")
    try:
        listed = [str(f["path"]) for f in json.loads((out / MANIFEST).read_text(encoding="utf-8"))["files"]]
    except (OSError, ValueError, KeyError, TypeError):
        listed = []
    return listed, extra


def earlier_stamps(out, listed) -> dict[str, tuple]:
    """Each file of an earlier set (``listed``: :func:`check_earlier_set`) as it is before the
    new set is written: (inode, size, modification and change time [ns]), for
    :func:`remove_stale` (a missing file: not there to remove)."""
    out = Path(out)
    stamps = {}
    for f in listed:
        try:
            st = (out / f).stat()
        except OSError:
            continue
        stamps[f] = (st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns)
    return stamps


def remove_stale(out, stamps: dict[str, tuple]) -> None:
    """Remove the files of an earlier set that the new one, written in place, did not write
    again: those still as :func:`earlier_stamps` found them before it was written (every
    output is written under a temporary name and renamed, a new file). Told by the files
    themselves, not by their times against this machine's clock: a file is stamped by the
    file system's (Linux: a coarse tick, up to some ms behind ``time.time()``; a file
    server's may be seconds off), which removed files just written. Called once the new set
    is written, so a run refused or failed before leaves the earlier set as it was."""
    out = Path(out)
    for f, was in stamps.items():
        p = (out / f).resolve()
        try:
            st = p.stat()
            if (p.is_file() and p.is_relative_to(out.resolve())
                    and (st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns) == was):
                p.unlink()
        except OSError:
            pass


#: the file in an output set's temporary folders naming the process that made them
OWNER = ".sumo-drvpw-owner"


def _own(folder: Path) -> None:
    """Name this process (host and pid) in a temporary folder of an output set."""
    import socket

    (folder / OWNER).write_text(f"{socket.gethostname()} {os.getpid()}\n", encoding="utf-8")


def remove_abandoned(parent: Path, name: str) -> list[Path]:
    """Remove the temporary folders of output sets named ``name`` in ``parent`` whose run
    was killed (``kill -9``, a crash of the machine's power aside: no cleanup ran) — those
    whose owner file names a process of this host that no longer exists; returns them.
    A folder without an owner file, or of another host, is left alone."""
    import shutil
    import socket

    host, gone = socket.gethostname(), []
    for d in parent.glob(f".{glob.escape(name)}.*"):
        if not (d.suffix in (".tmp", ".old") and d.is_dir()):
            continue
        try:
            who, pid = (d / OWNER).read_text(encoding="utf-8").split()
            pid = int(pid)
        except (OSError, ValueError):
            continue
        if who != host or pid == os.getpid():
            continue
        try:
            os.kill(pid, 0)
            continue  # still running (or a pid taken again by another process: left alone)
        except ProcessLookupError:
            pass
        except OSError:  # another user's process: alive
            continue
        shutil.rmtree(d, ignore_errors=True)
        gone.append(d)
    return gone


def _publish(tmp: Path, out: Path, parent: Path, olds: list, attempts: int = 20) -> None:
    """Move the folder ``tmp`` onto ``out``, moving an existing ``out`` aside first.

    Two runs publishing into one folder at once: each move is atomic, so ``out`` is always
    one whole set; when another run publishes between our two moves, its set is moved aside
    too and the last one to publish wins. The folders moved aside are appended to ``olds``.
    """
    import errno

    for attempt in range(attempts):
        if out.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{out.name}.", suffix=".old", dir=parent))
            _own(old)
            olds.append(old)
            try:
                os.replace(out, old / out.name)
            except FileNotFoundError:  # another run moved it aside first
                pass
        try:
            os.replace(tmp, out)
            return
        except OSError as e:
            if e.errno in (errno.ENOTEMPTY, errno.EEXIST) and attempt < attempts - 1:
                continue  # another run published in between: move its set aside as well
            if olds and not out.exists() and (olds[-1] / out.name).exists():
                os.replace(olds[-1] / out.name, out)  # put the earlier set back
            raise


def _foreign_folder(out: Path) -> bool:
    """True when ``out`` is a non-empty folder without a sumo-drvpw manifest.json.

    A set that a concurrent run moves aside while we look is not foreign: only a folder
    still there (same inode) and still without a manifest counts.
    """
    try:
        st = out.stat()
        if not stat.S_ISDIR(st.st_mode) or not any(out.iterdir()):
            return False
    except (FileNotFoundError, NotADirectoryError):
        return False
    if _is_output_set(out):
        return False
    try:
        return out.stat().st_ino == st.st_ino and not (out / MANIFEST).exists()
    except FileNotFoundError:
        return False


def unlisted_files(folder: Path) -> list[str]:
    """Files (relative paths) an earlier output set in ``folder`` does not list in its
    manifest.json — a user's own, added since: replacing the set would delete them. Hidden
    files (an editor's or the OS's) are not counted; [] for a folder that is no output set."""
    try:
        doc = json.loads((folder / MANIFEST).read_text(encoding="utf-8"))
        if doc.get("tool") != "sumo-drvpw":
            return []
        listed = {str(f["path"]) for f in doc.get("files", [])} | {MANIFEST}
    except (OSError, ValueError, AttributeError, KeyError, TypeError):
        return []
    out = []
    for p in sorted(folder.rglob("*")):
        rel = p.relative_to(folder)
        if p.is_file() and not any(part.startswith(".") for part in rel.parts) and str(rel) not in listed:
            out.append(str(rel))
    return out


def _is_output_set(folder: Path) -> bool:
    """True when ``folder`` holds a manifest.json written by :func:`output_set`."""
    p = folder / MANIFEST
    try:
        return json.loads(p.read_text(encoding="utf-8")).get("tool") == "sumo-drvpw"
    except (OSError, ValueError, AttributeError):
        return False
