"""Post-training keeps built clips in memory (``cache_clips``): latents and conditioning come back from
the cache unchanged, the loss is the one an uncached task computes, and the cache holds at most
``cache_clips`` clips, least recently used dropped first."""

from __future__ import annotations

import pytest
import torch

from drivewm.errors import DrivewmError
from drivewm.multiview.data import MultiViewDataset
from drivewm.multiview.model import MultiView
from drivewm.multiview.posttrain import MultiViewTask, posttrain, posttrain_config

FRONT3 = ["CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT"]


def test_a_negative_cache_size_is_refused():
    with pytest.raises(DrivewmError, match="cache_clips"):
        posttrain_config("debug", ["cache_clips=-1"])


@pytest.mark.slow  # post-trains the stand-in model for one step on the simulated clips
def test_cached_clips_give_the_uncached_loss_and_the_cache_is_bounded(mv_latents, mv_parent_dir, tmp_path):
    base = ["rig=front3", "train.steps=1", "sample_steps=1", "trajectory_probe_every=0"]
    posttrain(posttrain_config("debug", base), mv_parent_dir, mv_latents, tmp_path / "run")
    model = MultiView.from_pretrained(tmp_path / "run")
    ds = MultiViewDataset(mv_latents, FRONT3, 16, 0.5)
    assert len(ds) >= 2
    cached = MultiViewTask(posttrain_config("debug", [*base, "cache_clips=1"]), ds, model)
    plain = MultiViewTask(posttrain_config("debug", [*base, "cache_clips=0"]), ds, model)
    cpu = torch.device("cpu")
    with torch.no_grad():
        losses = [task.loss(model.net, [0, 1], [3, 4], cpu) for task in (plain, cached, cached)]
    assert torch.equal(losses[0], losses[1]) and torch.equal(losses[0], losses[2])
    assert list(cached._prepared) == [1] and not plain._prepared  # one clip kept: the last one used
    cond = cached.prepared(1).cond
    assert cached.prepared(1).cond is cond  # from memory, not rebuilt
    rebuilt = plain.prepared(1).cond
    assert torch.equal(rebuilt.rays, cond.rays) and torch.equal(rebuilt.text_emb, cond.text_emb)
