"""The diffusion transformer (DiT, Peebles & Xie 2023) over (latent frame, row, column) patches.

Cosmos-style (arXiv 2501.03575 sec. 5.1): 3D RoPE with the temporal position scaled by fps,
AdaLN-LoRA timestep modulation, QK-norm, and per block self-attention -> cross-attention to the
text -> MLP (the list is configurable, see drivewm.diffusion.blocks). The DiT is the raw backbone
F of EDM; preconditioning lives in drivewm.diffusion.denoiser.
"""

from __future__ import annotations

import math

import torch
from einops import rearrange
from torch import nn

from drivewm.diffusion.blocks import BlockContext, DiTBlock
from drivewm.diffusion.dit_config import DiTConfig
from drivewm.diffusion.rope import grid_positions, rope_angles, rope_rotation

#: Token grids whose RoPE rotations a DiT keeps (one per latent shape and frame rate in use).
ROPE_CACHE_SIZE = 8


def patchify(x: torch.Tensor, p: int, pt: int) -> torch.Tensor:
    """Latents (B, C, T, H, W) -> patches (B, N, C*pt*p*p), N = (T/pt)*(H/p)*(W/p) row-major over (t, h, w)."""
    return rearrange(x, "b c (t pt) (h ph) (w pw) -> b (t h w) (c pt ph pw)", pt=pt, ph=p, pw=p)


def unpatchify(tokens: torch.Tensor, grid_thw: tuple[int, int, int], p: int, pt: int) -> torch.Tensor:
    """Patches (B, N, C*pt*p*p) -> latents (B, C, T, H, W); the inverse of :func:`patchify`."""
    t, h, w = grid_thw
    return rearrange(tokens, "b (t h w) (c pt ph pw) -> b c (t pt) (h ph) (w pw)", t=t, h=h, w=w, pt=pt, ph=p, pw=p)


class TimestepEmbedding(nn.Module):
    """Noise level -> embedding ``emb`` (B, D) and the shared AdaLN-LoRA term (B, 3D)."""

    def __init__(self, dim: int, freq_dim: int = 256):
        super().__init__()
        self.freq_dim = freq_dim
        self.mlp = nn.Sequential(nn.Linear(freq_dim, dim), nn.SiLU(), nn.Linear(dim, dim))
        self.lora = nn.Sequential(nn.SiLU(), nn.Linear(dim, 3 * dim, bias=False))

    def sinusoid(self, noise_level: torch.Tensor) -> torch.Tensor:
        """(B,) -> (B, freq_dim) sin/cos features (Vaswani et al. 2017) of EDM's c_noise."""
        half = self.freq_dim // 2
        freqs = torch.exp(-math.log(10000.0) * torch.arange(half, device=noise_level.device) / half)
        args = noise_level.float()[:, None] * 1000.0 * freqs[None]  # c_noise ~ ln(sigma)/4 is O(1): spread it
        return torch.cat([args.cos(), args.sin()], dim=-1)

    def forward(
        self, noise_level: torch.Tensor, extra_global_cond: torch.Tensor | None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        emb = self.mlp(self.sinusoid(noise_level))  # (B, D)
        if extra_global_cond is not None:
            emb = emb + extra_global_cond
        return emb, self.lora(emb)  # (B, D), (B, 3D)


class FinalLayer(nn.Module):
    """AdaLN (shift, scale) then a zero-initialised projection back to patch values."""

    def __init__(self, cfg: DiTConfig):
        super().__init__()
        self.norm = nn.LayerNorm(cfg.hidden_dim, elementwise_affine=False, eps=1e-6)
        self.adaln = nn.Sequential(nn.SiLU(), nn.Linear(cfg.hidden_dim, 2 * cfg.hidden_dim))
        self.proj = nn.Linear(cfg.hidden_dim, cfg.in_channels * cfg.patch_t * cfg.patch_size**2)
        nn.init.zeros_(self.proj.weight)
        nn.init.zeros_(self.proj.bias)

    def forward(self, x: torch.Tensor, emb: torch.Tensor) -> torch.Tensor:
        shift, scale = self.adaln(emb).unsqueeze(1).chunk(2, dim=-1)  # (B, 1, D) each
        return self.proj(torch.addcmul(shift, self.norm(x), 1 + scale))


class ControlBranch(nn.Module):
    """ControlNet branch of a DiT (Zhang et al. 2023; PixArt-delta, Chen et al. 2024, sec. 3): a copy of
    the first blocks runs on the patch tokens plus the control input, and each block's output reaches
    the main path through a zero-initialised projection, so a new branch changes nothing until trained."""

    def __init__(self, cfg: DiTConfig):
        super().__init__()
        self.blocks = nn.ModuleList(DiTBlock(cfg, cfg.frame_local(i)) for i in range(cfg.control_depth))
        self.outs = nn.ModuleList(nn.Linear(cfg.hidden_dim, cfg.hidden_dim) for _ in range(cfg.control_depth))
        for out in self.outs:
            nn.init.zeros_(out.weight)
            nn.init.zeros_(out.bias)

    def forward(
        self, tokens: torch.Tensor, control: torch.Tensor, emb: torch.Tensor, lora: torch.Tensor, ctx: BlockContext
    ) -> list[torch.Tensor]:
        """(B, N, D) tokens and control input -> one (B, N, D) residual per branch block."""
        h, residuals = tokens + control, []
        for block, out in zip(self.blocks, self.outs):
            h = block(h, emb, lora, ctx)  # (B, N, D)
            residuals.append(out(h))
        return residuals


class DiT(nn.Module):
    """Text-conditioned video DiT: ``forward(x, noise_level, text_emb, text_mask, fps) -> (B, C, T, H, W)``."""

    def __init__(self, cfg: DiTConfig):
        super().__init__()
        cfg.validate()
        self.cfg = cfg
        patch_in = (cfg.in_channels + int(cfg.cond_mask_channel)) * cfg.patch_t * cfg.patch_size**2
        self.patch_embed = nn.Linear(patch_in, cfg.hidden_dim)
        self.time_embed = TimestepEmbedding(cfg.hidden_dim)
        self.text_proj = nn.Sequential(
            nn.Linear(cfg.text_dim, cfg.hidden_dim),
            nn.GELU(approximate="tanh"),
            nn.Linear(cfg.hidden_dim, cfg.hidden_dim),
        )
        # A learned always-visible "null" text token: dropped captions (CFG) attend to it alone.
        self.null_text = nn.Parameter(torch.zeros(1, 1, cfg.hidden_dim))
        self.blocks = nn.ModuleList(DiTBlock(cfg, cfg.frame_local(i)) for i in range(cfg.depth))
        self.final = FinalLayer(cfg)
        self.control = ControlBranch(cfg) if cfg.control_depth else None
        self._rope_cache: dict[tuple, torch.Tensor] = {}

    def rope(self, grid: tuple[int, int, int], fps: torch.Tensor) -> torch.Tensor:
        """3D RoPE rotations (B or 1, N, 1, head_dim // 2) of a token grid at frame rates ``fps`` (B,),
        computed once per (grid, frame rates, device) and reused: they are constants of the shape."""
        rates = fps.tolist()
        rates = rates[:1] if len(set(rates)) == 1 else rates  # one clip rate in the batch: broadcast over B
        key = (grid, tuple(rates), str(fps.device))
        if key not in self._rope_cache:
            with torch.inference_mode(False):  # a cached tensor made under inference_mode could not enter autograd
                self._rope_cache[key] = self._compute_rope(grid, rates, fps.device)
            if len(self._rope_cache) > ROPE_CACHE_SIZE:
                self._rope_cache.pop(next(iter(self._rope_cache)))
        return self._rope_cache[key]

    def _compute_rope(self, grid: tuple[int, int, int], rates: list[float], device: torch.device) -> torch.Tensor:
        cfg = self.cfg
        rates_t = torch.tensor(rates, device=device)
        pos = grid_positions(*grid, fps=rates_t, base_fps=cfg.rope_base_fps, spatial_scale=cfg.rope_spatial_scale)
        pos[..., 0] *= cfg.patch_t  # (B|1, N, 3), time in units of latent frames
        return rope_rotation(rope_angles(pos, cfg.head_dim, cfg.rope_theta)).unsqueeze(2)  # (B|1, N, 1, hd/2)

    def embed_text(self, text_emb: torch.Tensor, text_mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, L, text_dim), (B, L) -> tokens (B, 1+L, D) with the null token first, mask (B, 1+L)."""
        b = text_emb.shape[0]
        tokens = torch.cat([self.null_text.expand(b, -1, -1), self.text_proj(text_emb)], dim=1)
        mask = torch.cat([torch.ones(b, 1, dtype=torch.bool, device=text_mask.device), text_mask.bool()], dim=1)
        return tokens, mask

    def forward(
        self,
        x: torch.Tensor,
        noise_level: torch.Tensor,
        text_emb: torch.Tensor,
        text_mask: torch.Tensor,
        fps: torch.Tensor,
        *,
        extra_token_cond: torch.Tensor | None = None,
        extra_global_cond: torch.Tensor | None = None,
        num_views: int = 1,
        view_neighbors: torch.Tensor | None = None,
        control_tokens: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Predict (B, C, T, H, W) from latents ``x`` (B, C(+1 mask), T, H, W).

        ``noise_level`` (B,): EDM's c_noise. ``text_emb`` (B, L, text_dim), ``text_mask`` (B, L) bool.
        ``fps`` (B,): video frame rate of the clip (scales temporal RoPE).
        ``extra_token_cond`` (B, N, D): added to the patch tokens (e.g. camera rays per token).
        ``extra_global_cond`` (B, D): added to the timestep embedding (e.g. an ego trajectory).
        ``num_views``: views folded into B as (B V), read by cross-view sub-layers.
        ``view_neighbors`` (V, K) long: the views each view attends to across views (None = all).
        ``control_tokens`` (B, N, D): the ControlNet branch's input (:class:`ControlBranch`; None = the
        branch is skipped, as with no control).
        """
        cfg = self.cfg
        _, _, t, h, w = x.shape
        grid = (t // cfg.patch_t, h // cfg.patch_size, w // cfg.patch_size)
        tokens = self.patch_embed(patchify(x, cfg.patch_size, cfg.patch_t))  # (B, N, D)
        if extra_token_cond is not None:
            tokens = tokens + extra_token_cond
        emb, adaln_lora = self.time_embed(noise_level, extra_global_cond)  # (B, D), (B, 3D)
        text, mask = self.embed_text(text_emb, text_mask)  # (B, 1+L, D), (B, 1+L)
        ctx = BlockContext(self.rope(grid, fps), text, mask, grid, num_views, view_neighbors)
        residuals = []
        if self.control is not None and control_tokens is not None:
            residuals = self.control(tokens, control_tokens, emb, adaln_lora, ctx)  # control_depth x (B, N, D)
        for i, block in enumerate(self.blocks):
            tokens = block(tokens, emb, adaln_lora, ctx)  # (B, N, D)
            if i < len(residuals):
                tokens = tokens + residuals[i]
        return unpatchify(self.final(tokens, emb), grid, cfg.patch_size, cfg.patch_t)  # (B, C, T, H, W)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
