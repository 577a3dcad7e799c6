"""EDM preconditioning, loss and samplers against the paper's formulas and an exact oracle."""

from __future__ import annotations

import math

import pytest
import torch

from drivewm.diffusion.denoiser import (
    Conditioning,
    EDMConfig,
    EDMDenoiser,
    edm_loss,
    edm_loss_weight,
    edm_scalings,
    sample_sigma,
    scalings,
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
    sigma = sample_sigma(20000, EDMConfig(parameterization="edm"), torch.Generator().manual_seed(0))
    assert abs(sigma.log().mean().item() + 1.2) < 0.05 and abs(sigma.log().std().item() - 1.2) < 0.05


class LinearBackbone(torch.nn.Module):
    """F(x) = a * x (a learnable scalar), ignoring the conditioning, to check the loss by hand."""

    def __init__(self, a: float):
        super().__init__()
        self.a = torch.nn.Parameter(torch.tensor(a))

    def forward(self, x, noise_level, text_emb, text_mask, fps, **_):
        return self.a * x


def test_loss_matches_formula_and_video2world_masks_frames():
    cfg = EDMConfig(parameterization="edm")
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
    v2w = EDMDenoiser(LinearBackbone(0.3), EDMConfig(parameterization="edm", cond_frames=2))
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


# --- rectified flow in the same denoiser form (drivewm.diffusion.flow) ---


class VelocityProbe(torch.nn.Module):
    """A fixed nonlinear 'velocity network' F(x, c_noise) that records what it was given."""

    def forward(self, x, noise_level, text_emb, text_mask, fps, **_):
        self.seen = (x.clone(), noise_level.clone())
        return torch.sin(3 * x) * (1 + noise_level.view(-1, 1, 1, 1, 1))


def test_flow_denoiser_predicts_x0_as_x_t_minus_t_v_and_its_loss_is_the_velocity_loss():
    cfg = EDMConfig(parameterization="flow")
    probe = VelocityProbe()
    den = EDMDenoiser(probe, cfg)
    g = torch.Generator().manual_seed(0)
    x0, noise = 0.5 * torch.randn(3, 2, 4, 2, 2, generator=g), torch.randn(3, 2, 4, 2, 2, generator=g)
    t = torch.tensor([0.1, 0.5, 0.9])
    sigma = t / (1 - t)  # the VE noise level of interpolation time t
    tt = t.view(-1, 1, 1, 1, 1)
    x_t = (1 - tt) * x0 + tt * noise  # rectified flow's interpolant (SD3 eq. 3)
    cond = Conditioning(torch.zeros(3, 1, 8), torch.ones(3, 1, dtype=torch.bool), torch.full((3,), 10.0))
    out = den(x0 + sigma.view(-1, 1, 1, 1, 1) * noise, sigma, cond)  # the samplers' variable x = x_t / (1 - t)
    seen_x, seen_t = probe.seen
    assert torch.allclose(seen_x, x_t, atol=1e-6) and torch.allclose(seen_t, t, atol=1e-7)
    v = probe(x_t, t, None, None, None)
    assert torch.allclose(out, x_t - tt * v, atol=1e-6)
    loss = edm_loss(den, cfg, x0, cond, sigma, noise, torch.ones(3, dtype=torch.bool))
    velocity_loss = ((v - (noise - x0)) ** 2).mean(dim=(1, 2, 3, 4)).mean()
    assert torch.allclose(loss, velocity_loss, rtol=1e-4)


def test_video2world_frames_enter_as_clean_data_for_either_parameterization():
    """Given frames reach the network as clean data does (c_in at sigma = 0: x0 / sigma_data for EDM,
    x0 itself for flow, whose input at t = 0 is x_t = x0) and come back exactly."""
    g = torch.Generator().manual_seed(0)
    x0, x = torch.randn(2, 2, 3, 2, 2, generator=g), torch.randn(2, 2, 3, 2, 2, generator=g)
    cond = Conditioning(
        torch.zeros(2, 1, 8), torch.ones(2, 1, dtype=torch.bool), torch.full((2,), 10.0), cond_latents=x0, cond_frames=1
    )
    for parameterization, scale in (("edm", 1 / 0.5), ("flow", 1.0)):
        probe = VelocityProbe()
        out = EDMDenoiser(probe, EDMConfig(parameterization=parameterization, cond_frames=1))(x, torch.ones(2), cond)
        assert torch.allclose(probe.seen[0][:, :, :1], x0[:, :, :1] * scale), parameterization
        assert torch.equal(out[:, :, :1], x0[:, :, :1]), parameterization


def test_flow_time_distribution_is_shifted_logit_normal():
    """ln(sigma) = logit(t): the flow default is SD3's logit-normal(0, 1) over t, and a shift a maps
    t -> a t / (1 + (a - 1) t) (SD3 eq. 23)."""
    g = torch.Generator().manual_seed(0)
    sigma = sample_sigma(20000, EDMConfig(parameterization="flow"), g)
    t = sigma / (1 + sigma)
    assert abs(t.logit().mean().item()) < 0.03 and abs(t.logit().std().item() - 1.0) < 0.03
    shifted = sample_sigma(20000, EDMConfig(parameterization="flow", sigma_shift=3.0), torch.Generator().manual_seed(0))
    assert torch.allclose(shifted / (1 + shifted), 3 * t / (1 + 2 * t), atol=1e-5)
    assert EDMConfig(parameterization="edm").log_sigma_normal() == (-1.2, 1.2)  # EDM keeps Table 1


def _oracle_backbone(parameterization: str):
    """The raw network F whose denoiser is the mixture's exact E[x0 | x]: F = (D* - c_skip x) / c_out."""
    cfg = EDMConfig(parameterization=parameterization)

    class Oracle(torch.nn.Module):
        def forward(self, x, noise_level, text_emb, text_mask, fps, **_):
            # Recover sigma from c_noise (EDM: ln(sigma)/4; flow: t) and the VE input from c_in x.
            nl = noise_level.double()
            sigma = (4 * nl).exp() if parameterization == "edm" else nl / (1 - nl)
            c_skip, c_out, c_in, _ = (c.view(-1, 1) for c in scalings(sigma, cfg))
            x_ve = x.double().flatten(1) / c_in
            return ((oracle_denoiser(x_ve, sigma) - c_skip * x_ve) / c_out).view_as(x).to(x.dtype)

    return EDMDenoiser(Oracle(), cfg)


def test_flow_and_edm_denoisers_around_the_exact_network_sample_the_gaussian_mixture():
    """The samplers run either parameterization unchanged: with the exact network, 35-step Heun
    matches the mixture's moments as within the EDM-form test above."""
    mean, cov = mixture_moments()
    cond = Conditioning(torch.zeros(1, 1, 8), torch.ones(1, 1, dtype=torch.bool), torch.full((1,), 10.0))
    for parameterization in ("edm", "flow"):
        den = _oracle_backbone(parameterization)
        sigmas = karras_sigmas(35)
        x = seeded_noise((20000, 2, 1, 1, 1), list(range(20000))).double() * sigmas[0]
        y = sample_heun(lambda x, s, den=den: den(x, s, cond), x, sigmas.double()).flatten(1)
        assert (y.mean(0) - mean).abs().max() < 0.02, parameterization
        assert (torch.cov(y.T) - cov).abs().max() < 0.05, parameterization


class TinyMLP(torch.nn.Module):
    """F(x, c_noise) for 2D points stored as (B, 2, 1, 1, 1): an MLP on x and Fourier features of c_noise."""

    def __init__(self, width: int = 128):
        super().__init__()
        self.register_buffer("freqs", torch.pi * 2.0 ** torch.arange(-1, 7))
        self.net = torch.nn.Sequential(
            torch.nn.Linear(2 + 16, width),
            torch.nn.SiLU(),
            torch.nn.Linear(width, width),
            torch.nn.SiLU(),
            torch.nn.Linear(width, width),
            torch.nn.SiLU(),
            torch.nn.Linear(width, 2),
        )

    def forward(self, x, noise_level, text_emb, text_mask, fps, **_):
        arg = noise_level.view(-1, 1) * self.freqs  # (B, 8)
        return self.net(torch.cat([x.flatten(1), arg.sin(), arg.cos()], dim=1)).view_as(x)


def _mixture_samples(n: int, g: torch.Generator) -> torch.Tensor:
    k = torch.multinomial(WEIGHTS.float(), n, replacement=True, generator=g)
    return (MEANS[k] + STDS[k, None] * torch.randn(n, 2, generator=g, dtype=torch.float64)).float()


def _train_on_mixture(parameterization: str, steps: int = 1500, batch: int = 512) -> EDMDenoiser:
    torch.manual_seed(0)
    cfg = EDMConfig(parameterization=parameterization, sigma_data=1.0, text_dropout=0.0)
    den = EDMDenoiser(TinyMLP(), cfg)
    opt = torch.optim.Adam(den.parameters(), lr=2e-3)
    g = torch.Generator().manual_seed(1)
    cond = Conditioning(torch.zeros(batch, 1, 8), torch.ones(batch, 1, dtype=torch.bool), torch.full((batch,), 10.0))
    for _ in range(steps):
        x0 = _mixture_samples(batch, g).view(batch, 2, 1, 1, 1)
        noise = torch.randn(x0.shape, generator=g)
        loss = edm_loss(den, cfg, x0, cond, sample_sigma(batch, cfg, g), noise, torch.ones(batch, dtype=torch.bool))
        opt.zero_grad()
        loss.backward()
        opt.step()
    return den


@pytest.mark.slow
def test_flow_model_learns_the_gaussian_mixture_denoiser_as_the_edm_model_does():
    """The same MLP, steps, batch and data under either parameterization: the learned E[x0 | x] is
    close to the exact one. Score: held-out x0 error at a fixed grid of sigmas (the same noised inputs
    for both), against the Bayes error of the exact denoiser."""
    sigmas = torch.tensor([0.05, 0.1, 0.2, 0.5, 1.0, 2.0, 5.0])
    g = torch.Generator().manual_seed(2)
    x0 = _mixture_samples(4000, g)
    noise = torch.randn(len(sigmas), 4000, 2, generator=g)
    cond = Conditioning(torch.zeros(4000, 1, 8), torch.ones(4000, 1, dtype=torch.bool), torch.full((4000,), 10.0))
    bayes, learned = [], {}
    for s, n in zip(sigmas, noise):
        bayes.append(((oracle_denoiser(x0 + s * n, s.expand(4000)) - x0) ** 2).sum(1).mean())
    for parameterization in ("edm", "flow"):
        den = _train_on_mixture(parameterization)
        with torch.no_grad():
            learned[parameterization] = [
                ((den((x0 + s * n).view(-1, 2, 1, 1, 1), s.expand(4000), cond).flatten(1) - x0) ** 2).sum(1).mean()
                for s, n in zip(sigmas, noise)
            ]
    bayes_mean = torch.stack(bayes).mean()
    excess = {k: (torch.stack(v).mean() / bayes_mean).item() for k, v in learned.items()}
    print(f"x0 error / Bayes error, mean over the sigma grid: {excess}")
    assert excess["edm"] < 1.1 and excess["flow"] < 1.1
    assert abs(excess["flow"] - excess["edm"]) < 0.05
