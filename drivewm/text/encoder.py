"""The text-encoder interface: captions -> token embeddings (B, L, D) float32 + mask (B, L) bool.

Encoders are frozen (as T5 is in Cosmos), so an embedding is a pure function of the caption and is
cached per caption; the DiT learns its own projection and cross-attention on top. The encoders
(drivewm.text.hashed, drivewm.text.pretrained) implement this interface; drivewm.text.build picks one.
"""

from __future__ import annotations

import abc
import dataclasses
from collections import OrderedDict
from typing import Literal

import torch

from drivewm.config import at_least
from drivewm.errors import DrivewmError


@dataclasses.dataclass
class TextConfig:
    """Which text encoder, saved with every model so generation rebuilds the same one."""

    kind: Literal["hashed", "t5", "hf"] = "hashed"
    """``hashed``: built-in, no download (drivewm.text.hashed). ``t5``: a local T5 folder (encoder only).
    ``hf``: any local Hugging Face encoder folder, e.g. a sentence-transformers model."""
    path: str | None = None
    """Local folder of the pretrained encoder (``t5``/``hf``); never a hub name."""
    dim: int = 256
    """Embedding width of the ``hashed`` encoder (pretrained ones have their own)."""
    max_length: int = 32
    """Tokens per caption L (longer captions are cut, shorter ones padded and masked)."""
    seed: int = 0
    """Seed of the ``hashed`` encoder's word vectors."""
    cache_size: int = 4096
    """Captions whose embeddings are kept in memory."""

    def validate(self) -> None:
        if self.kind != "hashed" and not self.path:
            raise DrivewmError(f"text: kind {self.kind!r} needs path= a local model folder")
        at_least(self, 1, "max_length")
        at_least(self, 2, "dim")
        at_least(self, 0, "cache_size")


class TextEncoder(abc.ABC):
    """``encode(captions) -> (emb (B, L, dim) float32, mask (B, L) bool)``, cached per caption."""

    def __init__(self, max_length: int, cache_size: int = 4096):
        self.max_length = max_length
        self.cache_size = cache_size
        self._cache: OrderedDict[str, tuple[torch.Tensor, torch.Tensor]] = OrderedDict()

    @property
    @abc.abstractmethod
    def dim(self) -> int:
        """Embedding width D."""

    @abc.abstractmethod
    def encode_uncached(self, captions: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
        """(B, L, D) float32 and (B, L) bool on the CPU, L = max_length."""

    def encode(self, captions: list[str]) -> tuple[torch.Tensor, torch.Tensor]:
        """Embeddings (B, L, D) float32 and mask (B, L) bool for ``captions``, L = max_length."""
        missing = list(dict.fromkeys(c for c in captions if c not in self._cache))
        if missing:
            emb, mask = self.encode_uncached(missing)
            for i, caption in enumerate(missing):
                self._cache[caption] = (emb[i], mask[i])
        rows = [self._cache[c] for c in captions]
        for caption in captions:
            self._cache.move_to_end(caption)
        while len(self._cache) > self.cache_size:
            self._cache.popitem(last=False)
        return torch.stack([r[0] for r in rows]), torch.stack([r[1] for r in rows])
