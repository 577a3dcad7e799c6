"""The trajectory probe (drivewm.multiview.trajectory_probe): the loss gap of mirrored against own
waypoints flips sign exactly on mirrored data, is exactly 0 for a model whose trajectory pathway is
closed, the pathway split isolates the camera rays, and post-training logs the gap of the weights it is
training, in the rows it says."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
import torch

from drivewm.diffusion.text2world import Text2World
from drivewm.multiview.config import MultiViewConfig
from drivewm.multiview.data import MultiViewDataset
from drivewm.multiview.init import from_text2world
from drivewm.multiview.model import MultiView
from drivewm.multiview.posttrain import posttrain, posttrain_config
from drivewm.multiview.trajectory_probe import MIRROR, SPLIT, clip_losses, loss_gap, turning_clips

pytestmark = pytest.mark.slow  # the simulated clips coded by the stand-in tokenizer, and a post-training run

FRONT3 = ["CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT"]


class Mirrored:
    """A dataset whose every clip's waypoints are mirrored (y -> -y)."""

    def __init__(self, ds: MultiViewDataset):
        self.ds = ds

    def __getitem__(self, i: int):
        s = self.ds[i]
        return dataclasses.replace(s, trajectory=s.trajectory * MIRROR)


def _model(mv_parent_dir, open_trajectory: bool, **multiview) -> MultiView:
    """The tiny parent as a multi-view model, every weight perturbed (as after training: the parent's
    zero-initialised output layer would make every loss the same), the waypoint encoder's last
    layer too when ``open_trajectory`` (else it stays zero, as initialised)."""
    torch.manual_seed(0)
    multiview = {"frame_motion": False, "moving_camera_rays": True, **multiview}  # the pathways these tests isolate
    model = from_text2world(Text2World.from_pretrained(mv_parent_dir), MultiViewConfig(**multiview))
    closed = {id(p) for p in model.net.trajectory_encoder.net[-1].parameters()}
    with torch.no_grad():
        for p in model.net.parameters():
            if open_trajectory or id(p) not in closed:
                p.add_(0.05 * torch.randn_like(p))
    return model


def _dataset(mv_latents, model: MultiView) -> MultiViewDataset:
    return MultiViewDataset(mv_latents, FRONT3, model.cfg.multiview.trajectory_waypoints, model.cfg.edm.sigma_data)


def test_gap_flips_on_mirrored_data_and_is_zero_without_a_pathway(mv_latents, mv_parent_dir):
    model = _model(mv_parent_dir, open_trajectory=True)
    ds = _dataset(mv_latents, model)
    clips = turning_clips(ds, 4, min_turn_deg=0.0)
    assert len(clips) == 4
    gap, t = loss_gap(model.net, model, ds, clips)
    gap_m, t_m = loss_gap(model.net, model, Mirrored(ds), clips)
    assert abs(gap) > 1e-6
    assert gap_m == pytest.approx(-gap, rel=1e-4) and t_m == pytest.approx(-t, rel=1e-3)
    # a waypoint encoder whose last layer is zero and rays that do not move with the trajectory: nothing to follow
    closed = _model(mv_parent_dir, open_trajectory=False, moving_camera_rays=False)
    gap_0, t_0 = loss_gap(closed.net, closed, _dataset(mv_latents, closed), clips)
    assert gap_0 == 0.0 and math.isnan(t_0)


def test_split_pathways_isolate_the_camera_rays(mv_latents, mv_parent_dir):
    """With the waypoint encoder closed, only the moving-camera rays see the trajectory: own waypoints
    with mirrored rays score exactly as the mirrored trajectory, mirrored waypoints with own rays as
    the own one; with the encoder open as well, both splits differ from both."""
    closed = _model(mv_parent_dir, open_trajectory=False)
    ds = _dataset(mv_latents, closed)
    names = ("own", "mirrored", *SPLIT)
    for i in turning_clips(ds, 2, min_turn_deg=0.0):
        own, mirrored, own_mirrored_rays, mirrored_own_rays = clip_losses(
            closed.net, closed, ds, i, 1.0, True, 7, names
        )
        assert abs(own - mirrored) > 1e-7
        assert own_mirrored_rays == pytest.approx(mirrored, rel=1e-6) and mirrored_own_rays == pytest.approx(
            own, rel=1e-6
        )
    both = _model(mv_parent_dir, open_trajectory=True)
    own, mirrored, own_mirrored_rays, mirrored_own_rays = clip_losses(both.net, both, ds, i, 1.0, True, 7, names)
    assert min(abs(own_mirrored_rays - x) for x in (own, mirrored)) > 1e-7
    assert min(abs(mirrored_own_rays - x) for x in (own, mirrored)) > 1e-7


def test_posttrain_logs_the_gap_of_the_weights_it_trains(mv_latents, mv_parent_dir, tmp_path):
    overrides = [
        "rig=front3",
        "train.steps=4",
        "train.log_every=2",
        "train.checkpoint_every=1000",
        "sample_steps=1",
        "trajectory_probe_every=3",
        "trajectory_probe_clips=3",
        "trajectory_probe_min_turn_deg=0",
    ]
    posttrain(posttrain_config("debug", overrides), mv_parent_dir, mv_latents, tmp_path)
    rows = [json.loads(line) for line in (tmp_path / "metrics.jsonl").read_text().splitlines()]
    assert [r["step"] for r in rows] == [2, 4]
    assert "trajectory_loss_gap" not in rows[0]  # the first row at or after step 3 is step 4's
    model = MultiView.from_pretrained(tmp_path)
    model.net.load_state_dict(torch.load(tmp_path / "train_state.pt", weights_only=True)["model"])  # not the EMA
    ds = _dataset(mv_latents, model)
    gap, t = loss_gap(model.net, model, ds, turning_clips(ds, 3, min_turn_deg=0.0))
    assert rows[1]["trajectory_loss_gap"] == pytest.approx(gap, rel=1e-4, abs=1e-9)
    assert rows[1]["trajectory_loss_gap_t"] == pytest.approx(t, rel=1e-3)
