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
import threading
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor

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


_THREAD = threading.local()


def _sift(max_features: int, contrast_threshold: float) -> cv2.SIFT:
    """This thread's SIFT detector for the settings: one per thread, as OpenCV does not promise that
    one Feature2D object may detect on several threads at once."""
    detectors = _THREAD.__dict__.setdefault("sift", {})
    key = (max_features, contrast_threshold)
    if key not in detectors:
        detectors[key] = cv2.SIFT_create(nfeatures=max_features, contrastThreshold=contrast_threshold)
    return detectors[key]


def to_gray(image: np.ndarray) -> np.ndarray:
    """uint8 RGB (H, W, 3) or grey (H, W) -> grey (H, W) uint8."""
    if image.ndim == 2:
        return image
    return cv2.cvtColor(image, cv2.COLOR_RGB2GRAY)


def detect_sift(image: np.ndarray, cfg: MatchConfig) -> Features:
    """SIFT keypoints (pixels of ``image``) and descriptors of a uint8 RGB (H, W, 3) image, detected
    at most ``max_side_px`` on the longer side."""
    grey = to_gray(image)
    h, w = grey.shape
    scale = min(1.0, cfg.max_side_px / max(h, w))
    if scale < 1.0:
        grey = cv2.resize(grey, (max(1, round(w * scale)), max(1, round(h * scale))), interpolation=cv2.INTER_AREA)
    keypoints, desc = _sift(cfg.max_features, cfg.contrast_threshold).detectAndCompute(grey, None)
    if desc is None or not keypoints:
        return Features(np.zeros((0, 2)), np.zeros((0, 128), np.float32))
    uv = np.array([k.pt for k in keypoints], dtype=np.float64)
    s = np.array([grey.shape[1] / w, grey.shape[0] / h])
    return Features((uv + 0.5) / s - 0.5, desc.astype(np.float32))  # pixel centres at integers at both sizes


def match_indices(fa: Features, fb: Features, cfg: MatchConfig) -> np.ndarray:
    """Ratio-test (and mutual) nearest-neighbour matches between two descriptor sets: keypoint
    index pairs (N, 2) into ``fa`` and ``fb``."""
    if len(fa.uv) < 2 or len(fb.uv) < 2:
        return np.zeros((0, 2), int)
    # One squared-L2 distance matrix (N_a, N_b) serves both the 2-nearest-neighbour ratio test and
    # the mutual check: brute force as cv2.BFMatcher, at a fraction of its cost (it searches twice).
    d2 = squared_distances(fa.desc, fb.desc)
    rows = np.arange(len(d2))
    nearest_a = np.argmin(d2, axis=0)  # (N_b,) for the mutual check, before the best entries are masked
    best = np.argmin(d2, axis=1)
    first = d2[rows, best]
    d2[rows, best] = np.inf  # the second nearest is the nearest of the rest (a tie fails the ratio test either way)
    second = np.min(d2, axis=1)
    keep = np.sqrt(first) < cfg.ratio * np.sqrt(second)
    if cfg.mutual:
        keep &= nearest_a[best] == rows
    return np.stack([rows[keep], best[keep]], 1)


def squared_distances(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(N_a, N_b) squared L2 distances between descriptor rows of ``a`` (N_a, D) and ``b`` (N_b, D):
    |a|^2 + |b|^2 - 2 a.b, clipped at 0 (float32 rounding), in place on one matrix."""
    two_ab = a @ b.T
    two_ab *= 2.0
    d2 = np.sum(a * a, 1)[:, None] + np.sum(b * b, 1)[None, :]
    d2 -= two_ab
    return np.maximum(d2, 0.0, out=d2)


def check_threads(threads: int) -> None:
    """A thread count for one clip's work must be at least 1."""
    if threads < 1:
        raise DrivewmError(f"eval threads must be >= 1, got {threads}")


class FrameMatcher:
    """Matches pairs of frames with the configured matcher, caching features per frame id and
    matches per pair of ids: TSE, CSE and structure from motion share both (drivewm.eval.sfm).

    ``threads`` > 1 spreads one clip's work (SIFT, matching, F fits: OpenCV and NumPy release the
    GIL) over that many threads through :meth:`map`, which keeps input order, so every figure is
    the same as with one thread; the feature cache is filled by :meth:`prefetch` before the
    threads read it."""

    def __init__(self, cfg: MatchConfig, threads: int = 1):
        check_threads(threads)
        self.cfg = cfg
        self.threads = threads
        self._cache: dict[object, Features] = {}
        self._pairs: dict[tuple, np.ndarray] = {}
        self._memo: dict[tuple, object] = {}
        self._learned = load_learned_matcher(cfg.learned_weights) if cfg.matcher == "learned" else None
        if cfg.matcher not in ("sift", "learned"):
            raise DrivewmError(f"eval config: match.matcher {cfg.matcher!r} is not 'sift' or 'learned'")

    def features(self, frame_id: object, image: np.ndarray) -> Features:
        if frame_id not in self._cache:
            self._cache[frame_id] = detect_sift(image, self.cfg)
        return self._cache[frame_id]

    def prefetch(self, videos: dict[str, np.ndarray], cameras: Iterable[str] | None = None) -> None:
        """Detect the features of every frame (id ``(camera, t)``) of ``videos`` (uint8 (T, H, W, 3)
        per camera; only ``cameras`` if given) not cached yet, over ``threads`` threads."""
        names = videos if cameras is None else cameras
        todo = {(c, t): image for c in names for t, image in enumerate(videos[c]) if (c, t) not in self._cache}
        if self._learned is None:
            self._cache.update(zip(todo, self.map(lambda image: detect_sift(image, self.cfg), todo.values())))

    def map(self, fn: Callable, items: Iterable) -> list:
        """``[fn(x) for x in items]`` over ``threads`` threads, in input order."""
        if self.threads == 1:
            return [fn(x) for x in items]
        with ThreadPoolExecutor(self.threads) as pool:
            return list(pool.map(fn, items))

    @property
    def shares_features(self) -> bool:
        """True when matches index shared per-image keypoints (SIFT); a learned matcher gives pixel pairs only."""
        return self._learned is None

    def match_indices(self, id_a: object, image_a: np.ndarray, id_b: object, image_b: np.ndarray) -> np.ndarray:
        """Keypoint index pairs (N, 2) into ``features(id_a)`` and ``features(id_b)`` (SIFT only), cached."""
        key = (id_a, id_b)
        if key not in self._pairs:
            self._pairs[key] = match_indices(self.features(id_a, image_a), self.features(id_b, image_b), self.cfg)
        return self._pairs[key]

    def memo(self, key: tuple, compute: Callable[[], object]) -> object:
        """``compute()``, once per ``key``: e.g. the F fit of a frame pair that TSE, structure from
        motion and the pose check each verify (deterministic, so a race computes the same value twice)."""
        if key not in self._memo:
            self._memo[key] = compute()
        return self._memo[key]

    def match(self, id_a: object, image_a: np.ndarray, id_b: object, image_b: np.ndarray) -> Matches:
        """Matches between two uint8 RGB frames; ids key the feature cache (e.g. (camera, t))."""
        if self._learned is not None:
            return match_learned(self._learned, image_a, image_b)
        idx = self.match_indices(id_a, image_a, id_b, image_b)
        fa, fb = self.features(id_a, image_a), self.features(id_b, image_b)
        return Matches(fa.uv[idx[:, 0]].reshape(-1, 2), fb.uv[idx[:, 1]].reshape(-1, 2))


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
