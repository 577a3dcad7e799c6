"""Reshading the reprojection: the road at frame t looks as the first frame's road looks at that distance.

The reprojection (drivewm.multiview.warp, ``--reproject``) fetches a later frame's road from where
the first frame saw it, further away. Whatever makes the far road look unlike the near one comes
along: in fog the far road is mostly airlight, so a straight fog drive's warped road brightens frame
by frame (held-out: ground luma 118 -> 191 over 1.6 s, where the true frames stay at 118), and a
generated fog sample refined from 0.1 reads snow; on a wet road the grazing-angle sheen does the same.
Each view's first frame says how its road looks at every distance: mu(d), the median road colour in
bins of log distance. A road pixel of frame t at distance d_t, fetched from d_0, becomes

    I + mu(d_t) - mu(d_0)

(model-free; the identity where the road looks alike at every distance). Both distances are the
warp's own: the road plane, with the corridor's walls in front of it (walls and infinity are left
as warped). Measured (studies/warp_haze.py, 3 held-out drives per weather, 160x96): PSNR of the
warped later frames against the true ones, fog 16.7 -> 24.3 dB, rain 20.0 -> 22.6, clear 14.85 ->
14.79, snow 16.1 -> 15.6 (docs/quality-vs-compute.md, "Fog reads snow at --reproject 0.1").
"""

from __future__ import annotations

import numpy as np

from drivewm.geometry import Rig, pixel_rays
from drivewm.multiview.warp import ray_depths

PROFILE_M = (3.0, 150.0)  # road distances the profile is read over (nearer or further: its ends)
PROFILE_BINS = 16


def surface_distances(
    rig: Rig, hw: tuple[int, int], T_ego0_from_ego: np.ndarray, walls_m: float = 0.0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per view, frame and pixel of images ``hw`` (H, W) of ``rig``: the distance (m) from the camera
    at frame t to the surface its ray meets (road or wall; inf at infinity), from the same camera at
    frame 0 to that point, and whether the surface is the road; each (V, T, H, W)."""
    h, w = hw
    uv = np.stack(np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5), -1).reshape(-1, 2)
    shape = (len(rig.cameras), len(T_ego0_from_ego), h, w)
    d_t, d_0, road = np.full(shape, np.inf), np.full(shape, np.inf), np.zeros(shape, dtype=bool)
    for v, cam in enumerate(rig.cameras):
        rays = pixel_rays(cam.K * np.array([[w / cam.width], [h / cam.height], [1.0]]), uv)
        rays /= np.linalg.norm(rays, axis=1, keepdims=True)
        c0 = cam.T_ego_from_cam[:3, 3]
        for t, T in enumerate(T_ego0_from_ego):
            T_cam = T @ cam.T_ego_from_cam
            d, o = rays @ T_cam[:3, :3].T, T_cam[:3, 3]
            s = ray_depths(o, d, walls_m)
            hit = np.isfinite(s)
            point = o + np.where(hit, s, 0.0)[:, None] * d
            d_t[v, t] = s.reshape(h, w)
            d_0[v, t] = np.where(hit, np.linalg.norm(point - c0, axis=1), np.inf).reshape(h, w)
            road[v, t] = (hit & (ray_depths(o, d) <= s + 1e-6)).reshape(h, w)
    return d_t, d_0, road


def road_profile(first: np.ndarray, distance: np.ndarray, road: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per view of the first frames uint8 (V, H, W, 3), with their surfaces' ``distance`` and ``road``
    mask (V, H, W): the median road colour in PROFILE_BINS bins of log distance, as (centres (V, B),
    colours (V, B, 3)); NaN for a view that sees too little road to say."""
    v_count = len(first)
    centres, colours = np.full((v_count, PROFILE_BINS), np.nan), np.full((v_count, PROFILE_BINS, 3), np.nan)
    for v in range(v_count):
        m = road[v] & (distance[v] >= PROFILE_M[0]) & (distance[v] <= PROFILE_M[1])
        if m.sum() < 20 * PROFILE_BINS:
            continue
        log_d, rgb = np.log(distance[v][m]), first[v][m].astype(np.float64)
        edges = np.quantile(log_d, np.linspace(0, 1, PROFILE_BINS + 1))
        for b, (lo, hi) in enumerate(zip(edges[:-1], edges[1:])):
            sel = (log_d >= lo) & (log_d <= hi)
            centres[v, b], colours[v, b] = np.median(log_d[sel]), np.median(rgb[sel], axis=0)
    return centres, colours


def reshade(warped: np.ndarray, valid: np.ndarray, rig: Rig, T_ego0_from_ego: np.ndarray, walls_m: float = 0.0):
    """``warped`` uint8 (V, T, H, W, 3), frame 0 the first frames themselves, with every rendered
    (``valid`` (V, T, H, W)) road pixel given ``mu(d_t) - mu(d_0)`` of its view's road profile."""
    d_t, d_0, road = surface_distances(rig, warped.shape[2:4], T_ego0_from_ego, walls_m)
    centres, colours = road_profile(warped[:, 0], d_0[:, 0], road[:, 0])
    out = warped.astype(np.float64)
    for v in range(len(warped)):
        if np.isnan(centres[v]).any():
            continue
        m = valid[v] & road[v]
        log_t, log_0 = (np.log(np.maximum(d[v][m], 1e-3)) for d in (d_t, d_0))
        for c in range(3):
            mu_t, mu_0 = (np.interp(x, centres[v], colours[v, :, c]) for x in (log_t, log_0))
            out[v, ..., c][m] += mu_t - mu_0
    return np.clip(np.rint(out), 0, 255).astype(np.uint8)
