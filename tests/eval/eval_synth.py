"""Exactly-known multi-camera videos for the eval tests: a textured box world ray-cast through a rig.

The ego drives along a gently curving path inside a corridor (ground z=0, walls y=+-HALF_WIDTH,
ceiling z=CEILING, end walls x=+-END); every surface carries its own random multi-scale texture,
so SIFT finds plenty of features and every correspondence obeys the rig's true geometry exactly
(up to rendering and H.264 error). Images are rendered at 2x and area-downsampled (anti-aliasing).
"""

from __future__ import annotations

import cv2
import numpy as np

from drivewm.clips.format import ClipMeta, clip_from_arrays
from drivewm.geometry import Rig, T_from_xyz_yaw, invert_T, pixel_rays

HALF_WIDTH, CEILING, END = 9.0, 9.0, 80.0
TEX_SIZE, TEX_PX_PER_M = 1024, 24.0
# Planes as (normal n, offset d) with n . X = d, and the two world axes spanning their texture.
PLANES = [
    (np.array([0, 0, 1.0]), 0.0, (0, 1)),
    (np.array([0, 0, 1.0]), CEILING, (0, 1)),
    (np.array([0, 1.0, 0]), HALF_WIDTH, (0, 2)),
    (np.array([0, 1.0, 0]), -HALF_WIDTH, (0, 2)),
    (np.array([1.0, 0, 0]), END, (1, 2)),
    (np.array([1.0, 0, 0]), -END, (1, 2)),
]


def make_texture(seed: int) -> np.ndarray:
    """A random texture (repeats with a mirror seam), float32 (TEX_SIZE, TEX_SIZE, 3) in [0, 255]."""
    rng = np.random.default_rng(seed)
    acc = np.zeros((TEX_SIZE, TEX_SIZE, 3), np.float32)
    for sigma, weight in [(1.5, 0.5), (4.0, 1.0), (12.0, 1.0)]:
        noise = rng.normal(size=(TEX_SIZE, TEX_SIZE, 3)).astype(np.float32)
        blurred = cv2.GaussianBlur(noise, (0, 0), sigma, borderType=cv2.BORDER_REFLECT_101)
        acc += weight * blurred / blurred.std()
    base = rng.uniform(60, 190, 3).astype(np.float32)
    return np.clip(base + 28.0 * acc, 0, 255)


def render(
    rig: Rig, T_world_from_ego: np.ndarray, textures: list[np.ndarray], supersample: int = 2
) -> dict[str, np.ndarray]:
    """One uint8 RGB (H, W, 3) image per camera of ``rig`` at ego pose ``T_world_from_ego``."""
    out = {}
    for cam in rig.cameras:
        big = cam.scaled(cam.width * supersample, cam.height * supersample)
        vv, uu = np.mgrid[0 : big.height, 0 : big.width]
        uv = np.stack([uu.ravel(), vv.ravel()], 1).astype(np.float64)
        if np.any(cam.distortion):  # the ray through each pixel of a lens with OpenCV distortion
            xy = cv2.undistortPoints(uv.reshape(-1, 1, 2), big.K, cam.distortion).reshape(-1, 2)
            rays = np.concatenate([xy, np.ones((len(xy), 1))], 1)
        else:
            rays = pixel_rays(big.K, uv)
        T_wc = T_world_from_ego @ cam.T_ego_from_cam
        dirs, origin = rays @ T_wc[:3, :3].T, T_wc[:3, 3]
        color = _cast(origin, dirs, textures).reshape(big.height, big.width, 3)
        out[cam.name] = (
            cv2.resize(color, (cam.width, cam.height), interpolation=cv2.INTER_AREA).round().astype(np.uint8)
        )
    return out


def _cast(origin: np.ndarray, dirs: np.ndarray, textures: list[np.ndarray]) -> np.ndarray:
    """Colour (N, 3) of the nearest plane hit by each ray."""
    with np.errstate(divide="ignore", invalid="ignore"):
        ts = np.stack([(d - origin @ n) / (dirs @ n) for n, d, _ in PLANES], 1)
    ts[~(ts > 1e-6)] = np.inf
    which = np.argmin(ts, 1)
    t = ts[np.arange(len(ts)), which]
    hits = origin + dirs * t[:, None]
    color = np.zeros((len(dirs), 3), np.float32)
    for i, (_, _, (a, b)) in enumerate(PLANES):
        sel = which == i
        if np.any(sel):
            color[sel] = _sample(textures[i], hits[sel, a] * TEX_PX_PER_M, hits[sel, b] * TEX_PX_PER_M)
    return color


def _sample(texture: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Bilinear, wrapped texture lookup at texel coordinates x, y (N,) -> (N, 3)."""
    n, cols = len(x), 1024
    rows = -(-n // cols)
    pad = lambda v: np.pad((v % TEX_SIZE).astype(np.float32), (0, rows * cols - n)).reshape(rows, cols)  # noqa: E731
    out = cv2.remap(texture, pad(x), pad(y), cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP)
    return out.reshape(-1, 3)[:n]


def ego_path(num_frames: int, fps: float, speed_mps: float = 8.0, curve: float = 0.04) -> np.ndarray:
    """T_world_from_ego (T, 4, 4): forward at ``speed_mps`` on a slow left curve (curvature ``curve`` / 2 per m)."""
    s = np.arange(num_frames) * speed_mps / fps
    yaw = curve * s / 2.0
    y = 0.5 * curve * s**2 / 4.0
    return np.stack([T_from_xyz_yaw(si - 8.0, yi, 0.0, yi_yaw) for si, yi, yi_yaw in zip(s, y, yaw)])


def trajectory_waypoints(T_world_from_ego: np.ndarray) -> list[list[float]]:
    """Future positions (T-1, 3) of the ego in the first frame's ego frame (ClipMeta.trajectory_ego)."""
    T0_inv = invert_T(T_world_from_ego[0])
    return [(T0_inv @ T)[:3, 3].tolist() for T in T_world_from_ego[1:]]


def synth_frames(
    rig: Rig, num_frames: int = 9, fps: float = 10.0, seed: int = 0
) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Per-camera uint8 (T, H, W, 3) videos and T_world_from_ego (T, 4, 4)."""
    textures = [make_texture(seed * 10 + i) for i in range(len(PLANES))]
    poses = ego_path(num_frames, fps)
    per_frame = [render(rig, T, textures) for T in poses]
    return {c: np.stack([f[c] for f in per_frame]) for c in rig.names}, poses


def synth_clip(rig: Rig, key: str, num_frames: int = 9, fps: float = 10.0, seed: int = 0, tags: dict | None = None):
    """A :class:`drivewm.clips.Clip` of the synthetic world (H.264 encoded, like any real clip)."""
    frames, poses = synth_frames(rig, num_frames, fps, seed)
    meta = ClipMeta(
        key=key,
        source_log="synthetic",
        start_time_ns=0,
        fps=fps,
        timestamps_ns=[int(i * 1e9 / fps) for i in range(num_frames)],
        rig=rig.to_dict(),
        caption="a textured corridor",
        tags=tags or {},
        trajectory_ego=trajectory_waypoints(poses),
        trajectory_dt_s=1.0 / fps,
    )
    return clip_from_arrays(meta, frames, poses)
