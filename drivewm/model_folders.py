"""Where model folders are: the weights drivewm ships, ``shipped:KIND`` names, and folder references.

A *model folder* is ``config.json`` + ``model.safetensors`` (drivewm.train.checkpoint reads and
writes them). drivewm ships one per kind in ``drivewm/weights/KIND``; a command or a config field
names it ``shipped:KIND``, so it works wherever drivewm is installed. A model folder that depends on
another (a diffusion model's tokenizer, a transfer model's Text2World parent) records it so that the
record survives a move (:func:`portable_reference`, read back by :func:`resolve_reference`).

This module sits below every stage, the CLI and the product: it imports nothing of drivewm but
its errors, so the argparse types (drivewm.choices), the checkpoint code and the models all call
it without importing each other.
"""

from __future__ import annotations

import os
from pathlib import Path

from drivewm.errors import DrivewmError

#: The two files of a model folder.
CONFIG_NAME = "config.json"
WEIGHTS_NAME = "model.safetensors"

#: Where the installed shipped model folders are, one per kind.
WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
#: The kinds of model drivewm ships, each a folder under WEIGHTS_DIR.
SHIPPED_KINDS = ("tokenizer", "text2world", "multiview", "transfer", "judge")
#: Prefix of a model folder argument that names a shipped model: ``shipped:multiview``.
SHIPPED_PREFIX = "shipped:"


def shipped_model(kind: str) -> Path:
    """The installed model folder ``kind`` (tokenizer, text2world, multiview, transfer or judge)."""
    if kind not in SHIPPED_KINDS:
        raise DrivewmError(f"no shipped model {kind!r}: drivewm ships {', '.join(SHIPPED_KINDS)}")
    path = WEIGHTS_DIR / kind
    if not (path / WEIGHTS_NAME).is_file():
        raise DrivewmError(f"this drivewm has no shipped {kind} weights at {path}; give --model")
    return path


def resolve_model_folder(value: str | Path) -> Path:
    """``shipped:KIND`` is the installed ``drivewm/weights/KIND`` (:func:`shipped_model`; an unknown
    or missing kind raises DrivewmError), anything else a path as given."""
    if not (isinstance(value, str) and value.startswith(SHIPPED_PREFIX)):
        return Path(value)
    return shipped_model(value[len(SHIPPED_PREFIX) :])


def portable_reference(target: str | Path, folder: str | Path, root: str | Path) -> str:
    """How ``folder`` records the folder ``target`` it depends on (a model folder's tokenizer or
    Text2World parent, a latent cache's tokenizer) so that the record survives a move: relative to
    ``folder`` when ``target`` lies under ``root`` (the run folder both belong to: a recipe run,
    copied back from a GPU machine, moves as a whole); ``shipped:KIND`` when it is an installed
    shipped model (a fine-tune of the shipped weights outlives a new virtual environment or
    drivewm's installed path changing); else its absolute path. :func:`resolve_reference` reads it."""
    target, folder, root = (Path(p).resolve() for p in (target, folder, root))
    if target.is_relative_to(root):
        return os.path.relpath(target, folder)
    for kind in SHIPPED_KINDS:
        if target == (WEIGHTS_DIR / kind).resolve():
            return SHIPPED_PREFIX + kind
    return str(target)


def resolve_reference(reference: str, folder: str | Path) -> Path:
    """The folder that ``reference`` (as :func:`portable_reference` writes it, or an absolute path)
    names, recorded in ``folder``: a relative path is read from ``folder``."""
    if reference.startswith(SHIPPED_PREFIX):
        return resolve_model_folder(reference)
    path = Path(reference)
    return path if path.is_absolute() else (Path(folder) / path).resolve()
