"""Sampling token sequences from the AR transformer: temperature, top-k and top-p (nucleus, Holtzman et al.
2020, "The Curious Case of Neural Text Degeneration", sec. 3.1), with or without the KV cache.

Each token is drawn by inverting the cumulative distribution at one uniform number from the caller's
generator, one per sequence and step, so the draw depends only on the generator and the probabilities:
sampling with the cache gives the tokens sampling without it gives (the logits agree up to rounding),
which tests/ar/test_sampling.py checks and benchmarks/bench_ar_kv_cache.py times.
"""

from __future__ import annotations

import torch

from drivewm.ar.model import ARCondition, ARTransformer
from drivewm.ar.sampling_config import TokenSampling


def next_token_probs(logits: torch.Tensor, cfg: TokenSampling) -> torch.Tensor:
    """(B, vocab) logits -> (B, vocab) probabilities after temperature, top-k and top-p."""
    logits = logits.float() / cfg.temperature
    if 0 < cfg.top_k < logits.shape[-1]:
        kth = torch.topk(logits, cfg.top_k, dim=-1).values[:, -1:]  # (B, 1)
        logits = logits.masked_fill(logits < kth, float("-inf"))
    probs = torch.softmax(logits, dim=-1)
    if cfg.top_p < 1:
        sorted_p, order = torch.sort(probs, dim=-1, descending=True)
        before = torch.cumsum(sorted_p, dim=-1) - sorted_p  # mass of the more likely tokens
        drop = (before >= cfg.top_p).scatter(-1, order, before >= cfg.top_p)  # back to vocabulary order
        probs = probs.masked_fill(drop, 0.0)
        probs = probs / probs.sum(dim=-1, keepdim=True)
    return probs


def draw(probs: torch.Tensor, generator: torch.Generator) -> torch.Tensor:
    """(B, vocab) -> (B,) long: inverse-CDF sampling at one uniform number per row."""
    u = torch.rand(probs.shape[0], 1, generator=generator, dtype=torch.float64).to(probs.device)
    cdf = torch.cumsum(probs.double(), dim=-1)
    return torch.searchsorted(cdf, u * cdf[:, -1:]).squeeze(1).clamp_(max=probs.shape[-1] - 1)


@torch.no_grad()
def sample_tokens(
    model: ARTransformer,
    cond: ARCondition,
    prompt: torch.Tensor,
    num_new: int,
    cfg: TokenSampling,
    generator: torch.Generator,
    use_cache: bool = True,
) -> torch.Tensor:
    """Continue ``prompt`` (B, p) video tokens (p may be 0) by ``num_new`` sampled tokens -> (B, p + num_new).

    With ``use_cache`` the prompt runs once (prefill) and each new token one step; without, every step runs
    the whole sequence again. Both draw the same tokens from the same ``generator`` state.
    """
    cfg.validate()
    total = prompt.shape[1] + num_new
    if total > model.cfg.context_tokens:
        raise ValueError(f"{total} tokens exceed the model's context of {model.cfg.context_tokens}")
    tokens = prompt
    if use_cache:
        cache = model.new_cache(prompt.shape[0], cond.text.shape[1], model.token_embed.weight)
        step_inputs = model.inputs_of(torch.cat([prompt, prompt.new_zeros(prompt.shape[0], 1)], dim=1))
    for _ in range(num_new):
        if use_cache:
            logits = model(step_inputs, cond, cache)[:, -1]  # (B, vocab)
        else:
            full = torch.cat([tokens, tokens.new_zeros(tokens.shape[0], 1)], dim=1)
            logits = model(model.inputs_of(full), cond)[:, -1]
        new = draw(next_token_probs(logits, cfg), generator)  # (B,)
        tokens = torch.cat([tokens, new[:, None]], dim=1)
        step_inputs = new[:, None]
    return tokens
