"""Forked simulations: every future shares the source drive's past bit for bit, the same fork twice gives
the same futures, a plan into a stopped car collides and ranks last, and a follower behind a braking ego
brakes too (the other road users react)."""

from __future__ import annotations

import numpy as np
import pytest

from drivewm.multiverse.config import RankingConfig
from drivewm.multiverse.geometry2d import box_corners, box_distance
from drivewm.multiverse.ranking import rank
from drivewm.multiverse.scores import ego_state, score_future
from drivewm.sim.config import SimConfig
from drivewm.sim.drives import record
from drivewm.sim.ego_plan import EGO_LENGTH_M, EGO_WIDTH_M, EgoPlan, PlacedVehicle

pytestmark = pytest.mark.slow  # each test simulates a drive and its futures

PLANS = [EgoPlan("keep"), EgoPlan("brake", accel_mps2=-4.0)]
BRANCH_TICK = 10


def _fork(source: str):
    if source == "highway":
        from drivewm.sim.fork_highway import fork_highway

        cfg = SimConfig(source="highway", duration_s=6.0, seed=1, traffic_density="low")
        return cfg, fork_highway(cfg, BRANCH_TICK, PLANS, 50, [PlacedVehicle(90.0, 0.0), PlacedVehicle(-20.0)])
    from drivewm.sim.fork_sumo import fork_sumo

    cfg = SimConfig(source="sumo", scenario="grid", duration_s=6.0, seed=3, traffic_density="low")
    return cfg, fork_sumo(cfg, BRANCH_TICK, PLANS, 50, [PlacedVehicle(40.0, 0.0)])


def _layout(ticks):
    return [
        (t.T_world_from_ego.tobytes(), [(a.track_id, a.center_xyz.tobytes(), a.yaw_rad) for a in t.agents])
        for t in ticks
    ]


@pytest.mark.parametrize("source", ["highway", "sumo"])
def test_futures_share_the_source_past_collide_into_a_stopped_car_and_repeat(source: str) -> None:
    cfg, (past, futures, road, infeasible) = _fork(source)
    source_drive = record(cfg)
    assert _layout(past) == _layout(source_drive.ticks[: BRANCH_TICK + 1])  # bit-identical past
    assert len(futures) == 2 and all(len(f) == 50 for f in futures) and infeasible == ["", ""]
    ranked = rank(
        [{"plan": p.name, "scores": score_future(past, f, road)} for p, f in zip(PLANS, futures)], RankingConfig()
    )
    keep = next(r for r in ranked if r["plan"] == "keep")
    brake = next(r for r in ranked if r["plan"] == "brake")
    assert keep["scores"]["collision"] and keep["scores"]["collision_with"]["track_id"] == "placed0"
    assert not brake["scores"]["collision"] and brake["scores"]["min_gap_m"] > 0.5
    assert [r["plan"] for r in ranked] == ["brake", "keep"]  # the collision ranks last
    assert keep["scores"]["progress_m"] > brake["scores"]["progress_m"] + 10  # it was not ranked on progress
    _, (past2, futures2, _, _) = _fork(source)
    assert _layout(past2) == _layout(past) and [_layout(f) for f in futures2] == [_layout(f) for f in futures]


def _follower(future) -> tuple[list, np.ndarray]:
    """The placed follower's boxes and speeds (m/s) over a future."""
    boxes = [next(a for a in t.agents if a.track_id == "placed1") for t in future]
    return boxes, np.linalg.norm(np.diff([a.center_xyz[:2] for a in boxes], axis=0), axis=1) * 10.0


def test_a_follower_brakes_behind_a_braking_ego() -> None:
    """highway-env: the IDM car placed 20 m behind at the ego's speed slows down behind the braking ego
    (until MOBIL takes it round) and never touches it; behind the ego that keeps its speed it does not brake."""
    _, (past, futures, _, _) = _fork("highway")
    boxes, brake_speeds = _follower(futures[1])
    _, center, yaw = ego_state(futures[1])
    gaps = [
        box_distance(
            box_corners(c, y, EGO_LENGTH_M, EGO_WIDTH_M), box_corners(a.center_xyz[:2], a.yaw_rad, *a.size_lwh[:2])
        )
        for c, y, a in zip(center, yaw, boxes)
    ]
    assert min(gaps) > 0.0
    _, keep_speeds = _follower(futures[0])
    assert brake_speeds.min() < past[-1].ego_speed_mps - 5.0  # it braked hard, from about the ego's speed
    assert keep_speeds.min() > brake_speeds.min() + 1.5  # more than IDM falling back to its own gap


def _heading_change_deg(past, future) -> float:
    """The ego's heading at the future's end relative to the branch point (degrees, left positive)."""
    T = np.linalg.inv(past[-1].T_world_from_ego) @ future[-1].T_world_from_ego
    return float(np.degrees(np.arctan2(T[1, 0], T[0, 0])))


def test_sumo_futures_drive_through_the_junction_after_a_lane_change_or_turn() -> None:
    """SUMO grid, the ego at 12.9 m/s on the right lane, reaching a junction after about 5 s (its own route
    turns right there). Every future advances every tick: the ego never stands (SUMO's collisions are off,
    so nothing can hold it up), not after a lane change onto a lane that cannot take its route's next turn,
    not after a turn; it slows for a turn to the turn's speed limit (about 6 m/s), not to a stop. The turns
    go their way; a plan gives the same future whichever futures ran before it (each starts from the saved
    state alone)."""
    from drivewm.sim.fork_sumo import fork_sumo

    plans = [EgoPlan("keep"), EgoPlan("left", lane_change=1), EgoPlan("right", lane_change=-1)]
    plans += [EgoPlan("turn-left", turn="left"), EgoPlan("turn-right", turn="right"), EgoPlan("keep_again")]
    cfg = SimConfig(source="sumo", scenario="grid", duration_s=12.0, seed=6, traffic_density="low")
    past, futures, _, infeasible = fork_sumo(cfg, 20, plans, 80)
    assert [bool(r) for r in infeasible] == [False, False, True, False, False, False]
    assert "no lane to the right" in infeasible[2]
    speed = past[-1].ego_speed_mps
    for plan, future in zip(plans, futures):
        xy = np.array([t.T_world_from_ego[:2, 3] for t in [past[-1], *future]])
        steps = np.linalg.norm(np.diff(xy, axis=0), axis=1)
        assert steps.min() > 0.3 * speed / cfg.fps, (plan.name, int(steps.argmin()))
        if plan.turn or plan.name == "keep":
            assert steps.min() < 0.6 * speed / cfg.fps, plan.name  # it braked for the turn
    assert _layout(futures[5]) == _layout(futures[0])
    turns = {p.name: _heading_change_deg(past, f) for p, f in zip(plans, futures)}
    assert turns["turn-left"] > 45.0 and turns["turn-right"] < -45.0 and turns["keep"] < -45.0
    assert abs(turns["left"]) < 20.0  # the left lane goes straight on: so does the ego, routed on from it
    lateral = [(np.linalg.inv(past[-1].T_world_from_ego) @ f[30].T_world_from_ego)[1, 3] for f in futures[:3]]
    assert lateral[1] > lateral[0] + 2.0 and lateral[2] == lateral[0]  # left changed lanes; right could not
