"""Sampling from pure noise or from a noised clip (SDEdit), with one count of network evaluations.

SDEdit (Meng et al. 2022, "SDEdit: Guided Image Synthesis and Editing with Stochastic Differential
Equations", arXiv 2108.01073, sec. 3): perturb a guide x_g to x(t0) = x_g + sigma(t0) z and solve
the reverse process from t0 with the new condition; t0 trades faithfulness to the guide (small)
against realism under the condition (large). Here the reverse process is EDM's probability-flow
ODE (drivewm.diffusion.samplers) on the Karras schedule from ``start_sigma`` down to 0, so a run
with N steps costs the same number of network evaluations from any start: :func:`network_evaluations`.
"""

from __future__ import annotations

import torch
from torch import nn

from drivewm.diffusion.samplers import SAMPLERS, GuidedDenoiser, karras_sigmas, seeded_noise
from drivewm.errors import DrivewmError

SIGMA_MAX = 80.0  # EDM's sigma_max (Karras et al. 2022, Table 1): the start of sampling from pure noise


def network_evaluations(steps: int, guidance: float, sampler: str) -> int:
    """Denoiser calls of one sample: Euler N, Heun 2N - 1 (no correction on the last step), x2 with CFG."""
    calls = steps if sampler == "euler" else 2 * steps - 1
    return calls * (1 if guidance == 1.0 else 2)


@torch.no_grad()
def sample_from(
    denoiser: nn.Module,
    shape: tuple[int, ...],
    seeds: list[int],
    cond,
    steps: int,
    guidance: float,
    sampler: str,
    start: torch.Tensor | None = None,
    start_sigma: float | None = None,
) -> torch.Tensor:
    """Normalised latents ``shape`` (B, c, t, h, w) from ``denoiser(x, sigma, cond)``.

    ``start`` None: from noise at sigma_max (``start_sigma`` or 80). Else from ``start`` (B, c, t, h, w)
    noised to ``start_sigma`` (SDEdit). Sample b draws its noise from ``seeds[b]``; ``guidance`` is
    the classifier-free guidance scale on ``cond`` against ``cond.unconditional()``.
    """
    if sampler not in SAMPLERS:
        raise DrivewmError(f"unknown sampler {sampler!r}; known: {sorted(SAMPLERS)}")
    if steps < 1 or (start is not None and not start_sigma):
        raise DrivewmError(
            f"sampling: needs steps >= 1 and a start_sigma > 0 with a start (got {steps}, {start_sigma})"
        )
    sigma_max = float(start_sigma or SIGMA_MAX)
    sigmas = karras_sigmas(steps, sigma_max=sigma_max)
    x = seeded_noise(tuple(shape), seeds) * sigma_max
    if start is not None:
        x = start.float() + x
    return SAMPLERS[sampler](GuidedDenoiser(denoiser, guidance), x, sigmas, extra_args={"cond": cond})
