"""Epipolar geometry for the benchmark: canonical rectification, robust F / E fits, Sampson error.

All errors are reported in pixels of one canonical pinhole (docs/eval-protocol.md): keypoints are
undistorted with their camera's K and distortion and re-projected with ``K_canonical`` (960x540,
120 deg horizontal FOV, the target camera of NVIDIA's public Sampson code), so a 320x192 clip and a
1920x1080 clip with another lens are scored on the same scale. The Sampson error of one match is
sqrt of the first-order geometric distance of H&Z eq. 11.9 (``drivewm.geometry.sampson_distance_sq``).
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from drivewm.eval.config import EpipolarConfig
from drivewm.eval.matching import Matches
from drivewm.geometry import Camera, fundamental_from_T, make_T, sampson_distance_sq

#: Outcome of one pair / clip metric; NaN errors always come with a status other than OK.
OK = "ok"
TOO_FEW_MATCHES = "too_few_matches"
FIT_FAILED = "fit_failed"
NO_MOTION = "no_motion"


def canonical_K(cfg: EpipolarConfig) -> np.ndarray:
    """3x3 intrinsics of the canonical pinhole: f = W / (2 tan(hfov / 2)), principal point at the centre."""
    f = 0.5 * cfg.canonical_width / np.tan(np.radians(cfg.canonical_hfov_deg) / 2)
    return np.array([[f, 0, cfg.canonical_width / 2], [0, f, cfg.canonical_height / 2], [0, 0, 1.0]])


def rectify_points(uv: np.ndarray, camera: Camera, K_canonical: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) of ``camera`` -> pixels (N, 2) of the canonical pinhole looking along the same axes."""
    if len(uv) == 0:
        return np.zeros((0, 2))
    dist = camera.distortion if camera.distortion.size else None
    out = cv2.undistortPoints(uv.reshape(-1, 1, 2).astype(np.float64), camera.K, dist, P=K_canonical)
    return out.reshape(-1, 2)


def rectify_matches(m: Matches, cam_a: Camera, cam_b: Camera, K_canonical: np.ndarray) -> Matches:
    """Both sides of a match set rectified to the canonical pinhole."""
    return Matches(rectify_points(m.uv_a, cam_a, K_canonical), rectify_points(m.uv_b, cam_b, K_canonical))


def sampson_px(F: np.ndarray, x_a: np.ndarray, x_b: np.ndarray) -> np.ndarray:
    """Sampson error (px) per correspondence (N,) under x_b^T F x_a = 0: sqrt of H&Z eq. 11.9."""
    return np.sqrt(sampson_distance_sq(F, x_a, x_b))


def fit_fundamental(
    m: Matches, cfg: EpipolarConfig, native_px_per_px: float = 1.0
) -> tuple[np.ndarray | None, np.ndarray]:
    """Robust F (x_b^T F x_a = 0) with cv2.USAC_MAGSAC (Barath et al. 2020) at ``ransac_threshold_native_px``
    (``native_px_per_px``: the cameras' pixels per pixel of ``m``); (None, empty) when it fails."""
    if len(m) < max(cfg.min_matches, 8):
        return None, np.zeros(len(m), bool)
    try:
        F, mask = cv2.findFundamentalMat(
            m.uv_a,
            m.uv_b,
            cv2.USAC_MAGSAC,
            cfg.ransac_threshold_native_px / native_px_per_px,
            cfg.ransac_confidence,
            cfg.ransac_max_iters,
        )
    except cv2.error:  # USAC asserts on degenerate samples (e.g. all matches on one plane) instead of failing
        return None, np.zeros(len(m), bool)
    if F is None or F.shape != (3, 3):
        return None, np.zeros(len(m), bool)
    return F / np.linalg.norm(F), mask.reshape(-1).astype(bool)


#: recoverPose's triangulation cut-off in baselines. OpenCV's default (50) drops every point farther
#: than 50 baselines from its cheirality count and mask: on a driving stereo pair (0.5 m baseline,
#: scene to 100 m and beyond) that is nearly all of them. Far points are valid epipolar inliers.
CHEIRALITY_DISTANCE_BASELINES = 1e9


def normalised(uv: np.ndarray, K: np.ndarray) -> np.ndarray:
    """Pixels (N, 2) of a pinhole with intrinsics K -> normalised image coordinates (N, 2) (K^-1 x)."""
    return (np.c_[uv, np.ones(len(uv))] @ np.linalg.inv(K).T)[:, :2]


def relative_pose(
    m: Matches, K: np.ndarray, cfg: EpipolarConfig, native_px_per_px: float = 1.0
) -> tuple[np.ndarray | None, np.ndarray]:
    """T_b_from_a (4x4, unit-norm translation: monocular scale is unknown) and the inlier mask, from
    matches in pixels of a pinhole with intrinsics K (both views).

    E is fitted on normalised coordinates by OpenCV's USAC_ACCURATE (graph-cut local optimisation,
    Barath & Matas 2018, and a final least-squares fit on the inliers) with an inlier threshold of
    ``pose_threshold_native_px`` native pixels (``native_px_per_px``: native pixels per pixel of K,
    drivewm.eval.consistency.native_px_per_canonical_px), so a 1600 px and a 320 px camera keep the
    same matches. Cheirality (cv2.recoverPose, points at any distance) only picks which of E's four
    (R, t) decompositions is in front of both cameras (H&Z sec. 9.6.3); a far point's triangulated
    depth sign is noise and says nothing about the match. (None, empty mask) when the fit fails."""
    if len(m) < max(cfg.min_matches, 5):
        return None, np.zeros(len(m), bool)
    x_a, x_b = normalised(m.uv_a, K), normalised(m.uv_b, K)
    threshold = cfg.pose_threshold_native_px / native_px_per_px / np.sqrt(K[0, 0] * K[1, 1])
    try:
        E, mask = cv2.findEssentialMat(
            x_a, x_b, np.eye(3), cv2.USAC_ACCURATE, cfg.ransac_confidence, threshold, maxIters=cfg.ransac_max_iters
        )
    except cv2.error:  # USAC asserts on degenerate samples instead of failing
        return None, np.zeros(len(m), bool)
    if E is None or E.shape != (3, 3):
        return None, np.zeros(len(m), bool)
    _, R, t, _, _ = cv2.recoverPose(E, x_a, x_b, np.eye(3), distanceThresh=CHEIRALITY_DISTANCE_BASELINES, mask=mask)
    return make_T(R, t.reshape(3)), mask.reshape(-1).astype(bool)


def calibrated_fundamental(K_canonical: np.ndarray, T_b_from_a: np.ndarray) -> np.ndarray:
    """F between two canonical views related by the rigid motion T_b_from_a (H&Z eq. 9.12)."""
    return fundamental_from_T(K_canonical, K_canonical, T_b_from_a)


@dataclasses.dataclass
class SampsonResult:
    """Sampson errors (px) of one match set under one F; ``median_px`` is NaN unless status is OK."""

    errors_px: np.ndarray
    median_px: float
    num_matches: int
    status: str

    def to_json(self) -> dict:
        return {"median_px": self.median_px, "num_matches": self.num_matches, "status": self.status}


def verified_mask(
    F_fit: np.ndarray | None, m: Matches, cfg: EpipolarConfig, native_px_per_px: float = 1.0
) -> np.ndarray:
    """(N,) bool: the matches within ``verify_threshold_native_px`` (``native_px_per_px``: the cameras'
    pixels per pixel of ``m``) of the fitted F (none when the fit failed)."""
    if F_fit is None or len(m) == 0:
        return np.zeros(len(m), bool)
    return sampson_px(F_fit, m.uv_a, m.uv_b) <= cfg.verify_threshold_native_px / native_px_per_px


def fit_verified(
    m: Matches, cfg: EpipolarConfig, native_px_per_px: float = 1.0
) -> tuple[np.ndarray | None, np.ndarray]:
    """The robust F of ``m`` (:func:`fit_fundamental`) and the matches it verifies (:func:`verified_mask`)."""
    F, _ = fit_fundamental(m, cfg, native_px_per_px)
    return F, verified_mask(F, m, cfg, native_px_per_px)


def frame_pair_fit(matcher, id_a, id_b, m: Matches, cfg: EpipolarConfig, native_px_per_px: float) -> tuple:
    """:func:`fit_verified` of the rectified matches ``m`` of frames ``id_a`` and ``id_b``, once per
    pair and ``matcher`` (drivewm.eval.matching.FrameMatcher.memo): TSE, structure from motion's
    database and the pose check verify the same consecutive frame pairs."""
    key = ("fit_verified", id_a, id_b, native_px_per_px)
    return matcher.memo(key, lambda: fit_verified(m, cfg, native_px_per_px))


def score_matches(F: np.ndarray | None, m: Matches, cfg: EpipolarConfig) -> SampsonResult:
    """Median Sampson error of the verified matches ``m`` under F -- the same set for the fitted
    and the calibrated F (docs/eval-protocol.md, 'Per-pair error')."""
    if len(m) < cfg.min_matches:
        return SampsonResult(np.zeros(0), float("nan"), len(m), TOO_FEW_MATCHES)
    if F is None:
        return SampsonResult(np.zeros(0), float("nan"), len(m), FIT_FAILED)
    errors = sampson_px(F, m.uv_a, m.uv_b)
    return SampsonResult(errors, float(np.median(errors)), len(m), OK)
