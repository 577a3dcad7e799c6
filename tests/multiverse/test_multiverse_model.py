"""``drivewm multiverse --renderer model``: a multi-view model generates every future's cameras window
after window at the model's frame size, from its layout where the model has one, else from its ego
trajectory continuing the generated past; a model of another family is refused."""

from __future__ import annotations

import json

import numpy as np
import pytest
from multiverse_logs import write_test_log

from drivewm.cli import main
from drivewm.clips.video import decode_mp4
from drivewm.logs.reader import read_log
from drivewm.model_folders import resolve_model_folder
from drivewm.multiverse import MultiverseConfig
from drivewm.multiverse.model_cameras import ModelCameras, load_world_model, model_prompt, padded
from drivewm.multiverse.replay import branch_log
from drivewm.sim.scene import SceneTick


def _command(model, out) -> list[str]:
    return [
        "multiverse", "--scenario", "highway", "--at", "0.5", "--plans", "keep,brake", "--horizon", "2",
        "--rig", "front1", "--width", "160", "--height", "96", "--renderer", "model", "--model", str(model),
        "--steps", "1", "--prompt", "snow at night", "--out", str(out),
    ]  # fmt: skip


@pytest.mark.slow
def test_the_model_renders_every_future_from_its_layout(layout_model, tmp_path) -> None:
    assert main(_command(layout_model["tokens"], tmp_path / "out")) == 0
    ranking = json.loads((tmp_path / "out/ranking.json").read_text())
    assert ranking["renderer"] == "model" and ranking["model"] == str((layout_model["tokens"]).resolve())
    assert json.loads((tmp_path / "out/config.json").read_text())["model_steps"] == 1
    assert "(model " in (tmp_path / "out/report.html").read_text()
    futures = {}
    for plan in ("keep", "brake"):
        log = read_log(tmp_path / "out/futures" / plan / "drive.mcap")
        cam = log.rig.camera("CAM_FRONT")
        assert (cam.width, cam.height) == (80, 48)  # the calibration of the model's frames
        assert len(log.static) > 10  # the props the layouts were drawn with
        # past 0 .. 0.5 s (one window) and 2 s of future (two windows, the second padded): 6 + 20 frames
        assert len(log.pose_timestamps_ns) == 26 and len(log.images["CAM_FRONT"]) == 26
        futures[plan] = log.T_world_from_ego[-1, :3, 3]
        video = decode_mp4((tmp_path / "out/futures" / plan / "cameras/CAM_FRONT.mp4").read_bytes())
        assert video.shape == (20, 48, 80, 3) and video.std() > 1.0
    assert futures["brake"][0] < futures["keep"][0] - 1.0  # two different futures were generated


@pytest.mark.slow
def test_the_shipped_model_renders_every_future_from_its_trajectory(tmp_path) -> None:
    """shipped:multiview has no layout: the past is generated once (0 .. 0.5 s: one window) and each future
    continues its frame at the branch tick (2 s: one conditioning frame + 16 new ones a window, two windows),
    along the future's own ego trajectory, so keeping the speed and braking give different videos."""
    assert main(_command("shipped:multiview", tmp_path / "out")) == 0
    ranking = json.loads((tmp_path / "out/ranking.json").read_text())
    assert ranking["renderer"] == "model" and ranking["model"] == "shipped:multiview"
    assert ranking["renderer_description"].endswith("from its ego trajectory and prompt")
    assert ranking["model_sampling"]["steps"] == 1 and ranking["model_sampling"]["sampler"] == "heun"
    html = (tmp_path / "out/report.html").read_text()
    assert "from its ego trajectory and prompt" in html and "1 heun steps a window, guidance 7" in html
    videos, past = {}, None
    for plan in ("keep", "brake"):
        log = read_log(tmp_path / "out/futures" / plan / "drive.mcap")
        assert (log.rig.camera("CAM_FRONT").width, log.rig.camera("CAM_FRONT").height) == (160, 96)
        assert len(log.pose_timestamps_ns) == 26 and len(log.images["CAM_FRONT"]) == 26
        past = log.images["CAM_FRONT"][:6] if past is None else past
        assert log.images["CAM_FRONT"][:6] == past  # one generated past, the same bytes in every future
        videos[plan] = decode_mp4((tmp_path / "out/futures" / plan / "cameras/CAM_FRONT.mp4").read_bytes())
        assert videos[plan].shape == (20, 96, 160, 3) and videos[plan].std() > 1.0
    assert np.abs(videos["keep"].astype(int) - videos["brake"]).mean() > 1.0  # the trajectories differ


@pytest.mark.slow
def test_the_futures_batched_are_the_futures_generated_one_at_a_time(tmp_path) -> None:
    """Window k of every future is sampled in one denoiser batch: each future's frames are those of one
    call per future up to float rounding, and the batch keeps each future's own trajectory (the futures
    still differ). Rounding moves the first window by a few levels at most; the second window starts from
    those uint8 frames and guidance 7 amplifies the change at a few pixels (as 2 threads against 1 do:
    mean 0.018 levels there, against under 0.01 here)."""
    log = write_test_log(tmp_path / "drive.mcap")
    cfg = MultiverseConfig(log=str(log), at_s=1.0, horizon_s=2.5, past_s=0.5, plans=["keep", "brake", "left"])
    branch = branch_log(cfg)
    generator = load_world_model(resolve_model_folder("shipped:multiview"), "cpu")
    batched = ModelCameras(branch, generator, "", 3, steps=2, progress=False)
    together = batched.futures_frames(branch.futures)
    alone = ModelCameras(branch, generator, "", 3, steps=2, progress=False)
    one_by_one = [alone.frames(f) for f in branch.futures]
    assert batched.windows_sampled == alone.windows_sampled == 1 + 3 * 2  # the past, then 2 windows a future
    for a, b in zip(together, one_by_one):
        assert a.keys() == b.keys() and a["CAM_FRONT"].shape == (25, 96, 160, 3)
        diff = np.abs(a["CAM_FRONT"].astype(int) - b["CAM_FRONT"])
        assert diff[:16].max() <= 6 and diff.mean() < 0.03 and (diff > 2).mean() < 0.005, (diff.max(), diff.mean())
    keep, brake = (together[i]["CAM_FRONT"].astype(int) for i in (0, 1))
    assert np.abs(keep - brake)[16:].mean() > 1.0  # the second window follows each future's own trajectory


def test_a_model_of_another_family_is_refused_before_any_work(layout_model, tmp_path, capsys) -> None:
    tokenizer = layout_model["none"].parent / "tok"
    for model, message in [(tokenizer, "cannot generate from model_type"), ("", "needs --model")]:
        assert main(_command(model, tmp_path / "out")) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error: ") and message in err[0], err
        assert not (tmp_path / "out").exists()


def test_a_short_window_is_padded_at_the_last_velocity() -> None:
    T = [np.eye(4) for _ in range(2)]
    T[1][:3, 3] = [1.5, 0.2, 0.0]
    ticks = [SceneTick(k * 100_000_000, T[k], [], 15.0) for k in range(2)]
    out = padded(ticks, 4)
    assert [t.timestamp_ns for t in out] == [0, 100_000_000, 200_000_000, 300_000_000]
    assert np.allclose(out[3].T_world_from_ego[:3, 3], [4.5, 0.6, 0.0]) and out[:2] == ticks
    assert padded(ticks, 1) == ticks[:1]


def test_the_model_prompt_carries_the_branch_conditions_it_does_not_name() -> None:
    tags = {"weather": "rain", "time_of_day": "dusk", "road_type": "highway"}
    assert model_prompt("", tags) == "rain, dusk"
    assert model_prompt("fog", {**tags, "weather": "fog"}) == "fog, dusk"
    assert model_prompt("snow at night", {**tags, "weather": "snow", "time_of_day": "night"}) == "snow at night"
