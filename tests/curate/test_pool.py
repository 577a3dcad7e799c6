"""The local executor's pool (drivewm.curate.pool, drivewm.workers): workers forked from a server that
imported the stage and filterpy once, each on one OpenCV and one BLAS thread, giving the same shards as
one in-process worker."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from drivewm.curate import curate, load_curate_config

sys.path.insert(0, str(Path(__file__).parent))
from synth import write_synth_log  # noqa: E402

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]

#: a fresh driver process (its own fork server), one pool, the probe on each of its workers
DRIVER = """
import json, os, sys
sys.path.insert(0, sys.argv[1])
from pool_probe import probe
from drivewm.curate.pool import WORKER_PRELOAD, one_thread_per_worker
from drivewm.workers import process_pool
preload = WORKER_PRELOAD if sys.argv[2] == "forkserver" else ()
with process_pool(2, one_thread_per_worker, preload=preload) as pool:
    print(json.dumps({"driver": os.getpid(), "workers": list(pool.map(probe, range(4)))}))
"""


def _probe_workers(kind: str) -> dict:
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    proc = subprocess.run(
        [sys.executable, "-c", DRIVER, str(HERE), kind], capture_output=True, text=True, env=env, timeout=120
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


def test_pool_workers_are_forked_with_the_stage_imported_and_one_thread_each():
    out = _probe_workers("forkserver")
    for w in out["workers"]:
        # the fork server, not the driver, is their parent, and they hold its imports before any task ran
        assert w["ppid"] != out["driver"]
        assert w["preloaded"] == ["drivewm.curate.stage", "filterpy.kalman", "scipy.stats"]
        assert w["cv2_threads"] == 1
        assert w["pool_threads"] and set(w["pool_threads"].values()) == {1}, w["pool_threads"]


def test_spawned_workers_import_only_what_they_use():
    """The control: without preload the same probe finds a spawned child of the driver without the stage."""
    out = _probe_workers("spawn")
    for w in out["workers"]:
        assert w["ppid"] == out["driver"]
        assert w["preloaded"] == []
        assert w["cv2_threads"] == 1


@pytest.mark.slow  # 3 logs curated twice, ~15 s
def test_two_workers_write_the_same_shards_as_one(tmp_path):
    logs = [write_synth_log(tmp_path / "logs" / f"p{i}.mcap", seed=40 + i, n_frames=36) for i in range(3)]
    cfg = load_curate_config("test")
    one = curate(logs, tmp_path / "one", cfg, workers=1, progress=False)
    two = curate(logs, tmp_path / "two", cfg, workers=2, progress=False)
    assert one["kept"] == two["kept"] > 0
    shards = sorted(p.name for p in (tmp_path / "one").glob("*.tar"))
    assert shards == sorted(p.name for p in (tmp_path / "two").glob("*.tar"))
    for name in [*shards, "manifest.jsonl"]:
        assert (tmp_path / "one" / name).read_bytes() == (tmp_path / "two" / name).read_bytes(), name


@pytest.mark.parametrize("watch", ["exit_with_driver", "_poll_driver"])  # pidfd (Linux), polling (macOS)
def test_a_worker_exits_when_its_driver_ends(watch):
    """The watchdog both ways: a process watching another (here a `sleep`) exits with status 1 once
    that one ends, and lives while it runs."""
    driver = subprocess.Popen(["sleep", "30"])
    code = f"import time; from drivewm.workers import {watch}; {watch}({driver.pid}); time.sleep(30)"
    worker = subprocess.Popen([sys.executable, "-c", code], env={**os.environ, "PYTHONPATH": str(REPO)})
    try:
        with pytest.raises(subprocess.TimeoutExpired):
            worker.wait(timeout=1.5)  # the driver runs: the worker stays
        driver.kill()
        driver.wait()
        assert worker.wait(timeout=5) == 1
    finally:
        driver.kill()
        worker.kill()


#: a fresh process: the page faults of allocating, touching and freeing three 1 MB blocks together (a
#: streamed log's read chunk, its decompressed copy, a clip's frames) 10 times once warmed up, with and
#: without drivewm.workers.reuse_freed_memory (what every curation process calls first)
FAULTS = """
import resource, sys
import numpy as np
from drivewm.workers import reuse_freed_memory
tuned = reuse_freed_memory() if sys.argv[1] == "on" else False
def churn():
    for _ in range(10):
        blocks = [np.empty(1 << 20, np.uint8) for _ in range(3)]
        for b in blocks:
            b[::4096] = 1  # touch every page
        del blocks
churn()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
churn()
print(tuned, resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's mallopt: Linux only")
def test_curation_processes_reuse_freed_blocks_instead_of_faulting_in_fresh_pages():
    runs = {}
    for mode in ("off", "on"):
        out = subprocess.run([sys.executable, "-c", FAULTS, mode], capture_output=True, text=True, check=True, cwd=REPO)
        tuned, faults = out.stdout.split()
        runs[mode] = (tuned, int(faults))
    assert runs["on"][0] == "True"
    # glibc gives the heap above twice the largest block freed so far back to the kernel, so the next
    # blocks fault their pages in again (measured 992); kept for reuse, they need none (measured 0)
    assert runs["off"][1] > 500, runs
    assert runs["on"][1] < 50, runs
