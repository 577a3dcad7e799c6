"""The AR transformer's typed config and its named size presets (``debug`` on a CPU up to ``xl``)."""

from __future__ import annotations

import dataclasses
from typing import Literal

from drivewm.config import above, at_least, require
from drivewm.errors import DrivewmError


@dataclasses.dataclass
class ARConfig:
    """Shape of the causal transformer over FSQ tokens. A sequence is one camera view's latent frames,
    each frame's h x w tokens in :attr:`order`, after the caption's tokens as a prefix."""

    vocab_size: int = 1000
    """FSQ codebook size (filled from the tokenizer); one more embedding row is the start token."""
    grid_hw: list[int] = dataclasses.field(default_factory=lambda: [8, 12])
    """Tokens per latent frame (h, w) (filled from the token cache)."""
    max_frames: int = 5
    """Latent frames the context holds: the longest sequence is max_frames * h * w video tokens."""
    order: Literal["raster", "block"] = "raster"
    """Token order within a frame: row-major, or row-major over block_size x block_size blocks."""
    block_size: int = 2
    """Side of a block in ``block`` order (must divide h and w)."""
    hidden_dim: int = 128
    """Token width D."""
    depth: int = 4
    """Number of transformer blocks."""
    num_heads: int = 4
    """Attention heads (head_dim = D / heads, even, split over t/h/w by 3D RoPE)."""
    mlp_ratio: float = 4.0
    """MLP hidden width as a multiple of D."""
    text_dim: int = 256
    """Width of the text encoder's embeddings (filled from the text encoder)."""
    ego_features: int = 3
    """Per latent frame ego features: x, y (m, scaled) and yaw (rad) in the sequence's first ego frame."""
    layout: bool = False
    """Add the tokens of the per-camera layout video (same tokenizer) at each position."""
    rope_theta: float = 10000.0
    """RoPE base wavelength."""
    rope_base_fps: float = 10.0
    """Video frame rate at which latent frame i sits at temporal RoPE position i."""

    @property
    def head_dim(self) -> int:
        return self.hidden_dim // self.num_heads

    @property
    def frame_tokens(self) -> int:
        return self.grid_hw[0] * self.grid_hw[1]

    @property
    def context_tokens(self) -> int:
        """The most video tokens one sequence may hold."""
        return self.max_frames * self.frame_tokens

    def validate(self) -> None:
        at_least(self, 2, "vocab_size")
        at_least(self, 1, "max_frames", "block_size", "hidden_dim", "depth", "num_heads", "text_dim", "ego_features")
        above(self, 0, "mlp_ratio", "rope_theta", "rope_base_fps")
        require(len(self.grid_hw) == 2 and min(self.grid_hw) >= 1, "grid_hw", self.grid_hw, "[h, w], both >= 1")
        if self.hidden_dim % self.num_heads or self.head_dim % 2:
            raise DrivewmError(f"ar: hidden_dim {self.hidden_dim} must split into {self.num_heads} heads of even width")
        if self.order == "block" and (self.grid_hw[0] % self.block_size or self.grid_hw[1] % self.block_size):
            raise DrivewmError(f"ar: block_size {self.block_size} must divide the token grid {self.grid_hw}")


#: Named sizes (GPT-style widths). Parameter counts at vocab 1,000 and text_dim 256 (12 D^2 per block plus
#: embeddings): debug ~1.1M, tiny ~3.1M (CPU), small ~22M, base ~87M, large ~304M, xl ~1.0B (GPU; FSDP from
#: large, activation checkpointing at xl).
AR_PRESETS: dict[str, dict] = {
    "debug": dict(hidden_dim=128, depth=4, num_heads=4),
    "tiny": dict(hidden_dim=192, depth=6, num_heads=4),
    "small": dict(hidden_dim=384, depth=12, num_heads=6),
    "base": dict(hidden_dim=768, depth=12, num_heads=12),
    "large": dict(hidden_dim=1024, depth=24, num_heads=16),
    "xl": dict(hidden_dim=1536, depth=36, num_heads=24),
}


def ar_preset(name: str) -> dict:
    """The preset's fields as a dict (copy); an unknown name raises DrivewmError listing the known ones."""
    if name not in AR_PRESETS:
        raise DrivewmError(f"unknown ar preset {name!r}; known: {sorted(AR_PRESETS)}")
    return dict(AR_PRESETS[name])
