"""The one sampling function of every model kind (Text2World, multi-view, rollouts).

It owns what is the same for all of them: noise drawn per sample on the CPU from the sample's own
seed (so a sample does not depend on its batch or on the device), then moved to the device;
classifier-free guidance on the caption and, for models conditioned on an ego trajectory, on the
trajectory; bf16 autocast on CUDA; the Karras schedule and the sampler (drivewm.diffusion.samplers).
Video2World needs nothing here: its clean latents travel in the conditioning. SDEdit-style starts
(Meng et al. 2022, arXiv 2108.01073, sec. 3: a guide x_g perturbed to x_g + sigma(t0) z, then the
reverse process from t0) are ``start`` / ``start_sigma``: the schedule then runs from ``start_sigma``
down, so N steps cost the same network evaluations from any start. The model bundles
build the conditioning and (de)normalise latents; nothing here knows a tokenizer or a rig.
"""

from __future__ import annotations

import torch
from torch import nn

from drivewm.config import check_guidance_interval, finite_at_least
from drivewm.device import resolve_device
from drivewm.diffusion.denoiser import Conditioning
from drivewm.diffusion.samplers import SAMPLERS, GuidedDenoiser, karras_sigmas, seeded_noise
from drivewm.errors import DrivewmError


def guided(
    denoiser: nn.Module,
    guidance: float,
    trajectory_guidance: float = 1.0,
    interval: tuple[float, float] | None = None,
) -> nn.Module:
    """``denoiser`` with caption guidance ``guidance`` and, when not 1, trajectory guidance on top
    (D_free + w (D_traj - D_free), each branch caption-guided; ``cond.without_trajectory()`` drops it),
    both only for sigma in ``interval`` (lo, hi] when one is given."""
    model = GuidedDenoiser(denoiser, guidance, interval=interval)
    if trajectory_guidance != 1.0:
        model = GuidedDenoiser(model, trajectory_guidance, drop=_without_trajectory, interval=interval)
    return model


def _without_trajectory(cond: Conditioning) -> Conditioning:
    return cond.without_trajectory()


@torch.no_grad()
def sample(
    denoiser: nn.Module,
    cond: Conditioning,
    shape: tuple[int, ...],
    seeds: list[int],
    steps: int = 35,
    guidance: float = 7.0,
    sampler: str = "heun",
    trajectory_guidance: float = 1.0,
    device: torch.device | str = "cpu",
    start: torch.Tensor | None = None,
    start_sigma: float | None = None,
    guidance_interval: tuple[float, float] | None = None,
) -> torch.Tensor:
    """Normalised latents (B, *shape) float32 on the CPU; sample b starts from noise seeded ``seeds[b]``.

    ``denoiser``: D(x; sigma, cond) on ``device`` (an EDMDenoiser or a network wrapping one).
    ``shape``: one sample, (c, t, h, w), or (V, c, t, h, w) for V camera views, which the denoiser sees
    folded into its batch as (B V, c, t, h, w). ``cond``: the conditioning of that (folded) batch, its
    ``cond_latents`` normalised (Video2World). ``guidance`` / ``trajectory_guidance``: classifier-free
    guidance weights on the caption / the ego trajectory (1 = off). ``start`` (B, *shape) normalised
    latents (None: pure noise at sigma_max 80): sampling starts from them noised to ``start_sigma`` (SDEdit).
    ``guidance_interval`` (lo, hi): guide only at
    sigma in (lo, hi], the conditional model alone elsewhere (one network evaluation; None: guide at
    every sigma).
    """
    if sampler not in SAMPLERS:
        raise DrivewmError(f"unknown sampler {sampler!r}; known: {sorted(SAMPLERS)}")
    if steps < 1 or (start is not None and not start_sigma):
        raise DrivewmError(
            f"sampling: needs steps >= 1 and a start_sigma > 0 with a start (got {steps}, {start_sigma})"
        )
    # NaN would decode to a black video, not an error
    finite_at_least("sampling", 0, guidance=guidance, **{"trajectory guidance": trajectory_guidance})
    guidance_interval = check_guidance_interval("sampling", guidance_interval)
    device = resolve_device(device)
    sigmas = (karras_sigmas(steps, sigma_max=start_sigma) if start is not None else karras_sigmas(steps)).to(device)
    noise = seeded_noise((len(seeds), *shape), seeds)  # on the CPU: the same sample on every device
    x = noise * sigmas[0].cpu() + (start.float().cpu() if start is not None else 0.0)
    x = x.reshape(-1, *shape[-4:]).to(device)  # (B [V], c, t, h, w)
    model = guided(denoiser, guidance, trajectory_guidance, guidance_interval)
    with torch.autocast(device.type, dtype=torch.bfloat16, enabled=device.type == "cuda"):
        x = SAMPLERS[sampler](model, x, sigmas, extra_args={"cond": cond.to(device)})
    return x.float().cpu().reshape(len(seeds), *shape)
