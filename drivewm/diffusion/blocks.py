"""DiT blocks: a list of AdaLN-modulated sub-layers (attention, MLP, ...).

Each sub-layer reads the tokens and a :class:`BlockContext`; a block is the ordered list named by
``DiTConfig.block_layers``, so a new kind of attention (e.g. across camera views) is one small
module registered with :func:`register_sublayer` plus a config entry, never a forked DiT.

Modulation is AdaLN-LoRA (Cosmos, arXiv 2501.03575 sec. 5.1): the timestep embedding gives a
shared ``adaln_lora`` (B, 3D) term and each sub-layer adds its own low-rank projection of the
embedding, producing (shift, scale, gate). Every sub-layer's output projection starts at zero, so
a freshly inserted sub-layer is the identity and the block starts as the network it extends.

Text enters either through ``joint_attn`` (the default: the video tokens' self-attention also reads
the caption tokens as extra keys and values, one softmax over both, as CogVideoX's full attention
over concatenated text and video, arXiv 2408.06072 sec. 2.2, and SD3's MM-DiT, arXiv 2403.03206
sec. 5.1) or through a separate ``cross_attn`` sub-layer after ``self_attn`` (PixArt / Cosmos; the
layout of model folders written before joint attention). Joint attention spares the cross-attention's
query and output projections (2 D^2 of 14 D^2 multiply-adds per token and block) and one modulated
sub-layer; see benchmarks/bench_dit.py.

Attention over time: a block of a DiT whose ``full_attn_every`` is above 1 may be frame-local: its
``self_attn`` or ``joint_attn`` attends within each latent frame (the frames folded into the batch,
no mask over a full-length sequence), with the same parameters as a full block.

Layouts: attention works on (B, N, heads, head_dim) views of the fused projections, so neither the
heads split nor their merge copies memory (SDPA returns (B, N, heads, head_dim) storage for inputs
laid out so).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable

import torch
import torch.nn.functional as F
from torch import nn

from drivewm.diffusion.dit_config import DiTConfig
from drivewm.diffusion.rope import rotate
from drivewm.errors import DrivewmError


@dataclasses.dataclass
class BlockContext:
    """What sub-layers read besides the tokens (B, N, D)."""

    rope: torch.Tensor
    """(B or 1, N, 1, head_dim // 2) complex64 3D RoPE rotations of the tokens (drivewm.diffusion.rope)."""
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

    @functools.cached_property
    def joint_mask(self) -> torch.Tensor:
        """(B, 1, 1, N + L) bool: every video token, then the caption tokens ``text_mask`` allows."""
        return self._joint_mask(self.grid_thw[0] * self.grid_thw[1] * self.grid_thw[2])

    @functools.cached_property
    def frame_joint_mask(self) -> torch.Tensor:
        """(B t, 1, 1, h w + L) bool: :attr:`joint_mask` of frame-local attention (frames folded into B)."""
        return self._joint_mask(self.grid_thw[1] * self.grid_thw[2]).repeat_interleave(self.grid_thw[0], dim=0)

    def _joint_mask(self, n: int) -> torch.Tensor:
        b = self.text_mask.shape[0]
        video = torch.ones(b, n, dtype=torch.bool, device=self.text_mask.device)
        return torch.cat([video, self.text_mask.bool()], dim=1)[:, None, None]


def _zero(linear: nn.Linear) -> nn.Linear:
    nn.init.zeros_(linear.weight)
    if linear.bias is not None:
        nn.init.zeros_(linear.bias)
    return linear


def split_heads(x: torch.Tensor, parts: int, num_heads: int) -> torch.Tensor:
    """A fused projection (B, N, parts * D) -> (B, N, parts, heads, head_dim), a view."""
    return x.unflatten(-1, (parts, num_heads, -1))


def attend(q: torch.Tensor, k: torch.Tensor, v: torch.Tensor, mask: torch.Tensor | None = None) -> torch.Tensor:
    """SDPA of q (B, N, heads, hd) over k, v (B, M, heads, hd) -> (B, N, heads * hd); ``mask`` (B, 1, 1|N, M)."""
    out = F.scaled_dot_product_attention(q.transpose(1, 2), k.transpose(1, 2), v.transpose(1, 2), attn_mask=mask)
    return out.transpose(1, 2).flatten(2)  # (B, N, heads * hd); no copy for (B, N, heads, hd) inputs


def frames_as_batch(x: torch.Tensor, t: int) -> torch.Tensor:
    """(B, t*hw, ...) tokens -> (B t, hw, ...): each latent frame a sample of its own (a view)."""
    return x.unflatten(1, (t, -1)).flatten(0, 1)


def batch_as_frames(x: torch.Tensor, t: int) -> torch.Tensor:
    """(B t, hw, ...) -> (B, t*hw, ...): the inverse of :func:`frames_as_batch`."""
    return x.unflatten(0, (-1, t)).flatten(1, 2)


def rms_norm_pair(x: torch.Tensor, first: nn.RMSNorm, second: nn.RMSNorm) -> torch.Tensor:
    """QK-norm of queries and keys in one pass: ``x`` (..., 2, heads, hd) -> RMSNorm with ``first``'s
    weight on index 0 and ``second``'s on index 1 of the pair axis."""
    weight = torch.stack([first.weight, second.weight])[:, None]  # (2, 1, hd)
    return F.rms_norm(x, x.shape[-1:], eps=first.eps) * weight


class SelfAttention(nn.Module):
    """Attention over the tokens of a sample with QK-norm (RMSNorm) and 3D RoPE: all of them, or with
    ``frame_local`` those of the query's own latent frame."""

    def __init__(self, cfg: DiTConfig, frame_local: bool = False):
        super().__init__()
        self.num_heads = cfg.num_heads
        self.frame_local = frame_local
        self.qkv = nn.Linear(cfg.hidden_dim, 3 * cfg.hidden_dim)
        self.q_norm = nn.RMSNorm(cfg.head_dim, eps=1e-6)
        self.k_norm = nn.RMSNorm(cfg.head_dim, eps=1e-6)
        self.out = _zero(nn.Linear(cfg.hidden_dim, cfg.hidden_dim))

    def heads(self, x: torch.Tensor, ctx: BlockContext) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Tokens (B, N, D) -> q, k, v (B, N, heads, hd): q and k normalised and rotated by the 3D RoPE."""
        d = x.shape[-1]
        qk, v = self.qkv(x).split([2 * d, d], dim=-1)  # (B, N, 2D), (B, N, D); backward: one concatenation
        qk = split_heads(qk, 2, self.num_heads)  # (B, N, 2, heads, hd)
        qk = rotate(rms_norm_pair(qk, self.q_norm, self.k_norm), ctx.rope.unsqueeze(2))
        q, k = qk.unbind(2)  # (B, N, heads, hd) each
        return q, k, v.unflatten(-1, (self.num_heads, -1))

    def frames(self, ctx: BlockContext) -> int:
        """Latent frames folded into the batch by this layer's attention: 1 when it is full."""
        return ctx.grid_thw[0] if self.frame_local else 1

    def forward(self, x: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        t = self.frames(ctx)
        q, k, v = (frames_as_batch(a, t) for a in self.heads(x, ctx))  # (B t, N / t, heads, hd) each
        return self.out(batch_as_frames(attend(q, k, v), t))  # (B, N, D)


class JointAttention(SelfAttention):
    """Self-attention whose keys and values are the video tokens' and the caption tokens' together
    (one softmax; caption keys QK-normed, no RoPE, masked by ``ctx.text_mask``)."""

    def __init__(self, cfg: DiTConfig, frame_local: bool = False):
        super().__init__(cfg, frame_local)
        self.text_kv = nn.Linear(cfg.hidden_dim, 2 * cfg.hidden_dim)
        self.text_k_norm = nn.RMSNorm(cfg.head_dim, eps=1e-6)

    def forward(self, x: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        t = self.frames(ctx)
        q, k, v = (frames_as_batch(a, t) for a in self.heads(x, ctx))  # (B t, n = N / t, heads, hd) each
        text_k, text_v = split_heads(self.text_kv(ctx.text), 2, self.num_heads).unbind(2)  # (B, L, heads, hd)
        text_k = self.text_k_norm(text_k)
        if t > 1:  # every frame reads the caption
            text_k, text_v = text_k.repeat_interleave(t, dim=0), text_v.repeat_interleave(t, dim=0)
        k = torch.cat([k, text_k], dim=1)  # (B t, n + L, heads, hd)
        v = torch.cat([v, text_v], dim=1)
        mask = ctx.frame_joint_mask if t > 1 else ctx.joint_mask
        return self.out(batch_as_frames(attend(q, k, v, mask), t))  # (B, N, D)


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
        q = self.q_norm(split_heads(self.q(x), 1, self.num_heads)[:, :, 0])  # (B, N, heads, hd)
        k, v = split_heads(self.kv(ctx.text), 2, self.num_heads).unbind(2)  # (B, L, heads, hd)
        return self.out(attend(q, self.k_norm(k), v, ctx.text_mask[:, None, None]))  # (B, N, D)


class MLP(nn.Module):
    """Pointwise feed-forward: Linear -> GELU (exact, or tanh-approximated) -> Linear."""

    def __init__(self, cfg: DiTConfig):
        super().__init__()
        self.approximate = "tanh" if cfg.mlp_activation == "gelu_tanh" else "none"
        hidden = int(cfg.hidden_dim * cfg.mlp_ratio)
        self.fc1 = nn.Linear(cfg.hidden_dim, hidden)
        self.fc2 = _zero(nn.Linear(hidden, cfg.hidden_dim))

    def forward(self, x: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        return self.fc2(F.gelu(self.fc1(x), approximate=self.approximate))


#: Sub-layer builders by the name used in ``DiTConfig.block_layers``.
SUBLAYERS: dict[str, Callable[[DiTConfig], nn.Module]] = {
    "joint_attn": JointAttention,
    "self_attn": SelfAttention,
    "cross_attn": CrossAttention,
    "mlp": MLP,
}


def register_sublayer(name: str, builder: Callable[[DiTConfig], nn.Module]) -> None:
    """Make ``name`` usable in ``DiTConfig.block_layers``; ``builder(cfg)`` returns a module
    ``forward(x (B, N, D), ctx: BlockContext) -> (B, N, D)`` whose output starts at zero."""
    SUBLAYERS[name] = builder


#: The sub-layers a frame-local block restricts to latent frames (their builders take ``frame_local``).
FRAME_LOCAL_SUBLAYERS = ("joint_attn", "self_attn")


class ModulatedSublayer(nn.Module):
    """``x + gate * layer(norm(x) * (1 + scale) + shift)`` with AdaLN-LoRA (shift, scale, gate)."""

    def __init__(self, name: str, cfg: DiTConfig, frame_local: bool = False):
        super().__init__()
        if name not in SUBLAYERS:
            raise DrivewmError(f"dit: unknown block layer {name!r} in block_layers; registered: {sorted(SUBLAYERS)}")
        self.norm = nn.LayerNorm(cfg.hidden_dim, elementwise_affine=False, eps=1e-6)
        local = frame_local and name in FRAME_LOCAL_SUBLAYERS
        self.layer = SUBLAYERS[name](cfg, frame_local=True) if local else SUBLAYERS[name](cfg)
        self.adaln = nn.Sequential(
            nn.SiLU(),
            nn.Linear(cfg.hidden_dim, cfg.adaln_lora_dim, bias=False),
            nn.Linear(cfg.adaln_lora_dim, 3 * cfg.hidden_dim, bias=False),
        )

    def forward(self, x: torch.Tensor, emb: torch.Tensor, adaln_lora: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        shift, scale, gate = (self.adaln(emb) + adaln_lora).unsqueeze(1).chunk(3, dim=-1)  # each (B, 1, D)
        h = torch.addcmul(shift, self.norm(x), 1 + scale)  # one pass instead of a multiply and an add
        return torch.addcmul(x, gate, self.layer(h, ctx))  # (B, N, D)


class DiTBlock(nn.Module):
    """The sub-layers named by ``cfg.block_layers``, applied in order; ``frame_local``: the block's
    self- or joint attention stays within latent frames."""

    def __init__(self, cfg: DiTConfig, frame_local: bool = False):
        super().__init__()
        self.layers = nn.ModuleDict({name: ModulatedSublayer(name, cfg, frame_local) for name in cfg.block_layers})

    def forward(self, x: torch.Tensor, emb: torch.Tensor, adaln_lora: torch.Tensor, ctx: BlockContext) -> torch.Tensor:
        for layer in self.layers.values():
            x = layer(x, emb, adaln_lora, ctx)
        return x
