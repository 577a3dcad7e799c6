"""Issue 15 items 7 and 9: ``drivewm eval`` on inputs that cannot all be scored. A batch where every
input failed exits 2 with one line per input; a bad clip beside good ones is a failed item, not a
traceback; clips the metrics cannot fully score say so on the console."""

from __future__ import annotations

import json
import sys
from fractions import Fraction
from pathlib import Path

import av
import numpy as np

from drivewm.cli import main
from drivewm.clips import ShardWriter
from drivewm.clips.video import encode_mp4

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "clips"))
from hostile_shards import edit_json, members, tiny_clip, write_members, write_shard  # noqa: E402


def _error_lines(err: str) -> list[str]:
    lines = err.splitlines()
    return lines[next(i for i, line in enumerate(lines) if line.startswith("error:")) :]


def _video(T: int, W: int = 80, H: int = 48) -> np.ndarray:
    yy, xx = np.mgrid[0:H, 0:W]
    return np.stack([np.stack([(xx * 3 + 5 * t) % 256, yy * 4, 0 * xx + 99], -1) for t in range(T)]).astype(np.uint8)


def _faststart_mp4(frames: np.ndarray, path: Path) -> bytes:
    """H.264 mp4 with the index (moov) first, as streaming encoders write it (faststart rewrites a file)."""
    with av.open(str(path), mode="w", format="mp4", options={"movflags": "faststart"}) as container:
        stream = container.add_stream("libx264", rate=Fraction(10))
        stream.width, stream.height, stream.pix_fmt = frames.shape[2], frames.shape[1], "yuv420p"
        for frame in frames:
            container.mux(stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")))
        container.mux(stream.encode())
    return path.read_bytes()


def _eval(capsys, location: Path, out: Path, *extra: str) -> tuple[int, str, dict]:
    rc = main(["eval", str(location), "--out", str(out), "--metrics", "tse", "--no-pictures", *extra])
    metrics = json.loads((out / "metrics.json").read_text()) if (out / "metrics.json").is_file() else {}
    return rc, capsys.readouterr().err, metrics


def test_every_input_failed_exits_2_with_a_line_per_input(tmp_path, capsys):
    grid = tmp_path / "grid.mp4"
    grid.write_bytes(encode_mp4(_video(9, W=240), 10.0))  # 3 columns of 80 px: front3's 5:3
    rc, err, metrics = _eval(capsys, grid, tmp_path / "e1", "--rig", "front3", "--grid", "1x3", "--frames", "2:12")
    assert rc == 2 and metrics["num_failed_clips"] == 1
    assert _error_lines(err) == [
        "error: eval: every input failed (1 of 1)",
        f"  {grid}: --frames 2:12 but the video has 9 frames",
    ]
    data = _faststart_mp4(_video(30), tmp_path / "whole.mp4")
    cut = tmp_path / "cut"
    for name in ("a", "b"):
        (cut / name).mkdir(parents=True)
        (cut / name / "CAM_FRONT.mp4").write_bytes(data[: len(data) // 2])  # the index survives, frames do not
    rc, err, metrics = _eval(capsys, cut, tmp_path / "e2", "--rig", "front3")
    lines = _error_lines(err)
    assert rc == 2 and lines[0] == "error: eval: every input failed (2 of 2)" and len(lines) == 3
    assert all("CAM_FRONT.mp4" in line for line in lines[1:])


def test_a_singular_k_clip_fails_alone_and_the_good_clip_is_scored(tmp_path, capsys):
    shard = write_shard(tmp_path / "src", "d", ["good", "bad"])
    singular = [[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [0.0, 0.0, 1.0]]
    items = edit_json(members(shard), "bad", lambda m: m["rig"]["cameras"][0].update(K=singular))
    write_members(tmp_path / "clips" / shard.name, items)
    rc, err, metrics = _eval(capsys, tmp_path / "clips", tmp_path / "e")
    assert rc == 0 and metrics["num_clips"] == 2 and metrics["num_failed_clips"] == 1
    assert "error" not in metrics["clips"]["good"] and "tse" in metrics["clips"]["good"]
    assert "K is singular or flipped" in metrics["clips"]["bad"]["error"]
    assert f"warning: failed {metrics['clips']['bad']['error']}" in err


def test_one_frame_clip_and_ragged_camera_videos_are_reported(tmp_path, capsys):
    with ShardWriter(tmp_path / "clips", "one") as writer:
        writer.write(tiny_clip("single", T=1))
        writer.write(tiny_clip("nine", T=9))
    rc, err, metrics = _eval(capsys, tmp_path / "clips", tmp_path / "e1")
    assert rc == 0 and metrics["clips"]["single"]["status"]["tse"] == "too_few_frames"
    assert metrics["clips"]["single"]["tse"] is None  # NaN, written as null
    assert "warning: single: tse: 1 frame(s), needs 2 (frame_gap 1)" in err
    folder = tmp_path / "ragged" / "clip0"
    folder.mkdir(parents=True)
    (folder / "CAM_FRONT.mp4").write_bytes(encode_mp4(_video(17), 10.0))
    (folder / "CAM_FRONT_LEFT.mp4").write_bytes(encode_mp4(_video(8), 10.0))
    rc, err, metrics = _eval(capsys, tmp_path / "ragged", tmp_path / "e2", "--rig", "front3")
    assert rc == 2
    assert (
        _error_lines(err)[1]
        == "  clip0: the cameras' videos have different frame counts {'CAM_FRONT_LEFT': 8, 'CAM_FRONT': 17}"
    )


def test_a_killed_writers_temporary_is_never_scored(tmp_path, capsys):
    """Issue 70: ``generate`` killed while its first shard was open leaves the shard in a hidden temporary
    (``OUT/.generated-000000.tar.HOST-NS-PID.XXXX.tmp/generated-000000.tar``); eval had taken that folder
    for a folder of clip folders and scored it. No reader descends into a hidden name: alone it is no
    input (exit 2), beside a whole shard only the whole shard's clips are scored, in both layouts."""
    out = tmp_path / "gen"
    temporary = out / ".generated-000000.tar.host-4026531836-99999.k2j4x8y1.tmp"
    write_shard(temporary, "generated", ["torn0", "torn1"])  # whole bytes: what counts is where it lies
    rc, err, metrics = _eval(capsys, out, tmp_path / "e1", "--rig", "front3")
    assert rc == 2 and "torn0" not in json.dumps(metrics) and err.splitlines()[-1].startswith("error: ")
    write_shard(out, "generated", ["sample_000"])
    rc, err, metrics = _eval(capsys, out, tmp_path / "e2")
    assert rc == 0 and list(metrics["clips"]) == ["sample_000"]
    prompts = tmp_path / "prompts"  # a folder of generate outputs, one per prompt
    write_shard(prompts / "snow", "generated", ["sample_000"])
    write_shard(prompts / ".rain.host-1-99999.k2j4x8y1.tmp" / "rain", "generated", ["sample_000"])
    rc, err, metrics = _eval(capsys, prompts, tmp_path / "e3")
    assert rc == 0 and list(metrics["clips"]) == ["snow/sample_000"]


def test_a_rig_sharing_no_camera_with_the_clips_is_named(tmp_path, capsys):
    """``--rig`` whose cameras the clips do not have had failed with "min() arg is an empty sequence"."""
    write_shard(tmp_path / "clips", "c", ["c0"])  # front3's CAM_FRONT_LEFT and CAM_FRONT
    (tmp_path / "back.yaml").write_text(
        "name: back\ncameras:\n"
        "  - {name: CAM_BACK, width: 64, height: 48, hfov_deg: 90, xyz: [0, 0, 1.5], yaw_deg: 180}\n"
    )
    rc, err, _ = _eval(capsys, tmp_path / "clips", tmp_path / "ev2", "--rig", str(tmp_path / "back.yaml"))
    assert rc == 2 and _error_lines(err)[1] == (
        "  clip c0: the rig back (['CAM_BACK']) shares no camera with its ['CAM_FRONT_LEFT', 'CAM_FRONT']"
    )
