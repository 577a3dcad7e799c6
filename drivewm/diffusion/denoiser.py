"""EDM preconditioning and training loss (Karras et al. 2022, "Elucidating the Design Space of
Diffusion-Based Generative Models", arXiv 2206.00364), with classifier-free-guidance text dropout
and optional Video2World conditioning on clean first latent frames.

The denoiser is ``D(x; sigma) = c_skip(sigma) x + c_out(sigma) F(c_in(sigma) x; c_noise(sigma))``
around a raw backbone F (the DiT), Table 1 of the paper. Latents here are normalised per channel,
so ``sigma_data = 0.5`` as in Cosmos. ``EDMConfig.parameterization`` picks the coefficients, the
loss weight and the noise distribution: EDM's own, or rectified flow's (drivewm.diffusion.flow),
which is the same denoiser form, so samplers and guidance never know which one they run.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import Literal

import torch
from torch import nn

from drivewm.config import above, at_least, in_range, require
from drivewm.diffusion.flow import flow_loss_weight, flow_scalings

#: Default (P_mean, P_std) of ln(sigma) in training: EDM Table 1; flow: SD3's logit-normal(0, 1)
#: (ln sigma = logit t, drivewm.diffusion.flow).
LOG_SIGMA_DEFAULTS = {"edm": (-1.2, 1.2), "flow": (0.0, 1.0)}


@dataclasses.dataclass
class EDMConfig:
    """Formulation (EDM or rectified flow), preconditioning, noise distribution and conditioning dropout."""

    parameterization: Literal["edm", "flow"] = "flow"
    """``flow`` (default): rectified flow with a velocity target (SD3 / Cosmos-Predict2.5 / GAIA-2) written in
    the same form (drivewm.diffusion.flow); ``edm``: EDM's c_skip/c_out/c_in/c_noise and loss weight (Table
    1). Flow became the default on decoded samples at equal compute (docs/quality-vs-compute.md); folders
    saved before name ``edm`` or are read as it (dit_config.EDM_SAVED_BEFORE)."""
    sigma_data: float = 0.5
    """Standard deviation of the (normalised) data, EDM Table 1."""
    p_mean: float | None = None
    """Mean of ln(sigma) during training; None = -1.2 for ``edm`` (EDM Table 1, P_mean), 0 for ``flow``
    (ln sigma = logit t: the logit-normal's location m, SD3 eq. 19)."""
    p_std: float | None = None
    """Std of ln(sigma) during training; None = 1.2 for ``edm`` (P_std), 1 for ``flow`` (SD3's s)."""
    sigma_shift: float = 1.0
    """Training sigmas are multiplied by this: SD3's resolution shift (eq. 23) t -> a t / (1 + (a - 1) t)
    is sigma -> a sigma; > 1 spends more training on high noise (Cosmos-Predict2.5's shifted logit-normal)."""
    text_dropout: float = 0.1
    """Probability of dropping a sample's caption during training (classifier-free guidance)."""
    cond_frames: int = 0
    """Video2World: clean first latent frames given as conditioning (loss on the rest); 0 = Text2World."""

    def log_sigma_normal(self) -> tuple[float, float]:
        """(mean, std) of ln(sigma) in training, shift included."""
        mean, std = LOG_SIGMA_DEFAULTS[self.parameterization]
        mean = mean if self.p_mean is None else self.p_mean
        return mean + math.log(self.sigma_shift), std if self.p_std is None else self.p_std

    def validate(self) -> None:
        require(
            self.parameterization in LOG_SIGMA_DEFAULTS,
            "parameterization",
            self.parameterization,
            f"one of {list(LOG_SIGMA_DEFAULTS)}",
        )
        above(self, 0, "sigma_data", "sigma_shift")
        if self.p_std is not None:
            above(self, 0, "p_std")
        in_range(self, "text_dropout", 0, 1)
        at_least(self, 0, "cond_frames")


@dataclasses.dataclass
class Conditioning:
    """Everything the backbone is conditioned on besides the noisy latents, batch-first."""

    text_emb: torch.Tensor
    """(B, L, text_dim) caption token embeddings."""
    text_mask: torch.Tensor
    """(B, L) bool; all False = caption dropped (the unconditional branch of CFG)."""
    fps: torch.Tensor
    """(B,) video frame rate of the clip."""
    cond_latents: torch.Tensor | None = None
    """(B, C, T, H, W) clean latents whose first ``cond_frames`` frames condition (Video2World)."""
    cond_frames: int = 0
    """How many first latent frames of ``cond_latents`` are given."""
    extra_token_cond: torch.Tensor | None = None
    """(B, N, D) added to the DiT's patch tokens."""
    extra_global_cond: torch.Tensor | None = None
    """(B, D) added to the DiT's timestep embedding."""
    num_views: int = 1
    """Views folded into B (multi-view models)."""
    view_neighbors: torch.Tensor | None = None
    """(V, K) long: the views each view attends to in cross-view sub-layers (None = all)."""
    control_tokens: torch.Tensor | None = None
    """(B, N, D) input of the DiT's ControlNet branch (drivewm.diffusion.dit.ControlBranch); None = none."""

    def drop_text(self, keep: torch.Tensor) -> Conditioning:
        """A copy where samples with ``keep`` (B,) False have their caption masked out."""
        return dataclasses.replace(self, text_mask=self.text_mask & keep[:, None])

    def unconditional(self) -> Conditioning:
        """The same conditioning without any caption (CFG's unconditional branch)."""
        return dataclasses.replace(self, text_mask=torch.zeros_like(self.text_mask))

    def to(self, device: torch.device | str) -> Conditioning:
        """A copy with every tensor field (of subclasses too) on ``device``."""
        moved = {
            f.name: getattr(self, f.name).to(device)
            for f in dataclasses.fields(self)
            if isinstance(getattr(self, f.name), torch.Tensor)
        }
        return dataclasses.replace(self, **moved)


def edm_scalings(
    sigma: torch.Tensor, sigma_data: float
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """(c_skip, c_out, c_in, c_noise) of EDM Table 1 for ``sigma`` (any shape)."""
    sd2 = sigma_data**2
    c_skip = sd2 / (sigma**2 + sd2)
    c_out = sigma * sigma_data / (sigma**2 + sd2).sqrt()
    c_in = 1 / (sigma**2 + sd2).sqrt()
    c_noise = sigma.log() / 4
    return c_skip, c_out, c_in, c_noise


def edm_loss_weight(sigma: torch.Tensor, sigma_data: float) -> torch.Tensor:
    """lambda(sigma) = (sigma^2 + sigma_data^2) / (sigma * sigma_data)^2 (EDM Table 1), so the
    effective target of F has unit variance at every noise level."""
    return (sigma**2 + sigma_data**2) / (sigma * sigma_data) ** 2


Scalings = Callable[[torch.Tensor, float], tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]]

#: parameterization -> (c_skip, c_out, c_in, c_noise)(sigma, sigma_data) and lambda(sigma, sigma_data).
PARAMETERIZATIONS: dict[str, tuple[Scalings, Callable[[torch.Tensor, float], torch.Tensor]]] = {
    "edm": (edm_scalings, edm_loss_weight),
    "flow": (flow_scalings, flow_loss_weight),
}


def scalings(sigma: torch.Tensor, cfg: EDMConfig) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """(c_skip, c_out, c_in, c_noise) of ``cfg.parameterization`` for ``sigma`` (any shape)."""
    return PARAMETERIZATIONS[cfg.parameterization][0](sigma, cfg.sigma_data)


def loss_weight(sigma: torch.Tensor, cfg: EDMConfig) -> torch.Tensor:
    """lambda(sigma) of ``cfg.parameterization``."""
    return PARAMETERIZATIONS[cfg.parameterization][1](sigma, cfg.sigma_data)


def frame_mask(shape: torch.Size, cond_frames: int, device: torch.device) -> torch.Tensor:
    """(1, 1, T, 1, 1) float: 1 on the first ``cond_frames`` latent frames (given), 0 on the rest."""
    mask = torch.zeros(1, 1, shape[2], 1, 1, device=device)
    mask[:, :, :cond_frames] = 1.0
    return mask


class EDMDenoiser(nn.Module):
    """``D(x; sigma, cond)`` around a backbone; ``forward(x, sigma, cond) -> denoised (B, C, T, H, W)``."""

    def __init__(self, backbone: nn.Module, cfg: EDMConfig, cond_mask_channel: bool = False):
        super().__init__()
        self.backbone = backbone  # the raw network F, e.g. the DiT
        self.cfg = cfg  # sigma_data and the Video2World setting
        self.cond_mask_channel = cond_mask_channel  # the backbone takes one more input channel (mask)

    def forward(self, x: torch.Tensor, sigma: torch.Tensor, cond: Conditioning) -> torch.Tensor:
        """``x`` (B, C, T, H, W) noisy latents at ``sigma`` (B,) -> denoised latents (B, C, T, H, W)."""
        c_skip, c_out, c_in, c_noise = (s.view(-1, 1, 1, 1, 1) for s in scalings(sigma.to(x.dtype), self.cfg))
        net_in = c_in * x
        mask = None
        if cond.cond_latents is not None and cond.cond_frames > 0:
            # Video2World (Cosmos sec. 5.1): given frames enter clean, scaled as the network sees clean
            # data (c_in at sigma = 0: 1 / sigma_data for EDM, 1 for flow), and the output keeps them exactly.
            mask = frame_mask(x.shape, cond.cond_frames, x.device)
            clean_scale = scalings(x.new_zeros(()), self.cfg)[2]
            net_in = mask * cond.cond_latents * clean_scale + (1 - mask) * net_in
        if self.cond_mask_channel:
            m = mask if mask is not None else torch.zeros(1, 1, x.shape[2], 1, 1, device=x.device)
            net_in = torch.cat([net_in, m.expand(x.shape[0], 1, *x.shape[2:]).to(x.dtype)], dim=1)
        out = self.backbone(
            net_in,
            c_noise.flatten(),
            cond.text_emb,
            cond.text_mask,
            cond.fps,
            extra_token_cond=cond.extra_token_cond,
            extra_global_cond=cond.extra_global_cond,
            num_views=cond.num_views,
            view_neighbors=cond.view_neighbors,
            control_tokens=cond.control_tokens,
        )
        denoised = c_skip * x + c_out * out.to(x.dtype)
        if mask is not None:
            denoised = mask * cond.cond_latents + (1 - mask) * denoised
        return denoised


def sample_sigma(n: int, cfg: EDMConfig, generator: torch.Generator | None = None) -> torch.Tensor:
    """ln(sigma) ~ N(P_mean, P_std^2) (EDM Table 1; for flow the logit-normal t of SD3 eq. 19), shifted
    by ``cfg.sigma_shift``; (n,) float32."""
    mean, std = cfg.log_sigma_normal()
    return (mean + std * torch.randn(n, generator=generator)).exp()


def edm_loss(
    denoiser: Callable[..., torch.Tensor],
    cfg: EDMConfig,
    x0: torch.Tensor,
    cond: Conditioning,
    sigma: torch.Tensor,
    noise: torch.Tensor,
    keep_text: torch.Tensor,
) -> torch.Tensor:
    """EDM training loss, eq. 2 with Table 1's weighting: mean over samples of
    ``lambda(sigma) * ||D(x0 + sigma n; sigma) - x0||^2`` averaged over the non-conditioning frames
    (for ``flow``, lambda = 1 / t^2 makes this the velocity loss, drivewm.diffusion.flow).

    ``x0`` (B, C, T, H, W) clean normalised latents; ``sigma`` (B,), ``noise`` like x0 and ``keep_text``
    (B,) bool are drawn by the caller (so a run is reproducible per sample, see drivewm.train).
    ``denoiser`` is an :class:`EDMDenoiser` or its parallel wrapper (DDP), hence ``cfg`` apart.
    """
    if cfg.cond_frames > 0:
        cond = dataclasses.replace(cond, cond_latents=x0, cond_frames=cfg.cond_frames)
    s = sigma.to(x0.device, x0.dtype).view(-1, 1, 1, 1, 1)
    denoised = denoiser(x0 + s * noise, sigma.to(x0.device, x0.dtype), cond.drop_text(keep_text.to(x0.device)))
    err = (denoised - x0) ** 2  # (B, C, T, H, W)
    err = err[:, :, cfg.cond_frames :]  # the loss lives on the generated frames only
    return (loss_weight(s.flatten(), cfg) * err.mean(dim=(1, 2, 3, 4))).mean()
