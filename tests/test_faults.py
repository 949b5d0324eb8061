"""Faults while writing: Ctrl-C and SIGTERM, a full disk, two runs into one folder, and
random drive logs (issue #9 §3, §5). Output sets are whole or absent, inputs untouched."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import corpus
from conftest import BUNDLED_LOG
from sumo_drvpw.cli import main as cli_main
from sumo_drvpw.errors import UserError
from sumo_drvpw.fileio import MANIFEST, output_set, write_text

REPO = Path(__file__).resolve().parent.parent


def _hidden(folder: Path) -> list[str]:
    """Temporary or moved-aside folders/files an output set may leave (must be none)."""
    return sorted(p.name for p in folder.iterdir() if p.name.startswith("."))


def _assert_whole(out: Path):
    """A published set: the manifest lists exactly the files present."""
    man = json.loads((out / MANIFEST).read_text(encoding="utf-8"))
    listed = sorted(f["path"] for f in man["files"])
    present = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and p.name != MANIFEST)
    assert listed == present
    for f in man["files"]:
        assert (out / f["path"]).stat().st_size == f["bytes"]
    return man


# ------------------------------------------------------------------ output_set itself

def test_output_set_replaces_whole_and_keeps_on_failure(tmp_path):
    out = tmp_path / "set"
    with output_set(out, command=["x"]) as t:
        write_text(t / "a.txt", "first")
        write_text(t / "sub" / "b.txt", "first")
    man = _assert_whole(out)
    assert man["command"] == ["x"] and man["interrupted"] is False and man["version"]
    # a failing second run leaves the first set exactly as it was, and no temporary folder
    with pytest.raises(RuntimeError):
        with output_set(out) as t:
            write_text(t / "c.txt", "second")
            raise RuntimeError("boom")
    assert (out / "a.txt").read_text(encoding="utf-8") == "first" and not (out / "c.txt").exists()
    assert _hidden(tmp_path) == []
    # a successful second run replaces the set whole: nothing of the first remains
    with output_set(out) as t:
        write_text(t / "c.txt", "second")
    assert sorted(p.name for p in out.iterdir()) == ["c.txt", MANIFEST]
    assert _hidden(tmp_path) == []


def test_output_set_refuses_foreign_folder_and_inputs(tmp_path):
    from sumo_drvpw.errors import OutputExists

    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years", encoding="utf-8")
    with pytest.raises(OutputExists):
        with output_set(mine):
            pass
    assert (mine / "thesis.tex").read_text(encoding="utf-8") == "years"
    log = tmp_path / "in" / "log.csv"
    log.parent.mkdir()
    log.write_text("x", encoding="utf-8")
    for bad, inputs in ((tmp_path / "in", [log]), (tmp_path, [log]), (log, [log]),
                        (tmp_path / "in" / "rep", [log.parent])):
        with pytest.raises(UserError):
            with output_set(bad, inputs=inputs):
                pass
    with output_set(tmp_path / "in" / "rep", inputs=[log]) as t:  # beside a file input: fine
        write_text(t / "r.txt", "ok")
    assert log.read_text(encoding="utf-8") == "x"
    with output_set(mine, force=True) as t:
        write_text(t / "r.txt", "ok")
    assert sorted(p.name for p in mine.iterdir()) == [MANIFEST, "r.txt"]


def test_a_users_file_in_an_earlier_set_is_not_deleted_without_force(tmp_path):
    """Rehearsal: a note a user put into an earlier output folder was deleted without a
    word by the next run into it (the folder's manifest made all of it 'ours'). Now a file
    the manifest does not list is refused, named, and kept; --force replaces the set."""
    from sumo_drvpw.errors import OutputExists

    out = tmp_path / "set"
    with output_set(out) as t:
        write_text(t / "a.txt", "first")
    write_text(out / "notes" / "mine.txt", "my analysis")
    (out / ".DS_Store").write_text("os", encoding="utf-8")  # hidden files do not count
    with pytest.raises(OutputExists, match=r"1 file\(s\) it did not write \(first: notes/mine.txt\)"):
        with output_set(out) as t:
            write_text(t / "b.txt", "second")
    assert (out / "notes" / "mine.txt").read_text(encoding="utf-8") == "my analysis" and not (out / "b.txt").exists()
    assert _hidden(tmp_path) == []
    with output_set(out, force=True) as t:
        write_text(t / "b.txt", "second")
    assert sorted(p.name for p in out.iterdir()) == ["b.txt", MANIFEST]


def test_a_killed_runs_temporary_folder_is_removed_by_the_next_run(tmp_path):
    """Rehearsal: `kill -9` of an `fcd` run left its hidden temporary folder (2.2 MB,
    partial) beside --out, and later runs into that folder left it there too. Now each
    temporary folder names its process; the next run into the same folder removes those
    of processes that no longer exist, and leaves those of running processes (a concurrent
    run) and those it cannot attribute."""
    import socket

    from sumo_drvpw.fileio import OWNER

    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        host = socket.gethostname()
        for name, owner in ((".set.killed.tmp", f"{host} {dead.pid}"), (".set.moved.old", f"{host} {dead.pid}"),
                            (".set.running.tmp", f"{host} {alive.pid}"), (".set.unknown.tmp", None),
                            (".set.elsewhere.tmp", f"otherhost {dead.pid}"), (".other.killed.tmp", f"{host} {dead.pid}")):
            d = tmp_path / name
            write_text(d / "set" / "part.parquet", "partial")
            if owner:
                (d / OWNER).write_text(owner, encoding="utf-8")
        with output_set(tmp_path / "set") as t:
            write_text(t / "a.txt", "x")
        assert _hidden(tmp_path) == [".other.killed.tmp", ".set.elsewhere.tmp", ".set.running.tmp",
                                     ".set.unknown.tmp"]
        assert _assert_whole(tmp_path / "set")
    finally:
        alive.kill()
        alive.wait()


def test_companion_files_move_beside_the_set(tmp_path):
    """validate writes <DIR>.md beside <DIR>/: both appear together, links keep the name."""
    out = tmp_path / "validation"
    with output_set(out) as t:
        assert t.name == "validation"
        write_text(t / "summary.json", "{}")
        write_text(t.parent / "validation.md", "see validation/summary.json")
    assert (tmp_path / "validation.md").read_text(encoding="utf-8") == "see validation/summary.json"
    man = _assert_whole(out)
    assert man["companions"][0]["path"] == "../validation.md"


# ------------------------------------------------------------------ two runs, one folder

def test_two_runs_into_one_folder(tmp_path):
    """Sequential: the second set replaces the first whole. Concurrent: the folder ends as
    exactly one of the two sets, never a mix, with no temporary folder left."""
    log = corpus.write(tmp_path, "log.parquet", corpus.base_log())
    out = tmp_path / "cmp"
    assert cli_main(["compare", str(log), "--equation", "drvpw_prius3", "--equation", "vsp_ldv1999",
                     "--out", str(out), "--engine", "memory"]) == 0
    first = _assert_whole(out)
    assert cli_main(["compare", str(log), "--equation", "moves_passenger_car", "--out", str(out),
                     "--engine", "memory"]) == 0
    second = _assert_whole(out)
    rep = json.loads((out / "report.json").read_text(encoding="utf-8"))
    assert list(rep["equations"]) == ["moves_passenger_car"]
    assert first["command"] != second["command"]

    # concurrent writers of output_set (threads, so both publish within milliseconds);
    # neither may fail because the other moved the folder while it looked
    errors = []

    def writer(tag):
        try:
            for _ in range(20):
                with output_set(tmp_path / "race") as t:
                    for i in range(5):
                        write_text(t / f"{i}.txt", tag)
        except Exception as e:  # noqa: BLE001 - reported by the assertion below
            errors.append(repr(e))

    threads = [threading.Thread(target=writer, args=(tag,)) for tag in ("A", "B")]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert errors == []
    race = tmp_path / "race"
    _assert_whole(race)
    tags = {(race / f"{i}.txt").read_text(encoding="utf-8") for i in range(5)}
    assert len(tags) == 1, tags
    assert _hidden(tmp_path) == []


# ------------------------------------------------------------------ signals

@pytest.fixture(autouse=True)
def _sigint_as_a_terminal_sends_it():
    """The signal tests need SIGINT as a terminal delivers it. A process started in the
    background by a non-interactive shell (``cmd &``) or by nohup inherits SIGINT ignored;
    Python keeps it ignored, the CLI rightly leaves it so (test below), and so do the
    processes it starts — the tests' SIGINT then does nothing (a suite started that way on
    2026-11-27: 3 failed with exit 0, 3 skipped as "finished before the signal"). Each test
    of this file runs with Python's default SIGINT handler; a subprocess it starts gets the
    default action (exec resets a caught signal, not an ignored one)."""
    prev = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, prev)


def test_sigint_ignored_by_whoever_started_the_command_stays_ignored(tmp_path, monkeypatch):
    """Started with SIGINT ignored (nohup, a background job), the command leaves it so while
    it runs and after; SIGTERM still stops it."""
    import sumo_drvpw.cli.calibrate as cal

    seen = []

    def command(args):
        seen.append(signal.getsignal(signal.SIGINT))
        os.kill(os.getpid(), signal.SIGINT)     # ignored: nothing happens
        time.sleep(0.2)
        return 0

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    monkeypatch.setattr(cal, "main", command)
    code = cli_main(["calibrate", str(BUNDLED_LOG), "--vehicle", "prius3", "--out", str(tmp_path / "e.toml")])
    assert code == 0 and seen == [signal.SIG_IGN] and signal.getsignal(signal.SIGINT) is signal.SIG_IGN

    def terminated(args):
        os.kill(os.getpid(), signal.SIGTERM)
        time.sleep(5)                           # the handler raises here
        return 0

    monkeypatch.setattr(cal, "main", terminated)
    code = cli_main(["calibrate", str(BUNDLED_LOG), "--vehicle", "prius3", "--out", str(tmp_path / "e.toml")])
    assert code == 128 + signal.SIGTERM and signal.getsignal(signal.SIGINT) is signal.SIG_IGN


def _big_log(tmp_path: Path, trips: int) -> Path:
    """The bundled Prius3 log repeated as ``trips`` trips (power-split measured power)."""
    df = pd.read_parquet(BUNDLED_LOG)
    frames = [df.assign(trip_id=f"t{i}") for i in range(trips)]
    p = tmp_path / "big.parquet"
    pd.concat(frames, ignore_index=True).to_parquet(p, index=False)
    return p


def _signal_during(argv, cwd, sig, after_s):
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "sumo_drvpw", *argv], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    time.sleep(after_s)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=120)
    return proc.returncode, out, err


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_during_calibrate(tmp_path, sig):
    """Stopped mid-run: exit 130 (SIGINT) / 143 (SIGTERM), one line, neither the equation
    nor the report folder written, no temporary folder, the log unchanged."""
    log = _big_log(tmp_path, 40)
    before = corpus.snapshot(tmp_path)
    argv = ["calibrate", str(log), "--vehicle", "prius3", "--out", str(tmp_path / "eq.toml"),
            "--report", str(tmp_path / "rep")]
    code, out, err = _signal_during(argv, tmp_path, sig, after_s=4.0)
    if code == 0 or "its output was completed" in err:  # the machine was faster than the
        _assert_whole(tmp_path / "rep")                  # signal: then the set must be whole
        pytest.skip("calibration finished before the signal")
    assert code == 128 + sig, (code, err)
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert corpus.snapshot(tmp_path) == before


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_a_process_stopping_on_a_signal_ignores_its_late_repeat(tmp_path, monkeypatch, capsys, sig):
    """The process's own command line (main() without argv, as `sumo-drvpw` and `python -m
    sumo_drvpw` call it) stopped by a signal: from main's return to the exit the stop's signals
    are ignored — a library's re-send arriving after the handlers were restored killed the
    process by SIGINT after its one line (exit −2; CI under load, test_signal_during_calibrate).
    Called with argv (a script, a test), main restores the handlers it found."""
    import sumo_drvpw.cli.calibrate as cal

    def stopped(args):
        os.kill(os.getpid(), sig)
        time.sleep(5)                           # the handler raises here
        return 0

    monkeypatch.setattr(cal, "main", stopped)
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    argv = ["calibrate", str(BUNDLED_LOG), "--vehicle", "prius3", "--out", str(tmp_path / "e.toml")]
    try:
        monkeypatch.setattr(sys, "argv", ["sumo-drvpw", *argv])
        assert cli_main() == 128 + sig
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN and signal.getsignal(signal.SIGTERM) is signal.SIG_IGN
        os.kill(os.getpid(), sig)               # the late repeat: ignored, no KeyboardInterrupt
        time.sleep(0.2)
    finally:
        for s, h in before.items():
            signal.signal(s, h)
    assert cli_main(argv) == 128 + sig          # with argv: the handlers it found, restored
    assert {s: signal.getsignal(s) for s in before} == before
    capsys.readouterr()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_swallowed_by_library_code_still_exits_as_the_signal(tmp_path, monkeypatch, capsys, sig):
    """A signal's exception raised inside a library's C code can come out as that library's
    own error (seen on CI: SIGTERM while matplotlib drew a figure gave 'ValueError: Invalid
    bounding box', a traceback and exit 1). The record of the signal decides: exit 143/130,
    one line, no traceback."""
    import sumo_drvpw.cli.calibrate as cal

    def swallowing(args):
        try:
            os.kill(os.getpid(), sig)
            time.sleep(5)                       # the handler raises here
        except BaseException:
            raise ValueError("Invalid bounding box") from None
        return 0

    monkeypatch.setattr(cal, "main", swallowing)
    code = cli_main(["calibrate", str(BUNDLED_LOG), "--vehicle", "prius3", "--out", str(tmp_path / "e.toml")])
    err = capsys.readouterr().err
    assert code == 128 + sig and len(err.strip().splitlines()) == 1 and "Traceback" not in err, (code, err)
    # the handlers are restored, and a later failure that is no signal is not taken for one
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler

    def failing(args):
        raise ValueError("a bug")

    monkeypatch.setattr(cal, "main", failing)
    with pytest.raises(ValueError, match="a bug"):
        cli_main(["calibrate", str(BUNDLED_LOG), "--vehicle", "prius3", "--out", str(tmp_path / "e.toml")])


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_swallowed_entirely_still_exits_as_the_signal(tmp_path, monkeypatch, capsys, sig):
    """A fuzz run saw SIGTERM during calibrate end in exit 0 with the outputs written (3 of
    about 10 tries): some library code swallowed the signal's exception and the command went
    on to finish. The record of the signal decides the exit code all the same, and the one
    line says the output was completed (it was published whole)."""
    import sumo_drvpw.cli.calibrate as cal

    def swallowing(args):
        try:
            os.kill(os.getpid(), sig)
            time.sleep(5)                       # the handler raises here
        except BaseException:
            pass                                # and a library drops it
        return 0

    monkeypatch.setattr(cal, "main", swallowing)
    code = cli_main(["calibrate", str(BUNDLED_LOG), "--vehicle", "prius3", "--out", str(tmp_path / "e.toml")])
    err = capsys.readouterr().err
    assert code == 128 + sig, (code, err)
    assert err.strip().splitlines() == [err.strip()] and "output was completed" in err


def _signal_once_writing(argv, cwd, sig, delay_s=0.3, marker="*", timeout=120):
    """Start the CLI, send ``sig`` ``delay_s`` after a path matching ``marker`` appears in its
    output set's temporary folder (default: the folder itself, i.e. the command is past its
    checks and working), then collect the outcome."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "sumo_drvpw", *argv], cwd=cwd, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    sent = False
    while time.monotonic() - t0 < timeout and proc.poll() is None:
        stages = [p for p in Path(cwd).iterdir() if p.name.startswith(".") and p.name.endswith(".tmp")]
        if any(marker == "*" or any(st.rglob(marker)) for st in stages):
            time.sleep(delay_s)
            proc.send_signal(sig)
            sent = True
            break
        time.sleep(0.02)
    out, err = proc.communicate(timeout=timeout)
    return proc.returncode, out, err, sent


@pytest.mark.sumo
@pytest.mark.parametrize("sig,delay", [(signal.SIGINT, 0.05), (signal.SIGINT, 1.0), (signal.SIGTERM, 1.0)],
                         ids=["SIGINT-startup", "SIGINT-stepping", "SIGTERM-stepping"])
def test_signal_during_run(tmp_path, sig, delay):
    """A SUMO run stopped mid-way (signalled once the loop steps) exits 130/143 and leaves a
    whole output set marked ``interrupted: true``, or none at all — never a partial one."""
    out = tmp_path / "run"
    # "stepping": 1 s after the trace writer opens (SUMO started, the loop begins), in a run
    # to 100,000 s that takes far longer; "startup": 0.05 s after the output set opens
    code, o, err, sent = _signal_once_writing(
        ["run", "city", "--out", str(out), "--no-figures", "--trace", "--end", "100000"], tmp_path,
        sig, delay_s=delay, marker=".trace.parquet.*" if delay > 0.5 else "*")
    assert "Traceback" not in err, err
    if code == 0:
        _assert_whole(out)
        pytest.skip("run finished before the signal")
    assert _hidden(tmp_path) == []
    if sig == signal.SIGTERM:
        assert code == 143, (code, err)
        if delay > 1:  # inside the loop: the simulated part is written, marked as such
            assert _assert_whole(out)["interrupted"] is True
    else:
        # libsumo installs SUMO's own SIGINT handling while it runs: Ctrl-C may end the
        # process by the signal itself (-2) after our message; either way no partial set
        assert code in (130, -signal.SIGINT), (code, err)
    if out.exists():
        assert _assert_whole(out)["interrupted"] is True
        # the end is the last step booked whole (it read one step past what was booked)
        s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
        assert s["end_s"] == pytest.approx(s["begin_s"] + s["steps"] * s["step_length_s"])


def _ctrl_c_in_step(monkeypatch, k: int) -> None:
    """Ctrl-C (a KeyboardInterrupt) as the loop starts its k-th step: k − 1 steps booked."""
    from sumo_drvpw.sim.loop import Stepper

    step = Stepper.after_step

    def after_step(self):
        if self.ledger.steps == k - 1:
            raise KeyboardInterrupt()
        step(self)
    monkeypatch.setattr(Stepper, "after_step", after_step)


@pytest.mark.sumo
def test_interrupt_during_fcd_writes_the_replayed_part_marked(tmp_path, monkeypatch, capsys):
    """An FCD replay stopped mid-way (Ctrl-C in its 51st step) writes the replayed part marked
    ``interrupted: true`` in its manifest and summary, exits 130 and says so; it exited 0
    (or 130 saying "its output was completed") with the manifest's interrupted false (found
    by a sweep)."""
    from sumo_drvpw.sim import run_scenario

    city = REPO / "scenarios" / "city.toml"
    fcd = tmp_path / "fcd.xml"
    run_scenario(city, None, end=120, figures=False, options=["--fcd-output", str(fcd)])
    _ctrl_c_in_step(monkeypatch, 51)
    out = tmp_path / "replay"
    code = cli_main(["fcd", str(fcd), "--scenario", str(city), "--out", str(out), "--no-figures"])
    o = capsys.readouterr()
    assert code == 130 and "interrupted" in o.out and "completed" not in o.err, (o.out, o.err)
    assert _assert_whole(out)["interrupted"] is True and _hidden(tmp_path) == []
    s = json.loads((out / "summary.json").read_text(encoding="utf-8"))
    assert s["interrupted"] is True and s["steps"] == 50  # booked whole; the 51st was stopped


@pytest.mark.sumo
def test_interrupt_during_a_sweep_stops_it_there(tmp_path, monkeypatch, capsys):
    """`run city highway` (one after the other) stopped in the first scenario's 50th step:
    that part is written, the second scenario is not run, the manifest says interrupted and
    the command exits 130; the sweep ran on to its end and called itself whole (found by a
    sweep)."""
    _ctrl_c_in_step(monkeypatch, 51)
    out = tmp_path / "sweep"
    code = cli_main(["run", "city", "highway", "--end", "200", "--no-figures", "--out", str(out)])
    o = capsys.readouterr()
    assert code == 130 and "not run: highway" in o.out, (o.out, o.err)
    assert _assert_whole(out)["interrupted"] is True and _hidden(tmp_path) == []
    assert json.loads((out / "city" / "summary.json").read_text(encoding="utf-8"))["interrupted"] is True
    assert not (out / "highway").exists()
    assert set(pd.read_csv(out / "runs.csv").scenario) == {"city"}


@pytest.mark.sumo
def test_sigterm_during_a_parallel_sweep_stops_its_workers(tmp_path):
    """`run city highway --jobs 2` to 1,000,000 s (a minute or more of stepping), SIGTERM
    once it steps: the workers are stopped at once and the command exits 143 with no output
    set; the workers ran on to the end before (found by a sweep)."""
    out = tmp_path / "sweep"
    t0 = time.monotonic()
    code, o, err, sent = _signal_once_writing(
        ["run", "city", "highway", "--jobs", "2", "--end", "1000000", "--no-figures", "--out", str(out)],
        tmp_path, signal.SIGTERM, delay_s=3.0, timeout=300)
    assert sent and code == 143, (code, err)
    assert time.monotonic() - t0 < 25 and "Traceback" not in err, (time.monotonic() - t0, err)
    assert not out.exists() and _hidden(tmp_path) == []


def _children(pid: int) -> list[int]:
    """Process ids of ``pid``'s children (Linux /proc)."""
    out = []
    for task in Path(f"/proc/{pid}/task").glob("*"):
        kids = task / "children"
        if kids.exists():
            out += [int(x) for x in kids.read_text(encoding="utf-8").split()]
    return out


@pytest.mark.sumo
@pytest.mark.skipif(not Path("/proc/self/task").exists(), reason="needs Linux /proc")
def test_a_sweep_worker_that_dies_is_an_error_not_a_wait(tmp_path):
    """`run city highway --jobs 2` whose worker is killed (out of memory, a SUMO crash): one
    line, exit 2, nothing written, at once; a review found the sweep waiting for good."""
    out = tmp_path / "sweep"
    proc = subprocess.Popen([sys.executable, "-m", "sumo_drvpw", "run", "city", "highway", "--jobs", "2",
                             "--end", "1000000", "--no-figures", "--out", str(out)], cwd=tmp_path,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = time.monotonic()
    workers = []
    while time.monotonic() - t0 < 60 and proc.poll() is None and len(workers) < 2:
        workers = [c for c in _children(proc.pid)
                   if b"spawn_main" in Path(f"/proc/{c}/cmdline").read_bytes()]
        time.sleep(0.2)
    time.sleep(3.0)  # both stepping
    os.kill(workers[0], signal.SIGKILL)
    o, err = proc.communicate(timeout=60)
    assert proc.returncode == 2 and "ended abruptly" in err and "Traceback" not in err, err
    assert not out.exists() and _hidden(tmp_path) == []


# ------------------------------------------------------------------ disk full

@pytest.fixture
def tiny_disk(tmp_path):
    """A 512 kB tmpfs (root only), else skip: a real ENOSPC, not a simulated one."""
    if os.geteuid() != 0:
        pytest.skip("needs root to mount a tmpfs")
    d = tmp_path / "disk"
    d.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=512k", "tmpfs", str(d)],
                       capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount tmpfs: {r.stderr.strip()}")
    yield d
    subprocess.run(["umount", str(d)], check=False)


def _fill(disk: Path, leave: int) -> None:
    """Fill the tmpfs up to ``leave`` bytes of free space."""
    free = os.statvfs(disk).f_bavail * os.statvfs(disk).f_frsize
    (disk / "filler").write_bytes(b"\0" * max(0, free - leave))


@pytest.mark.parametrize("cmd", ["compare", "calibrate-report", "calibrate", "import", "synth"])
def test_disk_full(tmp_path, tiny_disk, capsys, cmd):
    """ENOSPC anywhere while writing: exit 2, one line saying the disk is full, and on the
    full disk nothing but what was there before (no partial set, no temporary file)."""
    log = corpus.write(tmp_path, "log.parquet", corpus.base_log())
    argv = {
        "compare": ["compare", str(log), "--equation", "drvpw_prius3", "--out", str(tiny_disk / "cmp")],
        "calibrate-report": ["calibrate", str(log), "--out", str(tmp_path / "eq.toml"),
                             "--report", str(tiny_disk / "rep")],
        "calibrate": ["calibrate", str(log), "--out", str(tiny_disk / "eq.toml")],
        "import": ["import", "columns", str(log), "--columns",
                   str(corpus.text(tmp_path, "m.toml", corpus.MAP_OK.replace('"t"', '"time_s"')
                                   .replace('"v"', '"speed_mps"').replace("km/h", "m/s"))),
                   "--out", str(tiny_disk / "out.parquet")],
        "synth": ["synth", "--minutes", "5", "--out", str(tiny_disk / "s.parquet")],
    }[cmd]
    _fill(tiny_disk, leave=8 * 1024 if cmd != "calibrate" else 0)
    before = corpus.snapshot(tiny_disk)
    inputs = log.read_bytes()
    code = cli_main(argv)
    err = capsys.readouterr().err
    assert code == 2, err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1, err
    assert "disk full" in err or "No space left" in err, err
    assert corpus.snapshot(tiny_disk) == before
    assert log.read_bytes() == inputs
    assert not (tmp_path / "eq.toml").exists()


# ------------------------------------------------------------------ random drive logs

COLUMNS = ["trip_id", "time_s", "speed_mps", "accel_mps2", "grade_rad", "grade_pct", "elevation_m",
           "wind_mps", "airspeed_mps", "air_density_kgm3", "ambient_c", "pressure_kpa", "mass_kg",
           "power_w", "brake", "reverse", "mg1_torque_nm", "extra", "speed_mps.1", ""]
VALUES = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64),
    st.floats(min_value=-1, max_value=40),
    st.integers(min_value=-10**12, max_value=10**12),
    st.booleans(), st.none(),
    st.text(max_size=6),
    st.sampled_from(["1.5", "nan", "inf", "-0.001", "True", "", " ", "1e400"]),
)


@st.composite
def frames(draw):
    cols = draw(st.lists(st.sampled_from(COLUMNS), min_size=0, max_size=8, unique=True))
    if draw(st.booleans()):  # usually a readable core, so the checks behind it are reached
        cols = list(dict.fromkeys(["time_s", "speed_mps"] + cols))
    n = draw(st.integers(min_value=0, max_value=25))
    data = {}
    for c in cols:
        kind = draw(st.sampled_from(["mixed", "ramp", "const"]))
        if kind == "ramp":
            data[c] = list(np.arange(n) * draw(st.floats(min_value=-2, max_value=2)))
        elif kind == "const":
            data[c] = [draw(VALUES)] * n
        else:
            data[c] = draw(st.lists(VALUES, min_size=n, max_size=n))
    return pd.DataFrame(data)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(df=frames())
def test_reader_random_frames_only_usererror(df):
    """The canonical reader on arbitrary columns and values: a DriveLog or a UserError,
    nothing else (no KeyError, ValueError, TypeError, …)."""
    from sumo_drvpw.data.log import from_frame

    try:
        log = from_frame(df, name="random.csv")
    except UserError as e:
        assert "\n" not in str(e)
        return
    v = log.df["speed_mps"].to_numpy(float)
    assert np.all(np.isfinite(v)) and np.all(v >= 0) and np.all(v <= 100)
    assert np.all(log.df["dt_s"].to_numpy(float) >= 0)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                  HealthCheck.function_scoped_fixture])
@given(df=frames(), fmt=st.sampled_from(["csv", "parquet"]))
def test_reader_random_files_only_usererror(tmp_path_factory, df, fmt):
    """The same through files, as the CLI reads them (CSV text, Parquet types)."""
    from sumo_drvpw.data.log import read_log

    d = tmp_path_factory.mktemp("rand")
    p = d / f"log.{fmt}"
    try:
        if fmt == "csv":
            df.to_csv(p, index=False)
        else:
            df.astype({c: str for c in df.columns if df[c].dtype == object}).to_parquet(p, index=False)
    except Exception:  # noqa: BLE001 - a frame pyarrow cannot store is not a test input
        return
    raw = p.read_bytes()
    try:
        read_log([p])
    except UserError as e:
        assert "\n" not in str(e)
    assert p.read_bytes() == raw


def test_a_signal_raised_inside_a_gc_callback_prints_no_traceback():
    """The flaky one of the suite (1 run in ~5): SIGINT's KeyboardInterrupt raised while the
    garbage collector ran a weakref callback cannot propagate; Python printed "Exception
    ignored in … Traceback" above the run's one line. The CLI's unraisable hook drops a
    signal's exception (the record of the signal decides the exit) and passes others on."""
    import types

    from sumo_drvpw.cli import _quiet_signal_hook

    seen = []
    hook = _quiet_signal_hook(seen.append)
    for exc in (KeyboardInterrupt(), ValueError("x")):
        hook(types.SimpleNamespace(exc_type=type(exc), exc_value=exc, exc_traceback=None,
                                   err_msg=None, object=None))
    assert [type(u.exc_value) for u in seen] == [ValueError]


def test_output_piped_into_a_reader_that_has_gone(tmp_path):
    """`sumo-drvpw import … | head -1` once head has exited: the reader's end is closed
    before the command writes; the command still writes its log, exits 0 and prints no
    traceback (it used to stop at its first print: BrokenPipeError, output absent)."""
    csv = tmp_path / "log.csv"
    csv.write_text("t,v\n" + "".join(f"{i},{i % 7}\n" for i in range(200)), encoding="utf-8")
    m = tmp_path / "map.toml"
    m.write_text('[columns.t]\nname = "time_s"\n[columns.v]\nname = "speed_mps"\nunit = "m/s"\n', encoding="utf-8")
    out = tmp_path / "log.parquet"
    exe = Path(sys.executable).with_name("sumo-drvpw")
    r, w = os.pipe()
    os.close(r)  # the reader is gone before anything is written
    try:
        p = subprocess.run([str(exe), "import", "columns", str(csv), "--columns", str(m), "--out", str(out)],
                           stdout=w, stderr=subprocess.PIPE, text=True, timeout=120)
        assert p.returncode == 0 and p.stderr == "", p.stderr
        assert len(pd.read_parquet(out)) == 200
        # `… 2>&1 | head` of a command that fails: the one-line error into the closed pipe
        # too, exit 2, no traceback anywhere, nothing written
        bad = subprocess.run([str(exe), "import", "columns", str(csv), "--columns", str(tmp_path / "no.toml"),
                              "--out", str(tmp_path / "x.parquet")], stdout=w, stderr=w, timeout=120)
        assert bad.returncode == 2 and not (tmp_path / "x.parquet").exists()
    finally:
        os.close(w)


def test_a_console_that_cannot_show_the_reports_symbols_gets_them_plain(tmp_path):
    """A Latin-1 (or cp1252) console: calibrate printed ρ, →, − and stopped with a
    UnicodeEncodeError traceback, writing nothing (a rehearsal, LC_ALL=de_DE.ISO-8859-1).
    Now the symbols come out plain and the command finishes."""
    env = dict(os.environ, PYTHONIOENCODING="latin-1")
    out = tmp_path / "eq.toml"
    r = subprocess.run([sys.executable, "-m", "sumo_drvpw", "calibrate", str(BUNDLED_LOG), "--vehicle", "prius3",
                        "--out", str(out)], capture_output=True, env=env, cwd=tmp_path, timeout=600)
    assert r.returncode == 0, r.stderr.decode("latin-1")[-500:]
    assert out.is_file() and b"Traceback" not in r.stderr
    text = r.stdout.decode("latin-1")
    assert text and "rho" in text  # ρ, plain
    # stderr escapes what its encoding lacks by itself (errors="backslashreplace"): plain there too
    import io

    from sumo_drvpw.cli import _ClosedPipeSafe

    raw = io.BytesIO()
    err = io.TextIOWrapper(raw, encoding="latin-1", errors="backslashreplace")
    _ClosedPipeSafe(err).write("C_d·A at ρ → 1.2 ×2 — ok\n")
    err.flush()
    assert raw.getvalue().decode("latin-1") == "C_d*A at rho -> 1.2 x2 - ok\n"


def test_no_usable_temporary_folder_is_one_line(tmp_path, monkeypatch, capsys):
    """Python finds no writable temporary folder (TMPDIR, /tmp, /var/tmp, the working
    folder): one line naming the remedy and exit 2, not a FileNotFoundError traceback."""
    import errno
    import tempfile

    def none(*a, **k):
        raise FileNotFoundError(errno.ENOENT, "No usable temporary directory found in ['/tmp', '/var/tmp']")

    monkeypatch.setattr(tempfile, "tempdir", None)
    monkeypatch.setattr(tempfile, "_get_default_tempdir", none)
    code = cli_main(["run", "city", "--end", "5", "--no-figures", "--no-progress", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert code == 2 and len(err.splitlines()) == 1 and "set TMPDIR to a writable folder" in err
    assert not (tmp_path / "o").exists()


def _signal_clock(monkeypatch):
    """cli/_signals with a clock the test sets ([seconds]) and no stop recorded yet."""
    import sumo_drvpw.cli._signals as sg

    clock = [100.0]
    monkeypatch.setattr(sg.time, "monotonic", lambda: clock[0])
    monkeypatch.setattr(sg, "_INTERRUPTED", []), monkeypatch.setattr(sg, "_TERMINATED", [])
    monkeypatch.setattr(sg, "_LAST", [float("-inf")])
    return sg, clock


def test_a_stop_s_signal_delivered_again_is_raised_once(monkeypatch):
    """A library that caught SIGINT sends it once more when it lets go (pyarrow's
    SignalStopHandler): a second KeyboardInterrupt raised while the first one's exit was
    written escaped main, and the process died of SIGINT (exit -2 after the one line; a
    fresh clone's CI, about 1 run in 30 of test_signal_during_calibrate). Repeated within
    RESENT_S it is recorded, not raised; later it stops again (Ctrl-C pressed once more)."""
    sg, clock = _signal_clock(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        sg._on_sigint(signal.SIGINT, None)
    clock[0] += 0.01
    sg._on_sigint(signal.SIGINT, None)   # the same stop, sent again: not raised
    sg._on_sigterm(signal.SIGTERM, None)  # (a SIGTERM right behind it: the same stop)
    assert sg._INTERRUPTED == [signal.SIGINT] * 2 and sg._TERMINATED == [signal.SIGTERM]
    clock[0] += 5.0
    with pytest.raises(KeyboardInterrupt):
        sg._on_sigint(signal.SIGINT, None)


def test_a_stop_pressed_again_and_again_still_stops(monkeypatch):
    """The window of a stop's repeat runs from the signal raised, not from the last one
    recorded: Ctrl-C pressed every 0.6 s where a library swallows the first stop was absorbed
    for ever (each press moved the window on)."""
    sg, clock = _signal_clock(monkeypatch)
    with pytest.raises(KeyboardInterrupt):
        sg._on_sigint(signal.SIGINT, None)
    clock[0] += 0.6
    sg._on_sigint(signal.SIGINT, None)  # within RESENT_S of the raised one: recorded
    clock[0] += 0.6  # 1.2 s after the raised one, 0.6 s after the last
    with pytest.raises(KeyboardInterrupt):
        sg._on_sigint(signal.SIGINT, None)


@pytest.mark.parametrize("out", ["", ".", "..", "sub/.."])
@pytest.mark.parametrize("force", [False, True])
def test_an_output_folder_that_names_the_working_folder_or_its_parent_is_one_line(tmp_path, monkeypatch, capsys,
                                                                                  out, force):
    """``--out ''`` (a shell variable left unset), ``--out .`` or ``--out ..`` name no output folder
    of their own: refused in one line naming the path, exit 2, the working folder untouched and no
    temporary folder left. Before: with --force (or an empty working folder) a FileExistsError
    traceback from output_set (the set's folder named '' or '..' inside its temporary sibling),
    and a hidden '..*.tmp' folder left in the working folder."""
    work = tmp_path / "work"
    (work / "sub").mkdir(parents=True)
    (work / "precious.txt").write_text("keep", encoding="utf-8")
    monkeypatch.chdir(work)
    rc = cli_main(["compare", str(BUNDLED_LOG), "--equation", "drvpw_prius3", "--out", out]
                  + (["--force"] if force else []))
    err = capsys.readouterr().err.strip()
    assert rc == 2 and len(err.splitlines()) == 1 and "Traceback" not in err, err
    assert "names the working folder" in err and repr(out or ".") in err, err  # ('' read as '.' by the CLI)
    assert sorted(p.name for p in work.iterdir()) == ["precious.txt", "sub"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["work"]
