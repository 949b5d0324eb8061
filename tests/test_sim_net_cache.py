"""The network table kept on disk (sim/net_cache.py): read back for the same net file,
settings and code; read anew when any of them changed or the kept file is damaged; never
read from a folder others may write."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from sumo_drvpw.sim import network
from sumo_drvpw.sim.network import load_network, read_network
from sumo_drvpw.sim.scenario import RoadClassRule

CITY = Path(network.__file__).parent / "builtin" / "networks" / "city.net.xml"


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """The cache on, in a folder of the test's; returns the list of networks read."""
    monkeypatch.setenv("SUMO_DRVPW_CACHE", str(tmp_path / "cache"))
    reads = []

    def counting(path, *a, **k):
        reads.append(Path(path))
        return read_network(path, *a, **k)

    monkeypatch.setattr(network, "read_network", counting)
    return reads


def _same(a, b) -> None:
    for k, v in vars(a).items():
        if k in ("path", "table_source"):  # (where this load found it: test_the_table_says_where_it_came_from)
            continue
        w = getattr(b, k)
        if isinstance(v, np.ndarray):
            np.testing.assert_array_equal(v, w, err_msg=k)
        elif isinstance(v, list) and v and isinstance(v[0], np.ndarray):
            for x, y in zip(v, w):
                np.testing.assert_array_equal(x, y, err_msg=k)
        else:
            assert v == w, k


def test_second_load_reads_the_kept_table(cache, tmp_path):
    net = tmp_path / "a.net.xml"
    shutil.copy(CITY, net)
    first = load_network(net, RoadClassRule())
    again = load_network(net, RoadClassRule())
    assert cache == [net], "the second load read the network again"
    _same(first, again)
    _same(read_network(net, RoadClassRule()), again)
    other = tmp_path / "b.net.xml"  # the same content elsewhere: the same table, its own path
    shutil.copy(CITY, other)
    assert load_network(other, RoadClassRule()).path == other and cache == [net]


def test_changed_file_or_settings_read_anew(cache, tmp_path):
    net = tmp_path / "a.net.xml"
    shutil.copy(CITY, net)
    load_network(net, RoadClassRule())
    load_network(net, RoadClassRule(), max_rad=0.2)  # other slope limit
    load_network(net, RoadClassRule(types={"x": "service"}))  # other road-class rule
    assert len(cache) == 3
    text = net.read_text(encoding="utf-8")  # the file rewritten in place: one lane 1 m shorter
    i = text.index('length="') + len('length="')
    j = text.index('"', i)
    net.write_text(text[:i] + f"{float(text[i:j]) - 1.0:.2f}" + text[j:], encoding="utf-8")
    changed = load_network(net, RoadClassRule())
    assert len(cache) == 4
    _same(read_network(net, RoadClassRule()), changed)


def test_damaged_or_foreign_cache_is_not_read(cache, tmp_path):
    net = tmp_path / "a.net.xml"
    shutil.copy(CITY, net)
    load_network(net, RoadClassRule())
    folder = tmp_path / "cache"
    (kept,) = folder.glob("net-*.pickle")
    kept.write_bytes(b"not a pickle")
    _same(read_network(net, RoadClassRule()), load_network(net, RoadClassRule()))
    assert len(cache) == 2
    load_network(net, RoadClassRule())
    assert len(cache) == 2  # (kept again whole)
    os.chmod(folder, 0o777)  # others may write in it: a pickle there is not read
    load_network(net, RoadClassRule())
    assert len(cache) == 3


def test_cache_off(cache, tmp_path, monkeypatch):
    monkeypatch.setenv("SUMO_DRVPW_CACHE", "off")
    net = tmp_path / "a.net.xml"
    shutil.copy(CITY, net)
    load_network(net, RoadClassRule())
    load_network(net, RoadClassRule())
    assert len(cache) == 2 and not (tmp_path / "cache").exists()


def test_least_recently_used_removed_beyond_the_bounds(cache, tmp_path, monkeypatch):
    """At most KEEP files and MAX_BYTES are kept; a file read is used (kept over older ones)."""
    from sumo_drvpw.sim import net_cache

    nets = []
    for k in range(4):  # four networks of different content (one lane 0.5·k m shorter)
        net = tmp_path / f"{k}.net.xml"
        text = CITY.read_text(encoding="utf-8")
        i = text.index('length="') + len('length="')
        j = text.index('"', i)
        net.write_text(text[:i] + f"{float(text[i:j]) - 0.5 * k:.2f}" + text[j:], encoding="utf-8")
        nets.append(net)
    folder = tmp_path / "cache"
    monkeypatch.setattr(net_cache, "KEEP", 2)
    for k, net in enumerate(nets[:3]):
        load_network(net, RoadClassRule())
        key = net_cache.network_key(net, (RoadClassRule(), 20.0, 0.25))
        os.utime(folder / f"net-{key[:40]}.pickle", (1000.0 + k, 1000.0 + k))  # (distinct times)
    assert len(list(folder.glob("net-*.pickle"))) == 2
    assert len(cache) == 3
    load_network(nets[0], RoadClassRule())  # the oldest was removed: read again
    assert len(cache) == 4
    size = max(p.stat().st_size for p in folder.glob("net-*.pickle"))
    monkeypatch.setattr(net_cache, "MAX_BYTES", size + 1)  # room for one only
    load_network(nets[3], RoadClassRule())
    assert len(list(folder.glob("net-*.pickle"))) == 1
    load_network(nets[3], RoadClassRule())
    assert len(cache) == 5  # the newest kept


def test_a_kept_table_read_is_used_when_its_time_cannot_be_set(cache, tmp_path, monkeypatch):
    """A table read whole is used though its time cannot be set afterwards (another run's
    pruning removed the file between the read and os.utime): it was thrown away and the
    network read anew."""
    from sumo_drvpw.sim import net_cache

    net = tmp_path / "a.net.xml"
    shutil.copy(CITY, net)
    load_network(net, RoadClassRule())

    def gone(*a, **k):
        raise FileNotFoundError("removed by another run")

    monkeypatch.setattr(net_cache.os, "utime", gone)
    load_network(net, RoadClassRule())
    assert cache == [net], "the table read back was thrown away"


def test_a_killed_run_s_partial_file_is_removed_later(cache, tmp_path):
    """A run killed while writing (SIGKILL, out of memory) left its '.net-*.tmp' for ever,
    outside the KEEP and MAX_BYTES bounds; one older than STALE_TMP_S goes at the next store,
    a younger one (another run writing now) stays."""
    from sumo_drvpw.sim import net_cache

    folder = tmp_path / "cache"
    folder.mkdir(mode=0o700)
    old, young = folder / ".net-old.tmp", folder / ".net-young.tmp"
    old.write_bytes(b"x" * 1000)
    young.write_bytes(b"y")
    t = old.stat().st_mtime - getattr(net_cache, "STALE_TMP_S", 3600.0) - 60
    os.utime(old, (t, t))
    net = tmp_path / "a.net.xml"
    shutil.copy(CITY, net)
    load_network(net, RoadClassRule())
    assert not old.exists() and young.exists()


def test_the_table_says_where_it_came_from(cache, tmp_path, monkeypatch):
    """A run's network table says in one line whether it was read from the cache, kept there, or
    why not (summary.json's network.table); the cache said nothing when it could not be written
    (a file where its folder should be, a folder others may write) or when it was off."""
    net = tmp_path / "a.net.xml"
    shutil.copy(CITY, net)
    folder = tmp_path / "cache"
    first = load_network(net, RoadClassRule())
    (kept,) = folder.glob("net-*.pickle")
    assert first.table_source == f"read from the net file and kept in the cache ({kept})"
    assert load_network(net, RoadClassRule()).table_source == f"read from the cache ({kept})"
    kept.write_bytes(b"not a pickle")
    damaged = load_network(net, RoadClassRule()).table_source
    assert damaged.startswith(f"read from the net file and kept in the cache ({kept}); the kept one was not read: ")
    os.chmod(folder, 0o777)  # others may write in it: neither read nor written
    foreign = load_network(net, RoadClassRule()).table_source
    assert foreign == (f"read from the net file; not kept in the cache ({folder}): PermissionError: the cache "
                       f"folder {folder} may be written by others: nothing kept there")
    blocked = tmp_path / "blocked"
    blocked.write_text("a file, not a folder", encoding="utf-8")
    monkeypatch.setenv("SUMO_DRVPW_CACHE", str(blocked / "networks"))
    why = load_network(net, RoadClassRule()).table_source
    assert why.startswith(f"read from the net file; not kept in the cache ({blocked / 'networks'}): ") and \
        "NotADirectoryError" in why and "\n" not in why
    monkeypatch.setenv("SUMO_DRVPW_CACHE", "off")
    assert load_network(net, RoadClassRule()).table_source.startswith("read from the net file (the cache is off")
    assert len(cache) == 5


def test_a_run_s_summary_says_where_its_network_came_from(tmp_path, monkeypatch, capsys):
    """summary.json's network block, from a real run twice with the cache on; nothing on the
    console about it."""
    import json

    from sumo_drvpw.cli import main

    monkeypatch.setenv("SUMO_DRVPW_CACHE", str(tmp_path / "cache"))
    for k in range(2):
        assert main(["run", "city", "--end", "5", "--out", str(tmp_path / f"o{k}"), "--no-figures",
                     "--no-progress"]) == 0
    first, again = (json.loads((tmp_path / f"o{k}" / "summary.json").read_text(encoding="utf-8"))["network"]["table"]
                    for k in range(2))
    assert first.startswith("read from the net file and kept in the cache (") and again.startswith("read from the cache (")
    out = capsys.readouterr()
    assert "cache" not in out.out + out.err
