"""Matcher options and grid splitting (cheap plumbing checks with real OpenCV / TorchScript)."""

import dataclasses

import numpy as np
import pytest
import torch

from drivewm.errors import DrivewmError
from drivewm.eval.config import MatchConfig
from drivewm.eval.inputs import GridLayout, split_grid
from drivewm.eval.matching import FrameMatcher


class BrightestPixels(torch.nn.Module):
    """A stand-in learned matcher: pairs the 8 brightest pixels of each image, by rank."""

    def top(self, img: torch.Tensor) -> torch.Tensor:
        idx = torch.topk(img.flatten(), 8).indices
        w = img.shape[-1]
        return torch.stack([(idx % w).float(), torch.div(idx, w, rounding_mode="floor").float()], 1)

    def forward(self, a: torch.Tensor, b: torch.Tensor):
        return self.top(a), self.top(b)


def test_learned_matcher_loads_from_a_local_torchscript_file(tmp_path):
    path = tmp_path / "matcher.pt"
    torch.jit.script(BrightestPixels()).save(str(path))
    img = np.zeros((32, 48, 3), np.uint8)
    img[5, 7] = 255
    shifted = np.roll(img, (2, 3), axis=(0, 1))
    m = FrameMatcher(MatchConfig(matcher="learned", learned_weights=str(path))).match(0, img, 1, shifted)
    assert len(m) == 8 and np.allclose(m.uv_a[0], [7, 5]) and np.allclose(m.uv_b[0], [10, 7])
    with pytest.raises(DrivewmError, match="learned_weights"):
        FrameMatcher(MatchConfig(matcher="learned"))
    with pytest.raises(DrivewmError, match="not 'sift' or 'learned'"):
        FrameMatcher(MatchConfig(matcher="orb"))


def test_sift_matches_a_shifted_texture():
    rng = np.random.default_rng(0)
    import cv2

    blurred = cv2.GaussianBlur(rng.normal(0, 1, (200, 300)).astype(np.float32), (0, 0), 2)
    tex = cv2.cvtColor(cv2.normalize(blurred, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8), cv2.COLOR_GRAY2RGB)
    a, b = tex[20:180, 20:260], tex[25:185, 12:252]  # b = a shifted by (+8, -5) px
    m = FrameMatcher(MatchConfig()).match("a", a, "b", b)
    assert len(m) > 50
    assert np.median(np.linalg.norm(m.uv_b - m.uv_a - [8, -5], axis=1)) < 0.5


def test_grid_split_skips_dash_cells():
    frames = np.zeros((2, 4, 6, 3), np.uint8)
    frames[:, :2, 2:4] = 7  # row 0, col 1
    views = split_grid(frames, GridLayout.parse("2x3", ["A", "B", "-", "C", "D", "E"]), "grid.mp4")
    assert list(views) == ["A", "B", "C", "D", "E"] and views["B"].shape == (2, 2, 2, 3) and views["B"].max() == 7
    uneven = split_grid(np.zeros((1, 5, 7, 3), np.uint8), GridLayout.parse("2x3", list("ABCDEF")), "grid.mp4")
    assert [v.shape[1:3] for v in uneven.values()] == [(2, 2), (2, 3), (2, 2), (3, 2), (3, 3), (3, 2)]
    with pytest.raises(DrivewmError, match="leaves no pixel"):
        split_grid(np.zeros((1, 4, 6, 3), np.uint8), GridLayout.parse("2x3", list("ABCDEF")), "grid.mp4", 1)


def test_match_indices_equal_opencv_brute_force_ratio_and_mutual_checks():
    """The one-matrix matcher keeps exactly the pairs that cv2.BFMatcher's 2-NN ratio test (Lowe
    2004, sec. 7.1) and its mutual nearest-neighbour check keep: SIFT of a texture and of a noisy,
    shifted crop of it that overlaps by two thirds (so that some ratio-test pairs are not mutual)."""
    import cv2

    from drivewm.eval.matching import detect_sift, match_indices

    rng = np.random.default_rng(1)
    blurred = cv2.GaussianBlur(rng.normal(0, 1, (240, 400)).astype(np.float32), (0, 0), 1.5)
    tex = cv2.cvtColor(cv2.normalize(blurred, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8), cv2.COLOR_GRAY2RGB)
    noisy = np.clip(tex[16:206, 104:384] + rng.normal(0, 12, (190, 280, 3)), 0, 255).astype(np.uint8)
    cfg = MatchConfig()
    fa, fb = detect_sift(tex[10:200, 10:290], cfg), detect_sift(noisy, cfg)
    bf = cv2.BFMatcher(cv2.NORM_L2)
    ratio = {
        (m.queryIdx, m.trainIdx) for m, n in bf.knnMatch(fa.desc, fb.desc, k=2) if m.distance < cfg.ratio * n.distance
    }
    back = {m.queryIdx: m.trainIdx for m in bf.match(fb.desc, fa.desc)}
    expected = sorted((i, j) for i, j in ratio if back[j] == i)
    assert len(expected) > 500 and len(ratio) > len(expected)
    assert [tuple(p) for p in match_indices(fa, fb, cfg).tolist()] == expected
    unchecked = match_indices(fa, fb, dataclasses.replace(cfg, mutual=False))
    assert sorted(map(tuple, unchecked.tolist())) == sorted(ratio)
