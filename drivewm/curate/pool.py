"""The local executor's worker processes: what their fork server imports once, and each worker's threads.

Light on purpose (no OpenCV, numpy or stage import at module level): ``drivewm curate --workers N``
starts the fork server (:func:`start_fork_server`) before the CLI process imports the stage itself,
so the two imports (~1 and ~1.4 CPU s) run on two cores at once instead of one after the other.
"""

from __future__ import annotations

from drivewm import workers

#: Modules a local pool's fork server imports once for all its workers: the stage (OpenCV, PyAV, the MCAP
#: reader) and filterpy, which the stage imports at a log's first smoothing (its package imports
#: scipy.stats). Spawned, each worker paid ~0.9 + ~1.5 CPU s for them (idle): with 2 workers on 1,800
#: camera-frames as much as the per-frame work (drivewm/recipes/curate/README.md, "Throughput and memory").
WORKER_PRELOAD = ("drivewm.curate.executors", "filterpy.kalman")


def start_fork_server() -> None:
    """Start the pool's fork server now (it imports :data:`WORKER_PRELOAD` in the background)."""
    workers.start_fork_server(WORKER_PRELOAD)


def one_thread_per_worker() -> None:
    """Each worker's initializer: parallelism comes from the pool, so OpenCV's pool and the BLAS/OpenMP
    pools (threadpoolctl) run on one thread each, not on the cores the other workers use."""
    # lazy: this module is imported by the CLI before the stage; in a worker both are already imported
    import cv2
    from threadpoolctl import threadpool_limits

    cv2.setNumThreads(1)
    threadpool_limits(1)
