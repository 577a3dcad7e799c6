"""EDM samplers (Karras et al. 2022, arXiv 2206.00364) with one k-diffusion-style signature.

``sample_x(model, x, sigmas, extra_args=None, callback=None)``: ``model(x, sigma, **extra_args)``
returns the denoised estimate D(x; sigma) for a batch; ``x`` starts as noise at ``sigmas[0]``;
``sigmas`` decreases to 0. Samplers know nothing of tokenizers, data or text encoders.
"""

from __future__ import annotations

from collections.abc import Callable

import torch
from torch import nn

Model = Callable[..., torch.Tensor]
Callback = Callable[[dict], None]


def karras_sigmas(steps: int, sigma_min: float = 0.002, sigma_max: float = 80.0, rho: float = 7.0) -> torch.Tensor:
    """EDM eq. 5: sigma_i = (smax^(1/rho) + i/(N-1) (smin^(1/rho) - smax^(1/rho)))^rho, then 0; (steps+1,)."""
    ramp = torch.linspace(0, 1, steps, dtype=torch.float64)
    inv_rho_min, inv_rho_max = sigma_min ** (1 / rho), sigma_max ** (1 / rho)
    sigmas = (inv_rho_max + ramp * (inv_rho_min - inv_rho_max)) ** rho
    return torch.cat([sigmas, torch.zeros(1, dtype=torch.float64)]).to(torch.float32)


def seeded_noise(shape: tuple[int, ...], seeds: list[int], device: torch.device | str = "cpu") -> torch.Tensor:
    """Standard normal (B, ...) where sample i is drawn from its own generator seeded ``seeds[i]``,
    so a sample does not depend on the batch it is generated in."""
    if len(seeds) != shape[0]:
        raise ValueError(f"need one seed per sample: {len(seeds)} seeds for batch {shape[0]}")
    gens = [torch.Generator().manual_seed(int(s)) for s in seeds]
    return torch.stack([torch.randn(shape[1:], generator=g) for g in gens]).to(device)


def _d(model: Model, x: torch.Tensor, sigma: torch.Tensor, extra_args: dict) -> tuple[torch.Tensor, torch.Tensor]:
    """(denoised, dx/dsigma) of the probability-flow ODE, EDM eq. 4 with sigma(t) = t: (x - D) / sigma."""
    denoised = model(x, sigma * x.new_ones(x.shape[0]), **extra_args)
    return denoised, (x - denoised) / sigma


@torch.no_grad()
def sample_euler(
    model: Model,
    x: torch.Tensor,
    sigmas: torch.Tensor,
    extra_args: dict | None = None,
    callback: Callback | None = None,
) -> torch.Tensor:
    """EDM Algorithm 1 without its second-order correction: first-order Euler steps of the ODE."""
    extra_args = extra_args or {}
    for i in range(len(sigmas) - 1):
        denoised, d = _d(model, x, sigmas[i], extra_args)
        x = x + d * (sigmas[i + 1] - sigmas[i])
        if callback is not None:
            callback({"i": i, "x": x, "sigma": sigmas[i], "denoised": denoised})
    return x


@torch.no_grad()
def sample_heun(
    model: Model,
    x: torch.Tensor,
    sigmas: torch.Tensor,
    extra_args: dict | None = None,
    callback: Callback | None = None,
) -> torch.Tensor:
    """EDM Algorithm 1 (deterministic Heun, 2nd order): an Euler step corrected by the average
    slope at its end, except on the last step to sigma = 0 (lines 9-11)."""
    extra_args = extra_args or {}
    for i in range(len(sigmas) - 1):
        denoised, d = _d(model, x, sigmas[i], extra_args)
        dt = sigmas[i + 1] - sigmas[i]
        x_next = x + d * dt
        if sigmas[i + 1] > 0:
            _, d_next = _d(model, x_next, sigmas[i + 1], extra_args)
            x_next = x + (d + d_next) / 2 * dt
        x = x_next
        if callback is not None:
            callback({"i": i, "x": x, "sigma": sigmas[i], "denoised": denoised})
    return x


SAMPLERS: dict[str, Callable] = {"euler": sample_euler, "heun": sample_heun}


class GuidedDenoiser(nn.Module):
    """Classifier-free guidance (Ho & Salimans 2022): D = D_drop + w (D_cond - D_drop), where D_drop is
    the prediction with one condition removed by ``drop(cond)``: the caption by default
    (``cond.unconditional()``), or e.g. the ego trajectory (as Vista and GEM guide on their actions).

    Wraps a denoiser ``denoiser(x, sigma, cond)``; ``guidance`` w = 1 is the plain conditional model
    (one evaluation), 0 the model without that condition. ``interval`` (lo, hi): guide only where
    lo < sigma <= hi and return the conditional prediction alone elsewhere, one evaluation instead of
    two (Kynkaenniemi et al. 2024, "Applying Guidance in a Limited Interval Improves Sample and
    Distribution Quality in Diffusion Models", arXiv 2404.07724); None guides at every sigma.
    """

    def __init__(
        self,
        denoiser: nn.Module,
        guidance: float,
        drop: Callable | None = None,
        interval: tuple[float, float] | None = None,
    ):
        super().__init__()
        self.denoiser = denoiser  # D(x; sigma, cond), possibly guided on another condition already
        self.guidance = guidance  # w
        self.drop = drop or (lambda cond: cond.unconditional())  # cond -> cond without the guided condition
        self.interval = interval  # (lo, hi] of sigma where guidance applies; None: everywhere

    def forward(self, x: torch.Tensor, sigma: torch.Tensor, cond) -> torch.Tensor:
        cond_out = self.denoiser(x, sigma, cond)
        if self.guidance == 1.0:
            return cond_out
        inside = torch.ones_like(sigma, dtype=torch.bool)
        if self.interval is not None:
            inside = (sigma > self.interval[0]) & (sigma <= self.interval[1])
            if not bool(inside.any()):
                return cond_out
        uncond_out = self.denoiser(x, sigma, self.drop(cond))
        guided = uncond_out + self.guidance * (cond_out - uncond_out)
        return torch.where(inside.view(-1, *[1] * (x.ndim - 1)), guided, cond_out)
