"""The baseline transfer: SDEdit with the Text2World model (no training).

Noise the source clip's latents to ``sigma`` and denoise them with the target caption
(drivewm.diffusion.sampling; Meng et al. 2022). Small sigma keeps the source (and its condition),
large sigma follows the caption but forgets the drive; the transfer model must beat the best
sigma at the same number of network evaluations (benchmarks/bench_transfer.py).
"""

from __future__ import annotations

import torch

from drivewm.diffusion.data import denormalize_latents, normalize_latents
from drivewm.diffusion.sampling import sample
from drivewm.diffusion.text2world import Text2World


@torch.no_grad()
def sdedit_latents(
    model: Text2World,
    source: torch.Tensor,
    captions: list[str],
    seeds: list[int],
    sigma: float,
    steps: int = 8,
    guidance: float = 1.0,
    sampler: str = "euler",
) -> torch.Tensor:
    """Raw latents (B, c, t, h, w): raw ``source`` latents (B, c, t, h, w) noised to ``sigma`` and
    denoised by ``model`` under ``captions`` (sample b's noise from ``seeds[b]``)."""
    mean, std = torch.tensor(model.latent.latent_mean), torch.tensor(model.latent.latent_std)
    sigma_data = model.cfg.edm.sigma_data
    z = normalize_latents(source.float(), mean, std, sigma_data)
    cond = model.conditioning(captions)  # on the model's device
    x = sample(
        model.denoiser,
        cond,
        z.shape[1:],
        seeds,
        steps,
        guidance,
        sampler,
        device=model.device,
        start=z,
        start_sigma=sigma,
    )
    return denormalize_latents(x, mean, std, sigma_data)
