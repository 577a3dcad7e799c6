"""``build_text_encoder``: the encoder a :class:`TextConfig` names."""

from __future__ import annotations

from drivewm.text.encoder import TextConfig, TextEncoder
from drivewm.text.hashed import HashedWordEncoder
from drivewm.text.pretrained import PretrainedTextEncoder


def build_text_encoder(cfg: TextConfig) -> TextEncoder:
    """The encoder ``cfg`` names (pretrained ones load from the local path only)."""
    cfg.validate()
    if cfg.kind == "hashed":
        return HashedWordEncoder(cfg.dim, cfg.max_length, cfg.seed, cfg.cache_size)
    return PretrainedTextEncoder(cfg.path, cfg.kind, cfg.max_length, cfg.cache_size)
