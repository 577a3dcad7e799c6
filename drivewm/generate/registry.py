"""Generators by model type: the one table ``drivewm generate`` and ``drivewm rollout`` dispatch on.

A model family adds one line here (``model_type -> "module:Class"``, a :class:`drivewm.generate.protocol.
Generator`); the class is imported on first use, so the command line imports no PyTorch.
"""

from __future__ import annotations

import importlib
from pathlib import Path

from drivewm.errors import DrivewmError
from drivewm.generate.protocol import Generator

#: model_type of a model folder -> "module:Class" of its generator.
GENERATORS: dict[str, str] = {
    "text2world": "drivewm.generate.text2world:Text2WorldGenerator",
    "multiview": "drivewm.generate.multiview:MultiViewGenerator",
    "ar": "drivewm.ar.generator:ARFolderGenerator",
}


def generator_class(model_type: str, where: str = "generate") -> type[Generator]:
    """The generator class registered for ``model_type`` (a DrivewmError naming the known ones otherwise)."""
    if model_type not in GENERATORS:
        raise DrivewmError(f"{where}: cannot generate from model_type {model_type!r}; known: {sorted(GENERATORS)}")
    module, name = GENERATORS[model_type].split(":")
    return getattr(importlib.import_module(module), name)


def load_generator(folder: str | Path, device: str = "auto") -> Generator:
    """The generator of model folder ``folder`` (dispatched on its ``model_type``) on ``device``."""
    from drivewm.train.checkpoint import read_model_config

    model_type = read_model_config(folder).get("model_type")
    return generator_class(model_type, str(folder)).from_pretrained(Path(folder), device)
