"""A future's video scores from ``drivewm eval``: multi-view consistency (Sampson errors across and
along cameras) and condition adherence (does it show the prompted weather and time of day)."""

from __future__ import annotations

import math

import numpy as np

from drivewm.eval.config import EvalConfig
from drivewm.eval.inputs import EvalItem
from drivewm.eval.suite import evaluate_item
from drivewm.geometry import Rig
from drivewm.sim.scene import SceneTick

#: The eval figures a future reports (NaN ones as None, with eval's status saying why).
REPORTED = ("tse", "cse", "overlap_disagreement", "adherence_weather", "adherence_time_of_day")


def video_scores(
    key: str, rig: Rig, fps: float, ticks: list[SceneTick], mp4_paths: dict[str, str], tags: dict, metrics: list[str]
) -> dict:
    """``drivewm eval``'s ``metrics`` on one future's camera videos (one frame per tick of ``ticks``)."""
    if not metrics:
        return {}
    item = EvalItem(
        key,
        rig,
        fps,
        T_world_from_ego=np.stack([t.T_world_from_ego for t in ticks]),
        tags={k: tags[k] for k in ("weather", "time_of_day") if k in tags},
        mp4_paths=mp4_paths,
        timestamps_ns=[t.timestamp_ns for t in ticks],
    )
    result = evaluate_item(item, EvalConfig(metrics=list(metrics))).metrics
    out = {k: _number(result[k]) for k in REPORTED if k in result}
    if result.get("error"):
        out["error"] = result["error"]
    if result.get("status"):
        out["status"] = dict(result["status"])
    return out


def _number(value) -> float | None:
    value = float(value)
    return None if math.isnan(value) else value
