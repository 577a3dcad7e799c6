"""Matcher options and grid splitting (cheap plumbing checks with real OpenCV / TorchScript)."""

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
    with pytest.raises(DrivewmError, match="does not split"):
        split_grid(np.zeros((1, 5, 6, 3), np.uint8), GridLayout.parse("2x3", list("ABCDEF")), "grid.mp4")
