"""The one place where parallelism and memory/speed options are applied to a model (torchtitan style).

Order: activation checkpointing per block, then ``torch.compile`` per block, then DDP or FSDP2
``fully_shard`` (per block, then the root). All three keep parameter names unchanged (composable
APIs), so checkpoints of a parallel run load into the plain single-device model.
"""

from __future__ import annotations

from torch import nn

from drivewm.train.config import Parallel
from drivewm.train.distributed import DistInfo


def apply_activation_checkpointing(blocks: list[nn.Module]) -> None:
    """Recompute each block's activations in the backward pass (less memory, ~1/3 more compute)."""
    from torch.distributed._composable import checkpoint

    for block in blocks:
        checkpoint(block)


def apply_compile(blocks: list[nn.Module]) -> None:
    """Compile every block on its own (repeated blocks share one compiled graph)."""
    for block in blocks:
        block.compile()


def apply_fsdp(model: nn.Module, blocks: list[nn.Module]) -> nn.Module:
    """FSDP2: shard each block's parameters over the ranks, then the remaining root parameters."""
    from torch.distributed.fsdp import fully_shard

    for block in blocks:
        fully_shard(block)
    fully_shard(model)
    return model


def parallelize(
    model: nn.Module,
    blocks: list[nn.Module],
    info: DistInfo,
    activation_checkpointing: bool,
    compile: bool,
    parallel: Parallel,
) -> nn.Module:
    """Apply the options to ``model`` (whose repeated ``blocks`` are given); returns the module to
    call in training (the DDP wrapper under DDP, ``model`` itself otherwise). ``auto`` = DDP."""
    if activation_checkpointing:
        apply_activation_checkpointing(blocks)
    if compile:
        apply_compile(blocks)
    if not info.distributed:
        return model
    if parallel == "fsdp":
        return apply_fsdp(model, blocks)
    from torch.nn.parallel import DistributedDataParallel

    device_ids = [info.device.index] if info.device.type == "cuda" else None
    return DistributedDataParallel(model, device_ids=device_ids)
