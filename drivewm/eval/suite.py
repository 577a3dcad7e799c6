"""``evaluate``: score every clip of an input with the pinned protocol, in parallel over clips.

One visible place orchestrates the metrics (``evaluate_item``); each metric is its own module.
Every per-clip number that could not be computed is NaN with a status saying why
(``too_few_matches``, ``not_registered``, ``no_reference``, ...), and aggregates count such clips
separately instead of averaging zeros in.
"""

from __future__ import annotations

import dataclasses
import math
import time
import traceback
from concurrent.futures import as_completed
from pathlib import Path

import numpy as np

from drivewm.config import to_dict
from drivewm.errors import DrivewmError
from drivewm.eval.config import EvalConfig
from drivewm.eval.inputs import EvalItem, load_items
from drivewm.workers import process_pool

#: Aggregate keys (DESIGN.md section 8) and the per-clip field each averages.
AGGREGATE_KEYS = (
    "tse",
    "tse_calibrated",
    "cse",
    "cse_calibrated",
    "pose_success",
    "registered_fraction",
    "ate",
    "rpe_trans",
    "rpe_rot",
    "tfe",
    "adherence_weather",
    "adherence_time_of_day",
)


@dataclasses.dataclass
class ClipResult:
    """Metrics of one clip (JSON-ready) and artifacts for the pictures (arrays, not written to JSON)."""

    key: str
    metrics: dict
    artifacts: dict


def evaluate_item(item: EvalItem, cfg: EvalConfig) -> ClipResult:
    """All configured metrics of one clip. Bad input is recorded as the clip's error, never raised;
    so is an unexpected exception (a bug or an input no check foresaw): the batch goes on."""
    try:
        return _evaluate_item(item, cfg)
    except DrivewmError as exc:
        return ClipResult(item.key, {"error": str(exc)}, {})
    except Exception as exc:  # noqa: BLE001 - one clip's failure must not end the batch
        detail = traceback.format_exception_only(type(exc), exc)[-1].strip()
        return ClipResult(item.key, {"error": f"{item.key}: unexpected error: {detail}"}, {})


def _evaluate_item(item: EvalItem, cfg: EvalConfig) -> ClipResult:
    import cv2

    cv2.setNumThreads(1)
    metrics: dict = {"status": {}, "seconds": {}}
    artifacts: dict = {}
    videos = item.videos()
    from drivewm.eval.matching import FrameMatcher

    matcher = FrameMatcher(cfg.match)
    for name, fn in (("tse", _tse), ("cse", _cse), ("pose", _pose), ("traj", _traj), ("adherence", _adherence)):
        if name in cfg.metrics or (name == "pose" and "traj" in cfg.metrics):
            t0 = time.perf_counter()
            fn(item, videos, cfg, matcher, metrics, artifacts)
            metrics["seconds"][name] = time.perf_counter() - t0
    return ClipResult(item.key, metrics, artifacts)


def _tse(item, videos, cfg, matcher, metrics, artifacts) -> None:
    from drivewm.eval.consistency import temporal_sampson

    frames = min(len(v) for v in videos.values())
    if frames <= cfg.consistency.frame_gap:  # no frame pair to score: say so, do not leave a silent gap
        metrics["tse"] = metrics["tse_calibrated"] = math.nan
        metrics["status"]["tse"] = "too_few_frames"
        metrics.setdefault("warnings", []).append(
            f"tse: {frames} frame(s), needs {cfg.consistency.frame_gap + 1} (frame_gap {cfg.consistency.frame_gap})"
        )
        return
    r = temporal_sampson(videos, item.rig, item.T_world_from_ego, cfg.epipolar, cfg.consistency, matcher)
    _put_sampson(metrics, "tse", r)


def _cse(item, videos, cfg, matcher, metrics, artifacts) -> None:
    from drivewm.eval.consistency import cross_sampson, overlapping_pairs

    pairs = overlapping_pairs(item.rig, cfg.consistency)
    metrics["cse_pairs"] = [f"{a}~{b}" for a, b in pairs]
    if not pairs:
        metrics["cse"] = metrics["cse_calibrated"] = math.nan
        metrics["status"]["cse"] = "no_overlapping_pairs"
        return
    _put_sampson(metrics, "cse", cross_sampson(videos, item.rig, pairs, cfg.epipolar, matcher))
    a, b = pairs[0]
    m = matcher.match((a, 0), videos[a][0], (b, 0), videos[b][0])
    artifacts["cse_matches"] = {
        "cameras": (a, b),
        "images": (videos[a][0], videos[b][0]),
        "uv_a": m.uv_a,
        "uv_b": m.uv_b,
    }


def _put_sampson(metrics: dict, name: str, r: dict) -> None:
    for kind, key in (("fitted", name), ("calibrated", f"{name}_calibrated")):
        if kind in r:
            metrics[key] = r[kind]["value_px"]
            metrics["status"][key] = r[kind]["status_counts"]
            metrics[f"{key}_per_group"] = r[kind]["per_group_px"]
            metrics[f"{key}_pair_medians"] = r[kind]["pair_medians_px"]


def _pose(item, videos, cfg, matcher, metrics, artifacts) -> None:
    from drivewm.eval.sfm import run_sfm

    sfm = run_sfm(videos, item.rig, cfg.pose)
    metrics["pose_success"] = float(sfm.all_registered)
    metrics["registered_fraction"] = sfm.registered_fraction
    artifacts["sfm"] = sfm


def _traj(item, videos, cfg, matcher, metrics, artifacts) -> None:
    from drivewm.eval.trajectory import ego_from_sfm
    from drivewm.eval.trajectory_errors import ate, rpe, tfe

    for k in ("ate", "rpe_trans", "rpe_rot", "tfe"):
        metrics[k] = math.nan
    ego = ego_from_sfm(artifacts["sfm"], item.rig, cfg.trajectory.camera)
    reg = ego.registered
    if reg.sum() < 3:
        metrics["status"]["traj"] = "not_registered"
        return
    est = ego.T_world_from_ego[reg]
    if item.T_world_from_ego is not None:
        ref = item.T_world_from_ego[reg]
        metrics["ate"], sim = ate(est, ref)
        metrics["rpe_trans"], metrics["rpe_rot"] = rpe(est, ref, cfg.trajectory.rpe_delta_frames, sim.scale)
        artifacts["trajectory"] = {"reference": ref[:, :3, 3], "recovered": sim.apply_points(est[:, :3, 3])}
    if item.trajectory_ego and reg.all():
        metrics["tfe"] = tfe(
            ego.T_world_from_ego, item.fps, np.asarray(item.trajectory_ego), item.trajectory_dt_s or 1 / item.fps
        )
    metrics["status"]["traj"] = "ok" if item.T_world_from_ego is not None else "no_reference"


def _adherence(item, videos, cfg, matcher, metrics, artifacts) -> None:
    from drivewm.eval.adherence import adherence, condition_scores

    scores = condition_scores(np.stack([videos[c] for c in item.rig.names]))
    result = adherence(scores, item.tags)
    metrics["condition_scores"] = scores
    metrics["adherence"] = result
    metrics["adherence_weather"] = result.get("weather_match", math.nan)
    metrics["adherence_time_of_day"] = result.get("time_of_day_match", math.nan)


def aggregate(results: list[ClipResult]) -> dict:
    """Top-level means over clips of finite values; ``nan_clips`` counts clips left out per key."""
    out: dict = {"num_clips": len(results), "num_failed_clips": sum("error" in r.metrics for r in results)}
    nan_clips = {}
    for key in AGGREGATE_KEYS:
        values = [r.metrics[key] for r in results if key in r.metrics]
        finite = [v for v in values if v is not None and np.isfinite(v)]
        if values:
            out[key] = float(np.mean(finite)) if finite else math.nan
            nan_clips[key] = len(values) - len(finite)
    out["nan_clips"] = nan_clips
    out["seconds_per_clip"] = _mean_seconds(results)
    return out


def _mean_seconds(results: list[ClipResult]) -> dict[str, float]:
    names = sorted({n for r in results for n in r.metrics.get("seconds", {})})
    return {
        n: float(np.mean([r.metrics["seconds"][n] for r in results if n in r.metrics.get("seconds", {})]))
        for n in names
    }


def run_items(items: list[EvalItem], cfg: EvalConfig, workers: int = 1, progress: bool = True) -> list[ClipResult]:
    """Evaluate items, in a process pool when ``workers`` > 1; results in input order."""
    from tqdm import tqdm

    bar = tqdm(total=len(items), desc="eval clips", unit="clip", disable=not progress)
    results: dict[int, ClipResult] = {}
    if workers <= 1:
        for i, item in enumerate(items):
            results[i] = evaluate_item(item, cfg)
            bar.update()
    else:
        with process_pool(workers) as pool:  # spawned workers that exit if this process is killed
            futures = {pool.submit(evaluate_item, item, cfg): i for i, item in enumerate(items)}
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
) -> dict:
    """Score clips at ``location`` (shards, mp4 folder or grid mp4; see drivewm.eval.inputs).

    Returns the metrics dict (aggregates at the top, per clip under ``clips``); with ``out_dir``
    also writes metrics.json, metrics.md (beside ``reference`` values), error-distribution plots
    and a Rerun recording (eval.rrd).
    """
    cfg = cfg or EvalConfig()
    items = load_items(location, rig, grid, cameras)
    if not items:
        raise DrivewmError(f"{location}: no clips to evaluate")
    results = run_items(items, cfg, workers, progress)
    metrics = aggregate(results)
    metrics["clips"] = {r.key: r.metrics for r in results}
    metrics["config"] = to_dict(cfg)
    metrics["location"] = str(location)
    if out_dir is not None:
        from drivewm.eval.report import write_report

        write_report(Path(out_dir), metrics, results, reference, pictures)
    return metrics
