"""Text encoders behind one interface: ``encode(list[str]) -> (emb (B, L, D), mask (B, L) bool)``."""

from drivewm.text.build import build_text_encoder
from drivewm.text.encoder import TextConfig, TextEncoder

__all__ = ["TextConfig", "TextEncoder", "build_text_encoder"]
