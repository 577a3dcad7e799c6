"""Curation configuration: typed dataclasses, built by :data:`CURATE_RECIPES` from a recipe.

Every field has a default, so a recipe (``drivewm/recipes/curate/*.yaml``) names only what it
changes; unknown keys and wrong types are refused with the key and the file named.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from drivewm.config import above, at_least, frame_rate, in_range, require
from drivewm.errors import DrivewmError
from drivewm.paths import check_name
from drivewm.recipe import RecipeBook


@dataclasses.dataclass
class FilterConfig:
    """Clip filters (drivewm.curate.filters). A threshold of 0 (or a fraction of 1) disables that filter."""

    min_ego_distance_m: float = 1.0
    """Drop clips whose ego moves less than this (m, path length over the clip): standing still."""
    min_sharpness: float = 5.0
    """Drop clips whose blurriest camera has a median variance of Laplacian (grey, 0-255) below this."""
    dark_luma: float = 15.0
    """A tick is too dark when the mean luma (0-255) over all cameras is below this ..."""
    dark_highlight: float = 100.0
    """... and its brightest 1 % of pixels stay below this luma (lit night scenes are kept)."""
    bright_fraction: float = 0.5
    """A tick is blown out when more than this fraction of its pixels (all cameras) is at luma >= 250."""
    max_bad_exposure_fraction: float = 0.1
    """Drop clips where more than this fraction of ticks is too dark or blown out."""
    frozen_diff: float = 0.5
    """Two consecutive frames are frozen/duplicated when their mean absolute difference (0-255) is below this."""
    max_frozen_fraction: float = 0.2
    """Drop clips where more than this fraction of consecutive frame pairs (any camera) is frozen."""
    min_camera_motion_px: float = 0.0
    """Static-camera filter for clips without ego poses: drop when the 75th percentile of the optical-flow
    magnitude (px at 160 px width, 10 fps) is below this. 0 disables it."""
    dedup_cosine: float = 0.985
    """Near-duplicate clips: cosine similarity of clip embeddings at or above this drops the later clip. 1 disables."""

    def validate(self) -> None:
        at_least(self, 0, "min_ego_distance_m", "min_sharpness", "dark_luma", "dark_highlight", "frozen_diff")
        at_least(self, 0, "min_camera_motion_px")
        for name in ("bright_fraction", "max_bad_exposure_fraction", "max_frozen_fraction", "dedup_cosine"):
            in_range(self, name, 0, 1)


@dataclasses.dataclass
class PrivacyConfig:
    """Face and licence-plate blurring (drivewm.curate.privacy)."""

    enabled: bool = False
    """Blur detections before encoding."""
    faces: bool = True
    """Blur faces; needs ``face_model`` (OpenCV 5 bundles no face detector weights)."""
    face_model: str = ""
    """Path to a YuNet ONNX file (opencv_zoo face_detection_yunet_*.onnx) for cv2.FaceDetectorYN."""
    face_score: float = 0.7
    """YuNet score threshold."""
    plates: bool = True
    """Blur licence-plate candidates of the classical plate detector (weak: see drivewm/curate/privacy.py)."""
    blur_kernel_frac: float = 0.5
    """Gaussian kernel size as a fraction of the box's shorter side."""

    def validate(self) -> None:
        in_range(self, "face_score", 0, 1)
        above(self, 0, "blur_kernel_frac")


@dataclasses.dataclass
class TrajectoryConfig:
    """Ego-pose smoothing (drivewm.curate.trajectory): constant-velocity Kalman filter + RTS smoother."""

    position_sigma_m: float = 0.3
    """Measurement noise of a logged position (m, per axis): GNSS jitter."""
    yaw_sigma_rad: float = 0.01
    """Measurement noise of a logged yaw (rad)."""
    accel_sigma_mps2: float = 5.0
    """Process noise: white acceleration (m/s^2) of the constant-velocity model."""
    yaw_accel_sigma_radps2: float = 3.0
    """Process noise: white yaw acceleration (rad/s^2)."""
    gate_chi2: float = 25.0
    """Innovation gate: a measurement whose squared Mahalanobis distance exceeds this is rejected as jitter."""

    def validate(self) -> None:
        above(self, 0, "position_sigma_m", "yaw_sigma_rad", "accel_sigma_mps2", "yaw_accel_sigma_radps2", "gate_chi2")


@dataclasses.dataclass
class CurateConfig:
    """One curation recipe (``drivewm/recipes/curate/*.yaml``)."""

    clip_frames: int = 17
    """Frames per clip (T = 1 + 4k suits the 4x and 8x temporal tokenizers)."""
    fps: float = 10.0
    """Clip frame rate; logs at another rate are resampled to it (nearest frame within the tolerance)."""
    stride_frames: int = 17
    """Start-to-start distance of consecutive clips, in clip frames."""
    resolution: list[int] | None = None
    """Output [W, H] (even numbers); null keeps the log's image size."""
    topic_map: str | None = None
    """Topic map (a name in drivewm/topicmaps/ or a YAML path) for logs not written by drivewm (ROS 2, other
    Foxglove layouts)."""
    cameras: list[str] | None = None
    """Cameras to keep, in this order; null keeps the log's rig."""
    sync_tolerance_ms: float = 25.0
    """A camera frame belongs to a tick when it is within this of the tick plus the camera's exposure
    offset (must be < half a clip frame)."""
    max_gap_ms: float = 1000.0
    """A camera's clock moving forward by more than this between frames (a recorder pause, a clock
    jump) ends a span of ticks, the next starts afresh; moving back by more than this drops frames
    until it passes its earlier maximum. Shorter gaps are dropped frames (invalid ticks)."""
    per_camera_offsets: bool = True
    """Estimate each camera's steady exposure offset from the reference (first) camera (rigs that fire
    cameras in turn) and apply the tolerance around it; false: around the tick for every camera."""
    trajectory_waypoints: int = 16
    """Future ego waypoints per clip (ClipMeta.trajectory_ego), from the 2nd to the last frame."""
    shot_threshold: float = 2.5
    """scenedetect AdaptiveDetector threshold (frame change / neighbours' average) for shot boundaries; 0 disables."""
    shot_min_frames: int = 3
    """Minimum shot length in clip frames for the detector."""
    crf: int = 18
    """H.264 constant rate factor of the clip videos."""
    h264_preset: str = "veryfast"
    """libx264 preset: encoding is most of curation's CPU time; "ultrafast" takes about a third of
    "veryfast"'s at the same crf, with higher PSNR and ~1.5x larger files (benchmarks/bench_curate.py)."""
    h264_threads: int = 0
    """libx264 threads per clip video: 0 lets x264 choose (slices over the machine's cores: the bytes
    depend on the machine, and workers oversubscribe the cores); 1: one core per worker, same bytes everywhere."""
    h264_yuv_converter: str = "swscale"
    """Who converts the RGB frames to the encoder's yuv420p: "swscale" (FFmpeg, through PyAV) or "opencv"
    (cv2.cvtColor: the same BT.601 limited range within 1-3 levels, ~0.3 dB lower PSNR, ~18 % less encode CPU
    with "ultrafast")."""
    h264_keep_encoder: bool = False
    """Keep one libx264 encoder per camera open over a log's clips (each clip starts with a forced IDR
    frame) instead of opening one per clip video: saves x264's ~3 ms set-up per video (0.15-0.2 ms per
    camera-frame of 17-frame clips). The first clip's bytes are unchanged; later clips differ slightly (the
    rate control remembers the clips before in the log), the same on every run and executor."""
    clips_per_shard: int = 32
    """Clips per tar shard."""
    filters: FilterConfig = dataclasses.field(default_factory=FilterConfig)
    privacy: PrivacyConfig = dataclasses.field(default_factory=PrivacyConfig)
    trajectory: TrajectoryConfig = dataclasses.field(default_factory=TrajectoryConfig)
    captioner: str = "template"
    """"template" (scene tags + measured motion) or "package.module:Class", a Captioner subclass."""
    contact_sheet_clips: int = 4
    """Sample clips shown in contact_sheet.png."""

    def validate(self) -> None:
        at_least(self, 2, "clip_frames")
        at_least(self, 1, "stride_frames", "trajectory_waypoints", "shot_min_frames", "clips_per_shard")
        at_least(self, 0, "shot_threshold", "sync_tolerance_ms", "contact_sheet_clips")
        frame_rate(self, "fps")
        in_range(self, "crf", 0, 51)  # libx264's range
        if self.cameras is not None:
            require(
                len(self.cameras) > 0 and len(set(self.cameras)) == len(self.cameras),
                "cameras",
                self.cameras,
                "a non-empty list of distinct names",
            )
            for name in self.cameras:
                check_name(name, "cameras: camera name")
        if self.sync_tolerance_ms * 1e-3 >= 0.5 / self.fps:
            raise DrivewmError(
                f"sync_tolerance_ms must be below half a frame ({500 / self.fps:.1f} ms), got {self.sync_tolerance_ms}"
            )
        if self.max_gap_ms <= 1000.0 / self.fps:
            raise DrivewmError(
                f"curate config: max_gap_ms {self.max_gap_ms} must exceed a clip frame ({1000 / self.fps:g} ms)"
            )
        if self.resolution is not None and (len(self.resolution) != 2 or any(v <= 0 or v % 2 for v in self.resolution)):
            raise DrivewmError(f"curate config: resolution {self.resolution} must be [W, H] with even positive values")
        from drivewm.clips.video import X264_PRESETS, YUV_CONVERTERS

        if self.h264_preset not in X264_PRESETS or self.h264_threads < 0:
            raise DrivewmError(
                f"curate config: h264_preset {self.h264_preset!r} must be one of {list(X264_PRESETS)} "
                f"and h264_threads ({self.h264_threads}) >= 0"
            )
        if self.h264_yuv_converter not in YUV_CONVERTERS:
            raise DrivewmError(
                f"curate config: h264_yuv_converter {self.h264_yuv_converter!r} must be one of {list(YUV_CONVERTERS)}"
            )

    @property
    def period_ns(self) -> float:
        """Clip frame period in ns."""
        return 1e9 / self.fps


CURATE_RECIPES = RecipeBook("curate", CurateConfig, {"default": {}}, "default", recipes="curate")
"""How a curation config is made (docs/DESIGN.md section 10): the defaults above, a recipe (a packaged
name such as ``test`` or a YAML path, ``drivewm/recipes/curate/``) and ``--set KEY=VALUE``."""


def load_curate_config(recipe: str | Path | None = None, overrides: list[str] = ()) -> CurateConfig:
    """The config of a curation ``recipe`` (a packaged name or a path; None: the defaults) with overrides."""
    return CURATE_RECIPES.resolve(None, recipe, list(overrides))
