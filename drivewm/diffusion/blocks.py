"""DiT blocks: a list of AdaLN-modulated sub-layers (self-attention, cross-attention, MLP, ...).

Each sub-layer reads the tokens and a :class:`BlockContext`; a block is the ordered list named by
``DiTConfig.block_layers``, so a new kind of attention (e.g. across camera views) is one small
module registered with :func:`register_sublayer` plus a config entry, never a forked DiT.

Modulation is AdaLN-LoRA (Cosmos, arXiv 2501.03575 sec. 5.1): the timestep embedding gives a
shared ``adaln_lora`` (B, 3D) term and each sub-layer adds its own low-rank projection of the
embedding, producing (shift, scale, gate). Every sub-layer's output projection starts at zero, so
a freshly inserted sub-layer is the identity and the block starts as the network it extends.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable

import torch
import torch.nn.functional as F
from einops import rearrange
from torch import nn

from drivewm.diffusion.dit_config import DiTConfig
from drivewm.diffusion.rope import apply_rope
from drivewm.errors import DrivewmError


@dataclasses.dataclass
class BlockContext:
    """What sub-layers read besides the tokens (B, N, D)."""

    rope_angles: torch.Tensor
    """(B, N, head_dim // 2) 3D RoPE angles of the tokens."""
    text: torch.Tensor
    """(B, L, D) projected text tokens (a learned null token first)."""
    text_mask: torch.Tensor
    """(B, L) bool, True where a text token may be attended."""
    grid_thw: tuple[int, int, int]
    """Token grid (t, h, w) of one sample: N = t * h * w."""
    num_views: int = 1
    """Camera views folded into the batch as (B V): consecutive samples are one clip's views."""
    view_neighbors: torch.Tensor | None = None
    """(V, K) long: the views each view reads in cross-view sub-layers (itself included); None = all."""


def _zero(linear: nn.Linear) -> nn.Linear:
    nn.init.zeros_(linear.weight)
    if linear.bias is not None:
        nn.init.zeros_(linear.bias)
    return linear


class SelfAttention(nn.Module):
    """Full attention over the tokens of a sample with QK-norm (RMSNorm) and 3D RoPE."""

    def __init__(self, cfg: DiTConfig):
        super().__init__()
        self.num_heads = cfg.num_heads
        self.qkv = nn.Linear(cfg.hidden_dim, 3 * cfg.hidden_dim)
        self.q_norm = nn.RMSNorm(cfg.head_dim, eps=1e-6)
        self.k_norm = nn.RMSNorm(cfg.head_dim, eps=1e-6)
        self.out = _zero(nn.Linear(cfg.hidden_dim, cfg.hidden_dim))

    def forward(self, x: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        q, k, v = rearrange(self.qkv(x), "b n (three h d) -> three b h n d", three=3, h=self.num_heads)
        q = apply_rope(self.q_norm(q), ctx.rope_angles)  # (B, heads, N, head_dim)
        k = apply_rope(self.k_norm(k), ctx.rope_angles)
        out = F.scaled_dot_product_attention(q, k, v)  # (B, heads, N, head_dim)
        return self.out(rearrange(out, "b h n d -> b n (h d)"))


class CrossAttention(nn.Module):
    """Tokens attend to the text tokens (QK-norm, no RoPE), masked by ``ctx.text_mask``."""

    def __init__(self, cfg: DiTConfig):
        super().__init__()
        self.num_heads = cfg.num_heads
        self.q = nn.Linear(cfg.hidden_dim, cfg.hidden_dim)
        self.kv = nn.Linear(cfg.hidden_dim, 2 * cfg.hidden_dim)
        self.q_norm = nn.RMSNorm(cfg.head_dim, eps=1e-6)
        self.k_norm = nn.RMSNorm(cfg.head_dim, eps=1e-6)
        self.out = _zero(nn.Linear(cfg.hidden_dim, cfg.hidden_dim))

    def forward(self, x: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        q = self.q_norm(rearrange(self.q(x), "b n (h d) -> b h n d", h=self.num_heads))  # (B, heads, N, hd)
        k, v = rearrange(self.kv(ctx.text), "b l (two h d) -> two b h l d", two=2, h=self.num_heads)
        mask = rearrange(ctx.text_mask, "b l -> b 1 1 l")
        out = F.scaled_dot_product_attention(q, self.k_norm(k), v, attn_mask=mask)  # (B, heads, N, hd)
        return self.out(rearrange(out, "b h n d -> b n (h d)"))


class MLP(nn.Module):
    """Pointwise feed-forward: Linear -> GELU(tanh) -> Linear."""

    def __init__(self, cfg: DiTConfig):
        super().__init__()
        hidden = int(cfg.hidden_dim * cfg.mlp_ratio)
        self.fc1 = nn.Linear(cfg.hidden_dim, hidden)
        self.fc2 = _zero(nn.Linear(hidden, cfg.hidden_dim))

    def forward(self, x: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        return self.fc2(F.gelu(self.fc1(x), approximate="tanh"))


#: Sub-layer builders by the name used in ``DiTConfig.block_layers``.
SUBLAYERS: dict[str, Callable[[DiTConfig], nn.Module]] = {
    "self_attn": SelfAttention,
    "cross_attn": CrossAttention,
    "mlp": MLP,
}


def register_sublayer(name: str, builder: Callable[[DiTConfig], nn.Module]) -> None:
    """Make ``name`` usable in ``DiTConfig.block_layers``; ``builder(cfg)`` returns a module
    ``forward(x (B, N, D), ctx: BlockContext) -> (B, N, D)`` whose output starts at zero."""
    SUBLAYERS[name] = builder


class ModulatedSublayer(nn.Module):
    """``x + gate * layer(norm(x) * (1 + scale) + shift)`` with AdaLN-LoRA (shift, scale, gate)."""

    def __init__(self, name: str, cfg: DiTConfig):
        super().__init__()
        if name not in SUBLAYERS:
            raise DrivewmError(f"dit.block_layers: unknown layer {name!r}; registered: {sorted(SUBLAYERS)}")
        self.norm = nn.LayerNorm(cfg.hidden_dim, elementwise_affine=False, eps=1e-6)
        self.layer = SUBLAYERS[name](cfg)
        self.adaln = nn.Sequential(
            nn.SiLU(),
            nn.Linear(cfg.hidden_dim, cfg.adaln_lora_dim, bias=False),
            nn.Linear(cfg.adaln_lora_dim, 3 * cfg.hidden_dim, bias=False),
        )

    def forward(self, x: torch.Tensor, emb: torch.Tensor, adaln_lora: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        shift, scale, gate = (self.adaln(emb) + adaln_lora).unsqueeze(1).chunk(3, dim=-1)  # each (B, 1, D)
        return x + gate * self.layer(self.norm(x) * (1 + scale) + shift, ctx)


class DiTBlock(nn.Module):
    """The sub-layers named by ``cfg.block_layers``, applied in order."""

    def __init__(self, cfg: DiTConfig):
        super().__init__()
        self.layers = nn.ModuleDict({name: ModulatedSublayer(name, cfg) for name in cfg.block_layers})

    def forward(self, x: torch.Tensor, emb: torch.Tensor, adaln_lora: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        for layer in self.layers.values():
            x = layer(x, emb, adaln_lora, ctx)
        return x
