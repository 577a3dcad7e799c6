"""Process pools whose workers never outlive their parent (curation, evaluation, simulation).

A ``spawn`` worker of :class:`concurrent.futures.ProcessPoolExecutor` waits for work on a pipe whose
writing end it holds itself, so when the parent is killed (``kill -9``, the OOM killer) the
worker never sees end-of-file and blocks forever. Every pool here is made by :func:`process_pool`,
whose workers start a watchdog thread that exits the worker within ``POLL_S`` of the parent's death
(the worker is re-parented, so ``os.getppid()`` changes).
"""

from __future__ import annotations

import multiprocessing
import os
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor

POLL_S = 0.5


def process_pool(workers: int, initializer: Callable[[], None] | None = None) -> ProcessPoolExecutor:
    """A ``spawn`` pool of ``workers`` processes that exit when this process dies; ``initializer``
    (picklable, e.g. a module-level function) runs first in each worker.

    Spawn, not fork: a parent that already ran torch or OpenCV holds thread-pool locks a forked
    child inherits locked, and the child hangs.
    """
    return ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=_start_worker,
        initargs=(os.getpid(), initializer),
    )


def _start_worker(parent_pid: int, initializer: Callable[[], None] | None) -> None:
    exit_with_parent(parent_pid)
    if initializer is not None:
        initializer()


def exit_with_parent(parent_pid: int) -> None:
    """Exit this process (status 1, no cleanup) soon after ``parent_pid`` is no longer its parent."""

    def watch() -> None:
        while os.getppid() == parent_pid:
            time.sleep(POLL_S)
        os._exit(1)  # the parent is gone: nobody will collect this worker's result

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()
