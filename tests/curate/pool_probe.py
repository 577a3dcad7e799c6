"""A task for pool workers that reports what the worker process looks like (tests/curate/test_pool.py).

Importable by the workers (the tests put this folder on ``sys.path``); it imports nothing heavy itself,
so what it finds in ``sys.modules`` was imported before the task ran.
"""

from __future__ import annotations

import os
import sys

HEAVY = ("drivewm.curate.stage", "filterpy.kalman", "scipy.stats")


def probe(_: int) -> dict:
    """The worker's parent pid, which heavy modules it holds, and its OpenCV and BLAS/OpenMP thread counts."""
    preloaded = [m for m in HEAVY if m in sys.modules]
    import cv2
    from threadpoolctl import threadpool_info

    return {
        "pid": os.getpid(),
        "ppid": os.getppid(),
        "preloaded": preloaded,
        "cv2_threads": cv2.getNumThreads(),
        "pool_threads": {f"{p['internal_api']}:{p['filepath']}": p["num_threads"] for p in threadpool_info()},
    }
