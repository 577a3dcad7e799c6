"""Scores of one future from its ticks and the road: safety (collision and with whom, minimum
time-to-collision and gap), progress, lane keeping and leaving the road, comfort (jerk, lateral
acceleration). Everything is measured on the ego's box (drivewm.sim.ego_plan: 5 m x 2 m, centre 1.5 m
ahead of the rear axle) and the road users' logged boxes, so simulated and replayed futures score alike.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
from scipy.signal import savgol_filter

from drivewm.multiverse.geometry2d import box_corners, box_distance, polyline_distance
from drivewm.sim.ego_plan import EGO_CENTER_AHEAD_OF_REAR_AXLE_M, EGO_LENGTH_M, EGO_WIDTH_M
from drivewm.sim.scene import RoadMap, SceneTick


def ego_state(ticks: list[SceneTick]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(times s (N,), box centres (N, 2) m, yaw (N,) rad) of the ego over ``ticks``."""
    T = np.stack([t.T_world_from_ego for t in ticks])
    yaw = np.arctan2(T[:, 1, 0], T[:, 0, 0])
    center = T[:, :2, 3] + EGO_CENTER_AHEAD_OF_REAR_AXLE_M * np.stack([np.cos(yaw), np.sin(yaw)], axis=1)
    times = np.array([t.timestamp_ns for t in ticks], dtype=np.float64) / 1e9
    return times, center, yaw


#: Ticks before the branch point that comfort looks at too, so the hand-over from the source's driver counts.
COMFORT_PAST_TICKS = 2


def score_future(past: list[SceneTick], future: list[SceneTick], road: RoadMap) -> dict:
    """Every geometric score of one future (its ticks after the branch point; ``past`` ends at the branch
    tick); JSON-ready (None: not measurable)."""
    ticks = [past[-1], *future]
    times, center, yaw = ego_state(ticks)
    scores = _safety(future, center, yaw, times)
    rear = np.stack([t.T_world_from_ego[:2, 3] for t in ticks])
    scores["progress_m"] = float(np.linalg.norm(np.diff(rear, axis=0), axis=1).sum())
    scores.update(_lane_keeping(center[1:], road))
    lead_in = past[-1 - COMFORT_PAST_TICKS : -1]
    t_in, c_in, _ = ego_state(lead_in) if lead_in else (np.zeros(0), np.zeros((0, 2)), None)
    scores.update(_comfort(np.concatenate([t_in, times]), np.concatenate([c_in, center])))
    return scores


def _ego_box(center: np.ndarray, yaw: float) -> np.ndarray:
    return box_corners(center, yaw, EGO_LENGTH_M, EGO_WIDTH_M)


def _agent_box(agent) -> np.ndarray:
    return box_corners(np.asarray(agent.center_xyz[:2]), agent.yaw_rad, agent.size_lwh[0], agent.size_lwh[1])


def _safety(future: list[SceneTick], center: np.ndarray, yaw: np.ndarray, times: np.ndarray) -> dict:
    """Collision (first contact: seconds after the branch point, track id, category), minimum gap and
    time-to-collision. ``center``, ``yaw``, ``times``: the ego at the branch tick, then at each future tick."""
    collision, min_gap, min_ttc = None, math.inf, math.inf
    velocities = _agent_velocities(future)
    for k, tick in enumerate(future):
        ego = _ego_box(center[k + 1], yaw[k + 1])
        v_ego = (center[k + 1] - center[k]) / max(times[k + 1] - times[k], 1e-9)
        for agent in tick.agents:
            gap = box_distance(ego, _agent_box(agent))
            min_gap = min(min_gap, gap)
            if gap == 0.0 and collision is None:
                when = round(float(times[k + 1] - times[0]), 6)
                collision = {"time_s": when, "track_id": agent.track_id, "category": agent.category}
            v_agent = velocities.get((k, agent.track_id), np.zeros(2))
            min_ttc = min(min_ttc, _ttc(center[k + 1], yaw[k + 1], v_ego, agent, v_agent))
    return {
        "collision": collision is not None,
        "collision_with": collision,
        "min_gap_m": None if math.isinf(min_gap) else float(min_gap),
        "min_ttc_s": None if math.isinf(min_ttc) else float(min_ttc),
    }


def _agent_velocities(future: list[SceneTick]) -> dict[tuple[int, str], np.ndarray]:
    """(tick, track id) -> velocity (2,) m/s from the track's box at the previous tick (or the next)."""
    pos = [{a.track_id: np.asarray(a.center_xyz[:2], dtype=np.float64) for a in t.agents} for t in future]
    times = [t.timestamp_ns / 1e9 for t in future]
    out = {}
    for k, here in enumerate(pos):
        for track, p in here.items():
            for j in (k - 1, k + 1):
                if 0 <= j < len(pos) and track in pos[j]:
                    out[(k, track)] = (p - pos[j][track]) / (times[k] - times[j])
                    break
    return out


def _ttc(center: np.ndarray, yaw: float, v_ego: np.ndarray, agent, v_agent: np.ndarray) -> float:
    """Time (s) until the ego's front reaches the back of a road user ahead in its path at the current
    speeds (inf when none is ahead in its corridor or the gap is opening)."""
    forward = np.array([math.cos(yaw), math.sin(yaw)])
    left = np.array([-forward[1], forward[0]])
    rel = np.asarray(agent.center_xyz[:2]) - center
    lateral = abs(rel @ left)
    if rel @ forward <= 0 or lateral > (EGO_WIDTH_M + agent.size_lwh[1]) / 2:
        return math.inf
    gap = rel @ forward - (EGO_LENGTH_M + agent.size_lwh[0]) / 2
    closing = (v_ego - v_agent) @ forward
    if gap <= 0:
        return 0.0
    return gap / closing if closing > 1e-6 else math.inf


def _lane_keeping(center: np.ndarray, road: RoadMap) -> dict:
    """Distance of the ego's centre from the nearest lane centre line (mean, max), and the share of ticks
    with the centre off the paved surface (None without lane centres / surface polygons)."""
    offsets = polyline_distance(center, road.lane_centers)
    out = {
        "lane_offset_mean_m": None if np.isinf(offsets).any() else float(offsets.mean()),
        "lane_offset_max_m": None if np.isinf(offsets).any() else float(offsets.max()),
    }
    polys = [p.astype(np.float32).reshape(-1, 1, 2) for p in road.surface_polygons if len(p) >= 3]
    if not polys:
        return {**out, "off_road_fraction": None}
    on = [any(cv2.pointPolygonTest(p, (float(x), float(y)), False) >= 0 for p in polys) for x, y in center]
    return {**out, "off_road_fraction": float(1.0 - np.mean(on))}


#: Savitzky-Golay windows (ticks) of the comfort derivatives, as nuPlan's comfort metrics take them
#: (nuplan-devkit, ``approximate_derivatives``: a local quadratic fit per window, Caesar et al. 2021): the
#: velocity and acceleration over 5 ticks, the jerk over 15. Plain finite differences of a 10 Hz path turn a
#: step in acceleration (a driver model's piecewise constant commands, a kink in a lane's polyline) into
#: jerk of tens of m/s^3 that no passenger feels.
COMFORT_WINDOW_TICKS = 5
JERK_WINDOW_TICKS = 15


def _comfort(times: np.ndarray, center: np.ndarray) -> dict:
    """Max |jerk| (m/s^3, of the speed along the path) and max |lateral acceleration| (m/s^2, the
    acceleration across the direction of motion: (v x a) / |v|), from the ego box centre's path (equally
    spaced ticks), differentiated by Savitzky-Golay filters (:data:`COMFORT_WINDOW_TICKS`)."""
    if len(times) < COMFORT_WINDOW_TICKS:
        return {"max_abs_jerk_mps3": None, "max_abs_lateral_accel_mps2": None}
    dt = float(np.median(np.diff(times)))
    vel = _derivative(center, dt, 1, COMFORT_WINDOW_TICKS)  # (N, 2)
    acc = _derivative(center, dt, 2, COMFORT_WINDOW_TICKS)
    speed = np.linalg.norm(vel, axis=1)
    lateral = (vel[:, 0] * acc[:, 1] - vel[:, 1] * acc[:, 0]) / np.maximum(speed, 0.5)
    accel = _derivative(speed, dt, 1, COMFORT_WINDOW_TICKS)
    jerk = _derivative(accel, dt, 1, JERK_WINDOW_TICKS)
    return {
        "max_abs_jerk_mps3": float(np.abs(jerk).max()),
        "max_abs_lateral_accel_mps2": float(np.abs(lateral).max()),
    }


def _derivative(values: np.ndarray, dt: float, order: int, window: int) -> np.ndarray:
    """The ``order``-th time derivative of equally spaced samples (N, ...) by a quadratic Savitzky-Golay
    filter over ``window`` samples (fewer, odd, on a short path)."""
    window = min(window, len(values) - (1 - len(values) % 2))
    return savgol_filter(values, window, 2, deriv=order, delta=dt, axis=0, mode="interp")
