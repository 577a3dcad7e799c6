"""Sampling: exact incremental decoding (KV cache vs. none) and the temperature / top-k / top-p filter."""

from __future__ import annotations

import pytest
import torch
from ar_synthetic import tiny_condition, tiny_model

from drivewm.ar.sampling import draw, next_token_probs, sample_tokens
from drivewm.ar.sampling_config import TokenSampling


@pytest.mark.parametrize(
    "cfg", [TokenSampling(), TokenSampling(temperature=0.7, top_k=5), TokenSampling(temperature=1.3, top_p=0.8)]
)
def test_cached_sampling_equals_uncached_at_fixed_seed(cfg):
    model, cond = tiny_model(), tiny_condition()
    prompt = torch.tensor([[3, 1, 4], [1, 5, 9]])
    cached = sample_tokens(model, cond, prompt, 15, cfg, torch.Generator().manual_seed(7), use_cache=True)
    plain = sample_tokens(model, cond, prompt, 15, cfg, torch.Generator().manual_seed(7), use_cache=False)
    assert cached.shape == (2, 18)
    assert torch.equal(cached[:, :3], prompt)
    assert torch.equal(cached, plain)
    other = sample_tokens(model, cond, prompt, 15, cfg, torch.Generator().manual_seed(8), use_cache=True)
    assert not torch.equal(cached, other)  # the seed matters: equality above is not a constant output


def test_sampling_from_an_empty_prompt_fills_the_context():
    model, cond = tiny_model(), tiny_condition()
    empty = torch.zeros(2, 0, dtype=torch.long)
    a = sample_tokens(model, cond, empty, 18, TokenSampling(), torch.Generator().manual_seed(0))
    b = sample_tokens(model, cond, empty, 18, TokenSampling(), torch.Generator().manual_seed(0), use_cache=False)
    assert torch.equal(a, b) and int(a.max()) < 40
    with pytest.raises(ValueError, match="exceed the model's context of 18"):
        sample_tokens(model, cond, empty, 19, TokenSampling(), torch.Generator().manual_seed(0))


def test_top_k_and_top_p_keep_the_right_tokens():
    logits = torch.log(torch.tensor([[0.5, 0.2, 0.15, 0.1, 0.05]]))
    top2 = next_token_probs(logits, TokenSampling(top_k=2))
    assert torch.allclose(top2, torch.tensor([[5 / 7, 2 / 7, 0, 0, 0]]))
    nucleus = next_token_probs(logits, TokenSampling(top_p=0.8))  # 0.5 + 0.2 < 0.8: the third is needed too
    assert torch.allclose(nucleus, torch.tensor([[0.5, 0.2, 0.15, 0, 0]]) / 0.85)
    cold = next_token_probs(logits, TokenSampling(temperature=0.01))
    assert cold[0, 0] > 0.999


def test_draw_inverts_the_cumulative_distribution():
    probs = torch.tensor([[0.0, 0.25, 0.0, 0.75]]).repeat(4000, 1)
    tokens = draw(probs, torch.Generator().manual_seed(0))
    assert set(tokens.tolist()) == {1, 3}
    assert abs(float((tokens == 3).double().mean()) - 0.75) < 0.03
