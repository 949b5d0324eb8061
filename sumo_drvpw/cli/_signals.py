"""How the commands stop on a signal: SIGINT and SIGTERM raised as KeyboardInterrupt (a
stop's repeated delivery once), the exit code and the one line said, and a signal's
exception that Python cannot propagate kept off the terminal."""

from __future__ import annotations

import signal
import sys
import time


class _Terminated(KeyboardInterrupt):
    """SIGTERM, raised where Ctrl-C (SIGINT) would be: the run stops the same clean way."""


_TERMINATED = []  # set when SIGTERM arrived: an interrupted command then exits 143, not 130
_INTERRUPTED = []  # set when SIGINT arrived
_LAST = [float("-inf")]  # when the last of them raised arrived [s, time.monotonic]

#: a stop's signal delivered again within this time [s] is the same stop, recorded and not
#: raised again: a library that caught it sends it once more when it lets go (pyarrow's
#: SignalStopHandler re-sends the signal it cancelled on), and a second KeyboardInterrupt
#: raised while the first one's exit was being written left the process killed by SIGINT
#: (exit −2 after the one line; tests/test_faults.py, about 1 run in 30). Later, it stops
#: again (a user who presses Ctrl-C once more where the first was swallowed).
RESENT_S = 1.0


def _again() -> bool:
    """Whether a signal arriving now repeats the stop already under way: within RESENT_S of
    the signal last raised (a repeat recorded does not move the window on, or a Ctrl-C
    pressed again and again would never stop a run whose first stop a library swallowed)."""
    now = time.monotonic()
    again = bool(_TERMINATED or _INTERRUPTED) and now - _LAST[0] < RESENT_S
    if not again:
        _LAST[0] = now
    return again


def _stop(record: list, signum, raised: type) -> None:
    """Record ``signum`` and raise ``raised`` unless it repeats the stop under way."""
    again = _again()
    record.append(signum)
    if not again:
        raise raised()


def _on_sigterm(signum, frame):
    _stop(_TERMINATED, signum, _Terminated)


def _on_sigint(signum, frame):
    _stop(_INTERRUPTED, signum, KeyboardInterrupt)


def _quiet_signal_hook(prev):
    """sys.unraisablehook that drops a signal's exception raised where Python cannot
    propagate it (a garbage collector's weakref callback printed "Exception ignored in …" and a
    traceback above the one line): the record of the signal decides the exit all the same."""
    def hook(unraisable):
        if not isinstance(unraisable.exc_value, KeyboardInterrupt):
            prev(unraisable)
    return hook


def _signal_exit(terminated: bool, finished: bool = False) -> int:
    """The one line and exit code of a run a signal stopped: 143 (SIGTERM) or 130 (SIGINT);
    ``finished``: the command completed its output all the same (the signal's exception
    was swallowed inside a library), so what it wrote is whole."""
    what = "its output was completed" if finished else "no partial output written"
    if terminated:
        print(f"sumo-drvpw: terminated (SIGTERM); {what}", file=sys.stderr)
        return 128 + signal.SIGTERM
    print(f"sumo-drvpw: interrupted; {what}", file=sys.stderr)
    return 130


def _stopped_by_signal() -> int | None:
    """Exit code of a run a signal stopped, else None. A signal's exception raised inside a
    library's C code (matplotlib drawing a path, say) can come out as that library's own
    error; the record of the signal says what happened."""
    return _signal_exit(bool(_TERMINATED)) if _TERMINATED or _INTERRUPTED else None
