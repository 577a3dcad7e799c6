"""Steering rebalance in post-training (``turn_repeat``): turning clips fill more of every epoch,
the loss reads the repeated clip at a repeated position, and a run resumed mid-way equals one that
ran through."""

from __future__ import annotations

import json
import shutil
import types

import numpy as np
import pytest
import torch

from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.multiview.data import MultiViewSample
from drivewm.multiview.posttrain import MultiViewTask, posttrain, posttrain_config
from drivewm.multiview.trajectory_probe import is_turning


def _arc(turn_deg: float, n: int = 16, length_m: float = 30.0) -> np.ndarray:
    """(n, 3) waypoints along a circular arc of ``length_m`` turning ``turn_deg`` (left positive)."""
    s = np.linspace(length_m / n, length_m, n)
    if turn_deg == 0:
        return np.stack([s, 0 * s, 0 * s], axis=1)
    r = length_m / np.radians(turn_deg)
    a = s / r
    return np.stack([r * np.sin(a), r * (1 - np.cos(a)), 0 * s], axis=1)


def _sample(turn_deg: float, known: bool = True) -> MultiViewSample:
    rig = load_rig("front3")
    return MultiViewSample(torch.zeros(3, 1, 1, 1, 1), ["x"] * 3, _arc(turn_deg), rig, 10.0, known)


def _task(samples: list[MultiViewSample], *overrides: str) -> MultiViewTask:
    cfg = posttrain_config("debug", list(overrides))
    return MultiViewTask(cfg, samples, types.SimpleNamespace(net=torch.nn.Linear(1, 1)))


def test_turning_clips_are_repeated_in_every_epoch():
    # straight, 30 left, 30 right, 10 left, and a 30-degree arc whose ego motion is unknown (counts straight)
    samples = [_sample(0), _sample(30), _sample(-30), _sample(10), _sample(30, known=False)]
    assert [is_turning(s, 15) for s in samples] == [False, True, True, False, False]
    task = _task(samples, "turn_repeat=3", "turn_repeat_min_deg=15")
    assert task.epoch_order() == [0, 1, 2, 3, 4, 1, 2, 1, 2, 1, 2]
    assert task.num_samples() == 11
    assert _task(samples, "turn_repeat=3", "turn_repeat_min_deg=5").num_samples() == 5 + 3 * 3
    assert _task(samples).epoch_order() == [0, 1, 2, 3, 4]  # the default: each clip once


def test_bad_settings_are_refused():
    for bad in ("turn_repeat=-1", "turn_repeat_min_deg=-5", "turn_repeat=two"):
        with pytest.raises(DrivewmError, match="turn_repeat"):
            posttrain_config("debug", [bad])


@pytest.mark.slow  # the simulated clips coded by the stand-in tokenizer, and post-training runs
def test_posttrain_with_turn_repeat_reads_the_repeated_clip_and_resumes_exactly(mv_latents, mv_parent_dir, tmp_path):
    base = ["rig=front3", "train.steps=4", "train.log_every=1", "train.checkpoint_every=2", "sample_steps=1"]
    base += ["trajectory_probe_every=0", "turn_repeat=2", "turn_repeat_min_deg=0.5"]
    through = posttrain(posttrain_config("debug", base), mv_parent_dir, mv_latents, tmp_path / "through")
    posttrain(posttrain_config("debug", base), mv_parent_dir, mv_latents, tmp_path / "resumed", stop_after=2)
    resumed = posttrain(posttrain_config("debug", base), mv_parent_dir, mv_latents, tmp_path / "resumed")
    assert resumed["loss"] == through["loss"] and resumed["step"] == through["step"] == 4
    a = torch.load(tmp_path / "through" / "train_state.pt", weights_only=True)["model"]
    b = torch.load(tmp_path / "resumed" / "train_state.pt", weights_only=True)["model"]
    assert all(torch.equal(a[k], b[k]) for k in a)

    from drivewm.multiview.data import MultiViewDataset
    from drivewm.multiview.model import MultiView

    model = MultiView.from_pretrained(tmp_path / "through")
    ds = MultiViewDataset(mv_latents, ["CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT"], 16, 0.5)
    task = MultiViewTask(posttrain_config("debug", base), ds, model)
    order = task.epoch_order()
    turning = [i for i in range(len(ds)) if is_turning(ds[i], 0.5)]
    assert turning and order == list(range(len(ds))) + turning * 2
    repeated = len(ds) + len(turning)  # the second repeat of the first turning clip
    with torch.no_grad():
        at_repeat = task.loss(model.net, [repeated], [11], torch.device("cpu"))
        at_clip = task.loss(model.net, [turning[0]], [11], torch.device("cpu"))
    assert torch.equal(at_repeat, at_clip)


def test_a_fine_tune_can_interpolate_the_positions_of_a_larger_grid(mv_latents, mv_parent_dir, tmp_path):
    """posttrain --set rope_spatial_scale=0.5: the run trains and saves a model whose DiT builds its
    rotations at half the row and column positions; without it, the init's (1) is kept."""
    from drivewm.multiview.model import MultiView

    base = ["rig=front3", "train.steps=3", "train.lr=1e-2", "sample_steps=1"]  # step 1 opens the zero gates
    losses = {}
    for scale in (None, 0.5):
        extra = [] if scale is None else [f"rope_spatial_scale={scale}"]
        torch.manual_seed(0)
        out = tmp_path / str(scale)
        losses[scale] = posttrain(posttrain_config("debug", base + extra), mv_parent_dir, mv_latents, out)["loss"]
        model = MultiView.from_pretrained(out)
        assert model.cfg.dit.rope_spatial_scale == (scale or 1.0)
        assert model.net.denoiser.backbone.cfg is model.cfg.dit  # the DiT reads the saved value
    assert losses[0.5] != losses[None]  # the positions changed what the later steps saw
    with pytest.raises(DrivewmError, match="rope_spatial_scale"):
        posttrain_config("debug", ["rope_spatial_scale=0"])


def test_a_fine_tune_whose_tokenizer_is_gone_stops_before_training(mv_with_tokenizer, mv_latents, tmp_path):
    """A copied model folder whose relative tokenizer path resolves to nothing: posttrain says so at
    once, instead of after the last step, when the sample grid needs the tokenizer."""
    copy = tmp_path / "copied"
    shutil.copytree(mv_with_tokenizer, copy)
    config = json.loads((copy / "config.json").read_text())
    config["latent"]["tokenizer"] = "../tokenizer"  # as the shipped folders record theirs
    (copy / "config.json").write_text(json.dumps(config))
    with pytest.raises(DrivewmError, match="tokenizer .*copied model folder"):
        posttrain(posttrain_config("debug", ["train.steps=1"]), copy, mv_latents, tmp_path / "run")
    assert not (tmp_path / "run").exists()
