"""The ranking rule and the box geometry the safety scores rest on."""

from __future__ import annotations

import math

import numpy as np
import pytest

from drivewm.errors import DrivewmError
from drivewm.multiverse.config import RankingConfig
from drivewm.multiverse.geometry2d import box_corners, box_distance, boxes_overlap
from drivewm.multiverse.ranking import rank


def test_box_overlap_and_distance() -> None:
    a = box_corners(np.zeros(2), 0.0, 4.0, 2.0)
    assert boxes_overlap(a, box_corners(np.array([3.9, 0.0]), 0.0, 4.0, 2.0))
    assert box_distance(a, box_corners(np.array([5.0, 0.0]), 0.0, 4.0, 2.0)) == pytest.approx(1.0)
    # rotated 45 degrees: its corner points at a's front face, sqrt(2) x 1 from its centre
    b = box_corners(np.array([2.0 + 0.5 + math.sqrt(2) / 2, 0.0]), math.pi / 4, 1.0, 1.0)
    assert box_distance(a, b) == pytest.approx(0.5)
    assert not boxes_overlap(a, b)


def _future(plan: str, collision: bool = False, progress: float = 50.0, jerk: float = 0.0, ttc=None) -> dict:
    scores = {"collision": collision, "progress_m": progress, "min_ttc_s": ttc, "min_gap_m": 2.0}
    scores |= {"off_road_fraction": 0.0, "max_abs_jerk_mps3": jerk, "max_abs_lateral_accel_mps2": 0.0}
    return {"plan": plan, "scores": scores}


def test_safety_then_progress_then_comfort() -> None:
    futures = [
        _future("fast_crash", collision=True, progress=90.0),
        _future("close", progress=80.0, ttc=0.8),
        _future("slow", progress=20.0),
        _future("far_jerky", progress=61.0, jerk=6.0),
        _future("far_smooth", progress=62.0, jerk=1.0),
    ]
    ranked = rank(futures, RankingConfig())
    assert [f["plan"] for f in ranked] == ["far_smooth", "far_jerky", "slow", "close", "fast_crash"]
    assert [f["safety_level"] for f in ranked] == [0, 0, 0, 1, 3]
    by_progress = rank(futures, RankingConfig(order=["progress", "safety"]))
    assert [f["plan"] for f in by_progress][:2] == ["fast_crash", "close"]


def test_a_bad_rule_is_refused() -> None:
    with pytest.raises(DrivewmError, match="order"):
        RankingConfig(order=["safety", "speed"]).validate()


def test_an_infeasible_plan_ranks_after_every_feasible_one() -> None:
    futures = [
        _future("no_lane", progress=90.0) | {"feasible": False},
        _future("crash", collision=True, progress=80.0) | {"feasible": True},
        _future("no_lane_slow", progress=20.0) | {"feasible": False},
        _future("slow", progress=20.0),
    ]
    ranked = rank(futures, RankingConfig())
    assert [f["plan"] for f in ranked] == ["slow", "crash", "no_lane", "no_lane_slow"]
