"""Rectified flow (flow matching with a velocity target) in EDM's denoiser form.

Rectified flow (Liu et al. 2022, arXiv 2209.03003; flow matching, Lipman et al. 2022, arXiv
2210.02747; the formulation of SD3, Esser et al. 2024, arXiv 2403.03206 sec. 2-3, of
Cosmos-Predict2.5, NVIDIA 2025 "World Simulation with Video Foundation Models for Physical AI"
sec. 3.1, and of GAIA-2, arXiv 2503.20523) interpolates

    x_t = (1 - t) x0 + t n,   t in [0, 1),   n ~ N(0, I)                         (SD3 eq. 3, a_t = 1 - t, b_t = t)

and trains a network F to predict the velocity v = dx_t/dt = n - x0, so that x0 = x_t - t v.

The samplers run in EDM's variance-exploding variables (x = x0 + sigma n, Karras et al. 2022 eq. 1).
Dividing x_t by 1 - t gives exactly that: sigma = t / (1 - t) and x = x_t / (1 - t). Hence a flow
model is an EDM denoiser ``D(x; sigma) = c_skip x + c_out F(c_in x; c_noise)`` (EDM Table 1) with

    c_in = 1 / (1 + sigma)  (x_t = c_in x),   c_skip = 1 / (1 + sigma),   c_out = -t,   c_noise = t,

since D = x_t - t F(x_t; t) = x / (1 + sigma) - t F(...). Its loss ||F - (n - x0)||^2 is
||D - x0||^2 / t^2 (D - x0 = -t (F - v)), i.e. EDM's weighted loss with lambda(sigma) = 1 / t^2.
Samplers, guidance, Video2World and multi-view therefore work unchanged.

The training distribution of t is logit-normal (SD3 eq. 19): logit(t) ~ N(m, s^2). As
logit(t) = ln(t / (1 - t)) = ln(sigma), that is EDM's log-normal sigma with P_mean = m and
P_std = s; SD3's resolution shift (eq. 23) t -> a t / (1 + (a - 1) t) is sigma -> a sigma.
"""

from __future__ import annotations

import torch


def flow_time(sigma: torch.Tensor) -> torch.Tensor:
    """Interpolation time t = sigma / (1 + sigma) of the VE noise level ``sigma`` (any shape)."""
    return sigma / (1 + sigma)


def flow_scalings(
    sigma: torch.Tensor, sigma_data: float
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """(c_skip, c_out, c_in, c_noise) of rectified flow for VE ``sigma`` (module docstring);
    ``sigma_data`` is unused (the interpolation sets the scales), kept for one signature."""
    t = flow_time(sigma)
    c_in = 1 / (1 + sigma)
    return c_in, -t, c_in, t


def flow_loss_weight(sigma: torch.Tensor, sigma_data: float) -> torch.Tensor:
    """lambda(sigma) = 1 / t^2 = ((1 + sigma) / sigma)^2: EDM's weighted denoising loss then equals
    the velocity loss ||F - (n - x0)||^2 of rectified flow (SD3 eq. 16 with w_t = 1)."""
    return ((1 + sigma) / sigma) ** 2
