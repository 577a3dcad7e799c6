import dataclasses
import io
import json
import tarfile

import numpy as np
import pytest

from drivewm.clips import ClipMeta, ShardWriter, iter_clips, read_manifest
from drivewm.clips.format import clip_from_arrays
from drivewm.clips.shards import iter_shard, write_manifest
from drivewm.clips.video import decode_mp4, encode_mp4
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig


def psnr(a, b):
    # yuv420p halves chroma resolution; on these saturated colour gradients that bounds PSNR near 34-36 dB
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return 10 * np.log10(255.0**2 / mse)


def smooth_video(T=9, H=64, W=96, seed=0):
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W]
    frames = []
    for t in range(T):
        r = 128 + 100 * np.sin(xx / 9.0 + t * 0.3 + seed)
        g = 128 + 100 * np.cos(yy / 7.0 - t * 0.2)
        b = 128 + 60 * np.sin((xx + yy) / 13.0)
        frames.append(np.stack([r, g, b], -1))
    return np.clip(np.stack(frames) + rng.normal(0, 2, (T, H, W, 3)), 0, 255).astype(np.uint8)


def make_clip(key, T=9):
    rig = load_rig("front3").scaled(96, 64, fit="stretch")
    meta = ClipMeta(
        key=key,
        source_log="test.mcap",
        start_time_ns=0,
        fps=10.0,
        timestamps_ns=[i * 100_000_000 for i in range(T)],
        rig=rig.to_dict(),
        caption="a road",
    )
    frames = {c: smooth_video(T, seed=i) for i, c in enumerate(rig.names)}
    ego = np.repeat(np.eye(4)[None], T, axis=0)
    ego[:, 0, 3] = np.arange(T)
    return clip_from_arrays(meta, frames, ego), frames


def test_mp4_round_trip_is_near_lossless():
    video = smooth_video()
    out = decode_mp4(encode_mp4(video, fps=10.0), expected_frames=len(video))
    assert out.shape == video.shape
    assert psnr(out, video) > 32.0


def test_truncated_mp4_is_a_clear_error():
    data = encode_mp4(smooth_video(), fps=10.0)
    with pytest.raises(DrivewmError, match="cam0"):
        decode_mp4(data[: len(data) // 3], expected_frames=9, where="cam0")


def test_shard_round_trip_and_manifest(tmp_path):
    clips = [make_clip(f"clip{i}") for i in range(3)]
    with ShardWriter(tmp_path, "drive", max_clips=2) as writer:
        for clip, _ in clips:
            writer.write(clip)
    assert sorted(p.name for p in tmp_path.glob("*.tar")) == ["drive-000000.tar", "drive-000001.tar"]
    write_manifest(tmp_path, [{"key": k, "shard": s} for s, k in writer.written])
    assert [r["key"] for r in read_manifest(tmp_path)] == ["clip0", "clip1", "clip2"]
    back = list(iter_clips(tmp_path))
    assert [c.key for c in back] == ["clip0", "clip1", "clip2"]
    for (orig, frames), got in zip(clips, back):
        assert got.meta == orig.meta
        assert np.array_equal(got.T_world_from_ego, orig.T_world_from_ego)
        for cam in orig.meta.cameras:
            assert psnr(got.video(cam), frames[cam]) > 32.0


def test_reading_some_clips_and_some_frames(tmp_path):
    """iter_shard(keys=...) parses only those clips; Clip.frames gives those frames of the full video."""
    with ShardWriter(tmp_path, "drive", max_clips=8) as writer:
        for i in range(3):
            writer.write(make_clip(f"clip{i}")[0])
    shard = tmp_path / "drive-000000.tar"
    assert [c.key for c in iter_shard(shard, {"clip2", "clip0", "absent"})] == ["clip0", "clip2"]
    clip, again = (next(iter_shard(shard, {"clip1"})) for _ in range(2))
    cam = clip.meta.cameras[1]
    assert np.array_equal(clip.frames(cam, [8, 0, 4, 8]), again.video(cam)[[8, 0, 4, 8]])
    assert np.array_equal(again.frames(cam, [3]), again.video(cam)[[3]])  # from the decoded video
    with pytest.raises(DrivewmError, match="no video for camera 'nope'"):
        clip.frames("nope", [0])


def test_unsafe_member_is_refused(tmp_path):
    path = tmp_path / "evil.tar"
    with tarfile.open(path, "w") as tar:
        info = tarfile.TarInfo("../evil.json")
        info.size = 2
        tar.addfile(info, io.BytesIO(b"{}"))
    with pytest.raises(DrivewmError, match="unsafe member"):
        list(iter_clips(path))


def test_corrupt_shard_is_a_clear_error(tmp_path):
    clip, _ = make_clip("c")
    with ShardWriter(tmp_path, "d") as w:
        w.write(clip)
    shard = tmp_path / "d-000000.tar"
    shard.write_bytes(shard.read_bytes()[:3000])
    with pytest.raises(DrivewmError, match="d-000000.tar"):
        list(iter_clips(tmp_path))


def test_a_rig_that_loaded_once_is_not_rechecked_but_a_changed_one_is():
    """validate_meta remembers rigs that loaded (a log's clips share one): the same rig again passes
    without rebuilding its cameras, and any changed value is checked afresh (a non-rigid pose, a NaN K)."""
    from drivewm.clips import format as clip_format

    meta = make_clip("k0")[0].meta
    clip_format.validate_meta(meta)
    assert json.dumps(meta.rig, sort_keys=True) in clip_format._LOADED_RIGS
    bad_pose = json.loads(json.dumps(meta.rig))
    bad_pose["cameras"][0]["T_ego_from_cam"][0][0] = 2.0  # scales an axis: not a rigid transform
    bad_K = json.loads(json.dumps(meta.rig))
    bad_K["cameras"][-1]["K"][0][0] = float("nan")
    for rig in (bad_pose, bad_K):
        for _ in range(2):  # a refused rig is not remembered either
            with pytest.raises(DrivewmError, match="clip k0"):
                clip_format.validate_meta(dataclasses.replace(meta, rig=rig))
