"""SIFT matching helpers for the sim geometry tests (OpenCV only; the reference geometry comes
from the log's own calibration and poses)."""

from __future__ import annotations

import cv2
import numpy as np

from drivewm.geometry import Camera, invert_T, pixel_rays, project, transform_points
from drivewm.logs.types import AgentBox

_SIFT = cv2.SIFT_create()


def sift(img_rgb: np.ndarray, ignore: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Keypoints (N, 2) px and descriptors (N, 128); ``ignore`` (H, W) bool drops keypoints on it."""
    kps, desc = _SIFT.detectAndCompute(cv2.cvtColor(img_rgb, cv2.COLOR_RGB2GRAY), None)
    xy = np.float64([k.pt for k in kps]).reshape(-1, 2)
    if desc is None:
        return xy, np.zeros((0, 128), np.float32)
    if ignore is not None:
        keep = ~ignore[xy[:, 1].astype(int), xy[:, 0].astype(int)]
        xy, desc = xy[keep], desc[keep]
    return xy, desc


def match(
    a: tuple[np.ndarray, np.ndarray], b: tuple[np.ndarray, np.ndarray], ratio: float = 0.8
) -> tuple[np.ndarray, np.ndarray]:
    """Lowe ratio-test matches between two (keypoints, descriptors): (x_a, x_b) each (M, 2)."""
    if len(a[1]) < 2 or len(b[1]) < 2:
        return np.zeros((0, 2)), np.zeros((0, 2))
    pairs = cv2.BFMatcher(cv2.NORM_L2).knnMatch(a[1], b[1], k=2)
    good = [m for m, n in (p for p in pairs if len(p) == 2) if m.distance < ratio * n.distance]
    return a[0][[m.queryIdx for m in good]].reshape(-1, 2), b[0][[m.trainIdx for m in good]].reshape(-1, 2)


def in_view_of(cam_from: Camera, cam_to: Camera, uv: np.ndarray, margin_px: float = 30.0) -> np.ndarray:
    """Which pixels of ``cam_from`` look in a direction ``cam_to`` also sees (rays at infinity,
    ``margin_px`` for parallax): a match outside the shared field of view cannot be right."""
    R = (invert_T(cam_to.T_ego_from_cam) @ cam_from.T_ego_from_cam)[:3, :3]
    p, z = project(cam_to.K, pixel_rays(cam_from.K, uv) @ R.T)
    return (
        (z > 0)
        & (p[:, 0] > -margin_px)
        & (p[:, 0] < cam_to.width + margin_px)
        & (p[:, 1] > -margin_px)
        & (p[:, 1] < cam_to.height + margin_px)
    )


def agent_mask(cam: Camera, T_world_from_ego: np.ndarray, boxes: list[AgentBox], pad_px: int = 3) -> np.ndarray:
    """(H, W) bool: the image rectangles of the other road users (they move: not for ego motion)."""
    mask = np.zeros((cam.height, cam.width), bool)
    T_cam_from_world = invert_T(T_world_from_ego @ cam.T_ego_from_cam)
    signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)], np.float64)
    for b in boxes:
        c, s = np.cos(b.yaw_rad), np.sin(b.yaw_rad)
        corners = (signs * np.asarray(b.size_lwh) / 2) @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + b.center_xyz
        p = transform_points(T_cam_from_world, corners)
        p = p[p[:, 2] > 0.1]
        if len(p):
            uv, _ = project(cam.K, p)
            x0, y0 = np.maximum(np.floor(uv.min(axis=0)) - pad_px, 0).astype(int)
            x1, y1 = np.ceil(uv.max(axis=0) + pad_px).astype(int)
            mask[y0 : max(y1, 0), x0 : max(x1, 0)] = True
    return mask
