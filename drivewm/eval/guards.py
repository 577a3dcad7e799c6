"""Guards that keep degenerate videos from winning the headline figures (docs/eval-protocol.md, 'Guards').

Epipolar errors reward what they cannot see: static points satisfy any F through the epipole, a
slowly zoomed still is a plane homography that every F through its centre fits, one view copied
into all cameras matches itself perfectly, and a time-reversed or camera-shifted video is as
self-consistent as the real one. Each guard tests the evidence those figures take for granted:

- **motion** (per frame pair): matches that no single homography explains (parallax, H&Z sec.
  13.3: a homography relates two views of a plane, or of any scene under pure rotation or zoom).
  Where the camera's travel (ego poses, else the conditioned trajectory's speed, else assumed)
  makes parallax resolvable at the camera's focal length (:func:`expected_parallax_px`), a TSE
  pair needs a share of its verified matches off the best homography (:func:`motion_evidence`),
  else it is scored as failed (``no_motion``).
- **direction** (per camera): the direction the camera travels between frames t and t + g,
  recovered from its own frames (:func:`drivewm.eval.epipolar.relative_pose`: E picks t's sign by
  cheirality, H&Z sec. 9.6.3), against the direction the clip's ego poses, its conditioned
  trajectory or, without either, a road vehicle driving forward (ego +x) put it in that camera's
  frame through the rig's extrinsics. Reversed time reads about 180 degrees off (``guard_time``);
  a view of another camera (shifted, swapped, copied, mirrored) reads that camera's mounting angle
  off (``guard_views``).
- **duplicate views**: two cameras whose frames are (mirror) copies of each other (``guard_views``).
- **plausible poses**: the yaw structure from motion reconstructs against the one two-view
  geometry reads, frame to frame (:func:`two_view_rotations`), and the distance it travels.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from drivewm.eval.config import EpipolarConfig, GuardConfig
from drivewm.eval.epipolar import frame_pair_fit, rectify_matches, relative_pose
from drivewm.eval.matching import FrameMatcher, Matches
from drivewm.geometry import Camera, Rig, invert_T, nearest_rotation

#: Matches off a plane's homography that fix the epipole, hence F (H&Z result 13.3).
MIN_PARALLAX_MATCHES = 2


def parallax_count(m: Matches, threshold_px: float) -> int:
    """Matches (pixels of one pinhole) farther than ``threshold_px`` from the best homography's
    transfer (cv2.findHomography, RANSAC at that threshold): the matches whose motion a plane, a
    rotation or a zoom cannot explain. 0 with fewer than 4 matches. RANSAC stops early on the
    degenerate pairs (nearly every match an inlier); the cap of 500 samples only ever leaves a
    real pair's homography short of the best, which counts more parallax, never less."""
    if len(m) < 4:
        return 0
    try:
        H, _ = cv2.findHomography(m.uv_a, m.uv_b, cv2.RANSAC, threshold_px, maxIters=500, confidence=0.99)
    except cv2.error:
        return 0
    if H is None:
        return len(m)
    uv = cv2.perspectiveTransform(m.uv_a.reshape(-1, 1, 2).astype(np.float64), H).reshape(-1, 2)
    return int(np.sum(np.linalg.norm(uv - m.uv_b, axis=1) > threshold_px))


def motion_evidence(m: Matches, cfg: GuardConfig, epi_cfg: EpipolarConfig, parallax_px: float) -> bool:
    """Whether a pair's verified matches (pixels of one pinhole) show the motion of a scene with
    depth: of the matches that moved ``epi_cfg.min_parallax_px``, as many as F's robust fit needs
    (``epi_cfg.min_matches``) or ``min_parallax_fraction`` of all, whichever is fewer, and at least
    2, lie ``parallax_px`` off the best homography (:func:`parallax_count`). The share serves small
    frames (a 160x96 pair verifies a tenth of a 320x192 one's matches), the count views where one
    plane (a wall) holds most matches; keypoint noise and mismatches put only a few percent of an
    exact homography's matches past ``parallax_px``. Two matches off a plane's homography fix F
    (plane plus parallax, H&Z result 13.3)."""
    moved = np.linalg.norm(m.uv_b - m.uv_a, axis=1) >= epi_cfg.min_parallax_px
    share = int(np.ceil(cfg.min_parallax_fraction * len(m)))
    need = max(MIN_PARALLAX_MATCHES, min(epi_cfg.min_matches, share))
    if moved.sum() < need:
        return False
    return parallax_count(Matches(m.uv_a[moved], m.uv_b[moved]), parallax_px) >= need


def expected_parallax_px(focal_native_px: float, travel_m: float | None, cfg: GuardConfig) -> float:
    """Parallax (the camera's own px) that a translation of ``travel_m`` between two frames gives
    between scene content at ``parallax_depth_m`` and the far background, seen across the
    direction of travel: f t / Z (H&Z sec. 13.3: parallax is proportional to the baseline and the
    inverse depth difference). Infinite when the travel is unknown (a road vehicle is assumed to drive)."""
    if travel_m is None:
        return float("inf")
    return focal_native_px * travel_m / cfg.parallax_depth_m


def motion_demanded(focal_native_px: float, travel_m: float | None, cfg: GuardConfig) -> bool:
    """A frame pair must show motion evidence when its expected parallax reaches
    ``parallax_threshold_native_px`` (the resolution at which :func:`motion_evidence` counts it):
    a slow ego, a short frame gap or a small frame leave a pair without that demand."""
    return expected_parallax_px(focal_native_px, travel_m, cfg) >= cfg.parallax_threshold_native_px


def camera_travel_m(
    camera: Camera, t: int, u: int, T_world_from_ego: np.ndarray | None, speed_mps: float | None, fps: float
) -> float | None:
    """How far (m) the camera travels from frame t to u: from the ego poses, else the conditioned
    speed over (u - t) / fps, else None."""
    if T_world_from_ego is not None:
        T_wc = T_world_from_ego @ camera.T_ego_from_cam
        return float(np.linalg.norm(T_wc[u, :3, 3] - T_wc[t, :3, 3]))
    if speed_mps is not None and fps > 0:
        return speed_mps * (u - t) / fps
    return None


def conditioned_speed_mps(trajectory_ego: list, dt_s: float) -> float | None:
    """Mean speed (m/s) of a conditioned trajectory (ego-frame waypoints ``dt_s`` apart, from the
    clip's start), or None without waypoints or a time step."""
    w = np.asarray(trajectory_ego, dtype=np.float64).reshape(-1, 3) if len(trajectory_ego) else np.zeros((0, 3))
    if len(w) == 0 or dt_s <= 0:
        return None
    path = np.linalg.norm(np.diff(np.vstack([np.zeros((1, 3)), w])[:, :2], axis=0), axis=1).sum()
    return float(path / (len(w) * dt_s))


@dataclasses.dataclass
class EgoPrior:
    """What the clip says of its ego motion beside its poses: the ego-frame travel direction
    ``forward_ego`` (3,) (:func:`forward_direction_ego`), the conditioned speed ``speed_mps`` (None
    when unknown, :func:`conditioned_speed_mps`) and the frame rate ``fps``."""

    forward_ego: np.ndarray
    speed_mps: float | None
    fps: float


def ego_prior(trajectory_ego: list, dt_s: float, fps: float) -> EgoPrior:
    """The :class:`EgoPrior` of a clip's conditioned trajectory (ego-frame waypoints ``dt_s`` apart;
    ``1 / fps`` when 0) and frame rate."""
    return EgoPrior(forward_direction_ego(trajectory_ego), conditioned_speed_mps(trajectory_ego, dt_s or 1 / fps), fps)


def travel_direction_cam(m: Matches, K: np.ndarray, cfg: EpipolarConfig, native_px_per_px: float) -> np.ndarray | None:
    """Unit direction (3,) in which the camera moved from image a to image b, in a's camera frame
    (the centre of b, -R^T t of T_b_from_a), or None when E cannot be fitted on ``min_matches`` inliers."""
    T, inliers = relative_pose(m, K, cfg, native_px_per_px)
    if T is None or inliers.sum() < cfg.min_matches:
        return None
    centre = -T[:3, :3].T @ T[:3, 3]
    return centre / max(np.linalg.norm(centre), 1e-12)


def expected_travel_cam(
    camera: Camera, t: int, u: int, T_world_from_ego: np.ndarray | None, forward_ego: np.ndarray
) -> np.ndarray | None:
    """The unit direction (3,) the camera should travel from frame t to u, in its frame at t: from
    the ego poses when known (None when the camera moves less than 1 cm), else ``forward_ego``
    (ego frame) turned into the camera's frame."""
    if T_world_from_ego is not None:
        T_wc = T_world_from_ego @ camera.T_ego_from_cam
        d = (invert_T(T_wc[t]) @ T_wc[u])[:3, 3]
        return d / np.linalg.norm(d) if np.linalg.norm(d) >= 0.01 else None
    return camera.T_ego_from_cam[:3, :3].T @ forward_ego


def forward_direction_ego(trajectory_ego: list) -> np.ndarray:
    """Unit ego-frame direction (3,) of travel: toward the first conditioned waypoint at least 1 m
    away, else ego +x (a road vehicle drives forward)."""
    w = np.asarray(trajectory_ego, dtype=np.float64).reshape(-1, 3) if len(trajectory_ego) else np.zeros((0, 3))
    far = np.flatnonzero(np.linalg.norm(w[:, :2], axis=1) >= 1.0)
    if len(far) == 0:
        return np.array([1.0, 0.0, 0.0])
    d = np.array([w[far[0], 0], w[far[0], 1], 0.0])
    return d / np.linalg.norm(d)


def angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (degrees) between two unit vectors."""
    return float(np.degrees(np.arccos(np.clip(a @ b, -1.0, 1.0))))


@dataclasses.dataclass
class DirectionVerdict:
    """Per camera, the median angle (degrees) between recovered and expected travel over its
    scored frame pairs (NaN when too few could be scored), and the two guards it decides."""

    error_deg: dict[str, float]
    reversed_fraction: float
    time_ok: bool | None
    views_ok: bool | None


#: ``guard_views``: cameras whose travel reads off before their views count as other cameras'.
MIN_CAMERAS_OFF = 2


def direction_verdict(errors: dict[str, list[float]], cfg: GuardConfig) -> DirectionVerdict:
    """``guard_time`` is False when more than ``max_reversed_fraction`` of all scored pairs travel
    more than 90 degrees off and either every camera does (reversed) or some camera goes both ways
    (shuffled); ``guard_views`` is False when two or more cameras travel more than
    ``direction_tolerance_deg`` off and time does not explain it (their views are other cameras':
    shifted, swapped, copied, mirrored). One camera alone cannot show another's view unless the
    two are copies (:func:`duplicate_views`) or its own view is elsewhere (a second camera off);
    one camera's E alone can be misled (falling snow near the lens).
    Only cameras with at least ``min_scored_pairs`` scored pairs are judged; None: no camera has
    that many (e.g. a 3-frame clip), or time already failed (views)."""
    judged = {c: e for c, e in errors.items() if len(e) >= cfg.min_scored_pairs}  # one pair's E can mislead
    medians = {c: float(np.median(errors[c])) if c in judged else float("nan") for c in errors}
    if not judged:
        return DirectionVerdict(medians, float("nan"), None, None)
    every = np.concatenate([np.asarray(e, float) for e in judged.values()])
    reversed_fraction = float(np.mean(every > 90.0))
    per_camera = [float(np.mean(np.asarray(e) > 90.0)) for e in judged.values()]
    low, high = cfg.max_reversed_fraction, 1.0 - cfg.max_reversed_fraction
    mixed = any(low < f < high for f in per_camera)
    time_ok = not (reversed_fraction > low and (mixed or all(f >= high for f in per_camera)))
    scored = [v for v in medians.values() if np.isfinite(v)]
    off = sum(v > cfg.direction_tolerance_deg for v in scored)
    views_ok = bool(off < MIN_CAMERAS_OFF) if time_ok else None
    return DirectionVerdict(medians, reversed_fraction, time_ok, views_ok)


def duplicate_views(videos: dict[str, np.ndarray], rig: Rig, cfg: GuardConfig) -> list[str]:
    """Camera pairs ``"a~b"`` (or ``"a~mirror(b)"``) whose frames are copies: the correlation of
    their grey thumbnails (``thumbnail_px`` wide, every ``thumbnail_frame_step``-th frame, each
    frame's mean removed) is at least ``duplicate_correlation``. Two real cameras look elsewhere."""
    thumbs = {c: _thumbnails(videos[c], cfg) for c in rig.names}
    out = []
    for i, a in enumerate(rig.names):
        for b in rig.names[i + 1 :]:
            if _correlation(thumbs[a], thumbs[b]) >= cfg.duplicate_correlation:
                out.append(f"{a}~{b}")
            elif _correlation(thumbs[a], thumbs[b][..., ::-1]) >= cfg.duplicate_correlation:
                out.append(f"{a}~mirror({b})")
    return out


def _thumbnails(frames: np.ndarray, cfg: GuardConfig) -> np.ndarray:
    """(T', h, w) float grey thumbnails of every ``thumbnail_frame_step``-th frame, each zero-mean."""
    _, h, w, _ = frames.shape
    size = (cfg.thumbnail_px, max(2, round(h * cfg.thumbnail_px / w)))
    out = []
    for f in frames[:: cfg.thumbnail_frame_step]:
        g = cv2.resize(cv2.cvtColor(np.ascontiguousarray(f), cv2.COLOR_RGB2GRAY), size, interpolation=cv2.INTER_AREA)
        g = g.astype(np.float64)
        out.append(g - g.mean())
    return np.stack(out)


def _correlation(a: np.ndarray, b: np.ndarray) -> float:
    """Normalised correlation of two equally shaped zero-mean stacks (thumbnails of different
    sizes are resized to a's); 0 when either is flat."""
    if a.shape != b.shape:
        b = np.stack([cv2.resize(f, (a.shape[2], a.shape[1]), interpolation=cv2.INTER_AREA) for f in b])
    n = min(len(a), len(b))
    a, b = a[:n].ravel(), b[:n].ravel()
    denom = np.linalg.norm(a) * np.linalg.norm(b)
    return float(a @ b / denom) if denom > 0 else 0.0


@dataclasses.dataclass
class TwoViewMotion:
    """A camera's frame-to-frame motion from two-view geometry alone: ``R_first_from_t`` (T, 3, 3)
    chained rotations (camera frame) and ``moved`` (T - 1,) whether each pair showed parallax."""

    R_first_from_t: np.ndarray
    moved: np.ndarray


def two_view_rotations(
    frames: np.ndarray,
    camera: Camera,
    matcher: FrameMatcher,
    K_c: np.ndarray,
    epi_cfg: EpipolarConfig,
    scale: float,
    guard_cfg: GuardConfig,
) -> TwoViewMotion:
    """Chained rotations of one camera over consecutive frames (uint8 (T, H, W, 3)): each pair's
    rotation from :func:`relative_pose` (USAC_ACCURATE E) on the matcher's (cached) matches
    rectified to ``K_c``; a pair whose F-verified matches show no parallax (:func:`motion_evidence`:
    pure rotation, zoom, frozen) from its homography instead (R = K^-1 H K, H&Z sec. 8.4.2), and
    identity when neither fits. ``scale``: the camera's native px per canonical px."""
    R = [np.eye(3)]
    moved = []
    parallax_px = guard_cfg.parallax_threshold_native_px / scale
    for t in range(len(frames) - 1):
        m = rectify_matches(
            matcher.match((camera.name, t), frames[t], (camera.name, t + 1), frames[t + 1]), camera, camera, K_c
        )
        _, keep = frame_pair_fit(matcher, (camera.name, t), (camera.name, t + 1), m, epi_cfg, scale)
        verified = Matches(m.uv_a[keep], m.uv_b[keep])
        has_parallax = motion_evidence(verified, guard_cfg, epi_cfg, parallax_px)
        R_b_from_a = _pair_rotation(m, K_c, epi_cfg, scale, has_parallax)
        moved.append(has_parallax)
        R.append(R[-1] @ R_b_from_a.T)
    return TwoViewMotion(np.stack(R), np.array(moved, dtype=bool))


def _pair_rotation(m: Matches, K_c: np.ndarray, epi_cfg: EpipolarConfig, scale: float, moved: bool) -> np.ndarray:
    """R_b_from_a of one frame pair: from E with parallax, else from the homography; identity if neither fits."""
    if moved:
        T, inliers = relative_pose(m, K_c, epi_cfg, scale)
        if T is not None and inliers.sum() >= epi_cfg.min_matches:
            return T[:3, :3]
    if len(m) < 4:
        return np.eye(3)
    H, _ = cv2.findHomography(m.uv_a, m.uv_b, cv2.RANSAC, 1.0 / scale)
    if H is None:
        return np.eye(3)
    return nearest_rotation(np.linalg.inv(K_c) @ H @ K_c)


def ego_yaw_deg(R_first_from_last_cam: np.ndarray, camera: Camera) -> float:
    """The ego's yaw change (degrees, left positive) for a camera rotation R_first_from_last (camera
    frame), through the camera's extrinsics."""
    R_ec = camera.T_ego_from_cam[:3, :3]
    R = R_ec @ R_first_from_last_cam @ R_ec.T
    return float(np.degrees(np.arctan2(R[1, 0], R[0, 0])))
