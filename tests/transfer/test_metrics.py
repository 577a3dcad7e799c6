"""The benchmark's measures can tell a kept geometry and a shown condition from their opposites."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivewm.clips import iter_clips
from drivewm.transfer.retarget import TargetCondition

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from transfer_benchmark import NOISE_LEVELS, with_noise  # noqa: E402
from transfer_metrics import adherent, cross_view_error, image_scores, sift_shift_px  # noqa: E402


@pytest.fixture(scope="module")
def snow_clip(sim_clip_dir):
    clip = next(iter_clips(sim_clip_dir / "highway_snow-000000.tar"))
    return clip, clip.videos()[:, ::8]  # (V, 3, H, W, 3): every 8th frame keeps the test fast


def _shifted(videos: np.ndarray, dx: float) -> np.ndarray:
    M = np.float32([[1, 0, dx], [0, 1, 0]])
    return np.stack([[cv2.warpAffine(f, M, f.shape[1::-1], borderMode=cv2.BORDER_REFLECT) for f in v] for v in videos])


def test_sift_shift_measures_a_displacement(snow_clip) -> None:
    videos = snow_clip[1][:3]
    same = sift_shift_px(videos, videos)
    moved = sift_shift_px(videos, _shifted(videos, 3.0))
    assert same["matches"] > 300 and same["median_px"] == 0.0
    assert moved["matches"] > 150 and abs(moved["median_px"] - 3.0) < 0.3


def test_image_scores(snow_clip) -> None:
    _, videos = snow_clip
    noisy = np.clip(videos.astype(int) + np.random.default_rng(0).integers(-8, 9, videos.shape), 0, 255).astype(
        np.uint8
    )
    scores = image_scores(noisy, videos)
    # uniform integer noise in [-8, 8] has variance (17^2 - 1) / 12 = 24: PSNR 10 log10(4 / (24 / 127.5^2)) = 34.3 dB
    assert 33.5 < scores["psnr"] < 35 and 0.5 < scores["ssim"] < 1.0
    assert image_scores(videos, videos)["ssim"] == pytest.approx(1.0)


@pytest.mark.slow
def test_cross_view_error_rises_when_views_are_swapped(snow_clip) -> None:
    clip = snow_clip[0]
    rig, videos = clip.meta.get_rig(), clip.videos()[:, ::2]  # 9 frames: enough matches for every pair
    true = cross_view_error(videos, rig)
    assert true["cse"] < 1.0 and true["cse_calibrated"] < 1.0  # measured 0.42 and 0.57 px
    # every pair has its verified matches, so the clip value is the counted pairs' own mean (no 4 px penalty)
    assert true["cse_counted"] == 1.0 and true["cse_counted_px"] == pytest.approx(true["cse"])
    swapped = videos[[1, 0, 2, 3, 4, 5]]  # two cameras' videos exchanged: the calibration no longer fits
    assert not cross_view_error(swapped, rig)["cse_calibrated"] < 5 * true["cse_calibrated"]  # measured 8.0 px


def test_adherence_names_the_rendered_condition(snow_clip) -> None:
    _, videos = snow_clip
    assert adherent(videos, TargetCondition("snow", "day"))["match"] == 1.0
    assert adherent(videos, TargetCondition("clear", "night"))["match"] == 0.0


def test_the_noise_reference_adds_one_invisible_level_fixed_by_its_seed(snow_clip) -> None:
    """``identity~noise`` of the benchmark: the source plus Gaussian noise of NOISE_LEVELS (1 level), so
    its PSNR to the source is about 10 log10(255^2 / (1 + 1/12)) = 47.8 dB (the rounding adds 1/12),
    the same draw for the same seed and another for another."""
    _, videos = snow_clip
    noisy = with_noise(videos, NOISE_LEVELS, 0)
    assert noisy.dtype == np.uint8 and np.array_equal(noisy, with_noise(videos, NOISE_LEVELS, 0))
    assert not np.array_equal(noisy, with_noise(videos, NOISE_LEVELS, 1))
    assert 47.0 < image_scores(noisy, videos)["psnr"] < 49.0
    assert np.abs(noisy.astype(int) - videos).max() <= 6  # a 6-sigma draw at most, never a visible change
