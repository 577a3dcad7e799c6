"""The AR model folder: ``config.json`` (model type ``ar``: the transformer's and the text encoder's
configs, the frame rate trained at, and the FSQ tokenizer it predicts, recorded portably) and
``model.safetensors`` (drivewm.train.checkpoint)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import torch

from drivewm.ar.config import ARConfig
from drivewm.ar.model import ARTransformer
from drivewm.config import from_dict, to_dict
from drivewm.model_folders import resolve_reference
from drivewm.text import TextConfig
from drivewm.train.checkpoint import load_model_folder, load_weights, save_model_folder

MODEL_TYPE = "ar"


@dataclasses.dataclass
class ARModelConfig:
    """What rebuilds a trained AR model."""

    ar: ARConfig = dataclasses.field(default_factory=ARConfig)
    """The transformer's shape."""
    text: TextConfig = dataclasses.field(default_factory=TextConfig)
    """The caption encoder (the one the diffusion models use)."""
    fps: float = 10.0
    """Video frame rate of the training clips."""


def save_ar_folder(path: str | Path, cfg: ARModelConfig, state: dict[str, torch.Tensor], tokenizer_dir: Path) -> None:
    """Write the model folder; ``tokenizer_dir`` is recorded as drivewm.model_folders.portable_reference."""
    extra = {"latent": {"tokenizer": str(Path(tokenizer_dir).resolve())}}
    save_model_folder(path, MODEL_TYPE, to_dict(cfg), state, extra)


def load_ar_folder(path: str | Path) -> tuple[ARTransformer, ARModelConfig, Path]:
    """(transformer in eval mode, its config, its tokenizer folder) of the model folder ``path``."""
    info, state = load_model_folder(path, MODEL_TYPE)
    cfg = from_dict(ARModelConfig, info["config"], f"{Path(path) / 'config.json'} config")
    model = ARTransformer(cfg.ar)
    load_weights(model, state, path)
    return model.eval(), cfg, resolve_reference(info["latent"]["tokenizer"], path)
