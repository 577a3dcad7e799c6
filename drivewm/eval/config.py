"""The evaluation protocol as one typed config: every constant of eval/protocol.md lives here.

Defaults are the pinned protocol; a suite YAML (eval/suites/*.yaml) may override them, and the
resolved config is written next to every metrics.json so numbers can be traced to their settings.
"""

from __future__ import annotations

import dataclasses

from drivewm.config import above, at_least, from_dict, in_range, require
from drivewm.errors import DrivewmError

ALL_METRICS = ("tse", "cse", "pose", "traj", "adherence")


@dataclasses.dataclass
class MatchConfig:
    """Feature matching between two images."""

    matcher: str = "sift"
    """'sift' (OpenCV SIFT, default) or 'learned' (a TorchScript matcher from ``learned_weights``)."""
    learned_weights: str = ""
    """Local path of a TorchScript matcher for matcher='learned'; nothing is ever downloaded."""
    max_features: int = 2000
    """SIFT keypoints kept per image (strongest first)."""
    ratio: float = 0.8
    """Lowe's ratio test: keep a match when best/second-best descriptor distance < ratio (Lowe 2004, sec. 7.1)."""
    mutual: bool = True
    """Keep only matches that are each other's nearest neighbour in both directions."""

    def validate(self) -> None:
        require(self.matcher in ("sift", "learned"), "matcher", self.matcher, "'sift' or 'learned'")
        require(
            self.matcher != "learned" or bool(self.learned_weights),
            "learned_weights",
            self.learned_weights,
            "a local file for matcher='learned'",
        )
        at_least(self, 1, "max_features")
        require(0 < self.ratio <= 1, "ratio", self.ratio, "in (0, 1]")


@dataclasses.dataclass
class EpipolarConfig:
    """Canonical camera and robust fundamental-matrix fitting."""

    canonical_width: int = 960
    """Width (px) of the canonical pinhole all keypoints are rectified to."""
    canonical_height: int = 540
    """Height (px) of the canonical pinhole."""
    canonical_hfov_deg: float = 120.0
    """Horizontal field of view of the canonical pinhole (focal = W / (2 tan(hfov/2)) = 277.1 px)."""
    ransac_threshold_px: float = 0.5
    """Inlier threshold of cv2.USAC_MAGSAC in canonical pixels."""
    ransac_confidence: float = 0.999
    """RANSAC confidence."""
    ransac_max_iters: int = 10000
    """RANSAC iteration cap."""
    verify_threshold_px: float = 4.0
    """Matches with a Sampson error above this (canonical px) under the fitted F are outliers and not
    scored, under either F: the scored set is the video's own geometrically verified matches."""
    min_matches: int = 16
    """Fewer matches than this in a pair: status 'too_few_matches', error NaN (never 0)."""

    def validate(self) -> None:
        at_least(self, 16, "canonical_width", "canonical_height")
        require(0 < self.canonical_hfov_deg < 180, "canonical_hfov_deg", self.canonical_hfov_deg, "in (0, 180)")
        above(self, 0, "ransac_threshold_px", "verify_threshold_px")
        require(0 < self.ransac_confidence < 1, "ransac_confidence", self.ransac_confidence, "in (0, 1)")
        at_least(self, 1, "ransac_max_iters")
        at_least(self, 8, "min_matches")  # the fundamental matrix needs 8 correspondences (H&Z 11.1)


@dataclasses.dataclass
class ConsistencyConfig:
    """TSE (temporal) and CSE (cross-view) Sampson errors."""

    frame_gap: int = 1
    """TSE compares frame t with frame t + frame_gap of the same camera."""
    overlap_min_fraction: float = 0.02
    """Two cameras form a CSE pair when at least this fraction of one frustum's sample points is seen by the other."""
    overlap_depths_m: list[float] = dataclasses.field(default_factory=lambda: [4.0, 8.0, 16.0, 32.0])
    """Depths (m) at which frustum sample points are placed for the overlap test."""
    overlap_grid: int = 24
    """Sample points per image axis for the overlap test."""

    def validate(self) -> None:
        at_least(self, 1, "frame_gap")
        at_least(self, 2, "overlap_grid")
        in_range(self, "overlap_min_fraction", 0, 1)
        require(
            len(self.overlap_depths_m) > 0 and min(self.overlap_depths_m) > 0,
            "overlap_depths_m",
            self.overlap_depths_m,
            "a non-empty list of depths > 0",
        )


@dataclasses.dataclass
class PoseConfig:
    """Structure from motion with pycolmap (pose-estimation success and the recovered trajectory)."""

    max_features: int = 4096
    """SIFT features per image extracted by COLMAP."""
    sequential_overlap: int = 3
    """Each frame is matched with the next ``sequential_overlap`` frames of the same camera."""
    min_model_size: int = 3
    """COLMAP's smallest model."""
    abs_pose_min_num_inliers: int = 15
    """COLMAP mapper: inliers needed to register a frame (COLMAP default 30; low-texture snow and
    night renders at 320x192 need fewer)."""
    abs_pose_min_inlier_ratio: float = 0.15
    """COLMAP mapper: inlier ratio needed to register a frame (COLMAP default 0.25)."""
    init_min_tri_angle_deg: float = 4.0
    """COLMAP mapper: triangulation angle of the initial pair (COLMAP default 16; forward driving
    at 10 fps rarely reaches it between nearby frames)."""
    seed: int = 0
    """pycolmap random seed (deterministic RANSAC)."""

    def validate(self) -> None:
        at_least(self, 1, "max_features", "sequential_overlap", "min_model_size", "abs_pose_min_num_inliers")
        in_range(self, "abs_pose_min_inlier_ratio", 0, 1)
        require(
            0 < self.init_min_tri_angle_deg < 180, "init_min_tri_angle_deg", self.init_min_tri_angle_deg, "in (0, 180)"
        )
        in_range(self, "seed", 0, 2**31 - 1)


@dataclasses.dataclass
class TrajectoryConfig:
    """Trajectory errors of the camera motion recovered from the video."""

    camera: str = ""
    """Camera whose recovered motion is the ego trajectory; '' = the camera looking most along ego +x."""
    rpe_delta_frames: int = 1
    """RPE compares relative motion over this many frames."""

    def validate(self) -> None:
        at_least(self, 1, "rpe_delta_frames")


@dataclasses.dataclass
class EvalConfig:
    """The whole protocol. ``metrics`` picks what runs."""

    metrics: list[str] = dataclasses.field(default_factory=lambda: list(ALL_METRICS))
    """Subset of tse, cse, pose, traj, adherence."""
    match: MatchConfig = dataclasses.field(default_factory=MatchConfig)
    """Feature matching."""
    epipolar: EpipolarConfig = dataclasses.field(default_factory=EpipolarConfig)
    """Canonical camera and F fitting."""
    consistency: ConsistencyConfig = dataclasses.field(default_factory=ConsistencyConfig)
    """TSE / CSE."""
    pose: PoseConfig = dataclasses.field(default_factory=PoseConfig)
    """SfM."""
    trajectory: TrajectoryConfig = dataclasses.field(default_factory=TrajectoryConfig)
    """Trajectory errors."""

    def validate(self) -> None:
        unknown = sorted(set(self.metrics) - set(ALL_METRICS))
        if unknown:
            raise DrivewmError(f"eval config: unknown metric(s) {unknown}; known: {list(ALL_METRICS)}")
        require(len(self.metrics) > 0, "metrics", self.metrics, f"a non-empty subset of {list(ALL_METRICS)}")


def eval_config_from_dict(data: dict, where: str = "eval config") -> EvalConfig:
    """Build and validate an :class:`EvalConfig` (unknown keys refused)."""
    return from_dict(EvalConfig, data, where)
