"""Video tokenizer: a causal video autoencoder with continuous or FSQ latents (issue 4).

``Tokenizer`` (model.py) codes video (B, 3, T, H, W) in [-1, 1] to latents (B, c, t, h, w);
``PRESETS`` (config.py) names the sizes and compressions; ``tiling.py`` codes long or large
videos in causal chunks and blended tiles; ``train.py`` trains on clip shards.
"""

from drivewm.tokenizer.config import PRESETS, TokenizerConfig, preset
from drivewm.tokenizer.model import Tokenizer

__all__ = ["PRESETS", "Tokenizer", "TokenizerConfig", "preset"]
