"""The opt-in ``reproject`` post-step (drivewm.generate.reproject, drivewm.views.reproject): the first
frame of a real simulated clip, rendered along a named turn, reads as that turn to the eval's own flow
reader; refined by the shipped model, the samples turn the way they are told, and say so in their
``post_processing``."""

from __future__ import annotations

import numpy as np
import pytest

from drivewm.cli import main
from drivewm.clips import iter_clips
from drivewm.eval.trajectory import flow_fallback
from drivewm.eval.trajectory_errors import heading_change_deg
from drivewm.geometry import Rig, yaw_of
from drivewm.multiview.config import MultiViewConfig
from drivewm.multiview.trajectories import poses_from_waypoints, resolve_trajectory
from drivewm.views.reproject import reproject_first_frame

FPS = 10.0


def front_yaw_deg(videos: np.ndarray, rig: Rig) -> float:
    """Heading change (deg, left positive) the eval's dense-flow reader sees in the front camera."""
    ego = flow_fallback({n: videos[i] for i, n in enumerate(rig.names)}, rig)
    return heading_change_deg(ego.T_world_from_ego[ego.registered])


def named_waypoints(name: str, speed_mps: float) -> np.ndarray:
    mv = MultiViewConfig()
    return resolve_trajectory(name, mv.trajectory_waypoints, mv.trajectory_dt_s, speed_mps)


@pytest.mark.slow
def test_a_clip_rendered_along_a_turn_reads_as_that_turn(sim_clip_dir):
    """Frame 0 of a simulated six-camera clip, rendered along the named left and right turns at 15 m/s
    for 0.8 s (14.6 degrees): the eval's flow reader recovers each turn to within 2 degrees, and a
    straight rendering reads under 1; frame 0 is the clip's own."""
    clip = next(iter_clips(sorted(sim_clip_dir.glob("*.tar"))[0]))
    rig = clip.meta.get_rig()
    videos = np.stack([clip.video(n)[:9] for n in rig.names])  # (V, 9, H, W, 3): 0.8 s
    dt = MultiViewConfig().trajectory_dt_s
    for name in ("left", "right", "straight"):
        wp = named_waypoints(name, 15.0)
        truth = np.degrees(yaw_of(poses_from_waypoints(wp, videos.shape[1], dt, FPS)[-1]))
        assert abs(truth) == pytest.approx(0 if name == "straight" else 14.6, abs=0.5)
        out, rendered = reproject_first_frame(videos, rig, poses_from_waypoints(wp, videos.shape[1], dt, FPS))
        assert out.shape == videos.shape and out.dtype == np.uint8 and rendered.mean() > 0.9
        assert np.abs(out[:, 0].astype(int) - videos[:, 0]).max() <= 1  # frame 0 maps onto itself
        assert front_yaw_deg(out, rig) == pytest.approx(truth, abs=2 if truth else 1), name


def test_a_text2world_model_refuses_the_multiview_settings_only_when_they_are_asked_for(tmp_path, capsys):
    """generate's multi-view settings at their defaults do not stop a Text2World model; asking for
    them does, in one line, before any sampling."""
    argv = ["generate", "--model", "shipped:text2world", "--prompt", "snow", "--out", str(tmp_path / "o")]
    for flags in (
        ["--rig", "front3"],
        ["--trajectory", "left"],
        ["--recipe", "reprojected"],
        ["--trajectory-guidance", "2"],
    ):
        assert main([*argv, *flags]) == 2
        err = capsys.readouterr().err
        assert "a Text2World model takes no" in err and len(err.strip().splitlines()) == 1
    assert main([*argv, "--condition-clip", str(tmp_path)]) == 2
    assert "a text2world model takes no condition_clip" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_the_shipped_model_refined_from_a_reprojection_turns_as_told(tmp_path):
    """The shipped multi-view model, the same prompt and seed under the left and right turns, with the
    ``reprojected`` recipe's post-steps (reprojection from sigma 0.1, reshaded, blended, stitched): the
    samples' front cameras turn the asked way by more than 10 degrees, and the clip names every post-step."""
    from drivewm.generate.captions import template_view_captions

    yaws = {}
    for name in ("left", "right"):
        out = tmp_path / name
        argv = ["generate", "--prompt", "a clear day on a suburban road", "--trajectory", name, "--seed", "5"]
        argv += ["--steps", "3", "--guidance", "1", "--device", "cpu", "--out", str(out)]
        assert main([*argv, "--recipe", "reprojected", "--set", "reproject.steps=3"]) == 0
        clip = next(iter_clips(sorted(out.glob("*.tar"))[0]))
        rig = clip.meta.get_rig()
        yaws[name] = front_yaw_deg(np.stack([clip.video(n) for n in rig.names]), rig)
        extra = clip.meta.extra
        assert extra["post_processing"] == ["reproject", "reshade", "blend", "stitch"] and extra["prompt_template"]
        assert extra["reproject"] == {"sigma": 0.1, "steps": 3}
        want = template_view_captions(extra["prompt"], rig, np.asarray(clip.meta.trajectory_ego), 0.1)
        assert [clip.meta.view_captions[n] for n in rig.names] == want
        assert ("turning left" if name == "left" else "turning right") in want[0]
    assert yaws["left"] > 10 and yaws["right"] < -10, yaws


@pytest.mark.slow
def test_a_rollout_of_a_real_clip_refined_from_its_reprojection_turns_as_told(sim_clip_dir):
    """The shipped model continues one real simulated clip under left and right (Video2World, the
    same seed): reprojected from sigma 0.5, the continuations turn the asked way by more than 10
    degrees, and the clip records the setting."""
    from drivewm.generate.config import RECIPES
    from drivewm.generate.rollout import load_clip, rollout
    from drivewm.model_folders import shipped_model
    from drivewm.multiview.model import MultiView
    from drivewm.tokenizer import Tokenizer

    model = MultiView.from_pretrained(shipped_model("multiview"))
    tokenizer = Tokenizer.from_pretrained(model.latent.tokenizer)
    clip = load_clip(sim_clip_dir)
    yaws = {}
    for name in ("left", "right"):
        cfg = RECIPES.resolve(
            overrides=[f"trajectory={name}", "rollout.windows=1", "sampling.steps=3", "sampling.guidance=1"]
            + ["sampling.seed=3", "post_processing=[reproject,reshade]", "reproject.sigma=0.5", "reproject.steps=3"]
        )
        sample = rollout(model, clip, cfg, tokenizer)
        yaws[name] = front_yaw_deg(sample.videos, sample.rig)
        assert sample.extra["post_processing"] == ["reproject", "reshade"] and sample.extra["reproject"]["sigma"] == 0.5
    assert yaws["left"] > 10 and yaws["right"] < -10, yaws
