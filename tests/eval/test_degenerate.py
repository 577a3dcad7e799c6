"""Degenerate outputs must not win: blurred (sigma 2.5 px), noised, frozen and shuffled copies of
real clips score worse than the real clips on every headline metric that the input has, and no
better on the pass rates (pose success, registered fraction: a blurred video whose poses still come
out passes them, and ``pose_auc`` ranks its poses), on a simulated clip (every metric: ego poses
and conditioning are known) and on the shared real dashcam video (TSE and the pass rates: one
camera, no poses)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from eval_degrade import DEGRADATIONS, GATES, HIGHER_IS_BETTER, LOWER_IS_BETTER, worse

from drivewm.eval.config import EvalConfig
from drivewm.eval.suite import evaluate_item
from drivewm.geometry import Camera, Rig, load_rig

HEADLINE = LOWER_IS_BETTER + HIGHER_IS_BETTER + GATES


def score_variants(item, cfg: EvalConfig) -> dict[str, dict]:
    """Metrics of the item's real videos and of each degraded copy (same rig, poses, conditioning)."""
    real = item.videos()
    out = {}
    for name, fn in {"real": lambda v: v, **DEGRADATIONS}.items():
        copy = dataclasses.replace(item)
        videos = fn(real)
        copy.videos = lambda videos=videos: videos
        out[name] = evaluate_item(copy, cfg, threads=2).metrics  # the figures of one thread, sooner on 2 cores
    return out


def check(scores: dict[str, dict], keys: tuple[str, ...]) -> list[str]:
    print({name: {k: m.get(k) for k in keys} for name, m in scores.items()})
    return [
        f"{name} {k}: {m.get(k)} vs real {scores['real'][k]}"
        for name, m in scores.items()
        if name != "real"
        for k in keys
        if not worse(k, m.get(k), scores["real"][k])
    ]


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_degraded_simulated_clip_scores_worse_on_every_headline_metric(sim_clip_dir):
    from drivewm.eval.inputs import load_items

    item = next(i for i in load_items(sim_clip_dir) if i.key == "highway_clear-000000")
    scores = score_variants(item, EvalConfig(metrics=["tse", "cse", "pose", "traj"]))
    keys = tuple(k for k in HEADLINE if k in scores["real"])
    assert set(keys) == set(HEADLINE)
    assert check(scores, keys) == []


def dashcam_camera() -> Camera:
    """The dashcam at 960x540: K from ../shared/data's chessboard calibration of the same car's camera
    (fx ~1156, fy ~1151, cx ~671, cy ~389 at 1280x720), scaled to the video's size; no distortion."""
    cam = Camera("CAM_FRONT", np.array([[1156.0, 0, 671], [0, 1151, 389], [0, 0, 1]]), 1280, 720, np.eye(4))
    return dataclasses.replace(load_rig("front1").camera("CAM_FRONT"), K=cam.scaled(960, 540).K, width=960, height=540)


@pytest.mark.slow
@pytest.mark.timeout(3600)
def test_degraded_real_dashcam_scores_worse_on_tse_and_pose(shared_data):
    """The first 32 frames (1.3 s at 25 fps) of the real highway dashcam video, at its native 960x540."""
    from drivewm.eval.inputs import load_items

    path = shared_data / "video" / "dashcam_highway" / "solidWhiteRight.mp4"
    item = load_items(path, Rig("dashcam", [dashcam_camera()]))[0]
    videos = {c: v[:32] for c, v in item.videos().items()}
    item.videos = lambda: videos
    scores = score_variants(item, EvalConfig(metrics=["tse", "pose"]))
    # no ego poses, so no path to travel: the pass rates without pose_success_path
    assert check(scores, ("tse", "tse_native", "pose_success", "registered_fraction")) == []
    assert "pose_success_path" not in scores["real"]
    assert scores["real"]["pose_success"] == 1.0
