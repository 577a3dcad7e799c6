"""``evaluate``: score every clip of an input with the pinned protocol, in parallel over clips.

One visible place orchestrates the metrics (``evaluate_item``); each metric is its own module.
Every per-clip number that could not be computed is NaN with a status saying why
(``too_few_matches``, ``not_registered``, ``no_reference``, ...), and aggregates count such clips
separately instead of averaging zeros in.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import os
import threading
import time
import traceback
from concurrent.futures import ThreadPoolExecutor, as_completed
from pathlib import Path

import cv2
import numpy as np
from threadpoolctl import threadpool_limits
from tqdm import tqdm

from drivewm.clips.shards import spread
from drivewm.config import to_dict
from drivewm.errors import DrivewmError, no_room
from drivewm.eval.adherence import adherence, condition_scores
from drivewm.eval.config import EpipolarConfig, EvalConfig
from drivewm.eval.consistency import cross_sampson, native_px_per_canonical_px, overlapping_pairs, temporal_sampson
from drivewm.eval.ego import forward_camera
from drivewm.eval.epipolar import canonical_K
from drivewm.eval.framing import WHOLE_VIDEO, Framing, input_record
from drivewm.eval.guards import (
    direction_verdict,
    duplicate_views,
    ego_prior,
    ego_yaw_deg,
    two_view_rotations,
)
from drivewm.eval.inputs import EvalItem, load_items
from drivewm.eval.matching import FrameMatcher, check_threads
from drivewm.eval.paths_record import ego_paths
from drivewm.eval.report import write_report
from drivewm.eval.sfm import run_sfm
from drivewm.eval.trajectory import ego_from_sfm, flow_fallback
from drivewm.eval.trajectory_errors import (
    ate,
    heading_change_deg,
    image_pose_errors,
    path_ratio,
    relative_pose_errors,
    tfe,
    waypoint_heading_deg,
)
from drivewm.workers import process_pool

#: Figures reported beside each Sampson metric (drivewm.eval.suite._put_sampson).
SAMPSON_SUFFIXES = ("_native", "_counted", "_counted_fraction", "_matches")
#: Aggregate keys (docs/DESIGN.md section 8) and the per-clip field each averages.
AGGREGATE_KEYS = (
    "tse",
    "tse_calibrated",
    "cse",
    "cse_calibrated",
    *(f"{m}{suffix}" for m in ("tse", "tse_calibrated", "cse", "cse_calibrated") for suffix in SAMPSON_SUFFIXES),
    "overlap_disagreement",
    "pose_success",
    "pose_success_path",
    "registered_fraction",
    "pose_auc",
    "pose_error_m",
    "pose_error_deg",
    "ate",
    "rpe_trans",
    "rpe_rot",
    "rpe_trans_mean",
    "rpe_rot_rmse",
    "tfe",
    "adherence_weather",
    "adherence_time_of_day",
)
#: Per-clip figures a failed guard (``guard_motion``, ``guard_time``, ``guard_views``) voids: pass
#: rates read 0, every other one NaN, and aggregates count them as failures (:func:`aggregate`).
VOIDED_KEYS = (
    *(k for k in AGGREGATE_KEYS if not k.startswith("adherence")),
    "yaw_change_deg",
    "path_ratio",
)
#: Pass rates: a voided one reads 0 (failed), not NaN.
PASS_RATES = ("pose_success", "pose_success_path", "registered_fraction", "pose_auc")
#: Sampson figures a voided clip counts at ``epipolar.failed_pair_px`` in the aggregates.
SAMPSON_KEYS = tuple(f"{m}{s}" for m in ("tse", "tse_calibrated", "cse", "cse_calibrated") for s in ("", "_counted"))
#: Per-clip fields aggregated as a median (``KEY_median``): a ratio where one clip's exploded path (a
#: reconstruction 5,000x its drive) would carry a mean.
MEDIAN_KEYS = ("path_ratio",)


@dataclasses.dataclass
class ClipResult:
    """Metrics of one clip (JSON-ready) and artifacts for the pictures (arrays, not written to JSON)."""

    key: str
    metrics: dict
    artifacts: dict


def evaluate_item(item: EvalItem, cfg: EvalConfig, threads: int = 1) -> ClipResult:
    """All configured metrics of one clip. Bad input is recorded as the clip's error, never raised;
    so is an unexpected exception (a bug or an input no check foresaw): the batch goes on.
    ``threads``: the clip's feature work runs on that many threads (the figures do not change)."""
    try:
        return _evaluate_item(item, cfg, threads)
    except DrivewmError as exc:
        return ClipResult(item.key, {"error": str(exc)}, {})
    except Exception as exc:  # noqa: BLE001 - one clip's failure must not end the batch
        if no_room(exc):  # a full or read-only disk is every clip's failure: the command stops on it
            raise
        detail = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return ClipResult(item.key, {"error": f"{item.key}: unexpected error: {detail}"}, {})


def _evaluate_item(item: EvalItem, cfg: EvalConfig, threads: int) -> ClipResult:
    # One thread each inside OpenCV and BLAS calls: clips run in parallel over processes, and one
    # clip over the matcher's own threads (whole frames and pairs per thread). OpenBLAS's own
    # threads made each 550 x 550 descriptor product 10x dearer in CPU on 2 busy cores (15.7 ms
    # against 1.5 ms), a third of a clip's matching time.
    cv2.setNumThreads(1)
    with threadpool_limits(limits=1):
        return _evaluate_metrics(item, cfg, threads)


def _evaluate_metrics(item: EvalItem, cfg: EvalConfig, threads: int) -> ClipResult:
    metrics, artifacts = _new_metrics(), {}
    videos = item.videos()

    matcher = FrameMatcher(cfg.match, threads)
    _view_copies(item, videos, cfg, metrics)
    stages = [(n, fn) for n, fn in _stages() if n in cfg.metrics or (n == "pose" and "traj" in cfg.metrics)]
    names = [n for n, _ in stages]
    with ThreadPoolExecutor(1) as side:
        pose = None
        if threads > 1 and "pose" in names and {"tse", "cse"} & set(names):
            # Structure from motion beside TSE and CSE: its mapping is a one-thread chain (COLMAP, GIL
            # released) whose idle core their threads fill. Features first, so neither extracts twice,
            # then its database on all threads, so the chain starts as early as it can.
            t0 = time.perf_counter()
            matcher.prefetch(videos)
            metrics["seconds"]["features"] = time.perf_counter() - t0  # else part of the first stage's
            ready = threading.Event()
            pose = side.submit(_pose_beside, ready, item, videos, cfg, matcher)
            ready.wait()
        for name, fn in stages:
            if name == "pose" and pose is not None:
                _merge(metrics, artifacts, *pose.result())  # in stage order: the same JSON as one thread
            else:
                _timed_stage(name, fn, item, videos, cfg, matcher, metrics, artifacts)
    if "sfm" in artifacts:
        t0 = time.perf_counter()
        _pose_plausibility(item, videos, cfg, matcher, metrics, artifacts)
        metrics["seconds"]["pose_plausibility"] = time.perf_counter() - t0
    _void_guarded(metrics)
    return ClipResult(item.key, metrics, artifacts)


def _view_copies(item, videos, cfg, metrics) -> None:
    """``duplicate_views``: camera pairs whose videos are (mirror) copies; any fails ``guard_views``."""
    if len(item.rig.cameras) < 2:
        return
    copies = duplicate_views(videos, item.rig, cfg.guard)
    metrics["duplicate_views"] = copies
    if copies:
        metrics["guard_views"] = False


def _void_guarded(metrics: dict) -> None:
    """A failed guard voids the clip's headline figures (:data:`VOIDED_KEYS`): pass rates read 0,
    the rest NaN; ``voided_by`` names the guards, ``status["voided"]`` says so."""
    failed = [g for g in ("guard_motion", "guard_time", "guard_views") if metrics.get(g) is False]
    if not failed:
        return
    metrics["voided_by"] = failed
    metrics["status"]["voided"] = ", ".join(failed)
    for key in VOIDED_KEYS:
        if key in metrics:
            metrics[key] = 0.0 if key in PASS_RATES else math.nan


def _pose_beside(ready: threading.Event, item, videos, cfg, matcher) -> tuple[dict, dict]:
    """The pose stage into its own metrics and artifacts; ``ready`` is set once its database is
    written, or when the stage ends before that (a failure), so a waiter never hangs."""
    try:
        pose_fn = functools.partial(_pose, database_ready=ready.set)
        return _timed_stage("pose", pose_fn, item, videos, cfg, matcher, _new_metrics(), {})
    finally:
        ready.set()


def _stages() -> tuple:
    return (("tse", _tse), ("cse", _cse), ("pose", _pose), ("traj", _traj), ("adherence", _adherence))


def _new_metrics() -> dict:
    return {"status": {}, "seconds": {}}


def _timed_stage(name, fn, item, videos, cfg, matcher, metrics, artifacts) -> tuple[dict, dict]:
    t0 = time.perf_counter()
    fn(item, videos, cfg, matcher, metrics, artifacts)
    metrics["seconds"][name] = time.perf_counter() - t0
    return metrics, artifacts


def _merge(metrics: dict, artifacts: dict, part: dict, part_artifacts: dict) -> None:
    """A stage's own metrics and artifacts into the clip's (status, seconds and warnings merged)."""
    for key, value in part.items():
        if key in ("status", "seconds"):
            metrics[key].update(value)
        elif key == "warnings":
            metrics.setdefault("warnings", []).extend(value)
        else:
            metrics[key] = value
    artifacts.update(part_artifacts)


def _tse(item, videos, cfg, matcher, metrics, artifacts) -> None:
    K_c = canonical_K(cfg.epipolar)
    metrics["native_px_per_canonical_px"] = {c.name: native_px_per_canonical_px(c, K_c) for c in item.rig.cameras}

    frames = min(len(v) for v in videos.values())
    if frames <= cfg.consistency.frame_gap:  # no frame pair to score: say so, do not leave a silent gap
        metrics["tse"] = metrics["tse_calibrated"] = math.nan
        metrics["status"]["tse"] = "too_few_frames"
        metrics.setdefault("warnings", []).append(
            f"tse: {frames} frame(s), needs {cfg.consistency.frame_gap + 1} (frame_gap {cfg.consistency.frame_gap})"
        )
        return
    ego = _ego_at_cameras(item, cfg)
    prior = ego_prior(item.trajectory_ego, item.trajectory_dt_s, item.fps)
    r = temporal_sampson(
        videos, item.rig, item.T_world_from_ego, cfg.epipolar, cfg.consistency, matcher, ego, cfg.guard, prior
    )
    _put_sampson(metrics, "tse", r)
    _put_direction_guards(cfg, r, metrics)


def _put_direction_guards(cfg, r: dict, metrics: dict) -> None:
    """``motion_fraction`` and ``guard_motion`` (at least half of the frame pairs whose expected
    parallax demands motion evidence must show it, drivewm.eval.consistency.motion_fraction; without
    ego poses or a conditioned trajectory every pair demands it, as a road vehicle drives),
    ``direction_error_deg`` per camera, ``guard_time`` and ``guard_views``
    (drivewm.eval.guards.direction_verdict); a guard that cannot decide is None."""
    metrics["motion_fraction"] = fraction = r["motion_fraction"]
    metrics["guard_motion"] = bool(fraction >= 0.5) if np.isfinite(fraction) else None
    verdict = direction_verdict(r["direction_errors_deg"], cfg.guard)
    metrics["direction_error_deg"] = verdict.error_deg
    metrics["reversed_fraction"] = verdict.reversed_fraction
    metrics["guard_time"] = verdict.time_ok
    if metrics.get("guard_views") is not False:  # duplicate views already failed it
        metrics["guard_views"] = verdict.views_ok


def _ego_at_cameras(item, cfg) -> dict[str, np.ndarray] | None:
    """Ego poses at each camera's exposure times, when the clip records its own times for any camera."""
    if item.T_world_from_ego is None or not item.camera_timestamps_ns or not cfg.consistency.compensate_exposure:
        return None
    from drivewm.eval.exposure import ego_at_cameras

    return ego_at_cameras(item.T_world_from_ego, item.timestamps_ns, item.camera_timestamps_ns, item.rig.names)


def _cse(item, videos, cfg, matcher, metrics, artifacts) -> None:
    pairs = overlapping_pairs(item.rig, cfg.consistency)
    metrics["cse_pairs"] = [f"{a}~{b}" for a, b in pairs]
    if not pairs:
        metrics["cse"] = metrics["cse_calibrated"] = math.nan
        metrics["status"]["cse"] = "no_overlapping_pairs"
        return
    ego = _ego_at_cameras(item, cfg)
    r = cross_sampson(videos, item.rig, pairs, cfg.epipolar, matcher, cfg=cfg.consistency, ego_at_camera=ego)
    _put_sampson(metrics, "cse", r)
    metrics["overlap_disagreement"] = _overlap_disagreement(item.rig, videos, cfg.consistency.overlap_frame_step)
    a, b = pairs[0]
    m = matcher.match((a, 0), videos[a][0], (b, 0), videos[b][0])
    artifacts["cse_matches"] = {
        "cameras": (a, b),
        "images": (videos[a][0], videos[b][0]),
        "uv_a": m.uv_a,
        "uv_b": m.uv_b,
    }


#: ``overlap_disagreement`` reads frames at most this wide (resized, the rig scaled alike): the colour
#: of an overlap, not its fine detail, is what it compares, and a 1600x900 camera would cost seconds a frame.
OVERLAP_WIDTH_PX = 320


def _overlap_disagreement(rig, videos: dict[str, np.ndarray], step: int) -> float:
    """Mean colour difference (8-bit levels) where two cameras see the same flat-world point, over
    every ``step``-th frame (drivewm.views.blend.overlap_disagreement), every camera at the first
    one's size, at most :data:`OVERLAP_WIDTH_PX` wide. The simulated drives read about 8, the parallax
    of what stands beside the road (real nuScenes far more, with exposure differences between
    cameras); views stitched through a flat world read about 2, so a CSE won by stitching shows
    here as a value far below the real clips' of the same rig (docs/eval-protocol.md)."""
    from drivewm.multiview.coding import resize_views
    from drivewm.views.blend import overlap_disagreement

    first = rig.cameras[0]
    w = min(first.width, OVERLAP_WIDTH_PX)
    h = max(1, round(first.height * w / first.width))
    frames = np.stack([resize_views(videos[n][None, ::step], (h, w))[0] for n in rig.names])  # (V, T, h, w, 3)
    return overlap_disagreement(frames, rig.scaled(w, h, fit="stretch"))


def _put_sampson(metrics: dict, name: str, r: dict) -> None:
    """Clip keys of one Sampson metric: ``tse`` (canonical px, failed pairs counted), ``tse_native``
    (the cameras' own px), ``tse_counted`` (mean over counted pairs only), ``tse_counted_fraction``,
    ``tse_matches`` (verified matches per pair), per-pair lists; the same with ``_calibrated``."""
    for kind, key in (("fitted", name), ("calibrated", f"{name}_calibrated")):
        if kind in r:
            k = r[kind]
            metrics[key] = k["value_px"]
            metrics[f"{key}_native"] = k["value_native_px"]
            metrics[f"{key}_counted"] = k["counted_mean_px"]
            metrics[f"{key}_counted_fraction"] = k["counted_fraction"]
            metrics[f"{key}_matches"] = k["matches_per_pair"]
            metrics["status"][key] = k["status_counts"]
            metrics[f"{key}_per_group"] = k["per_group_px"]
            metrics[f"{key}_pair_medians"] = k["pair_medians_px"]
            metrics[f"{key}_pair_matches"] = k["pair_matches"]


def _pose(item, videos, cfg, matcher, metrics, artifacts, database_ready=None) -> None:
    pairs = overlapping_pairs(item.rig, cfg.consistency)
    sfm = run_sfm(
        videos, item.rig, cfg.pose, matcher=matcher, epi_cfg=cfg.epipolar, pairs=pairs, database_ready=database_ready
    )
    metrics["pose_success"] = float(sfm.all_registered)  # and pose_plausible (_pose_plausibility)
    metrics["registered_fraction"] = sfm.registered_fraction
    metrics["seconds"].update({f"pose_{stage}": s for stage, s in sfm.seconds.items()})  # parts of "pose"
    artifacts["sfm"] = sfm


def _pose_plausibility(item, videos, cfg, matcher, metrics, artifacts) -> None:
    """``pose_plausible``: the reconstruction turns as two-view geometry of the trajectory camera
    does, frame to frame (drivewm.eval.guards.two_view_rotations; yaw change within
    ``guard.pose_yaw_tolerance_deg`` + ``pose_yaw_tolerance_fraction`` x |two-view yaw|), and, on a
    rig with a metric scale (several cameras), travels ``pose_min_travel_m`` where half the frame
    pairs show parallax (no rotation-only solution). The calibration is held fixed in COLMAP, so
    the intrinsics are respected by construction. Where it fails, ``pose_success`` and
    ``pose_success_path`` read 0 and ``yaw_change_deg`` is the two-view one. None (undecided) when
    SfM registers fewer than 3 frames of the camera."""
    camera = item.rig.camera(cfg.trajectory.camera or forward_camera(item.rig))
    est = ego_from_sfm(artifacts["sfm"], item.rig, camera.name)
    if est.registered.sum() < 3:
        metrics["pose_plausible"] = None
        return
    K_c = canonical_K(cfg.epipolar)
    scale = native_px_per_canonical_px(camera, K_c)
    motion = two_view_rotations(videos[camera.name], camera, matcher, K_c, cfg.epipolar, scale, cfg.guard)
    sfm_yaw = heading_change_deg(est.T_world_from_ego[est.registered])
    reg = np.flatnonzero(est.registered)
    two_view_yaw = ego_yaw_deg(motion.R_first_from_t[reg[0]].T @ motion.R_first_from_t[reg[-1]], camera)
    metrics["pose_yaw_change_deg"], metrics["two_view_yaw_change_deg"] = sfm_yaw, two_view_yaw
    g, reasons = cfg.guard, []
    if abs(sfm_yaw - two_view_yaw) > g.pose_yaw_tolerance_deg + g.pose_yaw_tolerance_fraction * abs(two_view_yaw):
        reasons.append(f"turns {sfm_yaw:.1f} deg where two-view geometry turns {two_view_yaw:.1f}")
    positions = est.T_world_from_ego[est.registered][:, :3, 3]
    travel_m = float(np.linalg.norm(np.diff(positions, axis=0), axis=1).sum())
    if len(item.rig.cameras) > 1 and motion.moved.mean() >= 0.5 and travel_m < g.pose_min_travel_m:
        reasons.append(f"travels {travel_m:.2f} m where the frames move (rotation only)")
    metrics["pose_plausible"] = not reasons
    if reasons:
        metrics["status"]["pose_plausible"] = "; ".join(reasons)
        for key in ("pose_success", "pose_success_path"):
            if key in metrics:
                metrics[key] = 0.0
        if metrics.get("yaw_source") == "sfm":
            metrics["yaw_change_deg"], metrics["yaw_source"] = two_view_yaw, "two_view"


def _traj(item, videos, cfg, matcher, metrics, artifacts) -> None:
    tc = cfg.trajectory
    for k in ("ate", "rpe_trans", "rpe_rot", "rpe_trans_mean", "rpe_rot_rmse", "tfe"):
        metrics[k] = math.nan
    if item.T_world_from_ego is not None:
        _image_poses(item, cfg, metrics, artifacts["sfm"])
    ego = ego_from_sfm(artifacts["sfm"], item.rig, cfg.trajectory.camera)
    reg = ego.registered
    artifacts["ego_paths"] = ego_paths(item, ego.T_world_from_ego, reg)
    if item.trajectory_ego:
        metrics["conditioned_yaw_change_deg"] = waypoint_heading_deg(np.asarray(item.trajectory_ego))
    if item.T_world_from_ego is not None:
        metrics["pose_success_path"] = 0.0  # 1 below where the reconstruction also travels the clip's path
    if reg.sum() < 3:
        metrics["status"]["traj"] = "not_registered"
        if tc.yaw_from_flow:
            _yaw_from_flow(item, videos, tc.camera, metrics)
        return
    est = ego.T_world_from_ego[reg]
    metrics["yaw_change_deg"] = heading_change_deg(est)  # the turn the video shows (first to last registered)
    metrics["yaw_source"] = "sfm"
    if item.T_world_from_ego is not None:
        ref = item.T_world_from_ego[reg]
        metrics["path_ratio"] = ratio = path_ratio(est, ref)
        on_path = 1 / PATH_RATIO_TOLERANCE <= ratio <= PATH_RATIO_TOLERANCE
        metrics["pose_success_path"] = float(artifacts["sfm"].all_registered and on_path)
        metrics["ate"], sim = ate(est, ref, alignment=tc.alignment)
        r = relative_pose_errors(
            est, ref, tc.rpe_delta, tc.rpe_delta_unit, tc.rpe_all_pairs, sim.scale, tc.rpe_pairs_from
        )
        metrics["rpe_trans"], metrics["rpe_rot"] = r.trans_rmse, r.rot_mean
        metrics["rpe_trans_mean"], metrics["rpe_rot_rmse"], metrics["rpe_pairs"] = (
            r.trans_mean,
            r.rot_rmse,
            len(r.pairs),
        )
        artifacts["trajectory"] = {"reference": ref[:, :3, 3], "recovered": sim.apply_points(est[:, :3, 3])}
    if item.trajectory_ego and reg.all():
        metrics["tfe"] = tfe(
            ego.T_world_from_ego, item.fps, np.asarray(item.trajectory_ego), item.trajectory_dt_s or 1 / item.fps
        )
    metrics["status"]["traj"] = "ok" if item.T_world_from_ego is not None else "no_reference"


#: ``pose_success_path``: a clip whose frames all register succeeds only where its recovered ego path
#: (metres: the rig fixes the scale) is within this factor of the clip's own (logged, or conditioned
#: for a generated clip; drivewm.eval.trajectory_errors.path_ratio). Static reconstructions, which
#: register every image of a frozen clip through the rig's baselines, read 0.03 on a 34 m drive.
PATH_RATIO_TOLERANCE = 2.0

#: Travel (m) of a clip's conditioned trajectory above which frames that show no motion at all cannot
#: be read as driving straight: a frozen or black clip asked to move has not followed its trajectory.
MOVING_TRAJECTORY_M = 1.0


def _yaw_from_flow(item, videos, camera: str, metrics) -> None:
    """The turn a clip shows, from dense optical flow of the trajectory camera, where structure from
    motion registered too few frames (trajectory.yaw_from_flow); frames flow cannot read are left out.
    Frames in which flow finds no motion at all give no yaw when the clip's conditioned trajectory
    moves (``status["yaw"]`` says so): a frozen or black clip would otherwise read as 0 degrees, a
    perfect straight drive."""
    try:
        ego = flow_fallback(videos, item.rig, camera)
    except DrivewmError as exc:  # e.g. frames too small or flat for flow
        metrics["status"]["yaw"] = str(exc)
        return
    if ego.registered.sum() < 2:
        return
    positions = ego.T_world_from_ego[ego.registered][:, :3, 3]
    waypoints = np.asarray(item.trajectory_ego, dtype=np.float64).reshape(-1, 3)
    asked_m = float(np.linalg.norm(waypoints[-1, :2])) if len(waypoints) else 0.0
    if np.ptp(positions, axis=0).max() == 0 and asked_m > MOVING_TRAJECTORY_M:
        metrics["status"]["yaw"] = f"no motion in the frames, where the conditioned trajectory moves {asked_m:.0f} m"
        return
    metrics["yaw_change_deg"] = heading_change_deg(ego.T_world_from_ego[ego.registered])
    metrics["yaw_source"] = "flow"


def _image_poses(item, cfg, metrics, sfm) -> None:
    """Every image's pose against the reference (the ego pose at its exposure, through the camera's
    extrinsics): ``pose_auc`` and the median errors of the registered images."""
    tc = cfg.trajectory
    ego = _ego_at_cameras(item, cfg) or {c: item.T_world_from_ego for c in item.rig.names}
    ref = {c.name: ego[c.name] @ c.T_ego_from_cam for c in item.rig.cameras}
    errors = image_pose_errors(sfm.T_world_from_cam, sfm.registered, ref, tc.alignment)
    metrics["pose_auc"] = errors.auc(tc.pose_auc_m, tc.pose_auc_deg)
    scored = len(errors.position_m) > 0
    metrics["pose_error_m"] = float(np.median(errors.position_m)) if scored else math.nan
    metrics["pose_error_deg"] = float(np.median(errors.rotation_deg)) if scored else math.nan


def _adherence(item, videos, cfg, matcher, metrics, artifacts) -> None:
    scores = condition_scores(np.stack([videos[c] for c in item.rig.names]))
    result = adherence(scores, item.tags)
    metrics["condition_scores"] = scores
    metrics["adherence"] = result
    metrics["adherence_weather"] = result.get("weather_match", math.nan)
    metrics["adherence_time_of_day"] = result.get("time_of_day_match", math.nan)


def aggregate(results: list[ClipResult], failed_px: float = EpipolarConfig.failed_pair_px) -> dict:
    """Top-level means over clips of finite values (medians for MEDIAN_KEYS, as ``KEY_median``);
    ``nan_clips`` counts clips left out per key. A clip whose guards voided its figures counts as a
    failure: its Sampson figures (:data:`SAMPSON_KEYS`) at ``failed_px``, its pass rates at 0, and
    ``voided_clips`` counts it per key."""
    out: dict = {"num_clips": len(results), "num_failed_clips": sum("error" in r.metrics for r in results)}
    nan_clips, voided = {}, {}
    reduced = [(k, k, np.mean) for k in AGGREGATE_KEYS] + [(k, f"{k}_median", np.median) for k in MEDIAN_KEYS]
    for key, name, reduce in reduced:
        values = [_counted(r.metrics, key, failed_px) for r in results if key in r.metrics]
        finite = [v for v in values if v is not None and np.isfinite(v)]
        if values:
            out[name] = float(reduce(finite)) if finite else math.nan
            nan_clips[name] = len(values) - len(finite)
            voided[name] = sum(bool(r.metrics.get("voided_by")) for r in results if key in r.metrics)
    out["nan_clips"] = nan_clips
    out["voided_clips"] = voided
    out["seconds_per_clip"] = _mean_seconds(results)
    return out


def _counted(metrics: dict, key: str, failed_px: float):
    """A clip's value of ``key`` in the aggregates: a voided Sampson figure at ``failed_px``."""
    if metrics.get("voided_by") and key in SAMPSON_KEYS:
        return failed_px
    return metrics[key]


def _mean_seconds(results: list[ClipResult]) -> dict[str, float]:
    names = sorted({n for r in results for n in r.metrics.get("seconds", {})})
    return {
        n: float(np.mean([r.metrics["seconds"][n] for r in results if n in r.metrics.get("seconds", {})]))
        for n in names
    }


def clip_threads(workers: int, clips: int, cores: int | None = None) -> int:
    """Threads per clip that fill the cores: the cores over the clips scored at once (``workers``,
    at most ``clips``), at least 1. One clip on 2 cores gets 2 threads; 2 workers get 1 each."""
    if cores is None:  # the cores this process may run on (sched_getaffinity is Linux-only)
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    return max(1, cores // max(1, min(workers, clips)))


def run_items(
    items: list[EvalItem], cfg: EvalConfig, workers: int = 1, progress: bool = True, threads: int | None = None
) -> list[ClipResult]:
    """Evaluate items, in a process pool when ``workers`` > 1; results in input order. ``threads``
    per clip: :func:`clip_threads` when None."""
    threads = clip_threads(workers, len(items)) if threads is None else threads
    check_threads(threads)  # here, not per clip: a bad value is the run's error, not every clip's
    bar = tqdm(total=len(items), desc="eval clips", unit="clip", disable=not progress)
    results: dict[int, ClipResult] = {}
    if workers <= 1:
        for i, item in enumerate(items):
            results[i] = evaluate_item(item, cfg, threads)
            bar.update()
    else:
        with process_pool(workers) as pool:  # spawned workers that exit if this process is killed
            futures = {pool.submit(evaluate_item, item, cfg, threads): i for i, item in enumerate(items)}
            for fut in as_completed(futures):
                results[futures[fut]] = fut.result()
                bar.update()
    bar.close()
    return [results[i] for i in range(len(items))]


def evaluate(
    location: str | Path,
    rig=None,
    out_dir: str | Path | None = None,
    cfg: EvalConfig | None = None,
    workers: int = 1,
    grid: str | None = None,
    cameras: list[str] | None = None,
    reference: str | Path | None = None,
    progress: bool = True,
    pictures: bool = True,
    rig_fit: str = "same",
    max_clips: int | None = None,
    threads: int | None = None,
    framing: Framing | None = None,
) -> dict:
    """Score clips at ``location`` (shards, mp4 folder or grid video; see drivewm.eval.inputs).

    Returns the metrics dict (aggregates at the top, per clip under ``clips``); with ``out_dir``
    also writes metrics.json, metrics.md (beside ``reference`` values), error-distribution plots
    and a Rerun recording (eval.rrd). ``rig_fit``: how videos of another aspect ratio than the rig
    were resized from it ('same' refuses them, 'stretch', 'crop'; drivewm.geometry.Camera.scaled).
    ``max_clips``: score that many clips spread evenly over the (sorted) input, e.g. a reference
    subset of a large held-out set. ``threads``: per clip (:func:`clip_threads` when None); the
    figures are the same for any number. ``framing``: mp4 inputs' crop box, frame range and grid cell
    borders (drivewm.eval.framing), recorded with the input under ``input`` so that ``eval compare``
    can read the same views again.
    """
    cfg = cfg or EvalConfig()
    framing = framing or WHOLE_VIDEO
    items = spread(load_items(location, rig, grid, cameras, rig_fit, framing), max_clips)
    if not items:
        raise DrivewmError(f"{location}: no clips to evaluate")
    results = run_items(items, cfg, workers, progress, threads)
    metrics = aggregate(results, cfg.epipolar.failed_pair_px)
    metrics["clips"] = {r.key: r.metrics for r in results}
    metrics["config"] = to_dict(cfg)
    metrics["location"] = str(location)
    metrics["input"] = input_record(location, rig, grid, cameras, rig_fit, framing)
    if out_dir is not None:
        write_report(Path(out_dir), metrics, results, reference, pictures)
    return metrics
