"""End to end on the simulated clips: posttrain -> generate (3- and 6-camera rigs) -> clips that the
clip reader and the eval stage's inputs accept; rollout of a real clip; bad input errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch
from mv_standin import PoolTokenizer

from drivewm.cli import main
from drivewm.clips import iter_clips
from drivewm.generate.config import RECIPES
from drivewm.generate.rollout import load_clip, rollout
from drivewm.multiview.model import MultiView
from drivewm.multiview.trajectories import resolve_trajectory

pytestmark = pytest.mark.slow  # post-trains a multi-view model

FRONT3 = ["CAM_FRONT_LEFT", "CAM_FRONT", "CAM_FRONT_RIGHT"]


@pytest.fixture(scope="module")
def trained_mv(mv_latents: Path, mv_parent_dir: Path, tmp_path_factory) -> tuple[Path, Path]:
    """A multi-view model post-trained on front3 (30 steps) from the tiny Text2World parent."""
    root, cache = tmp_path_factory.mktemp("mv_cli"), mv_latents
    (root / "t2w").symlink_to(mv_parent_dir)
    args = [
        "posttrain",
        "--init",
        str(root / "t2w"),
        "--data",
        str(cache),
        "--rig",
        "front3",
        "--out",
        str(root / "mv"),
        "--set",
        "train.steps=30",
        "--set",
        "train.checkpoint_every=1000",
        "--set",
        "sample_steps=2",
        "--set",  # without per-frame motion, so a fine-tune can add it
        "multiview.frame_motion=false",
        "--set",
        "multiview.moving_camera_rays=true",
    ]
    assert main(args) == 0
    return root, cache


def test_posttrain_writes_a_multiview_folder(trained_mv):
    root, _ = trained_mv
    model = MultiView.from_pretrained(root / "mv")
    assert model.training_rig.names == FRONT3
    rows = [json.loads(line) for line in (root / "mv" / "metrics.jsonl").read_text().splitlines()]
    assert rows[-1]["step"] == 30 and np.isfinite(rows[-1]["loss"])
    assert 5 < model.cfg.multiview.speed_mps < 40  # the simulated drives' median speed, m/s
    assert (root / "mv" / "samples" / "step_0000030.png").is_file()


def test_posttrain_fine_tunes_a_multiview_folder(trained_mv, tmp_path):
    """--init a multi-view folder (the fleet fine-tuning path): its weights start the run, none
    re-initialised; a structurally different config is refused in one line; per-frame motion
    conditioning can be added (its encoder starts at zero), and a model with it keeps it."""
    root, cache = trained_mv
    args = ["posttrain", "--init", str(root / "mv"), "--data", str(cache), "--rig", "front3"]
    own = ["--set", "multiview.frame_motion=false", "--set", "multiview.moving_camera_rays=true"]  # the init's
    assert main([*args, *own, "--out", str(tmp_path / "ft"), "--set", "train.steps=2", "--set", "sample_steps=2"]) == 0
    state = torch.load(tmp_path / "ft" / "train_state.pt", weights_only=True)
    start = MultiView.from_pretrained(root / "mv").net.state_dict()
    tuned = MultiView.from_pretrained(tmp_path / "ft").net.state_dict()
    assert state["config"]["init"] == str((root / "mv").resolve()) and start.keys() == tuned.keys()
    deltas = [float((tuned[k] - start[k]).abs().max()) for k in start if start[k].is_floating_point()]
    assert 0 < max(deltas) < 0.05  # two small steps away from the multi-view model, not a fresh init
    bad = [*args, "--out", str(tmp_path / "bad"), "--set", "multiview.camera_width=64"]
    assert main(bad) == 2
    motion = []  # the defaults (the shipped model's settings): per-frame motion, static rays
    two_steps = ["--set", "train.steps=2", "--set", "sample_steps=2"]
    assert main([*args, "--out", str(tmp_path / "motion"), *two_steps, *motion]) == 0
    added = MultiView.from_pretrained(tmp_path / "motion").net.state_dict()  # a fine-tune adds per-frame motion
    assert sorted(set(added) - set(start)) == sorted(k for k in added if k.startswith("motion_encoder."))
    assert 0 < float(added["motion_encoder.net.2.weight"].abs().max()) < 0.01  # fresh: zero, two steps ago
    again = ["posttrain", "--init", str(tmp_path / "motion"), "--data", str(cache), "--rig", "front3"]
    assert main([*again, "--out", str(tmp_path / "again"), *two_steps]) == 0  # no settings repeated: it keeps them
    kept = MultiView.from_pretrained(tmp_path / "again").cfg.multiview
    assert kept.frame_motion and not kept.moving_camera_rays


@pytest.mark.parametrize("rig,views", [("front3", 3), ("nuscenes6", 6)])
def test_generate_writes_clips_for_any_rig(trained_mv, rig, views):
    root, _ = trained_mv
    out = root / f"gen_{rig}"
    assert (
        main(
            [
                "generate",
                "--model",
                str(root / "mv"),
                "--rig",
                rig,
                "--prompt",
                "a snowy highway",
                "--trajectory",
                "left",
                "--steps",
                "2",
                "--set",
                "prompt_template=false",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    clips = list(iter_clips(out))
    assert len(clips) == 1 and len(clips[0].meta.cameras) == views
    meta = clips[0].meta
    np.testing.assert_allclose(
        meta.trajectory_ego, resolve_trajectory("left", 16, 0.1, meta.extra["speed_mps"]), atol=1e-9
    )
    assert meta.trajectory_ego[-1][1] > 0.1  # a left turn ends to the left (ego y > 0)
    assert clips[0].videos().shape[:2] == (views, 5) and clips[0].T_world_from_ego.shape == (
        5,
        4,
        4,
    )  # preview: latent frames
    assert "front-left camera view of a snowy highway" in meta.view_captions["CAM_FRONT_LEFT"]
    assert (out / "sample_000.mp4").stat().st_size > 0 and (out / "contact_sheet.png").is_file()
    from drivewm.eval.inputs import load_items

    (item,) = load_items(out)  # what `drivewm eval GENDIR` scores: the rig and the conditioned trajectory
    assert item.rig.names == meta.cameras and item.trajectory_ego == meta.trajectory_ego and item.trajectory_dt_s == 0.1
    assert meta.tags["weather"] == "snow" and item.tags["weather"] == "snow"  # adherence checks what was asked


def test_rollout_continues_a_real_clip_and_keeps_its_frames(trained_mv, sim_clip_dir):
    root, _ = trained_mv
    model = MultiView.from_pretrained(root / "mv")
    clip = load_clip(sim_clip_dir)
    cfg = RECIPES.resolve(overrides=["trajectory=stop", "rollout.windows=2", "sampling.steps=2", "sampling.guidance=1"])
    sample = rollout(model, clip, cfg, PoolTokenizer(32))
    assert sample.extra["post_processing"] == []  # the network's own frames
    assert sample.videos.shape[:2] == (3, 1 + 2 * 16)  # 1 conditioning frame + 2 windows of 16
    real = torch.from_numpy(clip.video("CAM_FRONT")[:1]).float()
    kept = torch.from_numpy(sample.videos[1, :1]).float()  # the first frame: the real one, at the tokenizer's size
    assert (real - kept).abs().mean() < 1.0
    travelled = sample.trajectory_ego[-1][0]
    assert np.asarray(sample.trajectory_ego).shape == (32, 3)
    np.testing.assert_allclose(
        travelled, sample.extra["speed_mps"] * 3.2 / 2, rtol=0.02
    )  # uniform stop over 3.2 s: v T / 2


def test_rollout_of_a_one_camera_dashcam_clip_on_a_three_camera_model(trained_mv, dashcam_clips):
    """Any rig: the real dashcam's one camera rolls out on a front3 model (it was refused for lacking
    the model's side cameras); its ego motion is unknown, so the named trajectory runs at the model's
    default speed, not at the 0 m/s of its identity placeholder poses."""
    root, _ = trained_mv
    model = MultiView.from_pretrained(root / "mv")
    clip = load_clip(dashcam_clips)
    cfg = RECIPES.resolve(overrides=["rollout.windows=1", "sampling.steps=2", "sampling.guidance=1"])
    sample = rollout(model, clip, cfg, PoolTokenizer(32))
    assert sample.rig.names == ["CAM_FRONT"] and sample.videos.shape[:2] == (1, 17)
    np.testing.assert_allclose(sample.rig.cameras[0].K, clip.meta.get_rig().cameras[0].K)  # the clip's calibration
    assert sample.extra["speed_mps"] == model.cfg.multiview.speed_mps > 1.0
    assert sample.trajectory_ego[-1][0] == pytest.approx(model.cfg.multiview.speed_mps * 1.6, rel=0.02)


def test_bad_inputs_give_one_line_errors(trained_mv, tmp_path, capsys):
    root, cache = trained_mv
    assert (
        main(
            [
                "generate",
                "--model",
                str(root / "mv"),
                "--prompt",
                "x",
                "--trajectory",
                str(tmp_path / "nope.npy"),
                "--out",
                str(tmp_path / "g"),
            ]
        )
        == 2
    )
    assert "nope.npy" in capsys.readouterr().err
    assert (
        main(
            [
                "posttrain",
                "--init",
                str(root / "t2w"),
                "--data",
                str(cache),
                "--rig",
                "nonexistent_rig",
                "--out",
                str(tmp_path / "m"),
            ]
        )
        == 2
    )
    assert "nonexistent_rig" in capsys.readouterr().err
    assert main(["posttrain", "--init", str(tmp_path), "--data", str(cache), "--out", str(tmp_path / "m")]) == 2
    assert "not a drivewm model folder" in capsys.readouterr().err
    for weight in ("nan", "-1"):  # NaN guidance had decoded to a black clip, written without a word
        command = ["generate", "--model", str(root / "mv"), "--prompt", "x", "--steps", "1"]
        assert main([*command, "--trajectory-guidance", weight, "--out", str(tmp_path / "tg")]) == 2
        err = capsys.readouterr().err
        assert err.startswith("error: ") and "trajectory_guidance" in err and len(err.strip().splitlines()) == 1
        assert not (tmp_path / "tg").exists()


def test_training_moves_the_trajectory_encoder_and_the_samples_follow_its_input(trained_mv):
    root, _ = trained_mv
    model = MultiView.from_pretrained(root / "mv")
    assert model.net.trajectory_encoder.net[-1].weight.abs().sum() > 0  # left zero-init behind
    rig = model.training_rig
    caps = [["a highway"] * 3]
    z = [
        model.sample_latents(rig, caps, resolve_trajectory(name, 16, 0.1, 20.0)[None], [7], steps=4, guidance=1.0)
        for name in ("left", "right")
    ]
    assert (z[0] - z[1]).abs().mean() > 1e-3  # same seed, other trajectory: another sample


def test_rollout_and_condition_clip_commands_with_a_real_tokenizer(mv_with_tokenizer, sim_clip_dir, tmp_path):
    first = load_clip(sim_clip_dir)
    assert (
        main(
            [
                "rollout",
                "--model",
                str(mv_with_tokenizer),
                "--clip",
                str(sim_clip_dir),
                "--key",
                first.key,
                "--trajectory",
                "right",
                "--windows",
                "1",
                "--steps",
                "1",
                "--trajectory-guidance",
                "2",
                "--out",
                str(tmp_path / "roll"),
            ]
        )
        == 0
    )
    (clip,) = list(iter_clips(tmp_path / "roll"))
    assert (
        clip.meta.cameras == ["CAM_FRONT"] and clip.meta.num_frames == 17 and clip.meta.extra["rollout_of"] == first.key
    )
    real, kept = first.video("CAM_FRONT")[0].astype(float), clip.video("CAM_FRONT")[0].astype(float)
    assert np.abs(real - kept).mean() < 4.0  # the conditioning frame is the real one (through H.264 at crf 18)
    assert clip.meta.trajectory_ego[-1][1] < -0.05  # turning right: the ego ends to the right (y < 0)
    assert clip.meta.extra["post_processing"] == [] and "reproject" not in clip.meta.extra  # plain by default

    assert (
        main(
            [
                "generate",
                "--model",
                str(mv_with_tokenizer),
                "--prompt",
                "night",
                "--condition-clip",
                str(sim_clip_dir),
                "--steps",
                "1",
                "--trajectory-guidance",
                "3",
                "--out",
                str(tmp_path / "gen"),
            ]
        )
        == 0
    )
    (gen,) = list(iter_clips(tmp_path / "gen"))
    assert gen.meta.num_frames == 17 and gen.meta.extra["condition_clip"] == str(sim_clip_dir)
    assert gen.meta.extra["trajectory_guidance"] == 3.0 and gen.meta.extra["post_processing"] == []
    stitched = ["--set", "post_processing=[stitch]", "--out", str(tmp_path / "refused")]
    command = ["generate", "--model", str(mv_with_tokenizer), "--prompt", "x", "--condition-clip", str(sim_clip_dir)]
    assert main([*command, "--steps", "1", *stitched]) == 2  # a real clip's frames are never blended
    assert not (tmp_path / "refused").exists()
