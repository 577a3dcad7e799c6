"""EDM preconditioning, loss and samplers against the paper's formulas and an exact oracle."""

from __future__ import annotations

import math

import torch

from drivewm.diffusion.denoiser import (
    Conditioning,
    EDMConfig,
    EDMDenoiser,
    edm_loss,
    edm_loss_weight,
    edm_scalings,
    sample_sigma,
)
from drivewm.diffusion.samplers import GuidedDenoiser, karras_sigmas, sample_euler, sample_heun, seeded_noise

# A 2D Gaussian mixture: weights, means (K, 2), isotropic stds (K,).
WEIGHTS = torch.tensor([0.2, 0.5, 0.3], dtype=torch.float64)
MEANS = torch.tensor([[-2.0, 0.0], [1.0, 1.0], [1.5, -2.0]], dtype=torch.float64)
STDS = torch.tensor([0.3, 0.5, 0.2], dtype=torch.float64)


def oracle_denoiser(x: torch.Tensor, sigma: torch.Tensor) -> torch.Tensor:
    """Exact E[y | y + sigma n = x] for the mixture: responsibilities times per-component Wiener means."""
    x64, s2 = x.double(), sigma.double()[:, None, None] ** 2  # (B, 2), (B, 1, 1)
    var = STDS[None, :, None] ** 2 + s2  # (B, K, 1)
    diff = x64[:, None, :] - MEANS[None]  # (B, K, 2)
    logp = WEIGHTS.log()[None] - (diff**2 / var).sum(-1) / 2 - var.squeeze(-1).log()  # (B, K), 2D Gaussian
    resp = logp.softmax(dim=1)[..., None]  # (B, K, 1)
    post = MEANS[None] + STDS[None, :, None] ** 2 / var * diff  # (B, K, 2)
    return (resp * post).sum(1).to(x.dtype)


def mixture_moments() -> tuple[torch.Tensor, torch.Tensor]:
    mean = (WEIGHTS[:, None] * MEANS).sum(0)
    second = (
        WEIGHTS[:, None, None] * (MEANS[:, :, None] * MEANS[:, None, :] + torch.eye(2) * STDS[:, None, None] ** 2)
    ).sum(0)
    return mean, second - mean[:, None] * mean[None]


def test_scalings_match_edm_table1():
    sigma, sd = torch.tensor([0.01, 0.5, 3.0, 80.0]), 0.5
    c_skip, c_out, c_in, c_noise = edm_scalings(sigma, sd)
    for i, s in enumerate(sigma.tolist()):
        assert math.isclose(c_skip[i].item(), sd**2 / (s**2 + sd**2), rel_tol=1e-5)
        assert math.isclose(c_out[i].item(), s * sd / math.sqrt(s**2 + sd**2), rel_tol=1e-5)
        assert math.isclose(c_in[i].item(), 1 / math.sqrt(s**2 + sd**2), rel_tol=1e-5)
        assert math.isclose(c_noise[i].item(), math.log(s) / 4, rel_tol=1e-5, abs_tol=1e-6)
        assert math.isclose(edm_loss_weight(sigma, sd)[i].item(), (s**2 + sd**2) / (s * sd) ** 2, rel_tol=1e-5)
    # The effective training target of F has unit variance at every sigma (EDM eq. 8 / App. B.6).
    assert torch.allclose(c_out**2 * edm_loss_weight(sigma, sd), torch.ones(4), atol=1e-5)


def test_sigma_distribution_is_lognormal():
    sigma = sample_sigma(20000, EDMConfig(), torch.Generator().manual_seed(0))
    assert abs(sigma.log().mean().item() + 1.2) < 0.05 and abs(sigma.log().std().item() - 1.2) < 0.05


class LinearBackbone(torch.nn.Module):
    """F(x) = a * x (a learnable scalar), ignoring the conditioning, to check the loss by hand."""

    def __init__(self, a: float):
        super().__init__()
        self.a = torch.nn.Parameter(torch.tensor(a))

    def forward(self, x, noise_level, text_emb, text_mask, fps, **_):
        return self.a * x


def test_loss_matches_formula_and_video2world_masks_frames():
    cfg = EDMConfig()
    den = EDMDenoiser(LinearBackbone(0.3), cfg)
    g = torch.Generator().manual_seed(0)
    x0, noise = torch.randn(3, 2, 4, 2, 2, generator=g), torch.randn(3, 2, 4, 2, 2, generator=g)
    sigma = torch.tensor([0.1, 1.0, 10.0])
    cond = Conditioning(torch.zeros(3, 1, 8), torch.ones(3, 1, dtype=torch.bool), torch.full((3,), 10.0))
    loss = edm_loss(den, cfg, x0, cond, sigma, noise, torch.ones(3, dtype=torch.bool))
    s = sigma.view(-1, 1, 1, 1, 1)
    c_skip, c_out, c_in, _ = (c.view(-1, 1, 1, 1, 1) for c in edm_scalings(sigma, 0.5))
    y = x0 + s * noise
    by_hand = (
        edm_loss_weight(sigma, 0.5) * ((c_skip * y + c_out * 0.3 * c_in * y - x0) ** 2).mean(dim=(1, 2, 3, 4))
    ).mean()
    assert torch.allclose(loss, by_hand, rtol=1e-5)
    # Video2World: the given frames come back exactly, and the loss ignores them.
    v2w = EDMDenoiser(LinearBackbone(0.3), EDMConfig(cond_frames=2))
    out = v2w(y, sigma, Conditioning(cond.text_emb, cond.text_mask, cond.fps, cond_latents=x0, cond_frames=2))
    assert torch.equal(out[:, :, :2], x0[:, :, :2]) and not torch.allclose(out[:, :, 2:], x0[:, :, 2:])
    loss_v2w = edm_loss(v2w, v2w.cfg, x0, cond, sigma, noise, torch.ones(3, dtype=torch.bool))
    by_hand_v2w = (edm_loss_weight(sigma, 0.5) * ((out - x0)[:, :, 2:] ** 2).mean(dim=(1, 2, 3, 4))).mean()
    assert torch.allclose(loss_v2w, by_hand_v2w, rtol=1e-5)


def _sample_mixture(sampler, steps: int, n: int = 20000) -> torch.Tensor:
    sigmas = karras_sigmas(steps, sigma_max=80.0)
    x = seeded_noise((n, 2), list(range(n))) * sigmas[0]
    return sampler(oracle_denoiser, x, sigmas)


def test_samplers_reproduce_gaussian_mixture_moments():
    """With the exact denoiser, 35-step Heun matches the mixture's mean (within 0.02), covariance
    (within 0.05 per entry) and component weights (within 0.01); 35-step Euler is looser (0.08/0.2/0.04;
    measured here: Heun 0.005/0.03/0.002, Euler 0.012/0.14/0.015)."""
    mean, cov = mixture_moments()
    for sampler, tol_mean, tol_cov, tol_w in [(sample_heun, 0.02, 0.05, 0.01), (sample_euler, 0.08, 0.2, 0.04)]:
        y = _sample_mixture(sampler, 35).double()
        assert (y.mean(0) - mean).abs().max() < tol_mean, sampler.__name__
        assert (torch.cov(y.T) - cov).abs().max() < tol_cov, sampler.__name__
        nearest = torch.cdist(y, MEANS).argmin(1)
        weights = torch.bincount(nearest, minlength=3).double() / len(y)
        assert (weights - WEIGHTS).abs().max() < tol_w, sampler.__name__


def test_heun_converges_faster_than_euler():
    exact = _sample_mixture(sample_heun, 200, 2000)
    err = {
        s.__name__: (_sample_mixture(s, 18, 2000) - exact).pow(2).mean().sqrt().item()
        for s in (sample_euler, sample_heun)
    }
    assert err["sample_heun"] < 0.5 * err["sample_euler"], err


def test_seeded_noise_is_per_sample():
    a = seeded_noise((3, 4), [5, 6, 7])
    b = seeded_noise((2, 4), [6, 7])
    assert torch.equal(a[1:], b)


def test_guidance_extrapolates_conditional_from_unconditional():
    class Toy(torch.nn.Module):
        def forward(self, x, sigma, cond):
            return x + cond.text_mask.float().sum(1).view(-1, 1)

    cond = Conditioning(torch.zeros(2, 3, 4), torch.ones(2, 3, dtype=torch.bool), torch.full((2,), 10.0))
    x = torch.zeros(2, 1)
    assert torch.allclose(GuidedDenoiser(Toy(), 7.0)(x, torch.ones(2), cond), torch.full((2, 1), 21.0))
    assert torch.allclose(GuidedDenoiser(Toy(), 0.0)(x, torch.ones(2), cond), torch.zeros(2, 1))
