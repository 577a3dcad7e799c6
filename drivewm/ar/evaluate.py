"""Held-out bits per token of an AR model against two baselines measured on the same tokens.

- copy: the token at the same (row, column) of the previous latent frame, as a distribution: probability
  ``a`` on it (``a`` the rate at which training tokens equal it) and the rest spread evenly; a frame
  without a previous one takes the unigram distribution.
- unigram: the training tokens' frequencies (add-one smoothed).

The model must beat the stronger (lower) of the two; the margin is ``1 - model / best baseline``.
"""

from __future__ import annotations

import math
from pathlib import Path

import torch
from tqdm import tqdm

from drivewm.ar.folder import load_ar_folder
from drivewm.ar.model import ARTransformer
from drivewm.ar.tokens import TokenDataset, check_cache_tokenizer
from drivewm.ar.train import batch_of, next_token_loss
from drivewm.atomic import write_json
from drivewm.clips.latents import find_latent_cache
from drivewm.errors import DrivewmError
from drivewm.text import TextEncoder, build_text_encoder


def unigram_bits(train: TokenDataset) -> torch.Tensor:
    """(vocab,) -log2 p of each token under add-one smoothed training frequencies."""
    counts = torch.ones(train.vocab_size, dtype=torch.float64)
    for i in range(len(train)):
        counts += torch.bincount(train[i].tokens.flatten(), minlength=train.vocab_size)
    return -torch.log2(counts / counts.sum())


def copy_rate(train: TokenDataset) -> float:
    """How often a training token equals the co-located token of the previous latent frame."""
    same = total = 0
    for i in range(len(train)):
        t = train[i].tokens  # (t, h, w)
        same += int((t[1:] == t[:-1]).sum())
        total += t[1:].numel()
    return same / max(total, 1)


def copy_bits(tokens: torch.Tensor, rate: float, unigram: torch.Tensor) -> torch.Tensor:
    """Total bits of ``tokens`` (t, h, w) under the copy baseline."""
    vocab = unigram.shape[0]
    rate = min(max(rate, 1e-6), 1 - 1e-6)
    hit = tokens[1:] == tokens[:-1]
    later = torch.where(hit, -math.log2(rate), -math.log2((1 - rate) / (vocab - 1)))
    return unigram[tokens[0].flatten()].sum() + later.double().sum()


@torch.no_grad()
def bits_per_token(
    model: ARTransformer, text: TextEncoder, train: TokenDataset, held_out: TokenDataset, batch: int = 8
) -> dict:
    """{"model", "copy", "unigram", "best_baseline", "margin", "tokens"} bits per held-out token."""
    unigram, rate = unigram_bits(train), copy_rate(train)
    sums = {"model": 0.0, "copy": 0.0, "unigram": 0.0}
    count = 0
    for start in tqdm(range(0, len(held_out), batch), desc="ar bits per token", leave=False):
        samples = [held_out[i] for i in range(start, min(start + batch, len(held_out)))]
        tokens, cond = batch_of(samples, text, model.cfg)
        n = tokens.numel()
        sums["model"] += float(next_token_loss(model, tokens, cond, model.start_token)) * n / math.log(2)
        sums["unigram"] += float(sum(unigram[s.tokens.flatten()].sum() for s in samples))
        sums["copy"] += float(sum(copy_bits(s.tokens, rate, unigram) for s in samples))
        count += n
    out = {k: v / count for k, v in sums.items()}
    best = min(out["copy"], out["unigram"])
    return {**out, "best_baseline": best, "margin": 1 - out["model"] / best, "copy_rate": rate, "tokens": count}


def evaluate_folder(
    model_dir: Path, data_dir: Path, latents: str | None, holdout_percent: int, batch: int, out_dir: Path
) -> dict:
    """:func:`bits_per_token` of the model folder on the held-out clips of its tokenizer's cache; writes
    ``out_dir/metrics.json``."""
    model, cfg, tokenizer_dir = load_ar_folder(model_dir)
    cache_dir = find_latent_cache(Path(data_dir), tokenizer_dir, latents)
    frames = cfg.ar.max_frames
    train = TokenDataset(cache_dir, None, "train", holdout_percent)
    held_out = TokenDataset(cache_dir, None, "holdout", holdout_percent)
    check_cache_tokenizer(held_out.cache, tokenizer_dir)
    if held_out.frames > frames:
        raise DrivewmError(
            f"{cache_dir}: clips of {held_out.frames} latent frames exceed the model's context of {frames}"
        )
    metrics = bits_per_token(model, build_text_encoder(cfg.text), train, held_out, batch)
    out_dir.mkdir(parents=True, exist_ok=True)
    write_json(out_dir / "metrics.json", metrics)
    return metrics
