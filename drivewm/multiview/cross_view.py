"""Attention across the camera views of a rig, as one more DiT sub-layer (``cross_view_attn``).

The views of a clip share the backbone and are folded into the batch as (B V); the in-view
self-attention of the pretrained DiT stays as it is. This sub-layer lets every token of view i
attend to all tokens (every latent frame) of the views ``view_neighbors[i]``: all views
("joint", as Cosmos' multi-view model's joint attention) or view i and its nearest cameras by
viewing direction ("neighbors", cost grows with V * K instead of V^2). Its output projection
starts at zero (drivewm.diffusion.blocks), so inserting it leaves the pretrained model unchanged.
The multi-view network registers it under ``cross_view_attn`` where it builds its DiT
(drivewm.multiview.model.MultiViewNet).
"""

from __future__ import annotations

import numpy as np
import torch
from einops import rearrange

from drivewm.diffusion.blocks import BlockContext, SelfAttention, attend
from drivewm.geometry import Rig
from drivewm.views.grid import viewing_azimuth_rad

SUBLAYER_NAME = "cross_view_attn"


class CrossViewAttention(SelfAttention):
    """Tokens (B V, N, D) of each view attend to the tokens of its neighbour views (QK-norm, 3D RoPE).
    The same projections as in-view self-attention (own weights, zero output projection)."""

    def forward(self, x: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        # Same RoPE angles in every view: a token's (time, row, column) relation holds across views,
        # and where the views differ is told by the camera (Plucker) conditioning.
        q, k, val = self.heads(x, ctx)  # (B V, N, heads, hd)
        neighbors = ctx.view_neighbors if ctx.view_neighbors is not None else all_views(ctx.num_views, x.device)
        k, val = (gather_views(t, neighbors) for t in (k, val))  # (B V, K N, heads, hd)
        return self.out(attend(q, k, val))  # (B V, N, D)


def gather_views(t: torch.Tensor, neighbors: torch.Tensor) -> torch.Tensor:
    """(B V, N, heads, d) per view -> (B V, K N, heads, d): for view i, the tokens of views ``neighbors[i]``."""
    num_views = neighbors.shape[0]
    per_clip = rearrange(t, "(b v) n h d -> b v n h d", v=num_views)
    picked = per_clip[:, neighbors.to(t.device)]  # (B, V, K, N, heads, d)
    return rearrange(picked, "b v k n h d -> (b v) (k n) h d")


def all_views(num_views: int, device: torch.device | str = "cpu") -> torch.Tensor:
    """(V, V) long: every view reads every view ("joint")."""
    return torch.arange(num_views, device=device).expand(num_views, num_views).contiguous()


def view_neighbors(rig: Rig, mode: str, neighbors: int) -> torch.Tensor:
    """(V, K) long indices of the views each view attends to, itself first.

    ``joint``: all V views. ``neighbors``: itself and the ``neighbors`` cameras whose optical axes
    are nearest in azimuth (from the rig's extrinsics, so any rig, order or camera count works).
    """
    v = len(rig.cameras)
    if mode == "joint" or neighbors + 1 >= v:
        return all_views(v)
    az = viewing_azimuth_rad(rig)
    gap = np.abs(np.angle(np.exp(1j * (az[:, None] - az[None, :]))))  # (V, V) wrapped angle difference
    order = np.argsort(gap + np.eye(v) * -1.0, axis=1, kind="stable")  # itself (gap -1) first
    return torch.from_numpy(order[:, : neighbors + 1].copy()).long()
