"""The network table of a run kept on disk, keyed by what it is made of: the net file's bytes,
the road-class rule and slope settings, and the code that builds it.

:func:`sumo_drvpw.sim.network.load_network` reads a network with sumolib and computes every
lane's slope profile, heading and centre line: seconds on a city's network (2.0 s of CPU on
DLR's port_lübeck, 6.8 s on MoST), paid again by every run of the same scenario. The table it returns
is kept in a cache folder, one file per key; the next load of the same network with the
same settings and the same code reads it back instead. The key is a SHA-256 over

- the net file's content (not its name or time: a file rewritten in place is a new key),
- the settings (the :class:`RoadClassRule`'s repr, the slope window and limit),
- every source file of the installed sumo_drvpw package, and the Python, numpy and sumolib
  versions (a changed computation, or a pickle another numpy reads differently, is a new key).

Folder: ``SUMO_DRVPW_CACHE`` (a path; ``off``, ``0`` or empty: no cache), else
``$XDG_CACHE_HOME/sumo-drvpw/networks``, else ``~/.cache/sumo-drvpw/networks``. It is made
readable by its owner only, and a file is read only from a folder the user owns that
nobody else may write (a pickle runs code when read). Files are written whole (a temporary
file renamed), and any failure of the cache
(unwritable folder, disk full, a damaged file) falls back to reading the network, and the
table's ``table_source`` says so (summary.json's ``network.table``). At most
:data:`KEEP` files and :data:`MAX_BYTES` are kept, the least recently used removed first; a
partial file a killed run left goes once older than :data:`STALE_TMP_S`.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import stat
import sys
import tempfile
import time
from pathlib import Path

#: cached networks kept (the most recently used); a city's table is tens of MB
KEEP = 8
#: … and at most this many bytes of them (the newest is kept whatever its size)
MAX_BYTES = 1 << 30
#: a partial file ('.net-*.tmp') older than this [s] is a killed run's, removed at the next store
STALE_TMP_S = 3600.0
_CODE: list[str] = []  # the package's code digest, computed once per process


def cache_dir() -> Path | None:
    """The cache folder (see module doc), or None when caching is off."""
    env = os.environ.get("SUMO_DRVPW_CACHE")
    if env is not None:
        return None if env.strip().lower() in ("", "0", "off", "no", "false") else Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "sumo-drvpw" / "networks"


def _code_digest() -> str:
    if not _CODE:
        import numpy
        import sumolib

        h = hashlib.sha256(f"{sys.version}|{numpy.__version__}|{getattr(sumolib, '__version__', '')}"
                           .encode())
        pkg = Path(__file__).resolve().parent.parent
        for p in sorted(pkg.rglob("*.py")):
            h.update(str(p.relative_to(pkg)).encode())
            h.update(p.read_bytes())
        _CODE.append(h.hexdigest())
    return _CODE[0]


def network_key(path: Path, settings: tuple) -> str:
    """The cache key of net file ``path`` loaded with ``settings`` (see module doc)."""
    h = hashlib.sha256(_code_digest().encode())
    h.update(repr(settings).encode())
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _private(folder: Path) -> bool:
    """The folder is the user's and nobody else may write in it."""
    st = folder.stat()
    return (not hasattr(os, "getuid") or st.st_uid == os.getuid()) and not st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def cached_network(path: Path, settings: tuple, build):
    """``build()``'s network table, from the cache when it holds one for ``path`` and
    ``settings``, else built and kept there. The table's ``path`` is ``path``; its
    ``table_source`` says in one line where it came from — read from the cache, kept there, or
    why it was not (a run's summary.json gives it under ``network``; nothing is printed)."""
    folder = cache_dir()
    file, why = None, None
    if folder is None:
        net = build()
        net.table_source = "read from the net file (the cache is off: SUMO_DRVPW_CACHE)"
        return net
    try:
        key = network_key(Path(path), settings)
        file = folder / f"net-{key[:40]}.pickle"
        if file.is_file():
            if not _private(folder):
                raise PermissionError(f"the cache folder {folder} may be written by others: not read")
            with open(file, "rb") as f:
                net = _unpacked(pickle.load(f))
            try:
                os.utime(file)  # (the most recently used are kept)
            except OSError:  # gone since (another run's pruning): the table read is whole all the same
                pass
            net.path = Path(path)
            net.table_source = f"read from the cache ({file})"
            return net
    except Exception as e:  # a damaged file (kept again below), no file to hash: read the network
        why = _reason(e)
    net = build()
    if file is not None:
        try:
            _store(folder, file, net)
            net.table_source = f"read from the net file and kept in the cache ({file})" + (
                f"; the kept one was not read: {why}" if why else "")
            return net
        except Exception as e:  # a cache that cannot be written does not fail the run
            why = _reason(e)
    net.table_source = f"read from the net file; not kept in the cache ({folder}): {why}"
    return net


def _packed(net):
    """A shallow copy of ``net`` whose edge shapes (one small array per edge) are one array and
    their lengths: a pickle of thousands of arrays read back one by one was a fifth of
    MoST's table's load (220 → 175 ms for its 10,914 edges)."""
    import copy

    import numpy as np

    out = copy.copy(net)
    shapes = net.edge_shapes
    out.edge_shapes = ("packed", np.concatenate(shapes) if len(shapes) else np.zeros((0, 2)),
                       np.array([len(x) for x in shapes], np.int64))
    return out


def _unpacked(net):
    """``net`` as :func:`_packed` kept it, its edge shapes a list again (views of one array)."""
    import numpy as np

    got = net.edge_shapes
    if type(got) is tuple and got and got[0] == "packed":
        net.edge_shapes = np.split(got[1], np.cumsum(got[2])[:-1]) if len(got[2]) else []
    return net


def _reason(e: Exception) -> str:
    """An exception of the cache as a reason on one line."""
    text = " ".join(str(e).split())
    return f"{type(e).__name__}: {text}" if text else type(e).__name__


def _store(folder: Path, file: Path, net) -> None:
    folder.mkdir(parents=True, exist_ok=True, mode=0o700)
    if not _private(folder):
        raise PermissionError(f"the cache folder {folder} may be written by others: nothing kept there")
    fd, tmp = tempfile.mkstemp(dir=folder, prefix=".net-", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as f:
            pickle.dump(_packed(net), f, protocol=pickle.HIGHEST_PROTOCOL)
        os.replace(tmp, file)
    except BaseException:
        os.unlink(tmp)
        raise
    for p in folder.glob(".net-*.tmp"):  # a run killed while writing (SIGKILL) left it
        try:
            if p.stat().st_mtime < time.time() - STALE_TMP_S:
                p.unlink()
        except OSError:
            pass
    kept = sorted(((p.stat().st_mtime, p.stat().st_size, p) for p in folder.glob("net-*.pickle")), reverse=True)
    total = 0
    for k, (_, size, p) in enumerate(kept):
        total += size
        if k and (k >= KEEP or total > MAX_BYTES):
            p.unlink(missing_ok=True)
