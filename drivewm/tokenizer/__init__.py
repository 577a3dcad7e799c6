"""Video tokenizer: a causal video autoencoder with continuous or FSQ latents.

``Tokenizer`` (model.py) codes video (B, 3, T, H, W) in [-1, 1] to latents (B, c, t, h, w);
``preset(size, compression, fsq)`` (config.py) builds a preset's config; ``tiling.py`` codes long or large
videos in causal chunks and blended tiles; ``train.py`` trains on clip shards.
"""

_EXPORTS = {
    "COMPRESSIONS": "drivewm.tokenizer.config",
    "SIZES": "drivewm.tokenizer.config",
    "TokenizerConfig": "drivewm.tokenizer.config",
    "preset": "drivewm.tokenizer.config",
    "Tokenizer": "drivewm.tokenizer.model",
}

__all__ = ["COMPRESSIONS", "SIZES", "Tokenizer", "TokenizerConfig", "preset"]


def __getattr__(name: str):
    """Import the public names on first use: ``drivewm --help`` imports this package for its
    commands and must not pay for PyTorch (PEP 562)."""
    if name in _EXPORTS:
        import importlib

        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
