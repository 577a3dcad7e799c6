"""Model folders and resumable training state (docs/DESIGN.md section 4).

A *model folder* is ``config.json`` + ``model.safetensors`` (Hugging Face style): the
inference weights (EMA where there is one) and the config that rebuilds the network.
The *training state* (``train_state.pt``: model, EMA, optimizer, step, data position, RNG,
resolved config) is separate and loads with ``torch.load(weights_only=True)``. Nothing here
unpickles code. All writes are atomic and fsynced (drivewm.atomic).

Weights and config are two files, so they are two renames: a reader between them would pair new
weights with the old config. Both therefore carry the same ``revision`` (a digest of weights and
config; in ``config.json`` and in the safetensors header), and :func:`load_model_folder` reads
until the two agree, so a reader never uses a mix. ``config.json`` also holds a digest of the
weights alone (``weights_digest``), which loading recomputes: weights whose bytes changed on disk
are refused instead of loaded, while the rest of config.json stays editable by hand. (One header
key only: safetensors writes its metadata map in no fixed order, and equal saves must be equal bytes.)

The training state carries a digest of its own content (``digest``), and each save keeps the state
it replaces as ``train_state.prev.pt``. A resume whose ``train_state.pt`` is missing, truncated or
changed (torch.load reads flipped tensor bytes without complaint) sets it aside as
``train_state.pt.damaged``, says so on stderr, and resumes from the previous state; only when no
intact state is left is it a one-line error. Everything a task keeps (``TrainTask.extra_state``,
e.g. the tokenizer's discriminator) is inside the same file, so it is covered the same way.
"""

from __future__ import annotations

import hashlib
import json
import os
import sys
import time
from pathlib import Path

import torch
from safetensors.torch import load as load_safetensors
from safetensors.torch import save_file

from drivewm import __version__
from drivewm.atomic import atomic_path, write_json
from drivewm.errors import DrivewmError
from drivewm.model_folders import (
    CONFIG_NAME,
    WEIGHTS_NAME,
    portable_reference,
    resolve_model_folder,
    verify_shipped,
)

TRAIN_STATE_NAME = "train_state.pt"
PREVIOUS_STATE_NAME = "train_state.prev.pt"
DAMAGED_SUFFIX = ".damaged"
DIGEST_KEY = "digest"
#: Entries every training state has (drivewm.train.loop._checkpoint).
STATE_KEYS = ("model", "ema", "optimizer", "step", "rng")
REVISION_KEY = "drivewm_revision"
#: config.json entries written by save_model_folder itself (never taken from ``extra``).
SAVE_KEYS = ("revision", "weights_digest")
#: A reader that finds config and weights of different saves waits for the writer's second rename.
READ_ATTEMPTS, READ_WAIT_S = 20, 0.1


def save_model_folder(
    path: str | Path, model_type: str, config: dict, state_dict: dict[str, torch.Tensor], extra: dict | None = None
) -> None:
    """Write ``config.json`` ({"model_type", "drivewm_version", "config", **extra, "revision"}) and
    weights (the weights first: see the module docstring)."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True)
    tensors = {k: v.detach().contiguous().cpu() for k, v in state_dict.items()}
    extra = {k: v for k, v in (extra or {}).items() if k not in SAVE_KEYS}  # e.g. a re-export's old digests
    extra = portable_extra(extra, path)
    info = {"model_type": model_type, "drivewm_version": __version__, "config": config, **extra}
    info["weights_digest"] = _weights_digest(tensors)
    info["revision"] = _revision(info)
    with atomic_path(path / WEIGHTS_NAME) as tmp:
        save_file(tensors, str(tmp), metadata={REVISION_KEY: info["revision"]})
    write_json(path / CONFIG_NAME, info)


def portable_extra(extra: dict, path: Path) -> dict:
    """``extra`` with the folders a model folder at ``path`` depends on (``latent.tokenizer``, a transfer
    model's ``parent``) recorded so that they survive a move (drivewm.model_folders.portable_reference, the
    run folder being ``path``'s parent): a recipe's run folder, copied from a GPU machine or renamed,
    keeps working, and so does a fine-tune of the shipped weights after drivewm is installed elsewhere.
    Relative and ``shipped:`` records are kept as they are."""
    extra = dict(extra)
    latent = extra.get("latent")
    tokenizer = latent.get("tokenizer") if isinstance(latent, dict) else None
    if isinstance(tokenizer, str) and Path(tokenizer).is_absolute():
        extra["latent"] = {**latent, "tokenizer": portable_reference(tokenizer, path, path.parent)}
    if isinstance(extra.get("parent"), str) and Path(extra["parent"]).is_absolute():
        extra["parent"] = portable_reference(extra["parent"], path, path.parent)
    return extra


def _revision(info: dict) -> str:
    """Digest of config.json's content, weights digest included: equal saves give equal bytes."""
    return hashlib.blake2b(json.dumps(info, sort_keys=True, default=str).encode(), digest_size=16).hexdigest()


def _weights_digest(tensors: dict[str, torch.Tensor]) -> str:
    """Digest of named tensors (names, dtypes, shapes and bytes)."""
    digest = hashlib.blake2b(digest_size=16)
    for name in sorted(tensors):
        digest.update(f"{name}:".encode())
        _update_tensor(digest, tensors[name])
    return digest.hexdigest()


def _update_tensor(digest, t: torch.Tensor) -> None:
    """Feed a tensor's dtype, shape and bytes to a hashlib digest."""
    t = t.detach().cpu().contiguous()
    digest.update(f"{t.dtype}:{tuple(t.shape)}".encode())
    digest.update(t.reshape(-1).view(torch.uint8).numpy().data)


def state_digest(obj: object) -> str:
    """Digest of a training state (nested dicts, lists and tuples of tensors and plain values), independent
    of dict order; equal content gives the equal digest after a torch.save / torch.load round trip."""
    digest = hashlib.blake2b(digest_size=16)
    _update_state(digest, obj)
    return digest.hexdigest()


def _update_state(digest, obj: object) -> None:
    if isinstance(obj, torch.Tensor):
        _update_tensor(digest, obj)
    elif isinstance(obj, dict):
        digest.update(b"{")
        for key in sorted(obj, key=repr):
            digest.update(repr(key).encode() + b":")
            _update_state(digest, obj[key])
        digest.update(b"}")
    elif isinstance(obj, (list, tuple)):
        digest.update(b"[")
        for item in obj:
            _update_state(digest, item)
        digest.update(b"]")
    else:
        digest.update(repr(obj).encode() + b",")


def read_model_type(path: str | Path) -> str | None:
    """The ``model_type`` of the model folder ``path`` (DrivewmError when it is not one)."""
    return read_model_config(path).get("model_type")


def load_model_folder(path: str | Path, model_type: str | tuple[str, ...]) -> tuple[dict, dict[str, torch.Tensor]]:
    """Read a model folder; returns (config.json contents, state dict).

    ``path`` may name a shipped model, ``shipped:KIND`` (drivewm.model_folders), as config fields such as
    a tokenizer run's ``init`` do. A missing folder/file or another ``model_type`` raises
    DrivewmError naming the folder; so does a shipped folder whose files differ from its manifest
    (drivewm.model_folders.verify_shipped), however it is named.
    """
    path = resolve_model_folder(path)
    if not (path / WEIGHTS_NAME).is_file():
        raise DrivewmError(f"{path}: not a drivewm model folder (needs {CONFIG_NAME} and {WEIGHTS_NAME})")
    verify_shipped(path)
    for _ in range(READ_ATTEMPTS):
        info = read_model_config(path, model_type)
        state, revision = _read_weights(path / WEIGHTS_NAME)
        if info.get("revision") in (None, revision):  # None: written before revisions, or by hand
            _check_weights(path, info, state)
            check_finite(state, f"{path / WEIGHTS_NAME}")
            return info, state
        time.sleep(READ_WAIT_S)
    raise DrivewmError(
        f"{path}: {CONFIG_NAME} (revision {info.get('revision')}) and {WEIGHTS_NAME} (revision {revision}) "
        "come from different saves: a run may still be writing it"
    )


def _check_weights(path: Path, info: dict, state: dict[str, torch.Tensor]) -> None:
    """The weights still hash to the digest saved in config.json (no byte changed on disk)."""
    expected = info.get("weights_digest")
    if expected is not None and _weights_digest(state) != expected:
        raise DrivewmError(
            f"{path}: {WEIGHTS_NAME} does not match {CONFIG_NAME}'s weights_digest: the weights changed after the "
            "save (a damaged copy) or come from another save"
        )


def check_finite(state: dict[str, torch.Tensor], where: str) -> None:
    """Refuse (DrivewmError) weights holding NaN or infinity, naming the first such tensor: a diverged run's
    weights generate black clips and turn every weight of a fine-tune NaN, so they never pass silently."""
    for name, tensor in state.items():
        if tensor.is_floating_point() and not torch.isfinite(tensor).all():
            raise DrivewmError(f"{where}: tensor {name} holds NaN or infinity (a diverged training run's weights)")


def read_model_config(path: str | Path, model_type: str | tuple[str, ...] | None = None) -> dict:
    """``config.json`` of a model folder, checked to be a JSON object of ``model_type`` (one of several;
    None: any)."""
    cfg_path = Path(path) / CONFIG_NAME
    types = (model_type,) if isinstance(model_type, str) else model_type
    if not cfg_path.is_file():
        raise DrivewmError(f"{path}: not a drivewm model folder (needs {CONFIG_NAME} and {WEIGHTS_NAME})")
    try:
        info = json.loads(cfg_path.read_text())
    except (ValueError, RecursionError):
        raise DrivewmError(f"{cfg_path}: not valid JSON") from None
    if not isinstance(info, dict):
        raise DrivewmError(f"{cfg_path}: expected a JSON object, got {type(info).__name__}")
    if types is not None and info.get("model_type") not in types:
        raise DrivewmError(f"{path}: model_type is {info.get('model_type')!r}, expected {' or '.join(types)}")
    if types is not None and not isinstance(info.get("config"), dict):  # every loader builds its network from it
        raise DrivewmError(
            f"{cfg_path}: 'config' must be a mapping of the network's settings, got {info.get('config')!r}"
        )
    return info


def _read_weights(weights_path: Path) -> tuple[dict[str, torch.Tensor], str | None]:
    """The tensors of a safetensors file and the revision in its header (None when it has none).

    The file is read once, into memory: a save replaces it by a rename, so one read sees one save's
    header and tensors. (safe_open could return the header of one save and the tensors of the next.)"""
    try:
        data = weights_path.read_bytes()
        header = json.loads(data[8 : 8 + int.from_bytes(data[:8], "little")])
        return load_safetensors(data), (header.get("__metadata__") or {}).get(REVISION_KEY)
    except Exception as exc:  # safetensors raises several types for bad files
        raise DrivewmError(f"{weights_path}: cannot read weights ({exc.__class__.__name__})") from None


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
    """Atomically write the training state (tensors, numbers, strings, lists and dicts only) with its
    digest; the state it replaces becomes ``train_state.prev.pt`` (see the module docstring)."""
    folder = Path(path)
    current = folder / TRAIN_STATE_NAME
    record = {**state, DIGEST_KEY: state_digest(state)}
    if current.is_file():
        os.replace(current, folder / PREVIOUS_STATE_NAME)  # a kill right here leaves the previous one to resume
    with atomic_path(current) as tmp:
        torch.save(record, tmp)


def load_train_state(path: str | Path) -> dict | None:
    """The newest intact training state in folder ``path``, or None when there is none (fresh run).
    A damaged ``train_state.pt`` is renamed ``train_state.pt.damaged`` (so the next save keeps the
    intact previous state) and the previous state is used, with a warning on stderr."""
    folder = Path(path)
    problems = []
    for file in (folder / TRAIN_STATE_NAME, folder / PREVIOUS_STATE_NAME):
        if not file.is_file():
            continue
        try:
            state = _read_state(file)
        except DrivewmError as exc:
            problems.append(str(exc))
            continue
        if file.name != TRAIN_STATE_NAME:
            why = "; ".join(problems) or f"{folder / TRAIN_STATE_NAME}: missing (a save was cut off)"
            print(f"warning: {why}; resuming from {file.name} (step {state['step']})", file=sys.stderr)
            if (folder / TRAIN_STATE_NAME).is_file():  # set aside, so the next save keeps the intact one
                os.replace(folder / TRAIN_STATE_NAME, folder / (TRAIN_STATE_NAME + DAMAGED_SUFFIX))
        return state
    if problems:
        raise DrivewmError(f"{'; '.join(problems)}; no intact training state left (move the folder away to restart)")
    return None


def _read_state(file: Path) -> dict:
    """One training-state file, checked: loadable without unpickling code, complete, and equal to its digest."""
    try:
        state = torch.load(file, map_location="cpu", weights_only=True)
    except Exception as exc:  # a truncated or foreign file: torch raises several types
        raise DrivewmError(f"{file}: cannot load training state ({exc.__class__.__name__})") from None
    missing = [k for k in STATE_KEYS if not isinstance(state, dict) or k not in state]
    if missing:
        raise DrivewmError(f"{file}: not a drivewm training state (missing {missing})")
    digest = state.pop(DIGEST_KEY, None)  # None: written before digests
    if digest is not None and state_digest(state) != digest:
        raise DrivewmError(f"{file}: training state does not match its digest (bytes changed on disk)")
    return state
