"""Per-camera quantities that stay fixed for a whole drive.

The ego moves on the flat ground z = 0 without pitch or roll, so where each pixel's ray meets
the ground *in the ego frame* never changes: the ground hits, their depths, the mip level
they need and the sky are computed once; per tick only a 2D rigid motion maps the hits into
the world to look up the ground texture.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from drivewm.geometry import Camera, invert_T
from drivewm.sim.conditions import Condition, fog_weight, to_uint8
from drivewm.sim.ground import DETAIL_LEVELS, DETAIL_RES_M

EGO_HEADLIGHT_X_M = 3.6  # front bumper ahead of the rear axle


@dataclasses.dataclass
class CameraView:
    """One camera's fixed geometry. Pixel (u, v) has normalised coordinates (xn[u], yn[v], 1)."""

    name: str
    K: np.ndarray
    width: int
    height: int
    T_cam_from_ego: np.ndarray
    xn: np.ndarray  # (W,) float32
    yn: np.ndarray  # (H,) float32
    ray_norm: np.ndarray  # (H, W) float32 length of (xn, yn, 1): camera depth z -> distance
    ground_z: np.ndarray  # (H, W) float32 camera depth of the ground hit, inf for sky
    ground_idx: np.ndarray  # flat indices of the drawn ground pixels, grouped by mip level
    level_slices: list[slice]  # per mip level: its part of ground_idx
    ground_ego_xy: np.ndarray  # (N, 1, 2) float32 ground hits of ground_idx in the ego frame
    headlight_gain: np.ndarray | None  # (N, 1) float32 ego low-beam gain per ground pixel, or None
    far_idx: np.ndarray  # flat indices of ground beyond the drawn range
    detail_runs: list[tuple[slice, int]]  # (part of ground_idx, grain level) runs that get fine grain
    sky: np.ndarray  # (H, W, 3) uint8 background (sky gradient)
    ground_fog: np.ndarray  # (H, W) float32 transmittance of the ground/sky per pixel
    side_planes: np.ndarray  # (4, 3) unit inward normals of the frustum side planes (camera frame)
    fog_image: np.ndarray  # (H, W, 3) uint8 of the fog colour

    @classmethod
    def build(cls, cam: Camera, texel_m: float, levels: int, cond: Condition, max_range_m: float) -> CameraView:
        """Precompute ``cam``'s rays, ground hits (texture mip level ``levels`` - 1 at most for
        ``texel_m`` texels) and condition-dependent backgrounds."""
        xn = ((np.arange(cam.width) - cam.K[0, 2]) / cam.K[0, 0]).astype(np.float32)
        yn = ((np.arange(cam.height) - cam.K[1, 2]) / cam.K[1, 1]).astype(np.float32)
        rays_cam = np.stack(np.broadcast_arrays(xn[None, :], yn[:, None], np.float32(1.0)), axis=-1)  # (H, W, 3)
        rays_ego = rays_cam @ cam.T_ego_from_cam[:3, :3].T
        t, hit = _ground_hits(rays_ego, cam.T_ego_from_cam[:3, 3])
        ray_norm = np.linalg.norm(rays_cam, axis=-1).astype(np.float32)
        ground = np.isfinite(t)
        near = ground & (np.linalg.norm(hit - cam.T_ego_from_cam[:2, 3], axis=-1) <= max_range_m)
        ground_idx, level_slices, detail_runs = _ground_runs(
            near, _mip_level(hit, texel_m, levels), _mip_level(hit, DETAIL_RES_M, DETAIL_LEVELS + 1), levels
        )
        ground_xy = hit.reshape(-1, 2)[ground_idx]
        gain = _headlight_gain(ground_xy, cond)
        # The sky already has the condition's colour: only surfaces (finite depth) are fogged.
        fog = np.where(ground, fog_weight(t * ray_norm, cond.visibility_m), 1.0).astype(np.float32)
        return cls(
            cam.name,
            cam.K,
            cam.width,
            cam.height,
            invert_T(cam.T_ego_from_cam),
            xn,
            yn,
            ray_norm,
            t.astype(np.float32),
            ground_idx,
            level_slices,
            ground_xy.astype(np.float32)[:, None, :],
            None if gain is None else gain[:, None].astype(np.float32),
            np.flatnonzero(ground & ~near),
            detail_runs,
            _sky(rays_ego, cond),
            fog,
            _side_planes(cam.K, cam.width, cam.height),
            np.broadcast_to(to_uint8(np.asarray(cond.fog_rgb)), (cam.height, cam.width, 3)).copy(),
        )

    def sphere_visible(self, centers_cam: np.ndarray, radii: np.ndarray, max_range_m: float) -> np.ndarray:
        """Which bounding spheres (N, 3 camera frame; N radii) touch the frustum within range."""
        inside = (centers_cam @ self.side_planes.T >= -radii[:, None]).all(axis=1)
        return inside & (centers_cam[:, 2] > -radii) & (np.linalg.norm(centers_cam, axis=1) - radii < max_range_m)


def _ground_hits(rays_ego: np.ndarray, center_ego: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Camera depth t (H, W) where each ray (H, W, 3 ego frame, camera z = 1) meets z = 0, inf if
    never, and the hit points (H, W, 2) in the ego frame."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(rays_ego[..., 2] < -1e-6, -center_ego[2] / rays_ego[..., 2], np.inf)
        hit = center_ego[:2] + t[..., None] * rays_ego[..., :2]  # inf/nan for sky
    return t, hit


def _ground_runs(near: np.ndarray, level: np.ndarray, grain: np.ndarray, levels: int):
    """Drawn ground pixels sorted by (mip level, grain level), so every group is one contiguous run:
    (flat indices, slice per mip level, [(slice, grain level)] of the runs that get grain)."""
    n_grain = DETAIL_LEVELS + 1  # the last grain level means no grain
    ground_idx = np.flatnonzero(near)
    key = (level * n_grain + grain).reshape(-1)[ground_idx]
    order = np.argsort(key, kind="stable")
    ground_idx, key = ground_idx[order], key[order]
    starts = np.searchsorted(key, np.arange(levels * n_grain + 1))
    level_slices = [slice(starts[k * n_grain], starts[(k + 1) * n_grain]) for k in range(levels)]
    runs = [(slice(starts[i], starts[i + 1]), i % n_grain) for i in range(levels * n_grain)]
    return ground_idx, level_slices, [(r, g) for r, g in runs if g < DETAIL_LEVELS and r.stop > r.start]


def _mip_level(hit: np.ndarray, texel_m: float, levels: int) -> np.ndarray:
    """Mip level per pixel: log2 of the ground footprint in texels. The footprint is the geometric
    mean of the distances to the neighbouring pixels' hits: sharper than their maximum at grazing
    angles (an anisotropic footprint), at the price of a little aliasing along the view direction."""
    with np.errstate(invalid="ignore"):
        du = np.linalg.norm(np.diff(hit, axis=1, append=hit[:, -1:] * np.nan), axis=-1)
        dv = np.linalg.norm(np.diff(hit, axis=0, prepend=hit[:1] * np.nan), axis=-1)
        foot = np.sqrt(du * dv)
        lv = np.floor(np.log2(np.maximum(foot, 1e-9) / texel_m) + 0.3)
    lv = np.where(np.isfinite(lv), lv, levels - 1)
    return np.clip(lv, 0, levels - 1).astype(np.int32)


def _headlight_gain(ground_ego_xy: np.ndarray, cond: Condition) -> np.ndarray | None:
    """Brightening of the ground by the ego's low beams (1 = none), night and dusk only."""
    if cond.time_of_day == "day":
        return None
    x, y = ground_ego_xy[:, 0] - EGO_HEADLIGHT_X_M, ground_ego_xy[:, 1]
    with np.errstate(invalid="ignore", over="ignore"):
        ang = np.arctan2(np.abs(y) - 0.4, np.maximum(x, 1e-3)).clip(0)
        beam = np.where(
            x > 0, np.exp(-((ang / 0.35) ** 2)) * np.minimum(1.0, (x / 4.0) ** 2) / (1 + (x / 22.0) ** 2), 0.0
        )
    strength = 9.0 if cond.time_of_day == "night" else 1.2
    return np.nan_to_num(1.0 + strength * beam, nan=1.0)


def _sky(rays_ego: np.ndarray, cond: Condition) -> np.ndarray:
    """Vertical sky gradient from the horizon colour to the zenith colour by ray elevation."""
    elev = np.arctan2(rays_ego[..., 2], np.linalg.norm(rays_ego[..., :2], axis=-1))
    k = (np.clip(elev / 0.7, 0, 1) ** 0.6)[..., None]
    return to_uint8(np.asarray(cond.sky_horizon) * (1 - k) + np.asarray(cond.sky_top) * k)


def _side_planes(K: np.ndarray, width: int, height: int) -> np.ndarray:
    """Inward unit normals of the four frustum side planes through the image borders."""
    x0, x1 = (-0.5 - K[0, 2]) / K[0, 0], (width - 0.5 - K[0, 2]) / K[0, 0]
    y0, y1 = (-0.5 - K[1, 2]) / K[1, 1], (height - 0.5 - K[1, 2]) / K[1, 1]
    n = np.array([[1, 0, -x0], [-1, 0, x1], [0, 1, -y0], [0, -1, y1]], np.float64)
    return n / np.linalg.norm(n, axis=1, keepdims=True)
