"""Temporal and cross-view Sampson errors (TSE, CSE) of a multi-camera clip.

TSE (Cosmos paper, multi-view table; docs/eval-protocol.md): per camera, frames t and t + frame_gap are
matched, keypoints rectified to the canonical pinhole, an F fitted robustly, and the pair scored by
the median Sampson error of its verified matches (within ``verify_threshold_native_px`` of the fitted F)
under (a) that fitted F and (b), when ego poses are known, the F implied by the ego motion and the
camera's extrinsics, with the ego pose at each image's own exposure time (drivewm.eval.exposure).
CSE: for every pair of cameras whose frusta overlap (from the rig geometry, not names), the distinct
matches of all frames are pooled and scored under one F fitted over all of them and under the
calibrated F of each frame (the two extrinsics, and the ego motion between the two exposures).

A pair counts when it has enough verified matches (and, for TSE, motion); a clip value is the mean
over pairs with a pair that does not count at ``failed_pair_px`` (docs/eval-protocol.md, 'Degenerate
videos'), so a blurred, frozen or shuffled video cannot win by keeping only its easy pairs. Beside
every figure: the verified matches per pair, the share of pairs that count, the mean over counted
pairs only (the Cosmos-style figure) and the value in the native pixels of the rig's cameras.
"""

from __future__ import annotations

import functools
import itertools
from collections.abc import Callable

import numpy as np

from drivewm.eval.config import ConsistencyConfig, EpipolarConfig, GuardConfig
from drivewm.eval.epipolar import (
    FIT_FAILED,
    NO_MOTION,
    OK,
    TOO_FEW_MATCHES,
    SampsonResult,
    calibrated_fundamental,
    canonical_K,
    fit_verified,
    frame_pair_fit,
    rectify_matches,
    sampson_px,
    score_matches,
)
from drivewm.eval.guards import (
    EgoPrior,
    angle_deg,
    camera_travel_m,
    expected_travel_cam,
    motion_demanded,
    motion_evidence,
    travel_direction_cam,
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


def native_px_per_canonical_px(camera: Camera, K_canonical: np.ndarray) -> float:
    """How many of the camera's own pixels one canonical pixel is near its centre: f / f_canonical
    (f = sqrt(fx fy)); 0.82 for nuscenes6's 70 deg cameras at 320 px, 4.2 for a 1156 px dashcam."""
    return float(np.sqrt(camera.K[0, 0] * camera.K[1, 1] / (K_canonical[0, 0] * K_canonical[1, 1])))


def _calibrated(T_b_from_a: np.ndarray, K_c: np.ndarray) -> np.ndarray | None:
    if np.linalg.norm(T_b_from_a[:3, 3]) < MIN_BASELINE_M:
        return None
    return calibrated_fundamental(K_c, T_b_from_a)


def _score_calibrated(F_by_match: list, frame_of: np.ndarray, verified: Matches, cfg: EpipolarConfig):
    """Sampson errors of ``verified`` under the calibrated F of each match's frame (``F_by_match[t]``)."""
    if len(verified) < cfg.min_matches:
        return SampsonResult(np.zeros(0), float("nan"), len(verified), TOO_FEW_MATCHES)
    errors = np.empty(len(verified))
    for t in np.unique(frame_of):
        if F_by_match[t] is None:
            return SampsonResult(np.zeros(0), float("nan"), len(verified), NO_BASELINE)
        sel = frame_of == t
        errors[sel] = sampson_px(F_by_match[t], verified.uv_a[sel], verified.uv_b[sel])
    return SampsonResult(errors, float(np.median(errors)), len(verified), OK)


def _score_pair(
    m: Matches,
    T_b_from_a: list[np.ndarray] | None,
    frame_of: np.ndarray,
    K_c: np.ndarray,
    cfg: EpipolarConfig,
    min_verified: int,
    motion_check: Callable[[Matches], bool] | None,
    native_px_per_px: float,
    fit: tuple | None = None,
) -> dict:
    """Scores of one match set (canonical px) under a fitted F and, if known, the calibrated F of
    each frame (``T_b_from_a[t]`` for the matches with ``frame_of == t``), and the verified matches;
    fit and verification thresholds in the cameras' pixels (``native_px_per_px`` per canonical px).
    ``motion_check`` (TSE, where the pair's expected parallax demands it): a pair whose verified
    matches fail it (drivewm.eval.guards.motion_evidence) fails under both F: static points, and a
    zoomed still, satisfy any F through the epipole. ``fit``: the (F, verified mask) of ``m`` when
    already known (drivewm.eval.epipolar.fit_verified)."""
    F_fit, keep = fit or fit_verified(m, cfg, native_px_per_px)
    verified, frames = Matches(m.uv_a[keep], m.uv_b[keep]), frame_of[keep]
    fitted = score_matches(F_fit, verified, cfg)
    if F_fit is None and len(m) >= cfg.min_matches:
        fitted.status = FIT_FAILED
    elif fitted.status == OK and len(verified) < min_verified:
        fitted = SampsonResult(np.zeros(0), float("nan"), len(verified), TOO_FEW_MATCHES)
    no_motion = fitted.status == OK and motion_check is not None and not motion_check(verified)
    if no_motion:
        fitted = SampsonResult(np.zeros(0), float("nan"), len(verified), NO_MOTION)
    out = {"fitted": fitted, "verified": verified}
    if T_b_from_a is not None:
        Fs = [_calibrated(T, K_c) for T in T_b_from_a]
        cal = _score_calibrated(Fs, frames, verified, cfg)
        if cal.status == OK and (len(verified) < min_verified or no_motion):
            cal = SampsonResult(np.zeros(0), float("nan"), len(verified), NO_MOTION if no_motion else TOO_FEW_MATCHES)
        out["calibrated"] = cal
    return out


def temporal_sampson(
    videos: dict[str, np.ndarray],
    rig: Rig,
    T_world_from_ego: np.ndarray | None,
    epi_cfg: EpipolarConfig,
    cfg: ConsistencyConfig,
    matcher: FrameMatcher,
    ego_at_camera: dict[str, np.ndarray] | None = None,
    guard_cfg: GuardConfig | None = None,
    prior: EgoPrior | None = None,
) -> dict:
    """TSE of a clip. ``videos``: uint8 (T, H, W, 3) per camera of ``rig``; ``T_world_from_ego``
    (T, 4, 4) or None; ``ego_at_camera`` (optional): per camera, the ego poses (T, 4, 4) at that
    camera's exposure times (drivewm.eval.exposure.ego_at_cameras), used instead of ``T_world_from_ego``.
    Also returns ``direction_errors_deg`` (per camera, the angles between recovered and expected
    travel of every ``guard_cfg.direction_frame_step``-th pair; drivewm.eval.guards) and
    ``motion_fraction`` (:func:`motion_fraction`); ``prior``: the expected ego travel direction
    and speed without poses (drivewm.eval.guards.ego_prior; default: forward, speed unknown)."""
    guard_cfg = guard_cfg or GuardConfig()
    prior = prior or EgoPrior(np.array([1.0, 0.0, 0.0]), None, 0.0)
    K_c = canonical_K(epi_cfg)
    scale = {cam.name: native_px_per_canonical_px(cam, K_c) for cam in rig.cameras}
    matcher.prefetch(videos)

    def score(task: tuple[Camera, int]) -> dict:
        cam, t = task
        frames, u = videos[cam.name], t + cfg.frame_gap
        m = rectify_matches(matcher.match((cam.name, t), frames[t], (cam.name, u), frames[u]), cam, cam, K_c)
        ego = None if T_world_from_ego is None else (ego_at_camera or {}).get(cam.name, T_world_from_ego)
        T_rel = None
        if ego is not None:
            T_wc = ego @ cam.T_ego_from_cam
            T_rel = [invert_T(T_wc[u]) @ T_wc[t]]
        travel_m = camera_travel_m(cam, t, u, ego, prior.speed_mps, prior.fps)
        demanded = motion_demanded(focal_native_px(cam), travel_m, guard_cfg)
        check = None
        if demanded:
            parallax_px = guard_cfg.parallax_threshold_native_px / scale[cam.name]
            check = functools.partial(motion_evidence, cfg=guard_cfg, epi_cfg=epi_cfg, parallax_px=parallax_px)
        fit = frame_pair_fit(matcher, (cam.name, t), (cam.name, u), m, epi_cfg, scale[cam.name])
        frame_of = np.zeros(len(m), int)
        out = _score_pair(m, T_rel, frame_of, K_c, epi_cfg, epi_cfg.min_matches, check, scale[cam.name], fit)
        out["motion_demanded"] = demanded
        if t % guard_cfg.direction_frame_step == 0 and out["fitted"].status == OK:
            forward = prior.forward_ego
            out["direction_deg"] = _direction_error(out["verified"], cam, t, u, ego, forward, K_c, epi_cfg, scale)
        return out

    tasks = [(cam, t) for cam in rig.cameras for t in range(len(videos[cam.name]) - cfg.frame_gap)]
    scores = matcher.map(score, tasks)
    per_camera = {cam.name: [r for (c, _), r in zip(tasks, scores) if c is cam] for cam in rig.cameras}
    out = summarize(per_camera, {g: scale[g] for g in per_camera}, epi_cfg.failed_pair_px)
    out["direction_errors_deg"] = {
        c: [r["direction_deg"] for r in rs if r.get("direction_deg") is not None] for c, rs in per_camera.items()
    }
    out["motion_fraction"] = motion_fraction(scores)
    return out


def motion_fraction(scores: list[dict]) -> float:
    """The share of frame pairs with motion evidence among those that demanded it and had an F fit
    (status ok or no_motion): a pair too blurred or dark to verify enough matches already counts as
    failed in TSE and says nothing about motion. 0 when pairs demanded motion and none had a fit
    (no evidence of motion anywhere, e.g. a flat grey clip); NaN when no pair demanded it."""
    fitted = [r["fitted"].status for r in scores if r["motion_demanded"]]
    judged = [status == OK for status in fitted if status in (OK, NO_MOTION)]
    if not fitted:
        return float("nan")
    return float(np.mean(judged)) if judged else 0.0


def focal_native_px(camera: Camera) -> float:
    """The camera's focal length (its own px): sqrt(fx fy)."""
    return float(np.sqrt(camera.K[0, 0] * camera.K[1, 1]))


def _direction_error(verified, cam, t, u, ego, forward_ego, K_c, epi_cfg, scale) -> float | None:
    """Angle (degrees) between the travel the pair's verified matches show and the expected one."""
    expected = expected_travel_cam(cam, t, u, ego, forward_ego)
    seen = travel_direction_cam(verified, K_c, epi_cfg, scale[cam.name]) if expected is not None else None
    return None if seen is None else angle_deg(seen, expected)


def _pooled_matches(videos, cam_a: Camera, cam_b: Camera, matcher: FrameMatcher, K_c) -> tuple[Matches, np.ndarray]:
    """Distinct rectified matches of all frames of a camera pair and the frame (N,) each came from
    (a repeated frame repeats its matches exactly; they count once)."""
    parts, frame_of = [], []
    for t in range(len(videos[cam_a.name])):
        m = matcher.match((cam_a.name, t), videos[cam_a.name][t], (cam_b.name, t), videos[cam_b.name][t])
        parts.append(rectify_matches(m, cam_a, cam_b, K_c))
        frame_of.append(np.full(len(m), t))
    pooled = Matches(np.concatenate([p.uv_a for p in parts]), np.concatenate([p.uv_b for p in parts]))
    frame_of = np.concatenate(frame_of).astype(int)
    _, first = np.unique(np.concatenate([pooled.uv_a, pooled.uv_b], 1), axis=0, return_index=True)
    first = np.sort(first)
    return Matches(pooled.uv_a[first], pooled.uv_b[first]), frame_of[first]


def cross_sampson(
    videos: dict[str, np.ndarray],
    rig: Rig,
    pairs: list[tuple[str, str]],
    epi_cfg: EpipolarConfig,
    matcher: FrameMatcher,
    matches_out: dict | None = None,
    cfg: ConsistencyConfig | None = None,
    ego_at_camera: dict[str, np.ndarray] | None = None,
) -> dict:
    """CSE of a clip over camera ``pairs``: one fitted F per pair over the distinct matches of all
    frames; the calibrated F per frame from the extrinsics and, with ``ego_at_camera`` (per camera,
    ego poses (T, 4, 4) at its exposure times), the ego motion between the two exposures.
    ``matches_out`` (optional) receives the pooled canonical matches per pair, for visualisation."""
    cfg = cfg or ConsistencyConfig()
    K_c = canonical_K(epi_cfg)
    per_pair = {}
    num_frames = len(next(iter(videos.values())))
    min_verified = max(epi_cfg.min_matches, int(np.ceil(cfg.cse_min_matches_per_frame * num_frames)))

    def score(pair: tuple[str, str]) -> tuple[dict, Matches]:
        name_a, name_b = pair
        cam_a, cam_b = rig.camera(name_a), rig.camera(name_b)
        pooled, frame_of = _pooled_matches(videos, cam_a, cam_b, matcher, K_c)
        T_b_from_a = invert_T(cam_b.T_ego_from_cam) @ cam_a.T_ego_from_cam
        if ego_at_camera is not None:  # T_cam_b(t_b)_from_cam_a(t_a) = (E_b T_eb)^-1 E_a T_ea
            T_wa = ego_at_camera[name_a] @ cam_a.T_ego_from_cam
            T_wb = ego_at_camera[name_b] @ cam_b.T_ego_from_cam
            T_rel = list(invert_T(T_wb) @ T_wa)
        else:
            T_rel = [T_b_from_a] * num_frames
        scale = 0.5 * (native_px_per_canonical_px(cam_a, K_c) + native_px_per_canonical_px(cam_b, K_c))
        return _score_pair(pooled, T_rel, frame_of, K_c, epi_cfg, min_verified, None, scale), pooled

    matcher.prefetch(videos, {c for p in pairs for c in p})
    for (name_a, name_b), (scored, pooled) in zip(pairs, matcher.map(score, pairs)):
        per_pair[f"{name_a}~{name_b}"] = [scored]
        if matches_out is not None:
            matches_out[(name_a, name_b)] = pooled
    scale = {
        f"{a}~{b}": 0.5
        * (native_px_per_canonical_px(rig.camera(a), K_c) + native_px_per_canonical_px(rig.camera(b), K_c))
        for a, b in pairs
    }
    return summarize(per_pair, scale, epi_cfg.failed_pair_px)


def summarize(
    groups: dict[str, list[dict[str, SampsonResult]]], native_scale: dict[str, float], failed_px: float
) -> dict:
    """Per F kind: the clip value (failed pairs at ``failed_px``), the mean over counted pairs, the
    share of pairs counted, verified matches per pair, native-pixel values (x the group's
    ``native_scale``), status counts and per-group values."""
    out: dict = {}
    for kind in ("fitted", "calibrated"):
        tagged = [(g, r[kind]) for g, rs in groups.items() for r in rs if kind in r]
        if not tagged:
            continue
        results = [r for _, r in tagged]
        scales = np.array([native_scale[g] for g, _ in tagged])
        out[kind] = {
            "value_px": _clip_value(results, failed_px),
            "value_native_px": _clip_value(results, failed_px, scales),
            "counted_mean_px": _clip_value([r for r in results if r.status == OK], failed_px),
            "counted_fraction": _counted_fraction(results),
            "matches_per_pair": float(np.mean([r.num_matches for r in results])),
            "status_counts": _counts(results),
            "per_group_px": {g: _clip_value([r[kind] for r in rs], failed_px) for g, rs in groups.items()},
            "pair_medians_px": [r.median_px for r in results],
            "pair_matches": [r.num_matches for r in results],
        }
    return out


def _clip_value(results: list[SampsonResult], failed_px: float, scales: np.ndarray | None = None) -> float:
    """Mean of pair medians, a pair that failed at ``failed_px``; pairs without a calibrated F
    (``no_baseline``: the ego did not move) are left out. NaN when no pair is left."""
    scales = np.ones(len(results)) if scales is None else scales
    values = [
        (r.median_px if r.status == OK else failed_px) * s for r, s in zip(results, scales) if r.status != NO_BASELINE
    ]
    return float(np.mean(values)) if values else float("nan")


def _counted_fraction(results: list[SampsonResult]) -> float:
    scored = [r for r in results if r.status != NO_BASELINE]
    return float(np.mean([r.status == OK for r in scored])) if scored else float("nan")


def _counts(results: list[SampsonResult]) -> dict[str, int]:
    counts: dict[str, int] = {}
    for r in results:
        counts[r.status] = counts.get(r.status, 0) + 1
    return counts
