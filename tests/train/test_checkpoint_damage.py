"""Issue 15 item 4, training side: a damaged checkpoint never resumes silently wrong. train_state.pt
carries a digest and the state it replaced stays as train_state.prev.pt, so a run whose latest state
was truncated, had bytes changed (torch.load reads those without complaint) or vanished between the
two renames resumes from the previous one and ends with exactly the weights, task state and
metrics rows of an uninterrupted run. Exercised through the shared loop (drivewm.train.loop) with
a small task that also keeps task state (the hook the tokenizer's discriminator uses)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
import torch
from safetensors.torch import load_file
from torch import nn

from drivewm.atomic import write_text
from drivewm.errors import DrivewmError
from drivewm.train.checkpoint import load_model_folder, save_model_folder
from drivewm.train.config import TrainConfig
from drivewm.train.loop import TrainTask, train

CFG = TrainConfig(steps=6, batch_size=4, lr=1e-2, warmup_steps=1, log_every=1, checkpoint_every=2, ema_decay=0.5)


class LinearTask(TrainTask):
    """Least squares on fixed data: model (64 -> 64 linear), loss MSE to a fixed linear map.
    ``extra_state`` counts the optimizer steps it saw, like a second network's step counter."""

    def __init__(self):
        gen = torch.Generator().manual_seed(0)
        self.x = torch.randn(16, 64, generator=gen)  # (N, 64)
        self.y = self.x @ torch.randn(64, 64, generator=gen)  # (N, 64)
        self.model = nn.Sequential(nn.Linear(64, 64))
        self.steps_seen = torch.zeros((), dtype=torch.int64)

    def blocks(self) -> list[nn.Module]:
        return [self.model[0]]

    def num_samples(self) -> int:
        return len(self.x)

    def tokens_per_sample(self) -> int:
        return 1

    def loss(self, forward, indices, seeds, device):
        return torch.nn.functional.mse_loss(forward(self.x[indices]), self.y[indices])

    def after_step(self, step: int) -> dict[str, float]:
        self.steps_seen += 1
        return {}

    def extra_state(self) -> dict:
        return {"steps_seen": self.steps_seen.clone()}

    def load_extra_state(self, state: dict) -> None:
        self.steps_seen = state["steps_seen"].clone()

    def save_model(self, ema_state, out_dir: Path) -> None:
        save_model_folder(out_dir, "linear", {}, ema_state)

    def sample_grid(self, ema_state, path: Path) -> None:
        write_text(path, "no samples for a linear map\n")


def _run(out: Path, stop_after: int | None = None) -> LinearTask:
    torch.manual_seed(0)
    task = LinearTask()
    train(task, CFG, out, stop_after=stop_after)
    return task


@pytest.fixture(scope="module")
def uninterrupted(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("full")
    _run(out)
    return out


def _flip_tensor_byte(path: Path) -> None:
    """Change one byte in the middle of the file: the model and optimizer tensors are most of it."""
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x5A
    path.write_bytes(bytes(data))


def _assert_same_run(out: Path, reference: Path, task: LinearTask) -> None:
    ours, theirs = load_file(str(out / "model.safetensors")), load_file(str(reference / "model.safetensors"))
    assert ours.keys() == theirs.keys() and all(torch.equal(ours[k], theirs[k]) for k in ours)
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    ref = [json.loads(line) for line in (reference / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == list(range(1, 7)) and [r["loss"] for r in rows] == [r["loss"] for r in ref]
    assert int(task.steps_seen) == 6  # the task state came back from the same (previous) checkpoint


def test_changed_bytes_resume_from_the_previous_state(uninterrupted, tmp_path, capsys):
    out = tmp_path / "run"
    _run(out, stop_after=4)  # checkpoints at steps 2 (now train_state.prev.pt) and 4
    _flip_tensor_byte(out / "train_state.pt")
    with (out / "metrics.jsonl").open("a") as f:
        f.write('{"step": 5, "loss": 0.1')  # and killed in the middle of a metrics row
    loaded = torch.load(out / "train_state.pt", weights_only=True)  # torch does not notice
    assert loaded["step"] == 4
    task = _run(out)
    err = capsys.readouterr().err
    assert "train_state.pt: training state does not match its digest" in err
    assert "resuming from train_state.prev.pt (step 2)" in err
    assert (out / "train_state.pt.damaged").is_file()
    _assert_same_run(out, uninterrupted, task)


@pytest.mark.parametrize("damage", ["truncated", "missing"])
def test_truncated_or_missing_state_resumes_from_the_previous_one(uninterrupted, tmp_path, capsys, damage):
    out = tmp_path / "run"
    _run(out, stop_after=4)
    state = out / "train_state.pt"
    if damage == "truncated":
        state.write_bytes(state.read_bytes()[: state.stat().st_size // 3])
    else:  # killed between keeping the previous state and writing the new one
        state.unlink()
    task = _run(out)
    assert "resuming from train_state.prev.pt (step 2)" in capsys.readouterr().err
    _assert_same_run(out, uninterrupted, task)


def test_no_intact_state_is_one_clear_error(tmp_path):
    out = tmp_path / "run"
    _run(out, stop_after=4)
    _flip_tensor_byte(out / "train_state.pt")
    (out / "train_state.prev.pt").write_bytes(b"PK\x03\x04 not a checkpoint")
    with pytest.raises(
        DrivewmError,
        match=r"^.*train_state\.pt: training state does not match its digest.*"
        r"train_state\.prev\.pt: cannot load training state .*no intact training state left",
    ) as exc:
        _run(out)
    assert "\n" not in str(exc.value)


def test_model_folder_with_changed_weights_is_refused(tmp_path):
    save_model_folder(tmp_path / "m", "linear", {"width": 64}, {"w": torch.arange(4096, dtype=torch.float32)})
    assert load_model_folder(tmp_path / "m", "linear")[1]["w"][7] == 7
    _flip_tensor_byte(tmp_path / "m" / "model.safetensors")
    with pytest.raises(
        DrivewmError, match=r"model\.safetensors does not match config\.json's weights_digest: the weights changed"
    ):
        load_model_folder(tmp_path / "m", "linear")
