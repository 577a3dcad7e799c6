"""The KV cache of incremental decoding: per block the keys and values of every position run so far.

With it a new token costs one query against the stored keys instead of a forward pass over the whole
sequence (the standard transformer decoding cache, e.g. Pope et al. 2022, "Efficiently Scaling
Transformer Inference", sec. 2). Storage is preallocated for the model's context so a step writes in
place.
"""

from __future__ import annotations

import torch


class KVCache:
    """Keys and values (B, heads, capacity, head_dim) per block, the first :attr:`length` filled, and
    which key positions may be attended (``key_mask`` (B, capacity) bool: padded caption tokens not)."""

    def __init__(self, depth: int, batch: int, heads: int, capacity: int, head_dim: int, like: torch.Tensor):
        shape = (batch, heads, capacity, head_dim)
        self.keys = [like.new_zeros(shape) for _ in range(depth)]
        self.values = [like.new_zeros(shape) for _ in range(depth)]
        self.key_mask = torch.zeros(batch, capacity, dtype=torch.bool, device=like.device)
        self.length = 0
        """Positions stored (caption prefix included)."""
        self.video_length = 0
        """Video positions stored (the next video position to run)."""

    def extend(self, layer: int, k: torch.Tensor, v: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Store ``k``, ``v`` (B, heads, n, head_dim) after the stored ones; returns all of them."""
        n = k.shape[2]
        self.keys[layer][:, :, self.length : self.length + n] = k
        self.values[layer][:, :, self.length : self.length + n] = v
        end = self.length + n
        return self.keys[layer][:, :, :end], self.values[layer][:, :, :end]

    def advance(self, key_mask: torch.Tensor, video: int) -> None:
        """After every block ran: ``key_mask`` (B, n) of the new positions, ``video`` of them video tokens."""
        n = key_mask.shape[1]
        self.key_mask[:, self.length : self.length + n] = key_mask
        self.length += n
        self.video_length += video
