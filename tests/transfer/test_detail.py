"""Restoring the source detail the tokenizer drops (drivewm.transfer.detail)."""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from drivewm.transfer.detail import restore_detail

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
from transfer_metrics import sift_shift_px  # noqa: E402


def _scene(seed: int = 0) -> np.ndarray:
    """uint8 (1, 2, 96, 160, 3): textured frames with fine detail (what a tokenizer blurs away)."""
    rng = np.random.default_rng(seed)
    base = cv2.resize(rng.uniform(40, 215, (12, 20)).astype(np.float32), (160, 96), interpolation=cv2.INTER_CUBIC)
    fine = rng.normal(0, 25, (96, 160)).astype(np.float32)
    img = np.clip(base + cv2.GaussianBlur(fine, (0, 0), 0.8) * 2, 0, 255)
    return np.broadcast_to(np.stack([img] * 3, -1), (1, 2, 96, 160, 3)).astype(np.uint8).copy()


def _coded(frames: np.ndarray) -> np.ndarray:
    """A tokenizer stand-in: detail gone (Gaussian blur, sigma 2 px)."""
    return np.stack([[cv2.GaussianBlur(f, (0, 0), 2.0) for f in v] for v in frames])


@pytest.mark.parametrize("band_px", [0.0, 4.0])
def test_a_transfer_that_changes_nothing_gets_the_source_back(band_px):
    src = _scene()
    coded = _coded(src)
    out = restore_detail(coded, src, coded, band_px=band_px)
    assert np.abs(out.astype(int) - src).max() <= 1  # gain 1 everywhere: G(coded) + (src - G(coded)) = src


def test_the_band_takes_the_structure_from_the_source_and_the_light_from_the_transfer():
    """A dusk transfer (0.6 of the contrast) with a texture of its own at 1.5 px: band 0 keeps that texture,
    band 4 px replaces it by the source's, at the transfer's contrast and brightness."""
    src = _scene(2)
    coded = _coded(src)
    own = cv2.GaussianBlur(np.random.default_rng(3).normal(0, 30, (96, 160)).astype(np.float32), (0, 0), 1.5)
    dusk = np.clip(coded * 0.6 + own[None, None, :, :, None], 0, 255).astype(np.uint8)
    want = src.astype(np.float32) * 0.6  # the source at dusk
    err = {b: np.abs(restore_detail(dusk, src, coded, band_px=b) - want).mean() for b in (0.0, 4.0)}
    print(f"mean error to the source at dusk: {err}")
    assert err[4.0] < 0.75 * err[0.0]  # measured 0.67: the own texture also raises the contrast gain a little


def test_detail_follows_the_contrast_the_target_keeps():
    src = _scene()
    coded = _coded(src)
    darker = (coded * 0.5).astype(np.uint8)  # night: half the contrast, so half the detail
    out = restore_detail(darker, src, coded).astype(np.float32)
    detail_out = out - _coded(out.astype(np.uint8))
    detail_src = src.astype(np.float32) - coded
    ratio = detail_out.std() / detail_src.std()
    assert 0.35 < ratio < 0.65, ratio
    flat = np.full_like(coded, 200)  # dense fog: no contrast left, so (almost) no detail comes back
    fogged = restore_detail(flat, src, coded).astype(np.float32)
    assert np.abs(fogged - 200).mean() < 0.2 * np.abs(detail_src).mean()
    # a floor on the gain gives at least that share of the source's detail back, even in dense fog
    floored = restore_detail(flat, src, coded, min_gain=0.4).astype(np.float32) - 200
    assert 0.3 < floored.std() / detail_src.std() < 0.5


def test_restored_detail_puts_sift_matches_back_where_they_were():
    """A darker transfer (dusk) of a blocky decode (8x8 cells, as the pooling stand-in tokenizer of
    test_must_hold): its SIFT matches with the source drift; with the source's detail back, at 0.7
    contrast, they sit where they were."""
    src = _scene(1)
    coded = np.stack(
        [[cv2.resize(cv2.resize(f, (20, 12), interpolation=cv2.INTER_AREA), (160, 96), interpolation=cv2.INTER_NEAREST)
          for f in v] for v in src]
    )  # fmt: skip
    dusk = (coded * 0.7).astype(np.uint8)
    before = sift_shift_px(src, dusk)["median_px"]
    after = sift_shift_px(src, restore_detail(dusk, src, coded))["median_px"]
    print(f"median SIFT shift: {before:.2f} px without the detail, {after:.2f} px with it")
    assert after < 0.5 < before


def test_shapes_must_agree():
    src = _scene()
    with pytest.raises(ValueError, match="shapes differ"):
        restore_detail(src[:, :1], src, src)
    with pytest.raises(ValueError, match="band_px must be a finite number >= 0"):
        restore_detail(src, src, src, band_px=float("nan"))
    with pytest.raises(ValueError, match="min_gain must lie in"):
        restore_detail(src, src, src, min_gain=2.0)
