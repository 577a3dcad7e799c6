"""Model folders and resumable training state (docs/DESIGN.md section 4).

A *model folder* is ``config.json`` + ``model.safetensors`` (Hugging Face style): the
inference weights (EMA where there is one) and the config that rebuilds the network.
The *training state* (``train_state.pt``: model, EMA, optimizer, step, data position, RNG,
resolved config) is separate and loads with ``torch.load(weights_only=True)``. Nothing here
unpickles code. All writes are atomic.
"""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors.torch import load_file, save_file

from drivewm import __version__
from drivewm.atomic import atomic_path, write_json
from drivewm.errors import DrivewmError

CONFIG_NAME = "config.json"
WEIGHTS_NAME = "model.safetensors"
TRAIN_STATE_NAME = "train_state.pt"


def save_model_folder(
    path: str | Path, model_type: str, config: dict, state_dict: dict[str, torch.Tensor], extra: dict | None = None
) -> None:
    """Write ``config.json`` ({"model_type", "drivewm_version", "config", **extra}) and weights."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    tensors = {k: v.detach().contiguous().cpu() for k, v in state_dict.items()}
    with atomic_path(path / WEIGHTS_NAME) as tmp:
        save_file(tensors, str(tmp))
    write_json(
        path / CONFIG_NAME,
        {"model_type": model_type, "drivewm_version": __version__, "config": config, **(extra or {})},
    )


def read_model_type(path: str | Path) -> str | None:
    """The ``model_type`` of the model folder ``path`` (DrivewmError when it is not one)."""
    cfg_path = Path(path) / CONFIG_NAME
    if not cfg_path.is_file():
        raise DrivewmError(f"{path}: not a drivewm model folder (no {CONFIG_NAME})")
    try:
        info = json.loads(cfg_path.read_text())
    except json.JSONDecodeError:
        raise DrivewmError(f"{cfg_path}: not valid JSON") from None
    if not isinstance(info, dict):
        raise DrivewmError(f"{cfg_path}: expected a JSON object")
    return info.get("model_type")


def load_model_folder(path: str | Path, model_type: str | tuple[str, ...]) -> tuple[dict, dict[str, torch.Tensor]]:
    """Read a model folder; returns (config.json contents, state dict).

    A missing folder/file or another ``model_type`` raises DrivewmError naming the folder.
    """
    path = Path(path)
    types = (model_type,) if isinstance(model_type, str) else model_type
    cfg_path, weights_path = path / CONFIG_NAME, path / WEIGHTS_NAME
    if not cfg_path.is_file() or not weights_path.is_file():
        raise DrivewmError(f"{path}: not a drivewm model folder (needs {CONFIG_NAME} and {WEIGHTS_NAME})")
    try:
        info = json.loads(cfg_path.read_text())
    except json.JSONDecodeError:
        raise DrivewmError(f"{cfg_path}: not valid JSON") from None
    if info.get("model_type") not in types:
        raise DrivewmError(f"{path}: model_type is {info.get('model_type')!r}, expected {' or '.join(types)}")
    try:
        state = load_file(str(weights_path))
    except Exception as exc:  # safetensors raises several types for bad files
        raise DrivewmError(f"{weights_path}: cannot read weights ({exc.__class__.__name__})") from None
    return info, state


def load_weights(module: torch.nn.Module, state: dict[str, torch.Tensor], path: str | Path) -> None:
    """Strictly load ``state`` into ``module``; weights that do not fit the network built from
    ``config.json`` raise DrivewmError naming the folder and the first offending keys."""
    expected = module.state_dict()
    missing = sorted(set(expected) - set(state))
    unexpected = sorted(set(state) - set(expected))
    wrong = sorted(k for k in set(expected) & set(state) if expected[k].shape != state[k].shape)
    if missing or unexpected or wrong:
        detail = f"missing {missing[:3]}, unexpected {unexpected[:3]}, wrong shape {wrong[:3]}"
        raise DrivewmError(f"{path}: {WEIGHTS_NAME} does not match {CONFIG_NAME} ({detail})")
    module.load_state_dict(state)


def save_train_state(path: str | Path, state: dict) -> None:
    """Atomically write the training state (tensors, numbers, strings, lists and dicts only)."""
    with atomic_path(Path(path) / TRAIN_STATE_NAME) as tmp:
        torch.save(state, tmp)


def load_train_state(path: str | Path) -> dict | None:
    """The training state in folder ``path``, or None when there is none (fresh run)."""
    file = Path(path) / TRAIN_STATE_NAME
    if not file.is_file():
        return None
    try:
        return torch.load(file, map_location="cpu", weights_only=True)
    except Exception as exc:  # a truncated or foreign file
        raise DrivewmError(f"{file}: cannot load training state ({exc.__class__.__name__}: {exc})") from None
