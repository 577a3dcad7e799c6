"""Images as curation decodes them (drivewm.curate.images): JPEGs scaled in the DCT domain to the
clip's size come within 40 dB of full decode + INTER_AREA, full-size decodes are the log reader's
pixels exactly, the filters' thumbnails and scores are those of the former per-clip code, and the
exposure filter's shortcut gives the same verdicts."""

import cv2
import numpy as np
import pytest

from drivewm.curate import filters
from drivewm.curate.images import analysis_grey, decode_rgb, fit, jpeg_scale
from drivewm.errors import DrivewmError
from drivewm.logs.reader import read_log
from drivewm.logs.types import ImageFrame


@pytest.fixture(scope="module")
def frames(sim_log_dir) -> list[ImageFrame]:
    log = read_log(sim_log_dir / "highway_clear.mcap")
    return [f for cam in ("CAM_FRONT", "CAM_BACK_LEFT") for f in log.images[cam][:17]]


def test_jpeg_scale_only_shrinks():
    assert jpeg_scale((320, 192), (320, 192)) == 1
    assert jpeg_scale((320, 192), (160, 96)) == 2
    assert jpeg_scale((320, 192), (161, 96)) == 1  # 1/2 would give 160 px: too few
    assert jpeg_scale((1600, 900), (320, 180)) == 4
    assert jpeg_scale((1600, 900), (160, 90)) == 8
    assert jpeg_scale((1601, 901), (201, 113)) == 8  # libjpeg rounds up: ceil(1601 / 8) = 201


def test_reduced_decode_matches_full_decode_and_area_resize(frames):
    for f in frames:
        full = f.decode()
        assert np.array_equal(decode_rgb(f, (320, 192)), full)  # straight to RGB: the same pixels
        reference = cv2.resize(full, (160, 96), interpolation=cv2.INTER_AREA)
        reduced = decode_rgb(f, (160, 96), scale=2)
        assert reduced.shape == (96, 160, 3)
        mse = np.mean((reduced.astype(np.float64) - reference) ** 2)
        assert 10 * np.log10(255.0**2 / mse) > 40.0
        assert np.array_equal(fit(decode_rgb(f, (80, 48), scale=2), (80, 48)).shape, (48, 80, 3))
    with pytest.raises(DrivewmError, match="cannot decode jpeg"):
        decode_rgb(ImageFrame(7, b"not a jpeg"), (160, 96), scale=2)


def test_thumbnails_and_scores_equal_the_per_clip_code(frames):
    clip = np.stack([f.decode() for f in frames]).reshape(2, 17, 192, 320, 3)
    old_grey = np.stack(
        [
            [cv2.resize(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY), (160, 96), interpolation=cv2.INTER_AREA) for f in c]
            for c in clip
        ]
    )
    grey = np.stack([[analysis_grey(f) for f in c] for c in clip])
    assert np.array_equal(grey, old_grey)
    old_sharp = np.median([[cv2.Laplacian(g, cv2.CV_64F).var() for g in c] for c in grey], axis=1).min()
    assert filters.sharpness(grey) == pytest.approx(old_sharp, rel=1e-12)
    for scaled in (grey, grey // 10, np.concatenate([grey[:, :8] // 10, grey[:, 8:]], axis=1)):
        per_tick = np.moveaxis(scaled, 1, 0).reshape(17, -1)
        old_dark = (per_tick.mean(axis=1) < 15) & (np.percentile(per_tick, 99, axis=1) < 100)
        bad, _ = filters.bad_exposure_fraction(scaled, 15.0, 100.0, 0.5)
        assert bad == pytest.approx(old_dark.mean())
