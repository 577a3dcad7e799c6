"""parallelize(): activation checkpointing really recomputes blocks, and parameter names stay put."""

from __future__ import annotations

import torch

from drivewm.diffusion.dit import DiT
from drivewm.diffusion.dit_config import DiTConfig
from drivewm.train.distributed import DistInfo
from drivewm.train.parallelize import parallelize


def _forward_backward_calls(activation_checkpointing: bool) -> tuple[int, list[str]]:
    torch.manual_seed(0)
    model = DiT(DiTConfig(in_channels=4, hidden_dim=32, depth=2, num_heads=2, text_dim=8, adaln_lora_dim=4))
    names = [n for n, _ in model.named_parameters()]
    calls = []
    for block in model.blocks:
        block.layers["mlp"].layer.register_forward_hook(lambda *_: calls.append(1))
    forward = parallelize(
        model, list(model.blocks), DistInfo(), activation_checkpointing, compile=False, parallel="auto"
    )
    out = forward(
        torch.randn(1, 4, 2, 4, 4),
        torch.zeros(1),
        torch.randn(1, 3, 8),
        torch.ones(1, 3, dtype=torch.bool),
        torch.tensor([10.0]),
    )
    out.square().mean().backward()
    assert [n for n, _ in model.named_parameters()] == names
    return len(calls), names


def test_activation_checkpointing_recomputes_each_block_once_and_keeps_names():
    plain, names = _forward_backward_calls(False)
    checkpointed, names_ac = _forward_backward_calls(True)
    assert plain == 2 and checkpointed == 4 and names == names_ac
