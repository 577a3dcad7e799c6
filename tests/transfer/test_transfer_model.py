"""The transfer model starts as its parent, uses the source and the condition once trained, and
samples with the number of network evaluations it claims."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest
import torch

from drivewm.diffusion.sampling import sample
from drivewm.errors import DrivewmError
from drivewm.transfer.config import TransferConfig
from drivewm.transfer.init import from_text2world
from drivewm.transfer.model import Transfer
from drivewm.transfer.retarget import TargetCondition
from drivewm.transfer.sdedit import sdedit_latents

sys.path.insert(0, str(Path(__file__).parent))
from transfer_tiny import tiny_text2world  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from transfer_benchmark import network_evaluations  # noqa: E402

TARGETS = [TargetCondition("snow", "day"), TargetCondition("clear", "night")]
CAPTIONS = ["A snow day drive on a highway.", "A clear-weather night drive on a highway."]


def _inputs(model, seed: int = 1):
    g = torch.Generator().manual_seed(seed)
    x, source = torch.randn(2, 4, 3, 4, 6, generator=g), torch.randn(2, 4, 3, 4, 6, generator=g)
    return x, torch.tensor([0.3, 4.0]), model.conditioning(source, CAPTIONS, TARGETS)


def _perturb_new_parts(model) -> None:
    with torch.no_grad():
        for name, p in model.net.named_parameters():
            if not name.startswith("denoiser."):
                p.add_(0.1 * torch.randn_like(p))


def test_step_zero_is_the_parent() -> None:
    parent = tiny_text2world()
    model = from_text2world(parent, TransferConfig())
    x, sigma, cond = _inputs(model)
    ours = model.net(x, sigma, cond)
    theirs = parent.denoiser(x, sigma, parent.conditioning(CAPTIONS))
    assert torch.equal(ours, theirs)
    assert not torch.equal(ours, parent.denoiser(x, sigma, parent.conditioning(CAPTIONS[::-1])))  # text matters


def test_trained_parts_read_the_source_and_the_condition_and_guidance_drops_only_the_condition() -> None:
    model = from_text2world(tiny_text2world(), TransferConfig())
    _perturb_new_parts(model)
    x, sigma, cond = _inputs(model)
    base = model.net(x, sigma, cond)
    other_source = model.conditioning(torch.randn_like(cond.source), CAPTIONS, TARGETS)
    assert (model.net(x, sigma, other_source) - base).abs().max() > 1e-3
    other_target = model.conditioning(cond.source, CAPTIONS, [TargetCondition("fog", "dusk")] * 2)
    assert (model.net(x, sigma, other_target) - base).abs().max() > 1e-3
    uncond = cond.unconditional()
    assert uncond.weather.tolist() == [0, 0] and uncond.time_of_day.tolist() == [0, 0] and not uncond.text_mask.any()
    assert torch.equal(uncond.source, cond.source)
    half = cond.drop_text(torch.tensor([True, False]))
    assert half.weather.tolist() == [cond.weather[0].item(), 0]


def test_new_parts_learn_from_the_first_step() -> None:
    model = from_text2world(tiny_text2world(), TransferConfig())
    x, sigma, cond = _inputs(model)
    model.net(x, sigma, cond).square().mean().backward()
    assert model.net.source_encoder.proj.weight.grad.abs().sum() > 0
    assert model.net.condition_encoder.mlp[-1].weight.grad.abs().sum() > 0


def test_model_folder_round_trip(tmp_path) -> None:
    model = from_text2world(tiny_text2world(), TransferConfig(condition_width=8), p_mean=0.4, name="/parent")
    _perturb_new_parts(model)
    model.save_pretrained(tmp_path / "m")
    back = Transfer.from_pretrained(tmp_path / "m")
    assert back.parent == "/parent" and back.cfg.edm.p_mean == 0.4 and back.cfg.transfer.condition_width == 8
    x, sigma, cond = _inputs(model)
    assert torch.equal(model.net(x, sigma, cond), back.net(x, sigma, back.conditioning(cond.source, CAPTIONS, TARGETS)))
    tiny_text2world().save_pretrained(tmp_path / "t2w")
    with pytest.raises(DrivewmError, match="model_type"):
        Transfer.from_pretrained(tmp_path / "t2w")


@pytest.mark.parametrize("sampler,steps,guidance", [("euler", 4, 1.0), ("heun", 3, 2.0), ("euler", 1, 3.0)])
def test_network_evaluations_are_counted_right(sampler, steps, guidance) -> None:
    model = from_text2world(tiny_text2world(), TransferConfig())
    calls = []

    def counting(x, sigma, cond):
        calls.append(1)
        return model.net(x, sigma, cond)

    _, _, cond = _inputs(model)
    start = torch.zeros(2, 4, 3, 4, 6)
    for s in (None, 2.0):  # from noise, or SDEdit from a noised start: the same count
        calls.clear()
        sample(
            counting, cond, (4, 3, 4, 6), [0, 1], steps, guidance, sampler, start=start if s else None, start_sigma=s
        )
        assert len(calls) == network_evaluations(steps, guidance, sampler)


def test_sdedit_keeps_the_source_at_low_noise_and_forgets_it_at_high_noise() -> None:
    parent = tiny_text2world()
    source = torch.randn(2, 4, 3, 4, 6, generator=torch.Generator().manual_seed(3))
    near = sdedit_latents(parent, source, CAPTIONS, [0, 1], sigma=0.01, steps=4)
    far = sdedit_latents(parent, source, CAPTIONS, [0, 1], sigma=80.0, steps=4)
    assert (near - source).abs().mean() < 0.05 * (far - source).abs().mean()
