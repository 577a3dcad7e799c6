"""Temporal and cross-view Sampson errors (TSE, CSE) of a multi-camera clip.

TSE (Cosmos paper, multi-view table; docs/eval-protocol.md): per camera, frames t and t + frame_gap are
matched, keypoints rectified to the canonical pinhole, an F fitted robustly, and the pair scored by
the median Sampson error of its verified matches (within ``verify_threshold_px`` of the fitted F)
under (a) that fitted F and (b), when ego poses are known, the F implied by the ego motion and the
camera's extrinsics. CSE: for every pair of cameras whose
frusta overlap (from the rig geometry, not names), matches of all frames are pooled and scored
under one F fitted over all of them and under the calibrated F from the two extrinsics.
A clip value is the mean of the pair medians whose status is 'ok'; pairs without enough matches
are NaN and counted by status, never averaged in as zeros.
"""

from __future__ import annotations

import itertools

import numpy as np

from drivewm.eval.config import ConsistencyConfig, EpipolarConfig
from drivewm.eval.epipolar import (
    FIT_FAILED,
    OK,
    SampsonResult,
    calibrated_fundamental,
    canonical_K,
    fit_fundamental,
    rectify_matches,
    score_matches,
    verified_matches,
)
from drivewm.eval.matching import FrameMatcher, Matches
from drivewm.geometry import Camera, Rig, invert_T, pixel_rays, project, transform_points

NO_BASELINE = "no_baseline"
MIN_BASELINE_M = 1e-3  # below this the calibrated E = [t]x R vanishes and F is undefined


def frustum_overlap(cam_a: Camera, cam_b: Camera, cfg: ConsistencyConfig) -> float:
    """Fraction of points sampled in a's frustum (image grid x depths) that project inside b's image."""
    g = cfg.overlap_grid
    uu, vv = np.meshgrid(np.linspace(0, cam_a.width - 1, g), np.linspace(0, cam_a.height - 1, g))
    rays = pixel_rays(cam_a.K, np.stack([uu.ravel(), vv.ravel()], 1))
    pts_a = np.concatenate([rays * d for d in cfg.overlap_depths_m])
    pts_b = transform_points(invert_T(cam_b.T_ego_from_cam) @ cam_a.T_ego_from_cam, pts_a)
    uv, z = project(cam_b.K, pts_b)
    inside = (
        (z > 0) & (uv[:, 0] >= 0) & (uv[:, 0] <= cam_b.width - 1) & (uv[:, 1] >= 0) & (uv[:, 1] <= cam_b.height - 1)
    )
    return float(np.mean(inside))


def overlapping_pairs(rig: Rig, cfg: ConsistencyConfig) -> list[tuple[str, str]]:
    """Camera pairs (rig order) whose frusta overlap by at least ``overlap_min_fraction`` either way."""
    pairs = []
    for a, b in itertools.combinations(rig.cameras, 2):
        if max(frustum_overlap(a, b, cfg), frustum_overlap(b, a, cfg)) >= cfg.overlap_min_fraction:
            pairs.append((a.name, b.name))
    return pairs


def _calibrated(T_b_from_a: np.ndarray, K_c: np.ndarray) -> np.ndarray | None:
    if np.linalg.norm(T_b_from_a[:3, 3]) < MIN_BASELINE_M:
        return None
    return calibrated_fundamental(K_c, T_b_from_a)


def _score_pair(m: Matches, T_b_from_a: np.ndarray | None, K_c: np.ndarray, cfg: EpipolarConfig) -> dict:
    """Scores of one match set (canonical px) under a fitted F and, if known, the calibrated one."""
    F_fit, _ = fit_fundamental(m, cfg)
    verified = verified_matches(F_fit, m, cfg)
    fitted = score_matches(F_fit, verified, cfg)
    if F_fit is None and len(m) >= cfg.min_matches:
        fitted.status = FIT_FAILED
    out = {"fitted": fitted}
    if T_b_from_a is not None:
        F_cal = _calibrated(T_b_from_a, K_c)
        cal = score_matches(F_cal, verified, cfg)
        if F_cal is None and len(verified) >= cfg.min_matches:
            cal.status = NO_BASELINE
        out["calibrated"] = cal
    return out


def temporal_sampson(
    videos: dict[str, np.ndarray],
    rig: Rig,
    T_world_from_ego: np.ndarray | None,
    epi_cfg: EpipolarConfig,
    cfg: ConsistencyConfig,
    matcher: FrameMatcher,
) -> dict:
    """TSE of a clip. ``videos``: uint8 (T, H, W, 3) per camera of ``rig``; ``T_world_from_ego`` (T, 4, 4) or None."""
    K_c = canonical_K(epi_cfg)
    per_camera = {}
    for cam in rig.cameras:
        frames = videos[cam.name]
        pairs = []
        for t in range(len(frames) - cfg.frame_gap):
            u = t + cfg.frame_gap
            m = rectify_matches(matcher.match((cam.name, t), frames[t], (cam.name, u), frames[u]), cam, cam, K_c)
            T_rel = None
            if T_world_from_ego is not None:
                T_wc = T_world_from_ego @ cam.T_ego_from_cam
                T_rel = invert_T(T_wc[u]) @ T_wc[t]
            pairs.append(_score_pair(m, T_rel, K_c, epi_cfg))
        per_camera[cam.name] = pairs
    return summarize(per_camera)


def cross_sampson(
    videos: dict[str, np.ndarray],
    rig: Rig,
    pairs: list[tuple[str, str]],
    epi_cfg: EpipolarConfig,
    matcher: FrameMatcher,
    matches_out: dict | None = None,
) -> dict:
    """CSE of a clip over camera ``pairs``: one fitted F per pair over the matches of all frames.
    ``matches_out`` (optional) receives the pooled canonical matches per pair, for visualisation."""
    K_c = canonical_K(epi_cfg)
    per_pair = {}
    for name_a, name_b in pairs:
        cam_a, cam_b = rig.camera(name_a), rig.camera(name_b)
        pooled = Matches.empty()
        for t in range(len(videos[name_a])):
            m = matcher.match((name_a, t), videos[name_a][t], (name_b, t), videos[name_b][t])
            pooled = pooled.concat(rectify_matches(m, cam_a, cam_b, K_c))
        T_b_from_a = invert_T(cam_b.T_ego_from_cam) @ cam_a.T_ego_from_cam
        per_pair[f"{name_a}~{name_b}"] = [_score_pair(pooled, T_b_from_a, K_c, epi_cfg)]
        if matches_out is not None:
            matches_out[(name_a, name_b)] = pooled
    return summarize(per_pair)


def summarize(groups: dict[str, list[dict[str, SampsonResult]]]) -> dict:
    """Clip value per F kind (mean of OK pair medians), status counts, and per-group means."""
    out: dict = {}
    for kind in ("fitted", "calibrated"):
        results = [r[kind] for rs in groups.values() for r in rs if kind in r]
        if not results:
            continue
        out[kind] = {
            "value_px": _mean_ok(results),
            "status_counts": _counts(results),
            "per_group_px": {g: _mean_ok([r[kind] for r in rs]) for g, rs in groups.items()},
            "pair_medians_px": [r.median_px for r in results],
        }
    return out


def _mean_ok(results: list[SampsonResult]) -> float:
    ok = [r.median_px for r in results if r.status == OK]
    return float(np.mean(ok)) if ok else float("nan")


def _counts(results: list[SampsonResult]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for r in results:
        counts[r.status] = counts.get(r.status, 0) + 1
    return counts
