"""``drivewm transfer``: transferred clips keep every label of their source; bad input is skipped."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from drivewm.cli import main
from drivewm.clips import iter_clips, read_manifest
from drivewm.clips.format import clip_from_arrays
from drivewm.clips.shards import ShardWriter
from drivewm.diffusion.dit_config import DiTConfig
from drivewm.diffusion.text2world import LatentInfo, Text2World, Text2WorldConfig
from drivewm.transfer.config import TransferConfig
from drivewm.transfer.init import from_text2world

KEPT_FIELDS = ("source_log", "start_time_ns", "fps", "timestamps_ns", "trajectory_ego", "trajectory_dt_s", "pair_id")


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> dict[str, Path]:
    """An untrained transfer model and its Text2World parent, both recording a real debug tokenizer (4x8x8)
    and latents of 160x96 clips (16 x 5 x 12 x 20)."""
    from drivewm.tokenizer import Tokenizer, preset

    root = tmp_path_factory.mktemp("transfer_models")
    torch.manual_seed(0)
    tok = Tokenizer(preset("debug"))
    tok.save_pretrained(root / "tok")
    parent = Text2World(
        Text2WorldConfig(DiTConfig(in_channels=16, hidden_dim=32, depth=1, num_heads=2, adaln_lora_dim=8)),
        LatentInfo([16, 5, 12, 20], tok.latent_mean.tolist(), tok.latent_std.tolist(), 10.0, str(root / "tok"), {}),
    )
    parent.save_pretrained(root / "t2w")
    from_text2world(parent, TransferConfig(), name=str(root / "t2w")).save_pretrained(root / "transfer")
    return {"transfer": root / "transfer", "t2w": root / "t2w", "tok": root / "tok"}


@pytest.fixture(scope="module")
def inputs(sim_clip_dir, tmp_path_factory) -> Path:
    """Two real simulated clips, a clip of the wrong length and a corrupt shard (and one/: one clip)."""
    root = tmp_path_factory.mktemp("transfer_inputs")
    clips = list(iter_clips(sim_clip_dir / "highway_clear-000000.tar"))[:2]
    with ShardWriter(root, "good") as writer:
        for clip in clips:
            writer.write(clip)
    with ShardWriter(root / "one", "one") as writer:
        writer.write(clips[0])
    short = clips[0]
    meta = type(short.meta)(**{**short.meta.to_json(), "key": "short", "timestamps_ns": short.meta.timestamps_ns[:9]})
    with ShardWriter(root, "short") as writer:
        writer.write(clip_from_arrays(meta, {c: short.video(c)[:9] for c in meta.cameras}, short.T_world_from_ego[:9]))
    (root / "broken-000000.tar").write_bytes(b"not a tar at all" * 100)
    return root


@pytest.mark.slow
def test_transfer_keeps_every_label(models, inputs, tmp_path) -> None:
    out = tmp_path / "out"
    argv = ["transfer", str(inputs), "--model", str(models["transfer"]), "--to", "snow", "--time-of-day", "night"]
    assert main([*argv, "--steps", "2", "--out", str(out)]) == 0
    report = json.loads((out / "report.json").read_text())
    assert len(report["written"]) == 2
    assert {f.get("clip", Path(f["shard"]).name) for f in report["failed"]} == {"short", "broken-000000.tar"}
    sources = {c.key: c for c in iter_clips(inputs / "good-000000.tar")}
    rows = {r["key"]: r for r in read_manifest(out)}
    for clip in iter_clips(out):
        src = sources[clip.meta.extra["transfer"]["source"]["key"]]
        assert clip.key == f"{src.key}-snow-night" and rows[clip.key]["pair_id"] == src.meta.pair_id != ""
        for field in KEPT_FIELDS:
            assert getattr(clip.meta, field) == getattr(src.meta, field), field
        np.testing.assert_array_equal(clip.T_world_from_ego, src.T_world_from_ego)
        assert clip.meta.tags == {**src.meta.tags, "weather": "snow", "time_of_day": "night"}
        assert "snow night" in clip.meta.caption and "clear" not in clip.meta.caption
        assert set(clip.meta.view_captions) == set(src.meta.cameras)
        assert all("snow night" in c for c in clip.meta.view_captions.values())
        assert clip.meta.rig == src.meta.rig  # at the source's size: its rig, intrinsics and all, exactly
        assert clip.videos().shape == src.videos().shape == (6, 17, 192, 320, 3)  # the model works at 160x96
        assert clip.meta.extra["transfer"]["method"] == "transfer" and clip.meta.extra["speed_mps"] > 0
        assert clip.meta.extra["transfer"]["model_resolution"] is False
        assert clip.meta.extra["transfer"]["shared_look"] is True  # the default
        assert (out / "sheets" / f"{clip.key}.png").is_file()
    assert (out / "contact_sheet.png").is_file()


def test_model_resolution_writes_the_models_size_with_the_rig_scaled(models, inputs, tmp_path) -> None:
    argv = ["transfer", str(inputs / "one"), "--model", str(models["transfer"]), "--to", "snow", "--steps", "1"]
    assert main([*argv, "--model-resolution", "--out", str(tmp_path)]) == 0
    (clip,) = iter_clips(tmp_path)
    (src,) = iter_clips(inputs / "one")
    assert clip.videos().shape == (6, 17, 96, 160, 3) and clip.meta.extra["transfer"]["model_resolution"] is True
    assert clip.meta.timestamps_ns == src.meta.timestamps_ns
    rig, src_rig = clip.meta.get_rig(), src.meta.get_rig()
    assert rig.names == src_rig.names
    for cam, src_cam in zip(rig.cameras, src_rig.cameras):
        # 320x192 -> the model's 160x96, pixel centres at integers: f' = f / 2, c' = (c + 0.5) / 2 - 0.5
        np.testing.assert_allclose(cam.K[:2, :2], src_cam.K[:2, :2] / 2)
        np.testing.assert_allclose(cam.K[:2, 2], (src_cam.K[:2, 2] + 0.5) / 2 - 0.5)
        np.testing.assert_array_equal(cam.T_ego_from_cam, src_cam.T_ego_from_cam)


@pytest.mark.slow
def test_transfer_keeps_each_clips_time_of_day_unless_told(models, inputs, tmp_path) -> None:
    argv = ["transfer", str(inputs / "one"), "--model", str(models["transfer"]), "--to", "fog"]
    assert main([*argv, "--steps", "1", "--out", str(tmp_path)]) == 0
    assert {c.meta.tags["time_of_day"] for c in iter_clips(tmp_path)} == {"day"}


@pytest.mark.slow
def test_max_clips_transfers_only_the_first_clips(models, inputs, tmp_path, capsys) -> None:
    argv = ["transfer", str(inputs / "good-000000.tar"), "--model", str(models["transfer"]), "--to", "rain"]
    assert main([*argv, "--steps", "1", "--max-clips", "1", "--out", str(tmp_path / "a")]) == 0
    first = next(iter_clips(inputs / "good-000000.tar"))
    assert [c.meta.extra["transfer"]["source"]["key"] for c in iter_clips(tmp_path / "a")] == [first.key]
    assert main([*argv, "--max-clips", "0", "--out", str(tmp_path / "b")]) == 2
    assert "max-clips" in capsys.readouterr().err and not (tmp_path / "b").exists()


@pytest.mark.slow
def test_sdedit_baseline_through_the_same_command(models, inputs, tmp_path, capsys) -> None:
    argv = ["transfer", str(inputs / "one"), "--model", str(models["t2w"]), "--to", "snow", "--steps", "1"]
    assert main([*argv, "--out", str(tmp_path / "x")]) == 2
    assert "start-sigma" in capsys.readouterr().err
    assert main([*argv, "--start-sigma", "2", "--out", str(tmp_path / "y")]) == 0
    assert {c.meta.extra["transfer"]["method"] for c in iter_clips(tmp_path / "y")} == {"sdedit"}


def test_nothing_transferred_is_an_error_with_each_reason(models, inputs, tmp_path, capsys) -> None:
    """A wrong-length clip and a corrupt shard and nothing else: exit 2 (it had exited 0 after
    "wrote 0 transferred clip(s)"), one line per skipped item, report.json still written."""
    bad = tmp_path / "bad"
    bad.mkdir()
    for name in ("short-000000.tar", "broken-000000.tar"):
        (bad / name).write_bytes((inputs / name).read_bytes())
    argv = ["transfer", str(bad), "--model", str(models["transfer"]), "--to", "snow", "--steps", "1"]
    assert main([*argv, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    failures = err[err.index("error: transfer: no clip transferred (2 skipped") :].splitlines()[1:]
    assert any("short" in line and "17-frame clips" in line for line in failures), err
    assert any("broken-000000.tar" in line for line in failures), err
    report = json.loads((tmp_path / "out" / "report.json").read_text())
    assert report["written"] == [] and len(report["failed"]) == 2


def test_a_missing_model_is_one_clear_error(inputs, tmp_path, capsys) -> None:
    assert (
        main(["transfer", str(inputs), "--model", str(tmp_path / "nope"), "--to", "snow", "--out", str(tmp_path)]) == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "nope" in err[0]


@pytest.mark.skipif(torch.cuda.is_available(), reason="checks the error on machines without CUDA")
def test_cuda_without_cuda_is_a_one_line_error_before_any_output(models, inputs, tmp_path, capsys) -> None:
    transfer = ["transfer", str(inputs / "one"), "--model", str(models["transfer"]), "--to", "snow"]
    train = ["transfer-train", "--init", str(models["t2w"]), "--data", str(inputs)]
    for argv in (transfer, train):
        assert main([*argv, "--device", "cuda", "--out", str(tmp_path / "out")]) == 2, argv[0]
        err = capsys.readouterr().err
        assert "CUDA is not available" in err and err.count("\n") == 1, err
        assert not (tmp_path / "out").exists()


DASHCAM_CALIBRATION = """name: dashcam
cameras:
  - {name: CAM_FRONT, width: 320, height: 180, hfov_deg: 60, xyz: [1.5, 0.0, 1.3], yaw_deg: 0}
"""


@pytest.mark.slow
def test_transfer_of_a_real_dashcam_video(models, shared_data, tmp_path) -> None:
    """The shared dashcam video (udacity solidWhiteRight, 221 frames at 25 fps) through import-video and
    curate, then transfer: one camera, unknown weather and ego motion, labels kept all the same."""
    (tmp_path / "cam.yaml").write_text(DASHCAM_CALIBRATION)
    video = shared_data / "video/dashcam_highway/solidWhiteRight.mp4"
    logs, clips, out = tmp_path / "logs", tmp_path / "clips", tmp_path / "out"
    assert main(["import-video", str(video), "--calibration", str(tmp_path / "cam.yaml"), "--out", str(logs)]) == 0
    assert main(["curate", str(logs), "--out", str(clips), "--recipe", "video"]) == 0
    argv = ["transfer", str(clips), "--model", str(models["transfer"]), "--to", "snow", "--steps", "1"]
    assert main([*argv, "--out", str(out)]) == 0
    sources = {c.key: c for c in iter_clips(clips)}
    done = list(iter_clips(out))
    assert len(done) == len(sources) == 5  # 8.8 s of video -> five 17-frame clips at 10 fps
    for clip in done:
        src = sources[clip.meta.extra["transfer"]["source"]["key"]]
        assert clip.meta.extra["transfer"]["source"]["weather"] == "unknown"
        assert clip.meta.tags["weather"] == "snow" and clip.meta.tags["time_of_day"] == "day"  # unknown -> day
        assert clip.meta.timestamps_ns == src.meta.timestamps_ns and clip.meta.pair_id == ""
        assert clip.meta.tags["ego_motion"] == "unknown"
        np.testing.assert_array_equal(clip.T_world_from_ego, src.T_world_from_ego)
        # the model works at 160x96 (320x180 stretched, not cropped); the clip comes back at 320x180, rig kept
        assert clip.videos().shape == src.videos().shape == (1, 17, 180, 320, 3)
        assert clip.meta.rig == src.meta.rig


@pytest.mark.slow
def test_no_shared_look_restores_each_view_on_its_own_and_says_so(models, inputs, tmp_path) -> None:
    """``--no-shared-look``: the same network output, each view's look its own; recorded in every clip.
    Only pixels in the cameras' overlaps may differ from the default's."""
    argv = ["transfer", str(inputs / "one"), "--model", str(models["transfer"]), "--to", "snow", "--steps", "1"]
    assert main([*argv, "--out", str(tmp_path / "shared")]) == 0
    assert main([*argv, "--no-shared-look", "--out", str(tmp_path / "own")]) == 0
    (shared,), (own,) = (list(iter_clips(tmp_path / d)) for d in ("shared", "own"))
    assert own.meta.extra["transfer"]["shared_look"] is False and shared.meta.extra["transfer"]["shared_look"]
    differs = np.abs(own.videos().astype(int) - shared.videos()).max(-1) > 0
    assert 0.0 < differs.mean() < 0.9
