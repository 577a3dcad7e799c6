"""Camera motion from dense optical flow: the fallback when structure from motion registers too few frames.

COLMAP needs repeatable SIFT features; blurry low-resolution generated frames (a debug tokenizer's
output, or a real one at 64 px) give it none, so it registers nothing there. Dense optical flow
(Farneback 2003) still finds where the image moved. Each consecutive frame pair gives
correspondences on a regular grid, from which the essential matrix (Nister's 5-point solver in
RANSAC, cv2.findEssentialMat) with the calibrated K yields the relative rotation and the direction
of translation (Hartley & Zisserman, sec. 9.6). The pairs are chained into camera poses.

The default motion model is a road vehicle's (``motion_model = "planar"``): between two frames the
ego turns by a yaw theta about its up axis and travels in its ground plane along a heading phi, two
degrees of freedom instead of the essential matrix's five. Scaramuzza et al. (ICRA 2009, "Real-time
monocular visual odometry for on-road vehicles with 1-point RANSAC") showed that this
non-holonomic constraint makes on-road motion recoverable from very few, noisy correspondences; here
(theta, phi) is found by a coarse-to-fine grid search minimising the Sampson error truncated at
``robust_px`` (so outliers cost a constant, as in a RANSAC consensus, without its randomness).
The free 5-point essential matrix confuses a yaw with a sideways translation when the flow is
noisy, and chaining 16 such pairs lets one wrong pair turn the clip: on the 187 clips of the first
20 held-out drives (front camera, 160x96) it read the sign of 51 of the 64 turning 10 degrees or
more (12 of 18 of 48 of them after the shipped tokenizer), the planar model 60 of 64 (17 of 18),
with a smaller median yaw error (1.15 against 1.80 degrees raw, 1.15 against 2.82 coded;
docs/eval-protocol.md, studies/flow_yaw_models.py).
``motion_model = "essential"`` keeps the 5-point model for rigs that are not on a road vehicle.

Scale: monocular motion has none; every step whose median flow exceeds ``min_flow_px`` gets a
translation of unit length (constant speed), steps without motion (a repeated frame, a stopped
car) get none. :func:`drivewm.eval.trajectory_errors.tfe` and ATE fit the scale anyway.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from drivewm.config import finite_at_least
from drivewm.errors import DrivewmError
from drivewm.eval.ego import EgoTrajectory, ego_trajectory
from drivewm.geometry import Camera, invert_T, make_T, rot_z, sampson_distance_sq, skew


@dataclasses.dataclass
class FlowMotionConfig:
    """Dense-flow relative poses between consecutive frames."""

    max_side_px: int = 160
    """Frames are resized so their longer side is at most this (flow is computed at that size, K scaled)."""
    blur_sigma_px: float = 1.0
    """Gaussian blur (at the working size) before the flow: removes blocky upsampling edges."""
    pyramid_levels: int = 4
    """Farneback pyramid levels (each halves the size): motions up to ~window * 2^levels / 2 px are found."""
    window_px: int = 15
    """Farneback averaging window (working px); larger is steadier on blurry frames."""
    grid_step_px: int = 4
    """Correspondences are taken on a grid with this spacing (working size)."""
    border_px: int = 4
    """Grid points this close to the image border are left out (flow is unreliable there)."""
    min_flow_px: float = 0.05
    """Median flow magnitude (working px) below which a frame pair counts as no motion (identity)."""
    ransac_threshold_px: float = 0.5
    """Epipolar inlier threshold of the essential-matrix RANSAC (working px)."""
    textured_fraction: float = 0.3
    """Only this fraction of grid points, the most textured (Shi-Tomasi min eigenvalue), is kept:
    flow in flat sky or road is ~0, and zero-flow points fit the identity rotation with any translation."""
    motion_model: str = "planar"
    """``planar``: yaw about the ego's up axis + travel in its ground plane (a road vehicle);
    ``essential``: any rigid motion (5-point essential matrix in RANSAC)."""
    max_yaw_deg: float = 12.0
    """Planar model: largest yaw between two consecutive frames searched (degrees)."""
    max_heading_deg: float = 30.0
    """Planar model: largest angle between the direction of travel and the ego's forward axis
    (degrees; it also absorbs the sideways motion of a camera mounted ahead of the turning axis)."""
    robust_px: float = 1.0
    """Planar model: Sampson errors (working px) are truncated here, so outliers cost a constant."""

    def validate(self) -> None:
        if self.motion_model not in MOTION_MODELS:
            raise DrivewmError(f"flow motion: motion_model must be one of {MOTION_MODELS}, got {self.motion_model!r}")
        finite_at_least("flow motion", 0, max_yaw_deg=self.max_yaw_deg, max_heading_deg=self.max_heading_deg)
        finite_at_least("flow motion", 1e-6, robust_px=self.robust_px)


MOTION_MODELS = ("planar", "essential")


def working_frames(frames: np.ndarray, camera: Camera, cfg: FlowMotionConfig) -> tuple[np.ndarray, np.ndarray]:
    """Grey float32 frames (T, h, w) at the working size and the camera matrix K (3, 3) there."""
    _, h, w, _ = frames.shape
    scale = min(1.0, cfg.max_side_px / max(h, w))
    size = (max(8, round(w * scale)), max(8, round(h * scale)))
    grey = [cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2GRAY) for f in frames]
    out = []
    for g in grey:
        g = cv2.resize(g, size, interpolation=cv2.INTER_AREA).astype(np.float32)
        out.append(cv2.GaussianBlur(g, (0, 0), cfg.blur_sigma_px) if cfg.blur_sigma_px > 0 else g)
    K = camera.scaled(size[0], size[1], fit="stretch").K.astype(np.float64)  # cv2.resize above
    return np.stack(out), K


def pair_correspondences(a: np.ndarray, b: np.ndarray, cfg: FlowMotionConfig) -> tuple[np.ndarray, np.ndarray]:
    """Grid points (N, 2) in frame ``a`` and where the dense flow a -> b puts them in ``b`` (px, x right, y down)."""
    flow = cv2.calcOpticalFlowFarneback(
        a,
        b,
        None,
        pyr_scale=0.5,
        levels=cfg.pyramid_levels,
        winsize=cfg.window_px,
        iterations=5,
        poly_n=7,
        poly_sigma=1.5,
        flags=0,
    )
    h, w = a.shape
    ys, xs = np.mgrid[
        cfg.border_px : h - cfg.border_px : cfg.grid_step_px, cfg.border_px : w - cfg.border_px : cfg.grid_step_px
    ]
    ys, xs = ys.ravel(), xs.ravel()
    texture = cv2.cornerMinEigenVal(a, 5)[ys, xs]
    keep = texture >= np.quantile(texture, 1 - cfg.textured_fraction)
    keep &= texture > 0
    p0 = np.stack([xs[keep], ys[keep]], 1).astype(np.float64)
    return p0, p0 + flow[ys[keep], xs[keep]].astype(np.float64)


def relative_pose(p0: np.ndarray, p1: np.ndarray, K: np.ndarray, cfg: FlowMotionConfig) -> np.ndarray | None:
    """T_cam1_from_cam0 (4, 4) with unit translation, identity when nothing moved, None when the
    essential matrix cannot be fitted."""
    if len(p0) < 8:
        return None
    if np.median(np.linalg.norm(p1 - p0, axis=1)) < cfg.min_flow_px:
        return np.eye(4)
    try:
        E, inliers = cv2.findEssentialMat(p0, p1, K, method=cv2.RANSAC, prob=0.999, threshold=cfg.ransac_threshold_px)
    except cv2.error:
        # OpenCV's RANSAC five-point solver asserts on a sample whose polynomial degenerates instead of
        # skipping it; USAC's samples the same matches with its own minimal solver.
        try:
            E, inliers = cv2.findEssentialMat(p0, p1, K, cv2.USAC_ACCURATE, 0.999, cfg.ransac_threshold_px)
        except cv2.error:
            return None
    if E is None or E.shape != (3, 3):
        return None
    _, R, t, _ = cv2.recoverPose(E, p0, p1, K, mask=inliers)
    return make_T(R, t.ravel() / max(np.linalg.norm(t), 1e-12))


def planar_relative_pose(
    p0: np.ndarray, p1: np.ndarray, K: np.ndarray, T_ego_from_cam: np.ndarray, cfg: FlowMotionConfig
) -> np.ndarray | None:
    """T_cam1_from_cam0 (4, 4) with unit translation under the planar vehicle model: the ego turns by
    theta about its z (up) axis and travels along (cos phi, sin phi, 0) of its first pose; (theta,
    phi) minimise the truncated Sampson error of ``p0`` -> ``p1`` (px) over a grid, then a finer one
    around the best. Identity when nothing moved, None with fewer than 8 points."""
    if len(p0) < 8:
        return None
    if np.median(np.linalg.norm(p1 - p0, axis=1)) < cfg.min_flow_px:
        return np.eye(4)
    K_inv = np.linalg.inv(K)
    x0 = (np.c_[p0, np.ones(len(p0))] @ K_inv.T)[:, :2]  # normalised image coordinates
    x1 = (np.c_[p1, np.ones(len(p1))] @ K_inv.T)[:, :2]
    R_c = T_ego_from_cam[:3, :3]
    f2 = K[0, 0] * K[1, 1]  # normalised -> px^2
    max_yaw, max_heading = np.radians(cfg.max_yaw_deg), np.radians(cfg.max_heading_deg)
    theta, phi = _grid(max_yaw, np.radians(0.5)), _grid(max_heading, np.radians(2.0))
    for _ in range(2):  # coarse, then around the best at a tenth of the step
        yaw, heading = (a.ravel() for a in np.meshgrid(theta, phi, indexing="ij"))
        R, t = _planar_motion(yaw, heading, R_c)
        with np.errstate(divide="ignore", invalid="ignore"):  # 0/0: a point on the epipole, no error
            sq = np.nan_to_num(sampson_distance_sq(skew(t) @ R, x0, x1), nan=0.0) * f2  # x1^T E x0 = 0
        cost = np.minimum(sq, cfg.robust_px**2).sum(axis=1)
        best = int(np.argmin(cost))
        d_theta, d_phi = np.diff(theta[:2])[0] / 10, np.diff(phi[:2])[0] / 10
        theta = np.clip(yaw[best] + d_theta * np.arange(-10, 11), -max_yaw, max_yaw)
        phi = np.clip(heading[best] + d_phi * np.arange(-10, 11), -max_heading, max_heading)
    return make_T(R[best], t[best])


def _grid(half_width: float, step: float) -> np.ndarray:
    """Values from -half_width to +half_width about ``step`` apart, 0 and both ends included."""
    n = max(1, int(np.ceil(half_width / step)))
    return np.linspace(-half_width, half_width, 2 * n + 1)


def _planar_motion(yaw: np.ndarray, heading: np.ndarray, R_ego_from_cam: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(H, 3, 3) R and (H, 3) unit t of T_cam1_from_cam0 for an ego that turned by ``yaw`` and travelled
    along ``heading`` (H,), the camera at the ego's origin (its offset is absorbed by the heading)."""
    Rz = rot_z(-yaw)  # ego1_from_ego0
    R = np.einsum("ji,hjk,kl->hil", R_ego_from_cam, Rz, R_ego_from_cam)
    travel = np.stack([np.cos(heading), np.sin(heading), np.zeros_like(heading)], axis=1)
    t = -np.einsum("ji,hjk,hk->hi", R_ego_from_cam, Rz, travel)
    return R, t


def flow_camera_poses(
    frames: np.ndarray, camera: Camera, cfg: FlowMotionConfig | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """``T_world_from_cam`` (T, 4, 4) with world = the first camera frame, and ``registered`` (T,) bool,
    from uint8 RGB frames (T, H, W, 3) of one calibrated camera. A pair that cannot be fitted ends
    the chain (later frames stay unregistered, NaN), as an SfM model would break there."""
    cfg = cfg or FlowMotionConfig()
    cfg.validate()
    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8 or len(frames) < 2:
        raise DrivewmError(
            f"flow motion of camera {camera.name}: need uint8 RGB frames (T >= 2, H, W, 3), "
            f"got {frames.dtype} {frames.shape}"
        )
    grey, K = working_frames(frames, camera, cfg)
    poses = np.full((len(grey), 4, 4), np.nan)
    registered = np.zeros(len(grey), dtype=bool)
    poses[0], registered[0] = np.eye(4), True
    for i in range(1, len(grey)):
        if np.array_equal(frames[i], frames[i - 1]):  # a repeated frame (a 4x causal decoder's layout): no motion
            poses[i], registered[i] = poses[i - 1], True
            continue
        p0, p1 = pair_correspondences(grey[i - 1], grey[i], cfg)
        T_cam1_from_cam0 = (
            planar_relative_pose(p0, p1, K, camera.T_ego_from_cam, cfg)
            if cfg.motion_model == "planar"
            else relative_pose(p0, p1, K, cfg)
        )
        if T_cam1_from_cam0 is None:
            break
        poses[i], registered[i] = poses[i - 1] @ invert_T(T_cam1_from_cam0), True
    return poses, registered


def flow_ego_trajectory(frames: np.ndarray, camera: Camera, cfg: FlowMotionConfig | None = None) -> EgoTrajectory:
    """The ego trajectory of one camera's frames from dense flow (world = the first camera frame)."""
    return ego_trajectory(*flow_camera_poses(frames, camera, cfg), camera)
