"""Curation on a real Ray cluster (``ray start`` head + worker, loopback only), by address through
the CLI: byte-identical manifest and shards to the local executor, also when a task is killed
mid-run and Ray retries it."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

pytest.importorskip("ray")
sys.path.insert(0, str(Path(__file__).parent))
from ray_cluster import LoopbackRayCluster  # noqa: E402
from synth import write_synth_log  # noqa: E402

from drivewm.curate import curate, load_curate_config  # noqa: E402

REPO = Path(__file__).resolve().parents[2]
RECIPE = "test"  # the packaged test recipe (drivewm/recipes/curate/test.yaml)


def _tree(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(out.glob("*.tar"))} | {
        "manifest": (out / "manifest.jsonl").read_bytes()
    }


def _kill_writer_of(out: Path, prefix: str, cluster: LoopbackRayCluster, proc: subprocess.Popen) -> int | None:
    """SIGKILL the cluster process that has ``prefix``'s first shard open (mid-log); its pid."""
    while proc.poll() is None:
        for worker in cluster.processes():
            try:
                if any(f".{prefix}-000000.tar." in f.path for f in worker.open_files()):
                    os.kill(worker.pid, signal.SIGKILL)
                    return worker.pid
            except (psutil.NoSuchProcess, psutil.AccessDenied):
                continue
        time.sleep(0.05)
    return None


@pytest.mark.slow
def test_ray_cluster_by_address_equals_local_even_after_a_killed_task(tmp_path):
    logs = [
        write_synth_log(tmp_path / "logs" / "long_drive.mcap", seed=11, n_frames=200),  # 11 clips: 8 in shard 0
        write_synth_log(tmp_path / "logs" / "drive_b.mcap", seed=12, n_frames=52),
        write_synth_log(tmp_path / "logs" / "drive_c.mcap", seed=13, n_frames=52, drop={"CAM_FRONT": [30]}),
    ]
    (tmp_path / "logs" / "broken.mcap").write_text("not a log")
    logs.append(tmp_path / "logs" / "broken.mcap")
    local = curate(logs, tmp_path / "local", load_curate_config(RECIPE), progress=False)
    assert local["kept"] == 11 + 3 + 2 and local["logs_failed"] == 1
    env = {"PYTHONPATH": str(REPO), "PATH": os.environ["PATH"]}
    with LoopbackRayCluster(tmp_path / "cluster", cpus_per_node=1, env=env) as cluster:
        assert all(ip in ("127.0.0.1", "::ffff:127.0.0.1") for ip, _ in cluster.listening()), cluster.listening()
        # one run through the cluster, one of its tasks killed mid-log: the retried task still leaves what
        # the local run wrote (a clean run through the cluster is the case where no kill lands)
        out = tmp_path / "killed"
        cmd = [sys.executable, "-m", "drivewm.cli", "curate", *map(str, logs), "--out", str(out)]
        cmd += ["--recipe", RECIPE, "--executor", "ray", "--ray-address", cluster.address]
        proc = subprocess.Popen(cmd, cwd=REPO, env={**cluster.env}, stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
        killed_pid = _kill_writer_of(out, "long_drive", cluster, proc)
        output = proc.communicate(timeout=900)[0].decode()
        assert proc.returncode == 0, output[-3000:]
        assert all(ip in ("127.0.0.1", "::ffff:127.0.0.1") for ip, _ in cluster.listening())
    assert killed_pid is not None, "no task was caught mid-log"
    assert _tree(out) == _tree(tmp_path / "local")  # same clips once each: no duplicate, none missing
    assert not list(out.glob(".*.tmp")), "the killed task's temporary shard is cleaned up"
