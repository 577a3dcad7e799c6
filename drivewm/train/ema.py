"""Exponential moving average of model weights (the weights a model folder ships)."""

from __future__ import annotations

import torch
from torch import nn


class EMA:
    """Shadow copies of the trainable parameters, updated as ``ema <- d * ema + (1 - d) * p``.

    The decay ramps up as ``min(decay, (1 + step) / (10 + step))`` so early averages are not
    dominated by the random initialisation. Works on plain and on FSDP2-sharded parameters.
    """

    def __init__(self, model: nn.Module, decay: float):
        self.decay = decay  # target decay d
        self.shadow = {name: p.detach().clone() for name, p in model.named_parameters() if p.requires_grad}

    @torch.no_grad()
    def update(self, model: nn.Module, step: int) -> None:
        decay = min(self.decay, (1 + step) / (10 + step))
        for name, p in model.named_parameters():
            if name in self.shadow:
                self.shadow[name].lerp_(p.detach(), 1 - decay)

    def state_dict(self) -> dict[str, torch.Tensor]:
        """Full (gathered) CPU tensors by parameter name."""
        return {k: _full(v).cpu() for k, v in self.shadow.items()}

    @torch.no_grad()
    def load_state_dict(self, state: dict[str, torch.Tensor]) -> None:
        for name, value in state.items():
            target = self.shadow[name]
            if hasattr(target, "device_mesh"):  # an FSDP2 DTensor: keep this rank's shard
                from torch.distributed.tensor import distribute_tensor

                value = distribute_tensor(value.to(target.device), target.device_mesh, target.placements)
            target.copy_(value)


def _full(t: torch.Tensor) -> torch.Tensor:
    return t.full_tensor() if hasattr(t, "full_tensor") else t
