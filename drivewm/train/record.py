"""What a training run folder says about its compute: steps and wall seconds.

Read from the folder's training state (drivewm.train.checkpoint), or, for a run brought back from a
GPU machine with its weights and metrics only, from the last row of the loop's ``metrics.jsonl``
(drivewm.train.loop). The release manifest and the model card quote it.
"""

from __future__ import annotations

import json
from pathlib import Path

from drivewm.errors import DrivewmError
from drivewm.train.checkpoint import load_train_state


def training_record(run_dir: Path) -> dict:
    """``{"steps", "train_seconds"}`` of a training run folder: from its training state, else from the
    last row of its ``metrics.jsonl`` (a run brought back from a GPU machine with its weights and
    metrics only); {} with neither."""
    saved = load_train_state(run_dir)
    if saved is None:
        return metrics_record(Path(run_dir) / "metrics.jsonl")
    seconds = saved.get("train_seconds")  # None: a run older than the loop's cumulative clock
    return {"steps": int(saved["step"]), "train_seconds": None if seconds is None else float(seconds)}


def metrics_record(path: Path) -> dict:
    """``{"steps", "train_seconds"}`` from the last row of a training loop's metrics file ({} without one)."""
    if not path.is_file():
        return {}
    rows = [line for line in path.read_text().splitlines() if line.strip()]
    try:
        last = json.loads(rows[-1]) if rows else {}
        return {"steps": int(last["step"]), "train_seconds": float(last["train_seconds"])} if last else {}
    except (ValueError, KeyError, TypeError):
        raise DrivewmError(f"{path}: the last row is not a training loop's metrics row (step, train_seconds)") from None
