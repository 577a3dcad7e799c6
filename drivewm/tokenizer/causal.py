"""Causal temporal processing state: what lets a long video be encoded chunk by chunk.

Every causal temporal layer left-pads its input with the previous ``kernel - 1`` frames. In one
pass those are copies of frame 0; when a video is processed in chunks, the layer keeps the last
frames of the chunk it saw in a :class:`CausalContext` and uses them as the next chunk's left
context, so chunked output equals one-pass output (the "feature cache" of causal video VAEs).
"""

from __future__ import annotations

import dataclasses

import torch


@dataclasses.dataclass
class CausalContext:
    """Streaming state shared by all causal layers of one encode or decode pass.

    ``first_chunk``: the chunk starts at frame 0 (frame 0 is coded alone, pads replicate it).
    ``cache``: per layer (keyed by ``id(layer)``), the trailing input frames kept for the next chunk.
    """

    first_chunk: bool = True
    cache: dict[int, torch.Tensor] = dataclasses.field(default_factory=dict)

    def next_chunk(self) -> None:
        """Call between chunks: later chunks continue the sequence instead of starting it."""
        self.first_chunk = False


def is_first(ctx: CausalContext | None) -> bool:
    return ctx is None or ctx.first_chunk


def causal_left_context(layer: object, x: torch.Tensor, frames: int, ctx: CausalContext | None) -> torch.Tensor:
    """Prepend ``frames`` frames of left context to ``x`` (B, C, T, H, W) and remember the new tail."""
    if frames == 0:
        return x
    if is_first(ctx):
        left = x[:, :, :1].expand(-1, -1, frames, -1, -1)  # replicate frame 0: nothing before the video
    else:
        left = ctx.cache[id(layer)]
    padded = torch.cat([left, x], dim=2)
    if ctx is not None:
        ctx.cache[id(layer)] = padded[:, :, -frames:].detach()
    return padded
