"""Clips without ego poses (the real dashcam through import-video): their identity placeholder poses
are never read as a car standing still, by post-training or by rollouts (DESIGN.md section 4)."""

import math

import numpy as np
import pytest
import torch

from drivewm.clips import iter_clips
from drivewm.diffusion.text2world import Text2World
from drivewm.generate.rollout import initial_speed_mps
from drivewm.multiview.data import MultiViewDataset
from drivewm.multiview.init import from_text2world
from drivewm.multiview.model import MultiView
from drivewm.multiview.posttrain import MultiViewTask, posttrain_config


def _front_cache(clip_dirs, out):
    """The front views of the clips of ``clip_dirs`` coded by the pooling stand-in into one latent
    cache: (3, 5, 6, 10) per view."""
    from mv_standin import PoolTokenizer, write_pooled_cache

    return write_pooled_cache(clip_dirs, out, PoolTokenizer(32), ["CAM_FRONT"])


@pytest.fixture(scope="module")
def mixed_cache(sim_clip_dir, dashcam_clips, tmp_path_factory):
    """Simulated clips (ego poses known) and the dashcam's (unknown) in one latent cache."""
    return _front_cache([sim_clip_dir, dashcam_clips], tmp_path_factory.mktemp("mixed_latents"))


def _split(ds):
    known = [i for i in range(len(ds)) if ds[i].trajectory_known]
    return known, [i for i in range(len(ds)) if i not in known]


def test_a_clip_without_ego_poses_has_no_trajectory_and_no_speed(mixed_cache):
    ds = MultiViewDataset(mixed_cache, ["CAM_FRONT"], 16)
    known, unknown = _split(ds)
    assert len(unknown) == 5 and all(ds.cache.rows[i]["key"].startswith("solidWhiteRight") for i in unknown)
    assert all(np.all(ds[i].trajectory == 0) for i in unknown)
    # The named trajectories' default speed comes from the clips that have one: the dashcam's 5
    # identity placeholders (0 m/s) do not pull it down.
    speeds = [np.linalg.norm(ds[i].trajectory[0, :2]) / ds.trajectory_dt_s for i in known]
    assert min(speeds) > 1.0
    assert ds.median_speed_mps(99.0) == pytest.approx(float(np.median(speeds)))


def test_post_training_drops_the_trajectory_of_a_clip_without_ego_poses(mixed_cache, mv_parent_dir):
    ds = MultiViewDataset(mixed_cache, ["CAM_FRONT"], 16)
    known, unknown = _split(ds)
    cfg = posttrain_config("debug", ["multiview.trajectory_dropout=0", "multiview.video2world_prob=0"])
    model = from_text2world(Text2World.from_pretrained(mv_parent_dir), cfg.multiview, cfg.cond_frames)
    task = MultiViewTask(cfg, ds, model)
    seen = []

    def forward(x, sigma, cond):
        seen.append(cond.trajectory_keep.tolist())
        return torch.zeros_like(x)

    task.loss(forward, [known[0], unknown[0], known[1]], [1, 2, 3], torch.device("cpu"))
    assert seen == [[True, False, True]]  # with dropout 0 only the clip without poses loses its trajectory


def test_fine_tuning_on_clips_without_ego_poses_keeps_the_models_speed(dashcam_clips, mv_parent_dir, tmp_path):
    """Fine-tuning a multi-view model on dashcam clips alone: no clip has a speed, so the named
    trajectories keep the model's (they were 0 m/s, then the preset's 15 m/s)."""
    from drivewm.multiview.config import MultiViewConfig
    from drivewm.multiview.posttrain import posttrain

    init = from_text2world(Text2World.from_pretrained(mv_parent_dir), MultiViewConfig(speed_mps=7.25))
    init.save_pretrained(tmp_path / "init")
    cache = _front_cache([dashcam_clips], tmp_path / "cache")
    posttrain(
        posttrain_config("debug", ["train.steps=1", "train.batch_size=1"]), tmp_path / "init", cache, tmp_path / "ft"
    )
    assert MultiView.from_pretrained(tmp_path / "ft").cfg.multiview.speed_mps == 7.25


def test_rollouts_from_a_clip_without_ego_poses_use_the_models_speed(sim_clip_dir, dashcam_clips):
    assert all(math.isnan(initial_speed_mps(c)) for c in iter_clips(dashcam_clips))  # was 0.0 m/s
    assert all(initial_speed_mps(c) > 1.0 for c in iter_clips(sim_clip_dir))
