"""A two-node Ray cluster on this machine for tests: ``ray start --head`` and ``ray start --address``
as separate processes, every port on the loopback interface, stopped (only these) at the end.

Ray keeps a cluster on 127.0.0.1 only when ``RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER=0`` (otherwise it
replaces 127.0.0.1 by the public interface's address and listens on every interface), but with
that setting ``ray start --address`` refuses to add a second node. So the worker node runs the
same ``ray start`` command in a Python process that lifts exactly that refusal and keeps the
given loopback address; everything it starts (raylet, workers) runs with the loopback setting.
"""

from __future__ import annotations

import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

LOOPBACK_ENV = {"RAY_ENABLE_WINDOWS_OR_OSX_CLUSTER": "0", "RAY_AUTH_MODE": "disabled", "RAY_USAGE_STATS_ENABLED": "0"}

_WORKER_NODE = """
import sys
import ray._private.ray_constants as constants
import ray._private.services as services
from ray.scripts.scripts import main

constants.ENABLE_RAY_CLUSTER = True  # allow this second node (the CLI refuses it on loopback)
services.resolve_ip_for_localhost = lambda host: host  # and keep its address on 127.0.0.1
sys.argv = ["ray", *sys.argv[1:]]
main()
"""


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class LoopbackRayCluster:
    """Head + one worker node, ``cpus_per_node`` CPUs each; ``address`` is "127.0.0.1:PORT"."""

    def __init__(self, folder: Path, cpus_per_node: int = 1, env: dict[str, str] | None = None):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.port = free_port()
        self.address = f"127.0.0.1:{self.port}"
        self.env = {**os.environ, **(env or {}), **LOOPBACK_ENV}
        self.cpus = cpus_per_node
        self.procs: list[subprocess.Popen] = []
        self.temp_dir = ""

    def _node_args(self) -> list[str]:
        return [
            "--node-ip-address=127.0.0.1",
            f"--num-cpus={self.cpus}",
            f"--dashboard-agent-listen-port={free_port()}",
            f"--metrics-export-port={free_port()}",
            f"--runtime-env-agent-port={free_port()}",
            "--disable-usage-stats",
            "--block",
        ]

    def _spawn(self, argv: list[str], log: str) -> None:
        out = open(self.folder / log, "w")  # noqa: SIM115 - open for the life of the process
        self.procs.append(
            subprocess.Popen(argv, stdout=out, stderr=subprocess.STDOUT, env=self.env, start_new_session=True)
        )

    def __enter__(self) -> LoopbackRayCluster:
        ray_cli = str(Path(sys.executable).with_name("ray"))
        self.temp_dir = tempfile.mkdtemp(prefix="dwray", dir="/tmp")  # unix socket paths must stay short
        head = ["--head", f"--port={self.port}", "--include-dashboard=false", f"--temp-dir={self.temp_dir}"]
        self._spawn([ray_cli, "start", *head, *self._node_args()], "head.log")
        self._wait(lambda: self._status_ok(), "head node")
        self._spawn(
            [sys.executable, "-c", _WORKER_NODE, "start", f"--address={self.address}", *self._node_args()], "worker.log"
        )
        self._wait(lambda: self.alive_nodes() >= 2, "worker node")
        return self

    def _status_ok(self) -> bool:
        cmd = [str(Path(sys.executable).with_name("ray")), "status", f"--address={self.address}"]
        return subprocess.run(cmd, capture_output=True, env=self.env).returncode == 0

    def alive_nodes(self) -> int:
        cmd = [str(Path(sys.executable).with_name("ray")), "status", f"--address={self.address}"]
        out = subprocess.run(cmd, capture_output=True, text=True, env=self.env).stdout
        active = out.split("Active:")[-1].split("Pending:")[0] if "Active:" in out else ""
        return sum("node_" in line for line in active.splitlines())

    def _wait(self, ready, what: str, timeout_s: float = 240.0) -> None:
        start = time.time()
        while time.time() - start < timeout_s:
            if any(p.poll() is not None for p in self.procs):
                raise RuntimeError(f"{what} exited; see {self.folder}")
            if ready():
                return
            time.sleep(1.0)
        raise TimeoutError(f"{what} not up after {timeout_s:.0f} s; see {self.folder}")

    def processes(self) -> list[psutil.Process]:
        """Every process of this cluster (the two ``ray start`` processes and their descendants)."""
        out = []
        for p in self.procs:
            try:
                root = psutil.Process(p.pid)
                out += [root, *root.children(recursive=True)]
            except psutil.NoSuchProcess:
                continue
        return out

    def listening(self) -> set[tuple[str, int]]:
        """(address, port) of every listening TCP socket of this cluster's processes."""
        pids = {p.pid for p in self.processes()}
        return {
            (c.laddr.ip, c.laddr.port) for c in psutil.net_connections("inet") if c.status == "LISTEN" and c.pid in pids
        }

    def __exit__(self, *exc) -> None:
        """SIGTERM to each ``ray start --block`` process group (it stops its node), then SIGKILL what is left."""
        survivors = self.processes()
        for p in reversed(self.procs):
            try:
                os.killpg(p.pid, signal.SIGTERM)
            except ProcessLookupError:
                pass
        for p in self.procs:
            try:
                p.wait(60)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
        _, alive = psutil.wait_procs(survivors, timeout=30)
        for p in alive:
            p.kill()
        shutil.rmtree(self.temp_dir, ignore_errors=True)
