"""The built-in text encoder: a fixed random vector per word, found by hashing the word.

Why this and not a trained tokenizer + transformer: the conditioning captions of driving clips are
short tag-like phrases ("snow, day, highway, medium traffic"); what the DiT needs is that different
words give clearly different, stable vectors. Hashing each lower-cased word to a seed and drawing a
Gaussian vector from it needs no vocabulary file and no download, gives every word (also unseen
ones) a vector that is identical in every process and on every rank, and has no parameters, so it is
frozen like Cosmos' T5 and its embeddings cache per caption. Word order enters through a small
sinusoidal position term. The DiT's learned text projection and cross-attention do the rest.

A hashed vector carries no meaning, so "snowy" would be as far from "snow" as from "tram": a model
trained on the template captions' "snow" would not hear a prompt for "snowfall". The words that
:mod:`drivewm.text.conditions` reads as a weather or time of day (the eval's own lexicon) are
therefore hashed as that condition's name, the one word the captions of drivewm's logs use ("snowy",
"snowfall", "blizzard" -> "snow"; "nighttime", "dark" -> "night"); every other word, the condition
names included, keeps its own vector, so models trained on those captions see the same embeddings.
"""

from __future__ import annotations

import hashlib
import math
import re

import torch

from drivewm.text.conditions import KEYWORDS
from drivewm.text.encoder import TextEncoder

WORD = re.compile(r"[a-z0-9]+")
POSITION_SCALE = 0.1  # position term is small next to the unit-variance word vectors


#: word -> the condition name it is hashed as (single words of drivewm.text.conditions.KEYWORDS).
SYNONYMS = {w: value for values in KEYWORDS.values() for value, ws in values.items() for w in ws if " " not in w}


def words(caption: str) -> list[str]:
    """Lower-cased alphanumeric words of ``caption``, condition words as their condition's name."""
    return [SYNONYMS.get(w, w) for w in WORD.findall(caption.lower())]


def word_seed(word: str, seed: int) -> int:
    """A stable 63-bit seed for ``word`` (blake2b, not Python's salted ``hash``)."""
    digest = hashlib.blake2b(f"{seed}:{word}".encode(), digest_size=8).digest()
    return int.from_bytes(digest, "little") >> 1


def sinusoidal_positions(length: int, dim: int) -> torch.Tensor:
    """(length, dim) sin/cos position features (Vaswani et al. 2017, sec. 3.5)."""
    pos = torch.arange(length, dtype=torch.float32)[:, None]
    freqs = torch.exp(-math.log(10000.0) * torch.arange(0, dim, 2, dtype=torch.float32) / dim)
    table = torch.zeros(length, dim)
    table[:, 0::2] = torch.sin(pos * freqs)
    table[:, 1::2] = torch.cos(pos * freqs[: dim // 2])
    return table


class HashedWordEncoder(TextEncoder):
    """Captions -> (B, L, dim) fixed hashed word vectors + position term, mask over the words."""

    def __init__(self, dim: int = 256, max_length: int = 32, seed: int = 0, cache_size: int = 4096):
        super().__init__(max_length, cache_size)
        self._dim = dim
        self.seed = seed
        self.positions = sinusoidal_positions(max_length, dim) * POSITION_SCALE

    @property
    def dim(self) -> int:
        return self._dim

    def word_vector(self, word: str) -> torch.Tensor:
        """(dim,) standard-normal vector drawn from the word's own generator."""
        return torch.randn(self._dim, generator=torch.Generator().manual_seed(word_seed(word, self.seed)))

    def encode_uncached(self, captions: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
        emb = torch.zeros(len(captions), self.max_length, self._dim)
        mask = torch.zeros(len(captions), self.max_length, dtype=torch.bool)
        for i, caption in enumerate(captions):
            tokens = words(caption)[: self.max_length]
            for j, word in enumerate(tokens):
                emb[i, j] = self.word_vector(word) + self.positions[j]
            mask[i, : len(tokens)] = True
        return emb, mask
