"""Feature matching between two frames: OpenCV SIFT with Lowe's ratio and mutual checks.

The default matcher is SIFT (Lowe 2004): keypoints and 128-d descriptors per image, brute-force
L2 k=2 nearest neighbours, a match kept when best/second < ``ratio`` (sec. 7.1) and, with
``mutual``, when the two keypoints are each other's nearest neighbour. A learned matcher can be
plugged in from a local TorchScript file (``matcher='learned'``); nothing is downloaded, and PyTorch
is imported only for that matcher (SIFT scoring runs without it). Keypoints are in pixels of the
input image (OpenCV convention: pixel centres at integers).
"""

from __future__ import annotations

import dataclasses
from functools import lru_cache

import cv2
import numpy as np

from drivewm.errors import DrivewmError
from drivewm.eval.config import MatchConfig


@dataclasses.dataclass
class Features:
    """Keypoints ``uv`` (N, 2) px and descriptors ``desc`` (N, 128) float32 of one image."""

    uv: np.ndarray
    desc: np.ndarray


@dataclasses.dataclass
class Matches:
    """Corresponding pixels ``uv_a`` <-> ``uv_b`` (N, 2) between images a and b."""

    uv_a: np.ndarray
    uv_b: np.ndarray

    def __len__(self) -> int:
        return len(self.uv_a)

    @staticmethod
    def empty() -> Matches:
        return Matches(np.zeros((0, 2)), np.zeros((0, 2)))

    def concat(self, other: Matches) -> Matches:
        return Matches(np.concatenate([self.uv_a, other.uv_a]), np.concatenate([self.uv_b, other.uv_b]))


@lru_cache(maxsize=4)
def _sift(max_features: int) -> cv2.SIFT:
    return cv2.SIFT_create(nfeatures=max_features)


def to_gray(image: np.ndarray) -> np.ndarray:
    """uint8 RGB (H, W, 3) or grey (H, W) -> grey (H, W) uint8."""
    if image.ndim == 2:
        return image
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)


def detect_sift(image: np.ndarray, cfg: MatchConfig) -> Features:
    """SIFT keypoints and descriptors of a uint8 RGB (H, W, 3) image."""
    keypoints, desc = _sift(cfg.max_features).detectAndCompute(to_gray(image), None)
    if desc is None or not keypoints:
        return Features(np.zeros((0, 2)), np.zeros((0, 128), np.float32))
    return Features(np.array([k.pt for k in keypoints], dtype=np.float64), desc.astype(np.float32))


def match_features(fa: Features, fb: Features, cfg: MatchConfig) -> Matches:
    """Ratio-test (and mutual) nearest-neighbour matches between two descriptor sets."""
    if len(fa.uv) < 2 or len(fb.uv) < 2:
        return Matches.empty()
    matcher = cv2.BFMatcher(cv2.NORM_L2)
    knn = matcher.knnMatch(fa.desc, fb.desc, k=2)
    keep = [m[0] for m in knn if len(m) == 2 and m[0].distance < cfg.ratio * m[1].distance]
    if cfg.mutual and keep:
        back = {m.queryIdx: m.trainIdx for m in matcher.match(fb.desc, fa.desc)}
        keep = [m for m in keep if back.get(m.trainIdx) == m.queryIdx]
    ia = np.array([m.queryIdx for m in keep], dtype=int)
    ib = np.array([m.trainIdx for m in keep], dtype=int)
    return Matches(fa.uv[ia].reshape(-1, 2), fb.uv[ib].reshape(-1, 2))


class FrameMatcher:
    """Matches pairs of frames with the configured matcher, caching features per frame id."""

    def __init__(self, cfg: MatchConfig):
        self.cfg = cfg
        self._cache: dict[object, Features] = {}
        self._learned = load_learned_matcher(cfg.learned_weights) if cfg.matcher == "learned" else None
        if cfg.matcher not in ("sift", "learned"):
            raise DrivewmError(f"eval config: match.matcher {cfg.matcher!r} is not 'sift' or 'learned'")

    def features(self, frame_id: object, image: np.ndarray) -> Features:
        if frame_id not in self._cache:
            self._cache[frame_id] = detect_sift(image, self.cfg)
        return self._cache[frame_id]

    def match(self, id_a: object, image_a: np.ndarray, id_b: object, image_b: np.ndarray) -> Matches:
        """Matches between two uint8 RGB frames; ids key the feature cache (e.g. (camera, t))."""
        if self._learned is not None:
            return match_learned(self._learned, image_a, image_b)
        return match_features(self.features(id_a, image_a), self.features(id_b, image_b), self.cfg)


def load_learned_matcher(path: str):
    """A TorchScript matcher from a local file: ``module(gray_a, gray_b) -> (uv_a (N, 2), uv_b (N, 2))``
    with grey images (1, 1, H, W) float in [0, 1]. Export e.g. LightGlue with torch.jit yourself."""
    import torch

    if not path:
        raise DrivewmError(
            "eval config: match.matcher='learned' needs match.learned_weights (a local TorchScript file)"
        )
    try:
        return torch.jit.load(path, map_location="cpu").eval()
    except (RuntimeError, ValueError, OSError) as exc:
        raise DrivewmError(f"{path}: cannot load a TorchScript matcher ({exc.__class__.__name__})") from None


def match_learned(module, image_a: np.ndarray, image_b: np.ndarray) -> Matches:
    """Run a TorchScript matcher (see :func:`load_learned_matcher`) on two uint8 RGB frames."""
    import torch

    def prep(image: np.ndarray) -> torch.Tensor:
        return torch.from_numpy(to_gray(image)).float().div(255.0)[None, None]

    with torch.no_grad():
        uv_a, uv_b = module(prep(image_a), prep(image_b))
    return Matches(uv_a.double().numpy().reshape(-1, 2), uv_b.double().numpy().reshape(-1, 2))
