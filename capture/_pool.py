"""Process pools for capture and targets whose workers never outlive the job.

``concurrent.futures.ProcessPoolExecutor`` lets a worker finish its task after its parent was
interrupted, and keeps it running when the parent is killed outright. :func:`worker_pool` stops
them: an exception in the ``with`` body (Ctrl-C included) cancels the queued tasks and terminates
the workers at once, and every worker watches its parent and exits within a second of its death
(``kill -9`` of ``rtp targets`` included). Work already finished is on disk (samples and targets
are written atomically); what a terminated worker was computing is redone by the next run.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import threading
import time
from collections.abc import Iterator
from concurrent.futures import ProcessPoolExecutor

#: Seconds between a worker's checks that its parent is still alive.
PARENT_POLL_S = 0.5


def _watch_parent(parent: int) -> None:
    """Worker initializer: exit as soon as the process that started the pool is gone."""

    def watch() -> None:
        while True:
            time.sleep(PARENT_POLL_S)
            if os.getppid() != parent:  # re-parented: the job's process died
                os._exit(1)

    threading.Thread(target=watch, name="rtp-parent-watch", daemon=True).start()


@contextlib.contextmanager
def worker_pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """A ``spawn`` process pool of ``workers`` processes that die with the job (module docstring)."""
    pool = ProcessPoolExecutor(max_workers=workers, mp_context=mp.get_context("spawn"),
                               initializer=_watch_parent, initargs=(os.getpid(),))
    try:
        yield pool
    except BaseException:
        procs = list((getattr(pool, "_processes", None) or {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in procs:
            p.terminate()
        for p in procs:
            p.join(5)
        raise
    pool.shutdown(wait=True)
