"""Degenerate copies of real videos that a consistency benchmark must not prefer: blurred, noised,
frozen, shuffled, time-reversed, a still slowly zoomed, and (several cameras) one view copied into
all and every camera shifted to its neighbour's video; each a uint8 (T, H, W, 3) per camera, like
the original."""

from __future__ import annotations

import cv2
import numpy as np

#: Headline metrics and which way is better; a missing value (NaN: could not be computed) ranks worst.
LOWER_IS_BETTER = ("tse", "tse_calibrated", "cse", "cse_calibrated", "ate", "rpe_trans", "rpe_rot", "tfe")
#: Scored as their headline metric is, where an input lacks that one (the dashcam's own pixels).
ALSO_LOWER_IS_BETTER = ("tse_native",)
HIGHER_IS_BETTER = ("pose_auc",)
#: Pass rates (docs/eval-protocol.md): every image registers, or the share that does. A degraded copy
#: whose poses still come out may tie with the real clip here, never beat it; ``pose_auc`` ranks.
GATES = ("pose_success", "pose_success_path", "registered_fraction")


def blurred(videos: dict[str, np.ndarray], sigma_px: float = 2.5) -> dict[str, np.ndarray]:
    return {c: np.stack([cv2.GaussianBlur(f, (0, 0), sigma_px) for f in v]) for c, v in videos.items()}


def noised(videos: dict[str, np.ndarray], sigma: float = 20.0, seed: int = 0) -> dict[str, np.ndarray]:
    rng = np.random.default_rng(seed)
    return {c: np.clip(v + rng.normal(0, sigma, v.shape), 0, 255).astype(np.uint8) for c, v in videos.items()}


def frozen(videos: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every frame the first."""
    return {c: np.repeat(v[:1], len(v), axis=0) for c, v in videos.items()}


def shuffled(videos: dict[str, np.ndarray], seed: int = 0) -> dict[str, np.ndarray]:
    """Each camera's frames in its own random order (a permutation shared by all cameras would keep
    every same-time view pair, which no cross-view score can or should notice)."""
    rng = np.random.default_rng(seed)
    return {c: v[rng.permutation(len(v))] for c, v in videos.items()}


def reversed_time(videos: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every camera's frames last to first."""
    return {c: v[::-1].copy() for c, v in videos.items()}


def zoomed_still(videos: dict[str, np.ndarray], zoom_per_frame: float = 0.01) -> dict[str, np.ndarray]:
    """The first frame, zoomed about its centre by ``zoom_per_frame`` more each frame: the image
    motion of driving toward a flat picture, with no parallax."""
    out = {}
    for c, v in videos.items():
        h, w = v.shape[1:3]
        frames = []
        for t in range(len(v)):
            M = cv2.getRotationMatrix2D(((w - 1) / 2, (h - 1) / 2), 0.0, (1 + zoom_per_frame) ** t)
            frames.append(cv2.warpAffine(v[0], M, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT))
        out[c] = np.stack(frames)
    return out


def copied_view(videos: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """The first camera's video in every camera."""
    first = next(iter(videos.values()))
    return {c: first.copy() for c in videos}


def shifted_cameras(videos: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Every camera shows the next camera's video (rig order, the last the first's)."""
    names = list(videos)
    return {c: videos[names[(i + 1) % len(names)]] for i, c in enumerate(names)}


def swapped_cameras(videos: dict[str, np.ndarray], a: str, b: str) -> dict[str, np.ndarray]:
    """Cameras ``a`` and ``b`` show each other's video."""
    return {**videos, a: videos[b], b: videos[a]}


def mirrored_view(videos: dict[str, np.ndarray], camera: str) -> dict[str, np.ndarray]:
    """``camera``'s video mirrored left-right."""
    return {**videos, camera: videos[camera][:, :, ::-1].copy()}


DEGRADATIONS = {
    "blurred": blurred,
    "noised": noised,
    "frozen": frozen,
    "shuffled": shuffled,
    "reversed": reversed_time,
    "zoomed_still": zoomed_still,
}
#: Degradations of a rig's views: they change nothing on a one-camera rig.
MULTIVIEW_DEGRADATIONS = {"copied_view": copied_view, "shifted_cameras": shifted_cameras}


def worse(key: str, degraded: float | None, real: float | None) -> bool:
    """True when ``degraded`` scores worse than ``real`` on ``key`` (a missing value is the worst),
    or, for a gate, no better."""
    missing = lambda v: v is None or not np.isfinite(v)  # noqa: E731
    if key not in LOWER_IS_BETTER + ALSO_LOWER_IS_BETTER + HIGHER_IS_BETTER + GATES:
        raise AssertionError(f"{key}: not a metric this comparison knows the direction of")
    if missing(real):
        raise AssertionError(f"{key}: the real clip has no value to compare with")
    if missing(degraded):
        return True
    if key in GATES:
        return degraded <= real
    return degraded < real if key in HIGHER_IS_BETTER else degraded > real
