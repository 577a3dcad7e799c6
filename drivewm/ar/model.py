"""The causal transformer over FSQ token sequences (a GPT, Radford et al. 2019, over video tokens).

A sequence is one camera view: the caption's tokens as a prefix (a learned null token first, always
visible), then the view's latent frames one after another, each frame's tokens in the config's order
(drivewm.ar.order). The input at video position p is the token at p - 1 (a start token at p = 0) plus
what is known of position p before its token is: the camera ray through its patch (Plucker
coordinates, drivewm.multiview.camera), the ego pose of its latent frame, and optionally the layout
video's token there. Attention is causal, with 3D RoPE (drivewm.diffusion.rope) at the position
being predicted and QK-norm. The logits at p give the distribution of the token at p.

``forward`` runs a whole sequence, or with a :class:`~drivewm.ar.kv_cache.KVCache` the next positions
of a partly run one: the two give the same logits up to rounding, which is what exact incremental
decoding rests on (drivewm.ar.sampling).
"""

from __future__ import annotations

import dataclasses

import torch
import torch.nn.functional as F
from torch import nn

from drivewm.ar.config import ARConfig
from drivewm.ar.kv_cache import KVCache
from drivewm.ar.order import sequence_grid
from drivewm.diffusion.rope import rope_angles, rope_rotation, rotate
from drivewm.multiview.camera import CameraEncoder

#: Ego features are x and y in units of this many metres (and yaw in radians): O(1) over a clip.
EGO_SCALE_M = 10.0


@dataclasses.dataclass
class ARCondition:
    """What a batch of sequences is conditioned on."""

    text: torch.Tensor
    """(B, L, text_dim) caption embeddings of the text encoder."""
    text_mask: torch.Tensor
    """(B, L) bool, True for real caption tokens."""
    rays: torch.Tensor
    """(B, h*w, 6) Plucker rays (ego frame, metres) of each view's token grid, row-major."""
    ego: torch.Tensor
    """(B, t, 3) per latent frame (x, y in metres, yaw in radians) in the first frame's ego frame."""
    fps: torch.Tensor
    """(B,) video frame rate (scales the temporal RoPE position)."""
    layout: torch.Tensor | None = None
    """(B, t*h*w) long layout tokens in sequence order, or None."""

    def to(self, device: torch.device | str) -> ARCondition:
        moved = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        return ARCondition(**{k: v.to(device) if v is not None else None for k, v in moved.items()})


class Block(nn.Module):
    """Pre-norm causal self-attention (QK-norm, RoPE) then an MLP."""

    def __init__(self, cfg: ARConfig):
        super().__init__()
        self.heads = cfg.num_heads
        self.norm1 = nn.LayerNorm(cfg.hidden_dim)
        self.qkv = nn.Linear(cfg.hidden_dim, 3 * cfg.hidden_dim)
        self.q_norm = nn.RMSNorm(cfg.head_dim)
        self.k_norm = nn.RMSNorm(cfg.head_dim)
        self.proj = nn.Linear(cfg.hidden_dim, cfg.hidden_dim)
        self.norm2 = nn.LayerNorm(cfg.hidden_dim)
        width = int(cfg.hidden_dim * cfg.mlp_ratio)
        self.mlp = nn.Sequential(nn.Linear(cfg.hidden_dim, width), nn.GELU(), nn.Linear(width, cfg.hidden_dim))

    def forward(
        self, x: torch.Tensor, rope: torch.Tensor, mask: torch.Tensor, cache: KVCache | None, layer: int
    ) -> torch.Tensor:
        q, k, v = self.qkv(self.norm1(x)).unflatten(-1, (3, self.heads, -1)).unbind(2)  # (B, n, H, hd) each
        q, k = rotate(self.q_norm(q), rope), rotate(self.k_norm(k), rope)
        q, k, v = (t.transpose(1, 2) for t in (q, k, v))  # (B, H, n, hd)
        if cache is not None:
            k, v = cache.extend(layer, k, v)  # (B, H, n_keys, hd)
        out = F.scaled_dot_product_attention(q, k, v, attn_mask=mask)  # (B, H, n, hd)
        x = x + self.proj(out.transpose(1, 2).flatten(2))  # (B, n, D)
        return x + self.mlp(self.norm2(x))


class ARTransformer(nn.Module):
    """``forward(inputs, cond, cache=None) -> logits (B, n, vocab_size)``; see the module docstring."""

    def __init__(self, cfg: ARConfig):
        super().__init__()
        cfg.validate()
        self.cfg = cfg
        self.start_token = cfg.vocab_size  # the input at video position 0
        self.token_embed = nn.Embedding(cfg.vocab_size + 1, cfg.hidden_dim)
        self.layout_embed = nn.Embedding(cfg.vocab_size, cfg.hidden_dim) if cfg.layout else None
        self.ray_embed = CameraEncoder(cfg.hidden_dim)
        self.ego_embed = nn.Linear(cfg.ego_features, cfg.hidden_dim)
        self.text_proj = nn.Linear(cfg.text_dim, cfg.hidden_dim)
        self.null_text = nn.Parameter(torch.zeros(1, 1, cfg.hidden_dim))
        self.blocks = nn.ModuleList(Block(cfg) for _ in range(cfg.depth))
        self.norm = nn.LayerNorm(cfg.hidden_dim)
        self.head = nn.Linear(cfg.hidden_dim, cfg.vocab_size)
        self.register_buffer("grid", sequence_grid(cfg, cfg.max_frames), persistent=False)  # (N_ctx, 3)

    def inputs_of(self, tokens: torch.Tensor) -> torch.Tensor:
        """Tokens (B, n) -> the inputs (B, n) that predict them: the start token, then tokens[:-1]."""
        start = torch.full_like(tokens[:, :1], self.start_token)
        return torch.cat([start, tokens[:, :-1]], dim=1)

    def new_cache(self, batch: int, caption_tokens: int, like: torch.Tensor) -> KVCache:
        """An empty cache for ``batch`` sequences with a caption of ``caption_tokens`` embeddings."""
        cfg = self.cfg
        capacity = 1 + caption_tokens + cfg.context_tokens
        return KVCache(cfg.depth, batch, cfg.num_heads, capacity, cfg.head_dim, like)

    def forward(self, inputs: torch.Tensor, cond: ARCondition, cache: KVCache | None = None) -> torch.Tensor:
        """Logits (B, n, vocab) of video positions start .. start+n-1 from ``inputs`` (B, n) at those
        positions (start = the cache's video length, 0 without a cache). An empty or absent cache runs the
        caption prefix first."""
        start = cache.video_length if cache is not None else 0
        n = inputs.shape[1]
        if start + n > self.cfg.context_tokens:
            raise ValueError(f"positions up to {start + n} exceed the context of {self.cfg.context_tokens} tokens")
        x = self.embed_video(inputs, cond, start)  # (B, n, D)
        rope = self.rope(cond.fps, start, n)  # (B, n, 1, hd/2)
        key_mask = torch.ones(x.shape[:2], dtype=torch.bool, device=x.device)
        if cache is None or cache.length == 0:
            prefix, prefix_mask = self.embed_text(cond)  # (B, 1+L, D), (B, 1+L)
            x, key_mask = torch.cat([prefix, x], dim=1), torch.cat([prefix_mask, key_mask], dim=1)
            rope = torch.cat([torch.ones_like(rope[:, :1]).expand(-1, prefix.shape[1], -1, -1), rope], dim=1)
        mask = self.attention_mask(key_mask, cache)  # (B, 1, n_q, n_keys)
        for layer, block in enumerate(self.blocks):
            x = block(x, rope, mask, cache, layer)
        if cache is not None:
            cache.advance(key_mask, n)
        return self.head(self.norm(x[:, -n:]))  # (B, n, vocab)

    def embed_video(self, inputs: torch.Tensor, cond: ARCondition, start: int) -> torch.Tensor:
        """Input embeddings (B, n, D) of video positions start .. start+n-1."""
        frame, row, col = self.grid[start : start + inputs.shape[1]].unbind(1)  # (n,) each
        x = self.token_embed(inputs)  # (B, n, D)
        x = x + self.ray_embed(cond.rays[:, row * self.cfg.grid_hw[1] + col])  # rays of the position's patch
        x = x + self.ego_embed(cond.ego[:, frame] / ego_scale(cond.ego))
        if self.layout_embed is not None:
            x = x + self.layout_embed(cond.layout[:, start : start + inputs.shape[1]])
        return x

    def embed_text(self, cond: ARCondition) -> tuple[torch.Tensor, torch.Tensor]:
        """Caption prefix (B, 1+L, D) with the null token first, and its key mask (B, 1+L)."""
        b = cond.text.shape[0]
        tokens = torch.cat([self.null_text.expand(b, -1, -1), self.text_proj(cond.text)], dim=1)
        always = torch.ones(b, 1, dtype=torch.bool, device=cond.text_mask.device)
        return tokens, torch.cat([always, cond.text_mask.bool()], dim=1)

    def rope(self, fps: torch.Tensor, start: int, n: int) -> torch.Tensor:
        """3D RoPE rotations (B, n, 1, hd/2) of video positions start .. start+n-1; time in latent frames at
        ``rope_base_fps``, scaled by base_fps / fps (drivewm.diffusion.rope)."""
        pos = self.grid[start : start + n].to(torch.float32).unsqueeze(0).repeat(fps.shape[0], 1, 1)  # (B, n, 3)
        pos[..., 0] *= self.cfg.rope_base_fps / fps.to(torch.float32)[:, None]
        return rope_rotation(rope_angles(pos, self.cfg.head_dim, self.cfg.rope_theta)).unsqueeze(2)

    @staticmethod
    def attention_mask(new_keys: torch.Tensor, cache: KVCache | None) -> torch.Tensor:
        """(B, 1, n, n_keys) bool: a query sees the attendable keys up to and including its own position."""
        past = cache.key_mask[:, : cache.length] if cache is not None else new_keys[:, :0]
        keys = torch.cat([past, new_keys], dim=1)  # (B, n_keys)
        n, n_keys = new_keys.shape[1], keys.shape[1]
        query_at = torch.arange(n_keys - n, n_keys, device=keys.device)
        causal = torch.arange(n_keys, device=keys.device)[None, :] <= query_at[:, None]  # (n, n_keys)
        return (keys[:, None, :] & causal[None]).unsqueeze(1)


def ego_scale(ego: torch.Tensor) -> torch.Tensor:
    """(3,) divisors of the ego features: metres for x and y, radians for yaw."""
    return torch.tensor([EGO_SCALE_M, EGO_SCALE_M, 1.0], dtype=ego.dtype, device=ego.device)
