"""Process pools for capture and targets whose workers never outlive the job.

``concurrent.futures.ProcessPoolExecutor`` lets a worker finish its task after its parent was
interrupted, and keeps it running when the parent is killed outright. :func:`worker_pool` stops
them: an exception in the ``with`` body (Ctrl-C included) cancels the queued tasks and terminates
the workers at once, and every worker watches its parent and exits within a second of its death
(``kill -9`` of ``rtp targets`` included). Work already finished is on disk (samples and targets
are written atomically); what a terminated worker was computing is redone by the next run.

Progress comes back through a plain queue handed to the workers when they start
(:func:`tick_queue`, ``worker_pool(n, ticks=q)``, ``pool.submit(with_ticks, fn, ...)``), not a
``multiprocessing.Manager``: a manager is a server process of its own, and ``kill -9`` of ``rtp
capture --workers 2`` left it (and with it multiprocessing's resource tracker) running for good.
Log records come back the same way, on a queue of their own that a thread of the parent hands to its
loggers (:class:`_LogForwarder`): ``-v`` shows what the workers log, and their warnings go through the
CLI's handler (its format, its collapse of repeats, the progress bar's redirection).

Each worker computes on its share of the cores (:func:`worker_threads`): the thread pools of
OpenMP (torch), the BLAS and Mesa's llvmpipe are limited to it before they start, and a worker's
onnxruntime sessions are given it (``rtp play``). Without that, two workers on two cores ran four
or more threads that took turns, onnxruntime's spinning between runs among them; with it, `rtp play
20kdm2 --frames 16 --composite --workers 2` took 100-113 s instead of 120-125 on the 2-core AVX2
EPYC of 2026-12-01, every figure the same (capture and targets, which run no onnxruntime, the same
time as before: docs/scaling.md). A variable the user set is kept.
"""

from __future__ import annotations

import contextlib
import logging
import logging.handlers
import multiprocessing as mp
import numbers
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator, Mapping
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Any

from rtp.sdk import EXIT_FAILED, RtpError

log = logging.getLogger("rtp.capture")

#: Seconds between a worker's checks that its parent is still alive.
PARENT_POLL_S = 0.5

#: The thread-pool sizes a worker sets to its share of the cores (OpenMP: torch; the BLAS numpy
#: links; Mesa's llvmpipe rasteriser), unless already set.
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "LP_NUM_THREADS")


class WorkerDiedError(RtpError, BrokenProcessPool):
    """A job's local worker process (``--workers N``) died: killed by the system (out of memory), by a
    signal, or by a crash of native code. Names the samples it may have been on; what finished is kept,
    and the same command resumes. Still a ``BrokenProcessPool``, as the pool raised it."""

    exit_code = EXIT_FAILED


def unfinished(tasks: Mapping[Future[Any], str]) -> list[str]:
    """The names of ``tasks`` (future -> what it works on) not finished well: when a worker dies, each of them
    fails with the broken pool, the one it was on among them."""
    return [name for f, name in tasks.items() if not f.done() or f.exception() is not None]


def worker_died(job: str) -> str:
    """The start of a :class:`WorkerDiedError`'s message for a ``job`` ("capture", "targets")."""
    return f"a {job} worker process died (killed by the system, out of memory?, or by a signal)"


def cores() -> int:
    """The cores this process may run on (its CPU affinity; the CPU count where there is none)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def worker_threads(workers: int) -> int:
    """The compute threads each of ``workers`` processes gets: the cores this process may run on,
    shared out, at least one."""
    return max(1, cores() // max(1, workers))


_TICKS: Any = None  # in a pool worker: the pool's tick queue (worker_pool(ticks=...)), else None


def _init_worker(parent: int, threads: int, ticks: Any = None, logs: Any = None, level: int = logging.WARNING) -> None:
    """Worker initializer: its thread pools on its share of the cores, the pool's tick queue, its log
    records sent to the parent (``logs``: those at ``level``, the parent's, and above), and exit as
    soon as the process that started the pool is gone."""
    global _TICKS
    _TICKS = ticks
    # Ctrl-C reaches the whole process group: the job stops its workers itself (worker_pool); a worker
    # that took it too could die between two tasks, and the job then failed on a BrokenProcessPool
    # traceback instead of "interrupted"
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if logs is not None:
        root = logging.getLogger()
        root.handlers[:] = [logging.handlers.QueueHandler(logs)]
        root.setLevel(level)
    for var in THREAD_VARIABLES:
        os.environ.setdefault(var, str(threads))
    torch = sys.modules.get("torch")  # imported while the initializer was unpickled: tell it directly
    omp = os.environ["OMP_NUM_THREADS"]
    if torch is not None and omp.isdigit() and int(omp) > 0:
        torch.set_num_threads(int(omp))
    _watch_parent(parent)


def _watch_parent(parent: int) -> None:
    """Exit as soon as the process that started the pool is gone (a thread of the worker)."""

    def watch() -> None:
        while True:
            time.sleep(PARENT_POLL_S)
            if os.getppid() != parent:  # re-parented: the job's process died
                os._exit(1)

    threading.Thread(target=watch, name="rtp-parent-watch", daemon=True).start()


def tick_queue() -> Any:
    """A queue for :func:`worker_pool`'s ``ticks``: the workers put progress on it, the job reads it
    (``get``, ``empty``). It lives in the processes that use it, with no server process to outlive them."""
    return mp.get_context("spawn").Queue()


def with_ticks(fn: Callable[..., Any], *args: Any, **kwargs: Any) -> Any:
    """Run in a pool worker (``pool.submit(with_ticks, fn, *args)``): ``fn(*args, queue=ticks, **kwargs)``
    with the pool's tick queue (None without one)."""
    return fn(*args, queue=_TICKS, **kwargs)


def name_task(exc: BaseException, task: str) -> None:
    """Say which ``task`` (``"scene 'sponza'"``, ``"sample 'a1b2'"``) a job's worker was on when ``exc``
    was raised, as a note under its traceback (Python 3.11+), the exception's type kept so that whatever
    catches it still does. Not on an rtp error, whose message names what it is about (and is printed
    alone, one line), nor on Ctrl-C, nor on a broken pool (a worker killed: every task still pending
    gets it, the one that was hit or not). The Ray path wraps the others in a RayWorkerError naming the task."""
    from concurrent.futures import BrokenExecutor

    from rtp.sdk import RtpError

    add_note = getattr(exc, "add_note", None)
    if isinstance(exc, Exception) and not isinstance(exc, (RtpError, BrokenExecutor)) and add_note is not None:
        add_note(f"(rtp: raised while working on {task})")


@contextlib.contextmanager
def worker_pool(workers: int, ticks: Any = None) -> Iterator[ProcessPoolExecutor]:
    """A ``spawn`` process pool of ``workers`` processes that die with the job, each on
    :func:`worker_threads` threads (module docstring); ``ticks``, a :func:`tick_queue`, is handed to
    every worker for :func:`with_ticks`. ``workers`` is an integer >= 1 (else a
    :class:`~rtp.sdk.ParameterError`)."""
    if isinstance(workers, bool) or not isinstance(workers, numbers.Integral) or workers < 1:
        from rtp.sdk import ParameterError

        raise ParameterError(f"workers: expected an integer >= 1, got {workers!r}", "workers")
    if workers > (n := cores()):
        log.warning("%d worker processes on the %d core%s this process may run on: each is a whole renderer or "
                    "metric process (hundreds of MB, torch's for targets), and more processes than cores add "
                    "memory, not speed", workers, n, "" if n == 1 else "s")
    logs = mp.get_context("spawn").Queue()
    workers = int(workers)
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"), initializer=_init_worker,
                               initargs=(os.getpid(), worker_threads(workers), ticks, logs,
                                         logging.getLogger().getEffectiveLevel()))
    forward = _LogForwarder(logs)  # (once the pool exists: a pool that failed to start left its thread running)
    try:
        yield pool
    except BaseException:
        procs = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in procs:
            p.terminate()
        for p in procs:
            p.join(5)
        forward.stop()
        raise
    pool.shutdown(wait=True)
    forward.stop()  # (after the workers exited: their last records are handled)


class _LogForwarder:
    """A thread of the parent that hands the workers' log records to its own loggers, so that they
    reach its handlers (``-v``, the collapse of repeats, the progress bar's redirection) as its own
    records do. A worker process starts with no logging set up: its INFO lines (each job's planning
    time) were lost and its warnings printed bare by Python's last-resort handler."""

    def __init__(self, queue: Any) -> None:
        self.queue = queue
        self._stopped = threading.Event()
        self._thread = threading.Thread(target=self._run, name="rtp-worker-logs", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        import queue as queue_module

        while True:
            try:
                record = self.queue.get(timeout=0.1)
            except queue_module.Empty:
                if self._stopped.is_set():
                    return
                continue
            except Exception:  # noqa: BLE001 (the queue closed, or a worker terminated mid-record broke it)
                return
            logging.getLogger(record.name).handle(record)

    def stop(self) -> None:
        """Hand over what is queued, then end the thread (at most a second's wait)."""
        self._stopped.set()
        self._thread.join(timeout=1.0)
