"""Executors: run the per-log stage over many logs, locally or on Ray Data.

Both call :func:`drivewm.curate.stage.curate_log` once per log and return its results in input
order; each log's shards and done-marker are written by the worker itself, so results survive
a crash of the driver. ``workers=1`` runs in-process (easiest to debug); more workers use a
process pool (drivewm.workers) whose workers exit when the driver dies, forked from a server that
imported the stage and filterpy once (:mod:`drivewm.curate.pool`). Ray runs the same
function as a ``map`` over a dataset of log paths; Ray (the optional ``ray`` extra, seconds to import) is
imported only when the Ray executor runs.
"""

from __future__ import annotations

import functools
import json
import os
import traceback
from collections.abc import Callable
from concurrent.futures import as_completed

from drivewm.curate.config import CurateConfig
from drivewm.curate.pool import WORKER_PRELOAD, one_thread_per_worker
from drivewm.curate.stage import curate_log, load_embeddings
from drivewm.errors import DrivewmError, no_room
from drivewm.workers import process_pool

Progress = Callable[[dict], None]


def _safe_curate(log: str, out_dir: str, cfg: CurateConfig, name: str) -> dict:
    """The stage, with unexpected exceptions turned into a failed result (the batch goes on); a full or
    read-only output folder (drivewm.errors.no_room) stops the batch, since every log would fail on it."""
    try:
        return curate_log(log, out_dir, cfg, name)
    except Exception as exc:  # a bug or an unforeseen bad input: report it, keep the other logs
        if no_room(exc):
            raise
        detail = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return {
            "log": log,
            "name": name,
            "status": "failed",
            "error": f"{log}: unexpected error: {detail}",
            "kept": 0,
            "dropped": {},
            "rows": [],
        }


def run_local(
    jobs: list[tuple[str, str]], out_dir: str, cfg: CurateConfig, workers: int, progress: Progress
) -> list[dict]:
    """``jobs`` (log path, name) -> results in input order, ``workers`` processes (1 = in-process)."""
    if workers <= 1:
        results = []
        for log, name in jobs:
            results.append(load_embeddings(out_dir, _safe_curate(log, out_dir, cfg, name)))
            progress(results[-1])
        return results

    by_index: dict[int, dict] = {}
    with process_pool(workers, one_thread_per_worker, preload=WORKER_PRELOAD) as pool:
        futures = {pool.submit(_safe_curate, log, out_dir, cfg, name): i for i, (log, name) in enumerate(jobs)}
        for fut in as_completed(futures):
            by_index[futures[fut]] = load_embeddings(out_dir, fut.result())
            progress(by_index[futures[fut]])
    return [by_index[i] for i in range(len(jobs))]


#: Times Ray reruns a log's task whose worker process or node died (the stage's own errors are results).
RAY_TASK_RETRIES = 3


def _ray_row(row: dict, out_dir: str, cfg: CurateConfig) -> dict:
    """One log on a Ray worker; the result travels as JSON text (Arrow would coerce its ragged dicts)."""
    one_thread_per_worker()
    return {"i": row["i"], "result": json.dumps(_safe_curate(row["log"], out_dir, cfg, row["name"]))}


def run_ray(
    jobs: list[tuple[str, str]],
    out_dir: str,
    cfg: CurateConfig,
    workers: int,
    progress: Progress,
    address: str | None = None,
) -> list[dict]:
    """The same stage as a Ray Data ``map`` (one log per row). ``address`` None starts a local Ray
    with ``max(workers, 2)`` CPUs; otherwise connects to that cluster ("HEAD_IP:6379" as printed by
    ``ray start --head``, or "auto"). On a cluster, the logs and ``out_dir`` must be at the same
    paths on every node (shared storage) and drivewm importable there.

    A task whose worker dies (a node lost, a process killed) is run again by Ray (``max_retries``):
    the stage rewrites that log's shards from scratch and writes its done-marker last, so the
    result is the same clips once each."""
    os.environ.setdefault("RAY_AUTH_MODE", "disabled")
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    try:
        import ray
    except ImportError:
        raise DrivewmError("--executor ray needs Ray: pip install 'drivewm[ray]'") from None
    started = not ray.is_initialized()
    if started:
        ray.init(
            address=address, num_cpus=None if address else max(workers, 2), include_dashboard=False, log_to_driver=False
        )
    try:
        rows = [{"i": i, "log": log, "name": name} for i, (log, name) in enumerate(jobs)]
        ds = ray.data.from_items(rows, override_num_blocks=max(1, len(rows)))
        task = functools.partial(_ray_row, out_dir=out_dir, cfg=cfg)
        mapped = ds.map(task, num_cpus=1, max_retries=RAY_TASK_RETRIES, retry_exceptions=False)
        by_index = {}
        for row in mapped.iter_rows():
            by_index[int(row["i"])] = load_embeddings(out_dir, json.loads(row["result"]))
            progress(by_index[int(row["i"])])
        return [by_index[i] for i in range(len(jobs))]
    finally:
        if started:
            ray.shutdown()
