"""drivewm.eval.truth and ``drivewm judge score``: generated clips paired with the simulator's truth and
scored on PSNR, SSIM and the judge's mIoU (synthetic labelled clips, a tiny untrained judge)."""

from __future__ import annotations

import dataclasses
import json

import cv2
import numpy as np
import pytest
import torch

from drivewm.cli import main
from drivewm.clips import ClipMeta, ShardWriter, iter_clips
from drivewm.clips.format import clip_from_arrays
from drivewm.eval.judge import Judge, JudgeConfig, confusion, predict, segmentation_scores
from drivewm.eval.truth import appearance, colour_labels
from drivewm.geometry import load_rig
from drivewm.layout.classes import LABEL_ID
from drivewm.layout.labels import labels_to_npz

T, H, W = 5, 40, 64


def scene_labels(shift: int) -> np.ndarray:
    """(T, H, W) label maps: sky above, road below with a lane line, a vehicle moving right."""
    labels = np.full((T, H, W), LABEL_ID["sky"], np.uint8)
    labels[:, H // 2 :] = LABEL_ID["road"]
    labels[:, 3 * H // 4, :] = LABEL_ID["lane_paint"]
    for t in range(T):
        labels[t, H // 2 - 6 : H // 2 + 4, 10 + shift + 3 * t : 24 + shift + 3 * t] = LABEL_ID["vehicle"]
    return labels


def labelled_clip(key: str, pair_id: str, condition: str, shift: int = 0, size_wh=(W, H), noise=0.0):
    """A one-camera clip whose frames are its label maps in the class colours (plus Gaussian ``noise``)."""
    weather, time_of_day = condition.split(":")
    rig = load_rig("front1").scaled(*size_wh, fit="stretch")
    labels = scene_labels(shift)
    frames = np.stack([colour_labels(m) for m in labels]).astype(np.float64)
    frames += np.random.default_rng(shift).normal(0, noise, frames.shape)
    frames = np.stack([cv2.resize(f, size_wh, interpolation=cv2.INTER_AREA) for f in frames.clip(0, 255)])
    meta = ClipMeta(
        key=key,
        source_log="sim.mcap",
        start_time_ns=0,
        fps=10.0,
        timestamps_ns=[i * 100_000_000 for i in range(T)],
        rig=rig.to_dict(),
        tags={"weather": weather, "time_of_day": time_of_day},
        pair_id=pair_id,
    )
    clip = clip_from_arrays(meta, {rig.names[0]: frames.astype(np.uint8)}, np.repeat(np.eye(4)[None], T, axis=0))
    if size_wh == (W, H):
        clip.labels_npz = {rig.names[0]: labels_to_npz(labels, meta.timestamps_ns)}
    return clip


def write_clips(folder, clips) -> None:
    with ShardWriter(folder, "clips") as writer:
        for clip in clips:
            writer.write(clip)


@pytest.fixture(scope="module")
def judge_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("judge")
    torch.manual_seed(0)  # an untrained judge: its guesses must not depend on the tests run before it
    Judge(JudgeConfig(base_channels=4, levels=2, groups=2)).save(folder)
    return folder


@pytest.fixture(scope="module")
def truth_dir(tmp_path_factory):
    folder = tmp_path_factory.mktemp("truth")
    write_clips(
        folder,
        [
            labelled_clip("d1-clear", "drive1-t0", "clear:day", 0),
            labelled_clip("d1-snow", "drive1-t0", "snow:day", 0, noise=3),
            labelled_clip("d2-clear", "drive2-t0", "clear:day", 8),
        ],
    )
    return folder


def test_ssim_and_psnr_match_their_reference_values():
    """Constant images: SSIM is the luminance term alone, (2ab + C1) / (a^2 + b^2 + C1), C1 = (0.01 * 255)^2
    (Wang et al. 2004, eq. 13); PSNR of a uniform error d is 20 log10(255 / d). A textured pair against
    the textbook Gaussian-window SSIM written with OpenCV (11x11, sigma 1.5, valid region)."""
    a, b = np.full((1, 2, 24, 24, 3), 100, np.uint8), np.full((1, 2, 24, 24, 3), 150, np.uint8)
    c1 = (0.01 * 255) ** 2
    scores = appearance(a, b)
    assert scores["ssim"] == pytest.approx((2 * 100 * 150 + c1) / (100**2 + 150**2 + c1), rel=1e-5)  # float32 window
    assert scores["psnr"] == pytest.approx(20 * np.log10(255 / 50), rel=1e-6)
    rng = np.random.default_rng(0)
    x = cv2.GaussianBlur(rng.uniform(0, 255, (32, 40)), (5, 5), 2)
    y = np.clip(x + rng.normal(0, 20, x.shape), 0, 255).round()
    x = x.round()
    ref = opencv_ssim(x, y)
    stack = lambda im: np.repeat(im[None, None, :, :, None], 3, axis=-1).astype(np.uint8)  # noqa: E731
    assert appearance(stack(x), stack(y))["ssim"] == pytest.approx(ref, abs=1e-5)  # float32 window weights
    assert 0.2 < ref < 0.95


def opencv_ssim(x: np.ndarray, y: np.ndarray) -> float:
    """Wang et al. 2004 SSIM of two 8-bit grey images, mean over the valid 11x11 windows."""
    c1, c2 = (0.01 * 255) ** 2, (0.03 * 255) ** 2
    g = cv2.getGaussianKernel(11, 1.5)
    window = g @ g.T

    def blur(im):
        return cv2.filter2D(im, -1, window, borderType=cv2.BORDER_REFLECT)[5:-5, 5:-5]

    mx, my = blur(x), blur(y)
    vx, vy, cov = blur(x * x) - mx**2, blur(y * y) - my**2, blur(x * y) - mx * my
    return float((((2 * mx * my + c1) * (2 * cov + c2)) / ((mx**2 + my**2 + c1) * (vx + vy + c2))).mean())


def test_score_pairs_by_drive_window_and_condition_and_reports_the_unpaired(judge_dir, truth_dir, tmp_path, capsys):
    generated = tmp_path / "generated"
    write_clips(
        generated,
        [
            labelled_clip("gen-d1-snow", "drive1-t0", "snow:day", 0, noise=6),
            labelled_clip("gen-d2-clear", "drive2-t0", "clear:day", 8, size_wh=(2 * W, 2 * H)),
            labelled_clip("gen-d2-snow", "drive2-t0", "snow:day", 8),
            labelled_clip("gen-nopair", "", "clear:day", 0),
        ],
    )
    out = tmp_path / "scores"
    argv = ["judge", "score", str(generated), "--truth", str(truth_dir), "--model", str(judge_dir), "--out", str(out)]
    assert main([*argv, "--device", "cpu"]) == 0
    scores = json.loads((out / "scores.json").read_text())
    rows = {r["clip"]: r for r in scores["clips"]}
    assert set(rows) == {"gen-d1-snow", "gen-d2-clear"}
    assert rows["gen-d1-snow"]["truth"] == "d1-snow" and rows["gen-d2-clear"]["truth"] == "d2-clear"
    assert rows["gen-d2-clear"]["resized"] and not rows["gen-d1-snow"]["resized"]
    assert {u["clip"]: u["reason"] for u in scores["unpaired"]} == {
        "gen-d2-snow": "no truth clip with pair_id drive2-t0 in snow:day",
        "gen-nopair": "no pair_id in its metadata",
    }
    assert "unpaired gen-d2-snow" in capsys.readouterr().out
    # PSNR and SSIM of the pair as read back from the shards
    clips = {c.key: c for c in [*iter_clips(generated), *iter_clips(truth_dir)]}
    expected = appearance(clips["gen-d1-snow"].videos(), clips["d1-snow"].videos())
    assert rows["gen-d1-snow"]["psnr"] == pytest.approx(expected["psnr"]) and 20 < expected["psnr"] < 45
    assert scores["by_condition"]["snow:day"]["ssim"] == pytest.approx(expected["ssim"])
    assert set(scores["by_condition"]) == {"snow:day", "clear:day"} and scores["overall"]["clips"] == 2
    # the judge's structure scores: its confusion against the exact labels, generated beside true
    judge = Judge.from_pretrained(judge_dir)
    cam = clips["d1-snow"].meta.cameras[0]
    labels = clips["d1-snow"].labels(cam)
    on_truth = segmentation_scores(confusion(predict(judge, clips["d1-snow"].video(cam)), labels))
    on_gen = segmentation_scores(confusion(predict(judge, clips["gen-d1-snow"].video(cam)), labels))
    row = rows["gen-d1-snow"]
    assert row["miou_truth"] == pytest.approx(on_truth["miou"]) and row["miou_generated"] == pytest.approx(
        on_gen["miou"]
    )
    assert row["miou_ratio"] == pytest.approx(on_gen["miou"] / on_truth["miou"])
    assert row["vehicle"]["truth"] == pytest.approx(on_truth["iou"]["vehicle"])
    assert row["lane_paint"]["generated"] == pytest.approx(on_gen["iou"]["lane_paint"])
    assert set(row["per_class"]) == {"sky", "road", "lane_paint", "vehicle"}
    sheet = cv2.imread(str(out / "contact_sheet.png"))
    assert sheet.shape[1] == 4 * W and sheet.shape[0] > 2 * H


def test_a_generated_clip_equal_to_its_truth_scores_ratio_one(judge_dir, truth_dir, tmp_path):
    generated = tmp_path / "generated"
    write_clips(generated, [dataclasses.replace(c) for c in iter_clips(truth_dir)])
    out = tmp_path / "scores"
    assert (
        main(
            ["judge", "score", str(generated), "--truth", str(truth_dir), "--model", str(judge_dir), "--out", str(out)]
        )
        == 0
    )
    overall = json.loads((out / "scores.json").read_text())["overall"]
    assert overall["clips"] == 3 and overall["ssim"] == pytest.approx(1.0) and overall["psnr"] is None  # infinite
    assert overall["miou_ratio"] == 1.0 and overall["vehicle"]["generated"] == overall["vehicle"]["truth"]


def test_bad_input_is_one_line_and_exit_2_with_nothing_written(judge_dir, truth_dir, tmp_path, capsys):
    unpaired = tmp_path / "unpaired"
    write_clips(unpaired, [labelled_clip("lonely", "drive9-t0", "fog:day")])
    out = tmp_path / "scores"
    base = ["judge", "score", "--model", str(judge_dir), "--out", str(out)]
    assert main([*base, str(unpaired), "--truth", str(truth_dir)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("error: ") and "lonely: no truth clip with pair_id drive9-t0 in fog:day" in err
    assert len(err.strip().splitlines()) == 1
    assert main([*base, str(tmp_path / "missing"), "--truth", str(truth_dir)]) == 2
    assert main([*base, str(unpaired), "--truth", str(truth_dir), "--model", str(truth_dir)]) == 2
    assert "error: " in capsys.readouterr().err
    assert not (out / "scores.json").exists()
