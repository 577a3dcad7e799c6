"""The evaluation protocol as one typed config: every constant of docs/eval-protocol.md lives here.

Defaults are the pinned protocol; a recipe (:data:`EVAL_RECIPES`: a packaged suite of
drivewm/recipes/eval/ or a YAML path, then ``--set``) may override them, and the resolved config
is written next to every metrics.json so numbers can be traced to their settings.
"""

from __future__ import annotations

import dataclasses

from drivewm.config import MAX_SEED, above, at_least, in_range, require
from drivewm.errors import DrivewmError
from drivewm.recipe import RecipeBook

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
    contrast_threshold: float = 0.01
    """SIFT's DoG contrast threshold. OpenCV's default 0.04 keeps ~300 keypoints of a 320x192 day render
    and 13-130 of a night one; structure from motion on the shared features then misregisters day
    clips (ATE 0.8 m against 0.06 m at 0.01) and loses night frames. 0.01 keeps 130-700."""
    max_side_px: int = 512
    """Keypoints are detected on the image resized (area) to at most this on its longer side and mapped
    back to the full image ((u + 0.5) / s - 0.5). SIFT costs ~290 ms a 960x540 frame here (64 s for a
    221-frame clip), ~80 ms at 512x288; 320x192 clips are untouched."""
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
    ransac_threshold_native_px: float = 0.41
    """Inlier threshold of cv2.USAC_MAGSAC for F, in the cameras' own pixels (keypoint noise is a
    fraction of a native pixel at any resolution; 0.5 canonical px is 0.41 native px of a 320 px
    70 deg camera, 2.3 of a 1600 px nuScenes one). Scaled to canonical px by f_canonical / f."""
    ransac_confidence: float = 0.999
    """RANSAC confidence."""
    ransac_max_iters: int = 10000
    """RANSAC iteration cap."""
    pose_threshold_native_px: float = 0.33
    """Inlier threshold (the cameras' own px) of the USAC_ACCURATE essential matrix behind relative
    poses (drivewm.eval.epipolar.relative_pose): on EuRoC's stereo pairs, rotation errors grow with
    it (median 0.06 deg at 0.33 native px, 0.15 at 0.8)."""
    verify_threshold_native_px: float = 3.3
    """Matches with a Sampson error above this (the cameras' own px, scaled to canonical px like
    ``ransac_threshold_native_px``) under the fitted F are outliers and not scored, under either F:
    the scored set is the video's own geometrically verified matches. 3.3 native px is 4 canonical
    px on a 320 px 70 deg camera, 0.7 on a 1600 px nuScenes camera (not 18 native px)."""
    min_matches: int = 16
    """Fewer verified matches than this in a frame pair: status 'too_few_matches' (the pair is not
    scored; a clip value counts it at ``failed_pair_px``)."""
    min_parallax_px: float = 0.5
    """TSE: a frame pair with fewer than ``min_matches`` verified matches that moved at least this
    (canonical px) has no baseline to fit F with (any F through the epipole fits static points):
    status 'no_motion', counted as failed."""
    failed_pair_px: float = 4.0
    """A pair that cannot be scored (too few verified matches, no fit, no motion) counts at this
    error in the clip value: at least the worst a verified match may have (``verify_threshold_native_px``). A blurred,
    frozen or shuffled video loses pairs and so scores worse, instead of scoring only its easy pairs."""

    def validate(self) -> None:
        at_least(self, 16, "canonical_width", "canonical_height")
        require(0 < self.canonical_hfov_deg < 180, "canonical_hfov_deg", self.canonical_hfov_deg, "in (0, 180)")
        above(self, 0, "ransac_threshold_native_px", "verify_threshold_native_px", "pose_threshold_native_px")
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
    cse_min_matches_per_frame: float = 4.0
    """CSE: a camera pair pooled over T frames is scored only with at least this x T distinct verified
    matches (a frozen video repeats one frame's few matches T times; the F fitted to them overfits)."""
    compensate_exposure: bool = True
    """Calibrated TSE / CSE use the ego pose at each camera's own exposure time
    (``ClipMeta.camera_timestamps_ns``, drivewm.eval.exposure), not at the clip's tick."""
    overlap_frame_step: int = 4
    """``overlap_disagreement`` (read beside CSE) on every this-many-th frame."""

    def validate(self) -> None:
        at_least(self, 1, "frame_gap")
        at_least(self, 1, "overlap_frame_step")
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

    features: str = "shared"
    """'shared' (the protocol): the benchmark's own SIFT keypoints and matches (those TSE and CSE use),
    verified by ``verify``, go into COLMAP's database; COLMAP neither extracts nor matches. 'colmap':
    COLMAP's own SIFT extraction and sequential matching (2.2x the pose CPU per reference clip;
    always so for a learned matcher, which has no per-image keypoints)."""
    temporal_gaps: list[int] = dataclasses.field(default_factory=lambda: [1, 2, 4, 8])
    """features='shared': each camera's frame t is matched with t + each gap (and overlapping cameras at t).
    Forward driving at 25 fps needs the long gaps: of the real dashcam video, [1, 2] registered 4 of the
    first 48 frames, [1, 2, 4] and [1, 4] 59% of all 221; [1, 2, 4, 8] registers every frame of both."""
    cross_gaps: list[int] = dataclasses.field(default_factory=lambda: [1])
    """features='shared': overlapping cameras a, b are also matched as a at t with b at t + gap and back."""
    verify: str = "drivewm"
    """features='shared': geometric verification of each image pair's matches by the benchmark's own
    robust F fit ('drivewm', as TSE and CSE verify: matches within ``verify_threshold_native_px`` of it) or by
    COLMAP ('colmap': E / F / H model selection with the known cameras). On the reference clips
    'colmap' left a snow clip 53% registered and two clips at ATE 0.35 and 0.42 m; 'drivewm'
    registers all 12 (mean ATE 0.024 m against 0.052 m with features='colmap')."""
    verify_max_trials: int = 2000
    """verify='colmap': RANSAC trials per image pair (COLMAP's default 10000 spends ~10 s a clip on snow
    renders, whose falling flakes make a third of the matches outliers)."""
    min_pair_inliers: int = 15
    """features='shared': image pairs with fewer verified matches are not written to COLMAP."""
    ba_global_frames_ratio: float = 1.1
    """COLMAP mapper: a global bundle adjustment runs when the registered frames (and points) grew by this factor."""
    ba_global_max_iterations: int = 5
    """COLMAP mapper: Ceres iterations per global bundle adjustment (COLMAP 50). A global adjustment
    starts from poses that local adjustments already refined, and the next one, after 10% more
    frames, goes on from where it stopped: on the 221-frame dashcam clip 5 cut mapping from 53 to 30
    CPU s, poses within 0.09% of the path length; the reference clips' pose success and ATE hold."""
    ba_local_max_refinements: int = 2
    """COLMAP mapper: rounds of bundle adjustment, re-triangulation and outlier filtering per local
    adjustment (COLMAP 2)."""
    ba_global_max_refinements: int = 5
    """COLMAP mapper: the same per global adjustment (COLMAP 5)."""
    max_features: int = 4096
    """features='colmap': SIFT features per image extracted by COLMAP."""
    sequential_overlap: int = 3
    """features='colmap': each frame is matched with the next ``sequential_overlap`` frames of the same camera."""
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
        require(self.features in ("colmap", "shared"), "features", self.features, "'colmap' or 'shared'")
        require(self.verify in ("colmap", "drivewm"), "verify", self.verify, "'colmap' or 'drivewm'")
        for name in ("temporal_gaps", "cross_gaps"):
            gaps = getattr(self, name)
            require(all(g >= 1 for g in gaps), name, gaps, "a list of frame gaps >= 1")
        at_least(self, 1, "max_features", "sequential_overlap", "min_model_size", "abs_pose_min_num_inliers")
        at_least(self, 1, "verify_max_trials")
        at_least(self, 0, "min_pair_inliers")
        above(self, 1, "ba_global_frames_ratio")
        at_least(self, 1, "ba_global_max_iterations", "ba_local_max_refinements", "ba_global_max_refinements")
        in_range(self, "abs_pose_min_inlier_ratio", 0, 1)
        require(
            0 < self.init_min_tri_angle_deg < 180, "init_min_tri_angle_deg", self.init_min_tri_angle_deg, "in (0, 180)"
        )
        in_range(self, "seed", 0, MAX_SEED)


@dataclasses.dataclass
class TrajectoryConfig:
    """Trajectory errors of the camera motion recovered from the video."""

    camera: str = ""
    """Camera whose recovered motion is the ego trajectory; '' = the camera looking most along ego +x."""
    alignment: str = "sim3"
    """Transform fitted onto the reference before ATE / RPE (Umeyama): 'sim3' (with scale: a video
    fixes motion only up to scale; evo -as), 'se3' (evo -a) or 'none'."""
    rpe_delta: float = 1.0
    """RPE compares relative motion over this distance, in ``rpe_delta_unit``."""
    rpe_delta_unit: str = "frames"
    """'frames' or 'm' (travelled path of the reference; evo --delta_unit m, e.g. drift per 10 m)."""
    rpe_all_pairs: bool = False
    """False: consecutive pairs (0-d, d-2d, ...; evo's default); True: every frame starts a pair (evo --all_pairs)."""
    rpe_pairs_from: str = "reference"
    """Trajectory whose frames / path choose the pairs: 'reference' (evo --pairs_from_reference) or 'estimate'."""
    pose_auc_m: float = 0.25
    """``pose_auc`` integrates per-image accuracy up to this position error (m) ..."""
    pose_auc_deg: float = 2.0
    """... and this rotation error (degrees): the finest threshold of Sattler et al. 2018's
    localization benchmark, (0.25 m, 2 deg)."""
    yaw_from_flow: bool = True
    """When structure from motion registers fewer than 3 frames of the trajectory camera, read the
    turn the clip shows (``yaw_change_deg``) from dense optical flow of that camera instead
    (drivewm.eval.flow_motion; ``yaw_source`` says which), so the turn of blurry low-resolution
    generated clips is still measured. ATE, RPE and TFE stay SfM's alone."""

    def validate(self) -> None:
        if not (self.pose_auc_m > 0 and self.pose_auc_deg > 0):
            raise DrivewmError(
                f"eval config: trajectory.pose_auc_m {self.pose_auc_m} and pose_auc_deg {self.pose_auc_deg} must be > 0"
            )
        if self.alignment not in ("none", "se3", "sim3"):
            raise DrivewmError(f"eval config: trajectory.alignment {self.alignment!r} is not none, se3 or sim3")
        if self.rpe_delta_unit not in ("frames", "m") or self.rpe_delta <= 0:
            raise DrivewmError(
                f"eval config: RPE delta {self.rpe_delta} {self.rpe_delta_unit!r} must be > 0 frames or m"
            )
        if self.rpe_delta_unit == "frames" and self.rpe_delta != int(self.rpe_delta):
            raise DrivewmError(f"eval config: trajectory.rpe_delta {self.rpe_delta} frames is not a whole number")
        if self.rpe_pairs_from not in ("reference", "estimate"):
            raise DrivewmError(f"eval config: trajectory.rpe_pairs_from {self.rpe_pairs_from!r}")


@dataclasses.dataclass
class GuardConfig:
    """Guards against degenerate videos (drivewm.eval.guards; docs/eval-protocol.md, 'Guards')."""

    parallax_threshold_native_px: float = 1.0
    """A TSE match shows parallax when it lies farther than this (the camera's own px: a few times
    keypoint noise at any resolution) from the best homography between the two frames."""
    min_parallax_fraction: float = 0.1
    """A TSE frame pair that must show motion has motion evidence when this share of its verified
    matches, or ``epipolar.min_matches`` of them if fewer (and at least 2), show parallax; else (a
    frozen, static or zoomed frame pair) it counts as failed (``no_motion``). Keypoint noise and
    mismatches put a few percent of an exact homography's matches past
    ``parallax_threshold_native_px``; a driving scene's depth puts a large share there."""
    parallax_depth_m: float = 30.0
    """A frame pair must show motion evidence when its camera's travel t (ego poses, else the
    conditioned speed; unknown: always) gives scene content this far away a parallax f t / Z of
    at least ``parallax_threshold_native_px`` against the far background (f: the camera's focal
    length, its own px): kerbs, lane markings, vehicles and roadside objects within 30 m."""
    direction_frame_step: int = 2
    """Travel directions are recovered on every this-many-th TSE frame pair of each camera."""
    direction_tolerance_deg: float = 30.0
    """``guard_views``: two or more cameras whose median recovered travel direction is farther than
    this from the one their extrinsics and the expected ego motion give show other cameras' views."""
    max_reversed_fraction: float = 0.25
    """``guard_time``: more than this share of scored frame pairs travelling over 90 degrees off
    the expected direction is a reversed or shuffled clip."""
    min_scored_pairs: int = 3
    """A camera with fewer scored frame pairs than this is not judged by the direction guards (one
    pair's E can be wrong); with no camera judged both read None."""
    duplicate_correlation: float = 0.95
    """``guard_views``: two cameras whose zero-mean grey thumbnails correlate at least this much
    (directly or mirrored) are copies of one view."""
    thumbnail_px: int = 64
    """Width (px) of the thumbnails compared for duplicate views."""
    thumbnail_frame_step: int = 4
    """Duplicate views are compared on every this-many-th frame."""
    pose_yaw_tolerance_deg: float = 2.0
    """``pose_plausible``: structure from motion's yaw change over the clip must lie within this
    plus ``pose_yaw_tolerance_fraction`` x |flow yaw| of the one dense flow reads (planar model)."""
    pose_yaw_tolerance_fraction: float = 0.2
    """See ``pose_yaw_tolerance_deg``."""
    pose_min_travel_m: float = 0.1
    """``pose_plausible``: a multi-camera reconstruction (metric scale) of a clip whose flow moves
    must travel at least this far; less is a rotation-only solution."""

    def validate(self) -> None:
        above(self, 0, "parallax_threshold_native_px", "parallax_depth_m", "direction_tolerance_deg")
        above(self, 0, "duplicate_correlation")
        in_range(self, "min_parallax_fraction", 0, 1)
        at_least(self, 1, "direction_frame_step", "min_scored_pairs", "thumbnail_frame_step")
        at_least(self, 8, "thumbnail_px")
        in_range(self, "max_reversed_fraction", 0, 1)
        at_least(self, 0, "pose_yaw_tolerance_deg", "pose_yaw_tolerance_fraction", "pose_min_travel_m")


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
    guard: GuardConfig = dataclasses.field(default_factory=GuardConfig)
    """Guards against degenerate videos."""

    def validate(self) -> None:
        unknown = sorted(set(self.metrics) - set(ALL_METRICS))
        if unknown:
            raise DrivewmError(f"eval config: unknown metric(s) {unknown}; known: {list(ALL_METRICS)}")
        require(len(self.metrics) > 0, "metrics", self.metrics, f"a non-empty subset of {list(ALL_METRICS)}")
        self.trajectory.validate()
        self.guard.validate()


EVAL_RECIPES = RecipeBook("eval", EvalConfig, {"default": {}}, "default", recipes="eval")
"""How an eval config is made (docs/DESIGN.md section 10): the pinned protocol above, a suite recipe
(``default``: the protocol written out, ``quick``: no structure from motion, or a YAML path), ``--set``."""
