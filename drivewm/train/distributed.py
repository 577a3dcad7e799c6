"""Process-group setup for ``torchrun`` (gloo on the CPU, NCCL on GPUs); single process otherwise."""

from __future__ import annotations

import dataclasses
import logging
import os
import sys

import torch
import torch.distributed as dist


@dataclasses.dataclass
class DistInfo:
    """Where this process sits: ``rank`` of ``world_size``, and the device it trains on."""

    rank: int = 0
    world_size: int = 1
    local_rank: int = 0
    device: torch.device = dataclasses.field(default_factory=lambda: torch.device("cpu"))

    @property
    def is_main(self) -> bool:
        return self.rank == 0

    @property
    def distributed(self) -> bool:
        return self.world_size > 1


def init_distributed(device: str = "auto") -> DistInfo:
    """Join the ``torchrun`` process group if the launcher's environment says so (WORLD_SIZE > 1).

    ``device``: ``auto`` (CUDA when available), ``cpu`` or ``cuda``.
    """
    use_cuda = torch.cuda.is_available() if device == "auto" else device == "cuda"
    world_size = int(os.environ.get("WORLD_SIZE", "1"))
    rank, local_rank = int(os.environ.get("RANK", "0")), int(os.environ.get("LOCAL_RANK", "0"))
    dev = torch.device("cuda", local_rank) if use_cuda else torch.device("cpu")
    if use_cuda:
        torch.cuda.set_device(dev)
    if world_size > 1 and not dist.is_initialized():
        dist.init_process_group(backend="nccl" if use_cuda else "gloo")
    return DistInfo(rank, world_size, local_rank, dev)


#: Whether this process left a ``torchrun`` process group (``drivewm.cli.main`` then exits without
#: interpreter finalisation: :func:`exit_worker`).
_left_group = False


def shutdown_distributed() -> None:
    """Leave the process group together: every rank first waits for the others (rank 0 may still be
    drawing the sample grid)."""
    global _left_group
    if dist.is_initialized():
        dist.barrier()
        dist.destroy_process_group()
        _left_group = True


def exit_worker(code: int) -> None:
    """End a ``torchrun`` worker that has finished its command, skipping interpreter finalisation.

    ``destroy_process_group`` does not free gloo's process group while DTensor's caches still hold
    the FSDP2 device mesh, so its threads (``gloo_tcp_loop``, ``pt_gloo_runloop``) outlive it, and
    tearing them down during finalisation aborted rank 1 after its work was written ("terminate
    called without an active exception"; 1 in 25 FSDP2 runs on a loaded 2-core machine, and twice
    in CI). Everything the command writes is closed by then, so the worker flushes its streams and
    leaves with ``os._exit``. A no-op in a process that never joined a group."""
    if not _left_group:
        return
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed or vanished reader: nothing more to hand it
            pass
    os._exit(code)


def barrier(info: DistInfo) -> None:
    if info.distributed:
        dist.barrier()
