"""Engines that reduce drive logs of any size to mergeable statistics: local or Dask.

Both engines run the same function on each :class:`~sumo_drvpw.data.stream.Part` (whole
trips of one file): read it batch by batch of whole trips, derive the model inputs and
measured power the reader's way, and add each batch to an accumulator
(:class:`~sumo_drvpw.fit.stream.CalibrationStats` or
:class:`~sumo_drvpw.fit.stream.CompareStats`). The accumulators of the Parts are merged in
Part order, so the local and the Dask engine add the same numbers in the same order.

* ``local``: one process, Parts one after the other; memory is one batch (at most
  ``BATCH_ROWS`` rows and ``BATCH_VALUES`` values of the columns read, plus the longest
  trip: :func:`~sumo_drvpw.data.stream.iter_measured`) plus the accumulator, whatever the
  rows and columns of the logs.
* ``dask``: one task per Part on a Dask cluster: ``scheduler`` = the address of an
  existing one (``tcp://host:8786``; a dask-jobqueue or Kubernetes cluster prints it),
  else a ``LocalCluster`` of ``workers`` processes. Dask is an optional extra:
  ``pip install 'sumo-drvpw[dask]'``.

Progress goes to stderr (tqdm: rows or Parts done, rate, ETA) when it is a terminal.
"""

from __future__ import annotations

import queue
import resource
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from functools import partial

import numpy as np

from sumo_drvpw.data.stream import BATCH_ROWS, PART_ROWS, Part, iter_measured, plan
from sumo_drvpw.errors import NoDrivingPower, UserError
from sumo_drvpw.fileio import signals_blocked

ENGINES = ("local", "dask")
#: Read the next batch in a thread while this one is added (2 cores: ~1.5× the rows/s).
PREFETCH = True
#: Seconds to wait for a Dask scheduler named by address.
CONNECT_TIMEOUT_S = 10.0


@dataclass
class RunInfo:
    """What a run cost: rows read, wall time [s], peak RSS of this process [MB], Parts."""

    rows: int
    seconds: float
    peak_rss_mb: float
    parts: int
    engine: str

    def line(self) -> str:
        """One-line resource summary for the end of a command."""
        rate = self.rows / self.seconds if self.seconds > 0 else float("nan")
        return (f"{self.engine} engine: {self.rows:,} rows from {self.parts} part(s) in "
                f"{self.seconds:.1f} s ({rate:,.0f} rows/s), peak RSS {self.peak_rss_mb:,.0f} MB")


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far [MB] (Linux: ru_maxrss in KiB)."""
    r = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return r / (1024.0 * 1024.0) if sys.platform == "darwin" else r / 1024.0


def part_stats(part: Part, make, vehicle=None, options=None, rows: int = BATCH_ROWS, tick=None,
               ids: list | None = None):
    """The statistics of one Part: ``make()`` (an empty accumulator) + every batch
    (``ids``: when a list, the Part's trip ids are appended to it in reading order).

    BLAS runs single-threaded here: the work is many small products per trip, for which
    OpenBLAS threads cost 10–30× on a busy machine (measured: a 14,400 × 9 QR 90 ms with
    threads, 9 ms without); parallelism comes from the Parts (Dask workers) and, within a
    Part, from reading the next batch (a thread: Parquet decoding, validation and
    derivations) while this one is added (:func:`prefetched`, when ``PREFETCH``).
    """
    with _one_blas_thread():
        st = make()
        cols = st.columns() if hasattr(st, "columns") else None
        batches = iter_measured(part, vehicle, options, rows, columns=cols,
                                target=getattr(st, "target", "wheel"))
        for m in (prefetched(batches) if PREFETCH else batches):
            if ids is not None:
                ids += _trip_ids(m)
            st.add(m)
            n = len(m.power_w)
            del m  # freed before the next batch is read
            if tick is not None:
                tick(n)
    return st


def _trip_ids(m) -> list[str]:
    """The trip ids of a batch, once per trip, in order."""
    from sumo_drvpw.data.trips import trip_codes_of

    col = m.log.df["trip_id"]
    codes = trip_codes_of(col)
    starts = np.flatnonzero(np.r_[True, codes[1:] != codes[:-1]])
    return [str(t) for t in col.iloc[starts]]


def _part_stats_ids(part: Part, **kw):
    """(statistics, trip ids) of a Part: the unit of work of the engines."""
    ids: list = []
    return part_stats(part, ids=ids, **kw), ids


def _check_one_file(part: Part, ids: list, seen: dict) -> None:
    """No trip id in two files: the check the in-memory reader makes, on the ids each
    Part read (same message as :func:`sumo_drvpw.data.plausible.check_distinct_trips`)."""
    for tid in ids:
        if seen.get(tid, part.path) != part.path:
            raise UserError(f"{part.path}: trip_id '{tid}' is also in {seen[tid]}; samples of one "
                            "trip belong in one file, give each trip its own id")
    for tid in ids:
        seen.setdefault(tid, part.path)


def prefetched(items, depth: int = 1):
    """The items of an iterator, produced one ahead in a background thread.

    At most ``depth`` items wait in the queue, so memory holds the item in use, ``depth``
    ready ones and the one being produced. The consumer sees the items in order; an
    exception of the producer is raised in the consumer; when the consumer stops early
    (an error, or it breaks off) the producer stops at its next item.
    """
    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()
    done = object()

    def produce():
        try:
            for item in items:
                while not stop.is_set():
                    try:
                        q.put((item, None), timeout=0.05)
                        break
                    except queue.Full:
                        continue
                del item  # the queue holds it now; not kept while the next one is read
                if stop.is_set():
                    return
            q.put((done, None))
        except BaseException as e:  # noqa: BLE001 - handed to the consumer, raised there
            q.put((done, e))

    th = threading.Thread(target=produce, name="sumo-drvpw-prefetch", daemon=True)
    th.start()
    try:
        while True:
            item, err = q.get()
            if item is done:
                if err is not None:
                    raise err
                return
            yield item
            del item
    finally:
        stop.set()
        while th.is_alive():
            try:
                q.get(timeout=0.05)  # unblock a producer waiting to put
            except queue.Empty:
                pass
        th.join()


def _one_blas_thread():
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # pragma: no cover - a dependency; without it BLAS keeps its threads
        from contextlib import nullcontext

        return nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def _progress(total, unit):
    from tqdm import tqdm

    return tqdm(total=total, unit=unit, unit_scale=True, disable=None, file=sys.stderr,
                dynamic_ncols=True, leave=False)


def run(paths, make, vehicle=None, options=None, engine: str = "local",
        scheduler: str | None = None, workers: int | None = None, rows: int = BATCH_ROWS,
        parts: list[Part] | None = None):
    """Reduce the logs ``paths`` to one accumulator.

    Parameters
    ----------
    paths : drive log files or folders
    make : picklable callable returning an empty accumulator with ``add(measured)`` and
        ``merge(other)`` (e.g. ``functools.partial(CalibrationStats, names)``)
    vehicle, options : as for :func:`sumo_drvpw.data.measured.load_measured`
    engine : ``local`` or ``dask``
    scheduler : Dask scheduler address (``dask`` only); None: a local cluster
    workers : processes of the local Dask cluster (default: CPU count)
    rows : rows per chunk read [-]
    parts : the Parts (default :func:`sumo_drvpw.data.stream.plan` of ``paths``: one
        per file locally, big Parquet files cut at trip starts for Dask)

    Returns (accumulator, :class:`RunInfo`).
    """
    if engine not in ENGINES:
        raise UserError(f"engine '{engine}' unknown; choose {' or '.join(ENGINES)}")
    if engine == "local" and scheduler is not None:
        raise UserError("a scheduler address needs the dask engine")
    if workers is not None and workers < 1:
        raise UserError(f"workers must be at least 1, got {workers}")
    t0 = time.perf_counter()
    if parts is None:  # Dask: cut big Parquet files at trip starts so workers share them
        parts = plan(paths, PART_ROWS if engine == "dask" else None)
    total = sum(p.rows for p in parts) or None
    if engine == "local":
        acc, seen = None, {}
        bar = _progress(total, "rows")
        try:
            for p in parts:
                st, ids = _part_stats_ids(p, make=make, vehicle=vehicle, options=options,
                                          rows=rows, tick=bar.update)
                _check_one_file(p, ids, seen)
                acc = st if acc is None else acc.merge(st)
        finally:
            bar.close()
    else:
        acc = _run_dask(parts, make, vehicle, options, scheduler, workers, rows)
    nrows = int(getattr(acc, "rows", 0))
    return acc, RunInfo(nrows, time.perf_counter() - t0, peak_rss_mb(), len(parts), engine)


@contextmanager
def dask_client(scheduler: str | None = None, workers: int | None = None):
    """A Dask client (context manager): of the scheduler at ``scheduler``, else of a local
    cluster of ``workers`` single-threaded processes; closed on exit. UserError without Dask
    or when the scheduler cannot be reached. Used by the log engines and SUMO sweeps."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise UserError("the dask engine needs Dask: pip install 'sumo-drvpw[dask]'") from None
    cluster = None
    if scheduler is None:
        import logging

        try:
            with _sigint_held_from_workers():
                # the cluster's own logs are for Dask's developers: a refusal that stops
                # the driver early left tracebacks of closed connections above our line
                cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                       dashboard_address=":0", silence_logs=logging.CRITICAL)
            client = Client(cluster)
        except BaseException:  # Ctrl-C while the cluster started: no cluster left behind
            if cluster is not None:
                cluster.close()
            raise
    else:
        try:
            client = Client(scheduler, timeout=f"{CONNECT_TIMEOUT_S}s")
        except (OSError, TimeoutError) as e:
            raise UserError(f"cannot reach the Dask scheduler at {scheduler}: {e}") from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


@contextmanager
def _sigint_held_from_workers():
    """SIGINT blocked in this thread while a local cluster starts, then restored (a Ctrl-C
    meanwhile is delivered then). The threads Dask starts here (its event loop, and the
    threads that spawn the worker processes) keep the mask, and so do the worker processes
    (a blocked signal stays blocked across fork and exec): Ctrl-C in a terminal reaches
    the whole process group, and each worker died with a KeyboardInterrupt traceback above
    the driver's one line, while the driver, interrupted too, closes the cluster anyway.
    SIGTERM is left as it is."""
    import signal

    if hasattr(signal, "pthread_sigmask"):  # (where signals can be blocked: POSIX)
        from multiprocessing import resource_tracker

        # started here, not by Dask inside the block: starting it unblocks SIGINT in the
        # thread that starts it (multiprocessing/resource_tracker.py), Dask's event loop
        resource_tracker.ensure_running()
    with signals_blocked(signal.SIGINT):
        yield


class Refused:
    """A task's UserError carried back as its result (:func:`guarded`): a bad input is the
    user's, not a task failure, so a Dask worker logs no "Compute Failed" block for it."""

    def __init__(self, message: str, targets: tuple | None = None):
        self.message = message
        self.targets = targets  # a NoDrivingPower's: what the log holds instead (None: another error)


def guarded(fn, *args, **kwargs):
    """``fn(*args, **kwargs)``, with a UserError returned as :class:`Refused`."""
    try:
        return fn(*args, **kwargs)
    except UserError as e:
        return Refused(str(e), e.targets if isinstance(e, NoDrivingPower) else None)


def unguarded(result):
    """A task's result; a :class:`Refused` raises its UserError here, in the driver."""
    if isinstance(result, Refused):
        if result.targets is not None:
            raise NoDrivingPower(result.message, result.targets)
        raise UserError(result.message)
    return result


def _run_dask(parts, make, vehicle, options, scheduler, workers, rows):
    with dask_client(scheduler, workers) as client:
        return _reduce_on(client, parts, make, vehicle, options, rows)


def _reduce_on(client, parts, make, vehicle, options, rows):
    fn = partial(guarded, partial(_part_stats_ids, make=make, vehicle=vehicle, options=options, rows=rows))
    futures = client.map(fn, parts, pure=False)
    bar = _progress(len(parts), "part")
    acc, seen = None, {}
    try:
        for p, f in zip(parts, futures):  # in Part order: the same sums, in the same order, as local
            st, ids = unguarded(f.result())
            f.release()
            _check_one_file(p, ids, seen)
            acc = st if acc is None else acc.merge(st)
            bar.update(1)
    finally:
        bar.close()
    return acc
