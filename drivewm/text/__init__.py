"""Text encoders behind one interface: ``encode(list[str]) -> (emb (B, L, D), mask (B, L) bool)``."""

from drivewm.text.encoder import TextConfig, TextEncoder, build_text_encoder

__all__ = ["TextConfig", "TextEncoder", "build_text_encoder"]
