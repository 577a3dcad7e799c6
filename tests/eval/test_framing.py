"""Published outputs as they are: crop box, frame range, grids with borders and uneven cells, real rigs."""

from __future__ import annotations

import io
import json

import av
import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from drivewm.cli import main
from drivewm.clips.video import encode_mp4
from drivewm.errors import DrivewmError
from drivewm.eval.framing import Framing, grid_cells
from drivewm.eval.inputs import GridLayout, load_items, split_grid
from drivewm.geometry import load_rig

NUSCENES_FRONT_RIGHT = {  # nuScenes v1.0-mini calibrated_sensor f8d0aaa1a8234ba3aeed5867e0aa81aa
    "translation": [1.5508477543, -0.493404796419, 1.49574800619],
    "rotation": [0.2060347966337182, -0.2026940577919598, 0.6824507824531167, -0.6713610884174485],
}


def _published_grid(views: dict[str, np.ndarray], names: list[str], line_px: int, caption_px: int) -> np.ndarray:
    """A 2x3 grid as generators publish it: a caption band on top, views framed by separator lines."""
    T, h, w, _ = views[names[0]].shape
    cell_h, cell_w = h + 2 * line_px, w + 2 * line_px
    out = np.full((T, caption_px + 2 * cell_h, 3 * cell_w, 3), 255, np.uint8)
    for i, name in enumerate(names):
        r, c = divmod(i, 3)
        y, x = caption_px + r * cell_h + line_px, c * cell_w + line_px
        out[:, y : y + h, x : x + w] = views[name]
    return out


def test_a_bordered_captioned_grid_splits_into_the_exact_views(synth_videos):
    names = list(synth_videos)
    grid = _published_grid(synth_videos, names, line_px=3, caption_px=20)
    T, H, W, _ = grid.shape
    framing = Framing((0, 20, W, H - 20), 2, 7, cell_border_px=3)
    views = split_grid(framing.apply(grid, "g"), GridLayout.parse("2x3", names), "g", framing.cell_border_px)
    for name in names:
        assert np.array_equal(views[name], synth_videos[name][2:7])
    # Without the borders the separator lines would be scored as part of each view.
    plain = split_grid(framing.apply(grid, "g"), GridLayout.parse("2x3", names), "g")
    assert plain[names[0]].shape[1:3] == (192 + 6, 320 + 6)


def test_uneven_cells_follow_the_rounded_boundaries():
    cells = grid_cells(1601, 900, 2, 3, 0)
    assert [c[2] for c in cells[:3]] == [534, 533, 534] and sum(c[2] for c in cells[:3]) == 1601
    assert all(c[1] + c[3] <= 900 for c in cells)


@pytest.mark.parametrize(
    ("framing", "message"),
    [
        (lambda: Framing((0, 0, 100, 100)).box(64, 48, "v.mp4"), "reaches outside the 64x48 frame"),
        (lambda: Framing(frame_start=5, frame_end=5), "an empty frame range"),
        (lambda: Framing((0, 0, 0, 10)), "positive width and height"),
        (lambda: Framing(frame_start=9).apply(np.zeros((9, 4, 4, 3), np.uint8), "v.mp4"), "the video has 9 frames"),
    ],
)
def test_bad_framing_is_one_clear_error(framing, message):
    with pytest.raises(DrivewmError, match=message):
        framing()


def test_cli_scores_a_published_grid_and_refuses_bad_framing(synth_videos, tmp_path, capsys):
    names = list(synth_videos)
    grid = _published_grid(synth_videos, names, line_px=2, caption_px=16)
    path = tmp_path / "published.mp4"
    path.write_bytes(encode_mp4(grid, 10.0))
    H, W = grid.shape[1:3]
    common = ["--rig", "nuscenes6", "--grid", "2x3", "--metrics", "tse", "--no-pictures"]
    ok = ["--crop", f"0,16,{W},{H - 16}", "--grid-border", "2", "--frames", "1:4"]
    assert main(["eval", str(path), "--out", str(tmp_path / "e"), *common, *ok]) == 0
    metrics = json.loads((tmp_path / "e" / "metrics.json").read_text())
    clip = next(iter(metrics["clips"].values()))
    assert len(clip["tse_pair_medians"]) == 6 * 2  # 6 views, frames 1-3: 2 pairs each
    assert metrics["input"]["framing"] == {"crop_xywh": [0, 16, W, H - 16], "frame_start": 1, "frame_end": 4,
                                           "cell_border_px": 2}  # fmt: skip
    assert metrics["tse"] < 1.0  # the exact views of a rigid synthetic scene
    capsys.readouterr()
    bad = {
        "crop": (["--crop", f"0,0,{W + 1},{H}"], "reaches outside"),
        "frames": (["--frames", "4:4"], "an empty frame range"),
        "cells": (["--cameras", "CAM_FRONT,CAM_BACK"], "6 cells but 2 camera names"),
    }
    for name, (extra, message) in bad.items():
        assert main(["eval", str(path), "--out", str(tmp_path / name), *common, *extra]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith("error:") and message in err[0], (name, err)


def _gif(frames: np.ndarray) -> bytes:
    """An animated GIF (FFmpeg's gif encoder through PyAV, 3-3-2 bit colour) of uint8 RGB frames."""
    buf = io.BytesIO()
    with av.open(buf, "w", format="gif") as container:
        stream = container.add_stream("gif", rate=10)
        stream.width, stream.height, stream.pix_fmt = frames.shape[2], frames.shape[1], "rgb8"
        for frame in frames:
            container.mux(stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")))
        container.mux(stream.encode())
    return buf.getvalue()


def test_published_gifs_and_still_images_are_read_as_grids(synth_videos, tmp_path):
    """A grid published as an animated GIF keeps its frames; a PNG still is a one-frame clip, exact."""
    names = list(synth_videos)
    grid = _published_grid({n: v[:4] for n, v in synth_videos.items()}, names, line_px=2, caption_px=16)
    H, W = grid.shape[1:3]
    framing = Framing((0, 16, W, H - 16), cell_border_px=2)
    (tmp_path / "grid.gif").write_bytes(_gif(grid))
    cv2.imwrite(str(tmp_path / "grid.PNG"), grid[2, :, :, ::-1])
    for name, frames in (("grid.gif", slice(0, 4)), ("grid.PNG", slice(2, 3))):
        (item,) = load_items(tmp_path / name, "nuscenes6", "2x3", names, framing=framing)
        views = item.videos()
        for cam in names:
            truth = synth_videos[cam][frames]
            assert views[cam].shape == truth.shape, (name, cam)
            error = np.abs(views[cam].astype(int) - truth).mean()
            assert error == 0 if name.endswith("PNG") else error < 20, (name, cam, error)  # GIF: 256 colours


def test_nuscenes_calibrated_rig_is_the_dataset_record():
    """CAM_FRONT_RIGHT's pose equals the calibrated_sensor record read with scipy (w-first quaternion),
    and every camera looks the way its name says."""
    rig = load_rig("nuscenes6_calib")
    cam = rig.camera("CAM_FRONT_RIGHT")
    R = Rotation.from_quat(NUSCENES_FRONT_RIGHT["rotation"], scalar_first=True).as_matrix()
    np.testing.assert_allclose(cam.T_ego_from_cam[:3, :3], R, atol=1e-12)
    np.testing.assert_allclose(cam.T_ego_from_cam[:3, 3], NUSCENES_FRONT_RIGHT["translation"])
    assert (cam.width, cam.height, cam.K[0, 0]) == (1600, 900, 1260.8474446004698)
    yaws = {c.name: np.degrees(np.arctan2(*(c.T_ego_from_cam[:3, 2][[1, 0]]))) for c in rig.cameras}
    expected = {"CAM_FRONT": 0, "CAM_FRONT_RIGHT": -55, "CAM_BACK_RIGHT": -110, "CAM_BACK": 180,
                "CAM_BACK_LEFT": 110, "CAM_FRONT_LEFT": 55}  # fmt: skip
    for name, yaw in expected.items():
        assert abs((yaws[name] - yaw + 180) % 360 - 180) < 3, (name, yaws[name])


def test_clip_shards_refuse_mp4_framing(tmp_path):
    (tmp_path / "d").mkdir()
    (tmp_path / "d" / "x.tar").write_bytes(b"")
    with pytest.raises(DrivewmError, match="apply to mp4 inputs"):
        load_items(tmp_path / "d" / "x.tar", None, framing=Framing(frame_start=2))
