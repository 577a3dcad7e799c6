"""3D rotary position embeddings over (latent frame, row, column) tokens.

RoPE (Su et al. 2021, "RoFormer", eq. 34) rotates pairs of query/key channels by an angle
proportional to the token's position. In 3D (as in Cosmos, arXiv 2501.03575 sec. 5.1) the head
dimension is split into a temporal, a vertical and a horizontal part, each rotated by its own
coordinate. The temporal coordinate is *time*, not frame index: latent frame ``i`` of a clip at
``fps`` sits at ``i * base_fps / fps``, so clips recorded at other rates share positions.

Channel pair (2j, 2j+1) is read as the complex number x_2j + i x_2j+1 and multiplied by
e^(i angle_j) (RoFormer eq. 34 written in complex form, as LLaMA does): one fused multiply instead of
slicing, stacking and re-interleaving the channels, and the rotations are computed once per token
grid (drivewm.diffusion.dit caches them).
"""

from __future__ import annotations

import torch


def split_head_dim(head_dim: int) -> tuple[int, int, int]:
    """Channels given to (t, h, w): h and w get ``head_dim // 6 * 2`` each, t the rest (all even)."""
    if head_dim % 2:
        raise ValueError(f"RoPE needs an even head dimension, got {head_dim}")
    dim_hw = head_dim // 6 * 2
    return head_dim - 2 * dim_hw, dim_hw, dim_hw


def grid_positions(
    t: int, h: int, w: int, fps: torch.Tensor, base_fps: float, spatial_scale: float = 1.0
) -> torch.Tensor:
    """Token positions (B, t*h*w, 3) as (time, row, column), row-major over (t, h, w).

    ``fps`` (B,) is the clip's video frame rate; the time coordinate is scaled by ``base_fps / fps``,
    row and column by ``spatial_scale``.
    """
    tt, hh, ww = torch.meshgrid(torch.arange(t), torch.arange(h), torch.arange(w), indexing="ij")
    pos = torch.stack([tt, hh, ww], dim=-1).reshape(1, -1, 3).to(torch.float32)  # (1, N, 3)
    scale = torch.full((fps.shape[0], 1, 3), float(spatial_scale), dtype=torch.float32, device=fps.device)
    scale[:, 0, 0] = base_fps / fps.to(torch.float32)
    return pos.to(fps.device) * scale  # (B, N, 3)


def rope_angles(pos: torch.Tensor, head_dim: int, theta: float = 10000.0) -> torch.Tensor:
    """Rotation angles (B, N, head_dim // 2) for positions ``pos`` (B, N, 3)."""
    angles = []
    for axis, dim in enumerate(split_head_dim(head_dim)):
        freqs = theta ** (-torch.arange(0, dim, 2, dtype=torch.float32, device=pos.device) / dim)  # (dim/2,)
        angles.append(pos[..., axis : axis + 1] * freqs)  # (B, N, dim/2)
    return torch.cat(angles, dim=-1)


def rope_rotation(angles: torch.Tensor) -> torch.Tensor:
    """Unit complex rotations e^(i angle), complex64 of the shape of ``angles`` (..., head_dim // 2)."""
    return torch.polar(torch.ones_like(angles), angles)


def rotate(x: torch.Tensor, rotation: torch.Tensor) -> torch.Tensor:
    """RoPE: channel pairs of ``x`` (..., head_dim) times ``rotation`` (complex, broadcastable to
    (..., head_dim // 2)); computed in float32 (complex bf16 does not exist), returned in x's dtype."""
    pairs = torch.view_as_complex(x.float().unflatten(-1, (-1, 2)).contiguous())  # (..., head_dim/2)
    return torch.view_as_real(pairs * rotation).flatten(-2).to(x.dtype)
