"""Token order within a latent frame: raster (row-major) or block order.

Block order visits block_size x block_size blocks row-major and the tokens of each block row-major, so a
block's tokens are neighbours in the sequence (as in MaskGIT-style and VAR-style block scans). Either
order keeps every token's (frame, row, column) position; 3D RoPE and the camera rays follow the
position, not the sequence index.
"""

from __future__ import annotations

import torch
from einops import rearrange

from drivewm.ar.config import ARConfig


def frame_permutation(cfg: ARConfig) -> torch.Tensor:
    """(h*w,) long: the raster index of the token at each sequence index of one frame."""
    h, w = cfg.grid_hw
    raster = torch.arange(h * w).view(h, w)
    if cfg.order == "raster":
        return raster.flatten()
    b = cfg.block_size
    return rearrange(raster, "(hb b1) (wb b2) -> (hb wb b1 b2)", b1=b, b2=b)


def sequence_grid(cfg: ARConfig, num_frames: int) -> torch.Tensor:
    """(num_frames*h*w, 3) long (frame, row, column) of each sequence index."""
    h, w = cfg.grid_hw
    raster = frame_permutation(cfg)
    rows, cols = raster // w, raster % w
    frames = torch.arange(num_frames).repeat_interleave(h * w)
    return torch.stack([frames, rows.repeat(num_frames), cols.repeat(num_frames)], dim=1)


def to_sequence(indices: torch.Tensor, cfg: ARConfig) -> torch.Tensor:
    """Token grids (..., t, h, w) -> sequences (..., t*h*w) in the config's order."""
    flat = indices.flatten(-2)  # (..., t, h*w) raster
    return flat[..., frame_permutation(cfg).to(flat.device)].flatten(-2)


def from_sequence(sequence: torch.Tensor, cfg: ARConfig) -> torch.Tensor:
    """Sequences (..., t*h*w) -> token grids (..., t, h, w); the inverse of :func:`to_sequence`."""
    h, w = cfg.grid_hw
    frames = sequence.unflatten(-1, (-1, h * w))  # (..., t, h*w) in sequence order
    inverse = torch.argsort(frame_permutation(cfg)).to(sequence.device)
    return frames[..., inverse].unflatten(-1, (h, w))
