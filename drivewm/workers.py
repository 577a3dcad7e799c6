"""Process pools whose workers never outlive their parent (curation, evaluation, simulation).

A ``spawn`` worker of :class:`concurrent.futures.ProcessPoolExecutor` waits for work on a pipe whose
writing end it holds itself, so when the parent is killed (``kill -9``, the OOM killer) the
worker never sees end-of-file and blocks forever. Every pool here is made by :func:`process_pool`,
whose workers start a watchdog thread that exits the worker as soon as the driver (the process that
made the pool) ends: it waits on a pidfd of the driver (Linux >= 5.3), which becomes readable when that
process ends, reaped or not, and cannot name another process that reuses its pid.

A pool with ``preload`` modules forks its workers from a ``forkserver`` that imported them once,
instead of spawning interpreters that each import them again: a curate worker's ~2 CPU s of imports
(the stage, OpenCV, filterpy's scipy.stats) is paid once per driver process, not once per worker.
The fork server is a fresh interpreter that only imported modules (no thread pool ever ran a
task in it), so forking it is as safe as spawning. It does not exit with the driver while its workers
live (CPython gives each forked child a copy of the server's "alive" pipe), which is why the workers
watch the driver itself, not their parent; once they exit, the server does.
"""

from __future__ import annotations

import ctypes
import functools
import multiprocessing
import multiprocessing.forkserver
import os
import select
import threading
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor

POLL_S = 0.5  # seconds between checks of the driver's pid where there are no pidfds


def process_pool(
    workers: int, initializer: Callable[[], None] | None = None, preload: tuple[str, ...] = ()
) -> ProcessPoolExecutor:
    """A pool of ``workers`` processes that exit when this process dies; ``initializer`` (picklable,
    e.g. a module-level function) runs first in each worker.

    Without ``preload``: ``spawn`` workers, each a fresh interpreter. Never plain fork: a parent that
    already ran torch or OpenCV holds thread-pool locks a forked child inherits locked, and the child
    hangs. With ``preload`` (module names): ``forkserver`` workers forked from one server process that
    imported those modules (this process's ``sys.path``). The server is started once per process and
    reused by later pools; a preload list given after it started is not imported by it (the workers
    then import what they use themselves, as spawned ones do).
    """
    if preload:
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(list(preload))
    else:
        context = multiprocessing.get_context("spawn")
    return ProcessPoolExecutor(
        max_workers=workers,
        mp_context=context,
        initializer=_start_worker,
        initargs=(os.getpid(), initializer),
    )


def start_fork_server(preload: tuple[str, ...]) -> None:
    """Start this process's fork server now, importing ``preload``, so that it imports while this
    process goes on (a pool with the same ``preload`` made later forks its workers from it)."""
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(list(preload))
    multiprocessing.forkserver.ensure_running()


def _start_worker(driver_pid: int, initializer: Callable[[], None] | None) -> None:
    exit_with_driver(driver_pid)
    if initializer is not None:
        initializer()


def exit_with_driver(driver_pid: int) -> None:
    """Exit this process (status 1, no cleanup) as soon as process ``driver_pid`` ends (a spawned
    worker's parent, a forked one's grandparent)."""
    if not hasattr(os, "pidfd_open"):  # not Linux (macOS): poll the driver's pid instead
        return _poll_driver(driver_pid)
    try:
        pidfd = os.pidfd_open(driver_pid)
    except ProcessLookupError:  # the driver died before this worker started
        os._exit(1)

    def watch() -> None:
        select.select([pidfd], [], [])  # readable once the driver has ended
        os._exit(1)  # nobody will collect this worker's result

    threading.Thread(target=watch, name="exit-with-driver", daemon=True).start()


def _poll_driver(driver_pid: int) -> None:
    """Without pidfds: exit within ``POLL_S`` of ``driver_pid`` no longer existing (a pid reused by
    another process in between keeps the worker alive until that one ends too)."""

    def watch() -> None:
        while True:
            try:
                os.kill(driver_pid, 0)
            except (ProcessLookupError, PermissionError):  # gone, or its pid is another user's process now
                os._exit(1)
            time.sleep(POLL_S)

    threading.Thread(target=watch, name="exit-with-driver", daemon=True).start()


#: glibc mallopt parameters (malloc.h) and the values :func:`reuse_freed_memory` sets
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3
MMAP_THRESHOLD = 32 << 20  # glibc's largest (DEFAULT_MMAP_THRESHOLD_MAX on 64-bit)
TRIM_THRESHOLD = 256 << 20


@functools.cache
def reuse_freed_memory() -> bool:
    """Let glibc's malloc reuse freed blocks of up to 32 MB instead of unmapping them, and keep up to
    256 MB of free heap before giving it back; True if set (glibc), False elsewhere (macOS, musl).

    glibc serves blocks from 128 kB up (raised to the largest block freed so far) with fresh ``mmap``
    pages, zero-filled by the kernel one page fault at a time on first touch, and unmaps them on free.
    It also gives the heap above twice the largest block freed so far back to the kernel. A log
    streamed chunk by chunk allocates the same few MB again and again (an MCAP chunk read and
    decompressed, a clip's frames), so curating 1,800 camera-frames (fleet 160x96) took 18,000-24,000
    page faults and 2-5 % more CPU than with this set (3,700 faults; 3 interleaved pairs of runs).
    Memory stays bounded by what is live at once (the clip window), plus up to 256 MB of free heap
    held for reuse; blocks of 32 MB and more are still mapped and unmapped. Process-wide and lasting:
    called where curation runs (the stage, each worker), it also applies to whatever that process does
    afterwards.
    """
    try:
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_MMAP_THRESHOLD, MMAP_THRESHOLD)) and bool(mallopt(_M_TRIM_THRESHOLD, TRIM_THRESHOLD))
