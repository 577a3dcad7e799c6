"""No file drivewm reads runs code: a training state, latent cache or model folder that carries a pickle
whose unpickling would act is refused (or passed over) without acting, and no loader in the package can
unpickle."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
import torch

from drivewm.errors import DrivewmError
from drivewm.train.checkpoint import load_train_state

PACKAGE = Path(__file__).resolve().parents[2] / "drivewm"


class _Acts:
    """Unpickled, it would create the marker file (what a planted file would do with a shell command)."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (os.mkdir, (str(self.marker),))


def test_a_training_state_that_would_run_code_is_refused_without_running_it(tmp_path):
    marker = tmp_path / "ran"
    torch.save({"step": 3, "model": {}, "payload": _Acts(marker)}, tmp_path / "train_state.pt")
    with pytest.raises(DrivewmError, match="cannot load training state .*no intact training state left"):
        load_train_state(tmp_path)
    assert not marker.exists()


def test_no_loader_in_the_package_can_unpickle():
    """Every torch.load passes weights_only=True, no np.load allows pickles, and pickle is never loaded."""
    risky = []
    for path in PACKAGE.rglob("*.py"):
        text = path.read_text()
        for call in re.findall(r"torch\.load\([^)]*\)", text):
            risky += [f"{path.name}: {call}"] if "weights_only=True" not in call else []
        risky += [
            f"{path.name}: {m}" for m in re.findall(r"allow_pickle=True|pickle\.loads?\(|dill\.|joblib\.load", text)
        ]
    assert risky == []
