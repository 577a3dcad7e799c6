"""Parallel eval equals serial eval, also when the calling process already ran torch and OpenCV
thread pools (as `drivewm quickstart` does before its eval stages): forked workers used to hang."""

from __future__ import annotations

import dataclasses

import cv2
import pytest
import torch

from drivewm.clips import Clip, ShardWriter
from drivewm.eval.config import EvalConfig
from drivewm.eval.suite import evaluate

pytestmark = pytest.mark.slow  # scores clips in two worker processes


@pytest.fixture(scope="module")
def two_clip_shard(tmp_path_factory, synth_clip6):
    out = tmp_path_factory.mktemp("two_clips")
    with ShardWriter(out, "synth") as writer:
        for key in ("synth_a", "synth_b"):
            meta = dataclasses.replace(synth_clip6.meta, key=key)
            writer.write(Clip(meta, synth_clip6.mp4, synth_clip6.T_world_from_ego))
    return out


@pytest.mark.timeout(300)
def test_two_workers_after_torch_and_opencv_threads_match_one(two_clip_shard):
    cv2.setNumThreads(2)
    torch.set_num_threads(2)
    x = torch.randn(512, 512)
    (x @ x).sum().item()  # start torch's intra-op pool in this process
    cv2.GaussianBlur(torch.rand(256, 256).numpy(), (5, 5), 1.0)  # and OpenCV's
    cfg = EvalConfig(metrics=["tse", "cse"])
    serial = evaluate(two_clip_shard, cfg=cfg, workers=1, progress=False, pictures=False)
    parallel = evaluate(two_clip_shard, cfg=cfg, workers=2, progress=False, pictures=False)
    for key in ("tse", "cse", "tse_calibrated", "cse_calibrated"):
        assert parallel[key] == pytest.approx(serial[key], rel=1e-9), key
    assert serial["tse"] < 0.5  # the synthetic clip is consistent, so the values compared are real
