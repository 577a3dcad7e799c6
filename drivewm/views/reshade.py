"""Reshading the reprojection: the road at frame t looks as the first frame's road looks at that distance.

The reprojection (drivewm.views.warp, the ``reproject`` post-step) fetches a later frame's road from where
the first frame saw it, further away. Whatever makes the far road look unlike the near one comes
along: in fog the far road is mostly airlight, so a straight fog drive's warped road brightens frame
by frame (held-out: ground luma 118 -> 191 over 1.6 s, where the true frames stay at 118), and a
generated fog sample refined from 0.1 reads snow; on a wet road the grazing-angle sheen does the same.
The first frames say how the road looks at every distance: mu(d), the median colour of the road
within LANE_M of the ego's line (every distance of that strip is in view; a bin of the whole ground
would hold the lane near and the verges and fields beside it far) in bins of log distance, pooled
over the views and smoothed by a quadratic. A road pixel of frame t at distance d_t, fetched from
d_0, becomes

    I + mu(d_t) - mu(d_0)

(model-free; the identity where the road looks alike at every distance). Both distances are the
warp's own: the road plane (infinity is left as warped).
"""

from __future__ import annotations

import numpy as np

from drivewm.geometry import Rig, pixel_rays
from drivewm.views.rays import patch_centres_px
from drivewm.views.warp import ray_depths

PROFILE_M = (3.0, 150.0)  # road distances the profile is read over (nearer or further: its ends)
PROFILE_BINS = 14  # log-spaced over PROFILE_M
MIN_PIXELS_PER_BIN = 20  # a distance bin with fewer road pixels has no median
PROFILE_DEGREE = 2  # the profile is smoothed by a quadratic in log distance
LANE_M = 3.0  # the profile's strip: road this far (m) left and right of the first ego frame's line


def surface_distances(
    rig: Rig, hw: tuple[int, int], T_ego0_from_ego: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per view, frame and pixel of images ``hw`` (H, W) of ``rig``: the distance (m) from the camera
    at frame t to the road point its ray meets (inf at infinity), from the same camera at
    frame 0 to that point, whether the surface is the road, and the point's lateral position (m, y of
    the first ego frame; NaN at infinity); each (V, T, H, W)."""
    h, w = hw
    shape = (len(rig.cameras), len(T_ego0_from_ego), h, w)
    d_t, d_0, road = np.full(shape, np.inf), np.full(shape, np.inf), np.zeros(shape, dtype=bool)
    lateral = np.full(shape, np.nan)
    for v, cam in enumerate(rig.cameras):
        rays = pixel_rays(cam.K, patch_centres_px(cam, hw))  # the warp's rays (warp.flat_world_points)
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        c0 = cam.T_ego_from_cam[:3, 3]
        for t, T in enumerate(T_ego0_from_ego):
            T_cam = T @ cam.T_ego_from_cam
            d, o = rays @ T_cam[:3, :3].T, T_cam[:3, 3]
            s = ray_depths(o, d)
            hit = np.isfinite(s)
            point = o + np.where(hit, s, 0.0)[:, None] * d
            d_t[v, t] = s.reshape(h, w)
            d_0[v, t] = np.where(hit, np.linalg.norm(point - c0, axis=1), np.inf).reshape(h, w)
            road[v, t] = hit.reshape(h, w)
            lateral[v, t] = np.where(hit, point[:, 1], np.nan).reshape(h, w)
    return d_t, d_0, road, lateral


def road_profile(
    first: np.ndarray, distance: np.ndarray, road: np.ndarray, lateral: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """How the road's colour changes with distance, read from the first frames uint8 (V, H, W, 3) of
    every view, their surfaces' ``distance``, ``road`` mask and ``lateral`` position (V, H, W): the
    median colour of the road within LANE_M of the ego's line, in PROFILE_BINS bins of log distance,
    pooled over the views. Only that strip: every distance of it is in view, where a bin of the
    whole ground holds the lane near and the verges and fields beside it far. Returns the bins' median
    log distances and colours ((B,), (B, 3)), NaN where a bin has too few pixels."""
    m = road & np.isfinite(distance) & (np.abs(np.nan_to_num(lateral, nan=np.inf)) <= LANE_M)
    m &= (distance >= PROFILE_M[0]) & (distance <= PROFILE_M[1])
    log_edges = np.linspace(*np.log(PROFILE_M), PROFILE_BINS + 1)
    log_d, rgb = np.log(distance[m]), first[m].astype(np.float64)
    which = np.digitize(log_d, log_edges[1:-1])
    centres, colours = np.full(PROFILE_BINS, np.nan), np.full((PROFILE_BINS, 3), np.nan)
    for b in range(PROFILE_BINS):
        sel = which == b
        if sel.sum() >= MIN_PIXELS_PER_BIN:
            centres[b], colours[b] = np.median(log_d[sel]), np.median(rgb[sel], axis=0)
    return centres, colours


def reshade(warped: np.ndarray, valid: np.ndarray, rig: Rig, T_ego0_from_ego: np.ndarray):
    """``warped`` uint8 (V, T, H, W, 3), frame 0 the first frames themselves, with every rendered
    (``valid`` (V, T, H, W)) road pixel given ``mu(d_t) - mu(d_0)`` of the road profile
    (:func:`road_profile`; left as warped where fewer than two bins saw road)."""
    d_t, d_0, road, lateral = surface_distances(rig, warped.shape[2:4], T_ego0_from_ego)
    centres, colours = road_profile(warped[:, 0], d_0[:, 0], road[:, 0], lateral[:, 0])
    seen = np.isfinite(centres)
    if seen.sum() < PROFILE_DEGREE + 2:
        return warped
    m = valid & road
    lo, hi = centres[seen].min(), centres[seen].max()  # the fit is not extrapolated beyond the bins
    log_t, log_0 = (np.clip(np.log(np.maximum(d[m], 1e-3)), lo, hi) for d in (d_t, d_0))
    out = warped.astype(np.float64)
    for c in range(3):
        mu = smooth_profile(centres[seen], colours[seen, c])
        out[..., c][m] += mu(log_t) - mu(log_0)
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)


def smooth_profile(log_d: np.ndarray, colour: np.ndarray):
    """A polynomial of PROFILE_DEGREE in log distance through the bins' colours, fitted again without
    the bins more than 3 MADs off the first fit (a car ahead in the lane fills a bin or two)."""
    coef = np.polyfit(log_d, colour, PROFILE_DEGREE)
    resid = colour - np.polyval(coef, log_d)
    mad = np.median(np.abs(resid - np.median(resid))) + 1e-6
    keep = np.abs(resid) <= 3 * 1.4826 * mad
    if keep.sum() >= PROFILE_DEGREE + 2:
        coef = np.polyfit(log_d[keep], colour[keep], PROFILE_DEGREE)
    return lambda x: np.polyval(coef, x)
