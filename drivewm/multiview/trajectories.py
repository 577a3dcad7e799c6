"""Ego trajectories to condition on: named generators, files, and waypoints <-> poses.

A trajectory is given to the model as ``ClipMeta.trajectory_ego``: (N, 3) waypoints (m) in the
first frame's ego frame (x forward, y left, z up), spaced ``dt_s`` apart starting one step after
the first frame. The named ones model a vehicle at ``speed_mps``: ``straight`` (constant speed),
``left``/``right`` (constant speed on a circle of curvature +-``curvature_per_m``, y positive
to the left) and ``stop`` (constant deceleration to rest within the horizon).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.geometry import T_from_xyz_yaw, invert_T, transform_points

NAMED = ("straight", "left", "right", "stop")
#: Largest |coordinate| (m) in a waypoint file: a drive's horizon with room to spare, not a typo's 1e200.
MAX_WAYPOINT_M = 10_000.0


def arc_poses(arc_length_m: np.ndarray, curvature_per_m: float) -> np.ndarray:
    """(T, 4, 4) T_world_from_ego along a circle of signed curvature (+ = turning left) starting at
    the origin heading +x, at the given arc lengths (T,)."""
    s = np.asarray(arc_length_m, dtype=np.float64)
    yaw = curvature_per_m * s
    if abs(curvature_per_m) < 1e-9:
        x, y = s, np.zeros_like(s)
    else:
        x, y = np.sin(yaw) / curvature_per_m, (1 - np.cos(yaw)) / curvature_per_m
    return np.stack([T_from_xyz_yaw(xi, yi, 0.0, ki) for xi, yi, ki in zip(x, y, yaw)])


def named_arc_length(name: str, times_s: np.ndarray, speed_mps: float, horizon_s: float) -> np.ndarray:
    """Distance travelled (m) at ``times_s``: constant speed, or for ``stop`` constant deceleration
    reaching rest at ``horizon_s`` (s = v t - v t^2 / (2 T) up to T)."""
    t = np.asarray(times_s, dtype=np.float64)
    if name == "stop":
        tc = np.minimum(t, horizon_s)
        return speed_mps * tc - speed_mps * tc**2 / (2 * horizon_s)
    return speed_mps * t


def named_poses(
    name: str,
    num_frames: int,
    dt_s: float,
    speed_mps: float = 15.0,
    curvature_per_m: float = 0.02,
    horizon_s: float | None = None,
) -> np.ndarray:
    """(num_frames, 4, 4) T_world_from_ego of a named manoeuvre, frame 0 at the origin."""
    if name not in NAMED:
        raise DrivewmError(f"trajectory {name!r}: not one of {list(NAMED)} and not a file")
    times = np.arange(num_frames) * dt_s
    s = named_arc_length(name, times, speed_mps, horizon_s or times[-1] or dt_s)
    kappa = {"left": curvature_per_m, "right": -curvature_per_m}.get(name, 0.0)
    return arc_poses(s, kappa)


def waypoints_from_poses(T_world_from_ego: np.ndarray, start: int, num: int) -> np.ndarray:
    """(num, 3) positions of frames start+1 .. start+num in the ego frame of frame ``start``
    (the ClipMeta.trajectory_ego convention); poses past the end are extrapolated at the last velocity."""
    T = np.asarray(T_world_from_ego, dtype=np.float64)
    positions = T[:, :3, 3]
    idx = np.arange(start + 1, start + num + 1)
    last = len(T) - 1
    step = positions[last] - positions[last - 1] if last > 0 else np.zeros(3)
    pts = positions[np.minimum(idx, last)] + np.maximum(idx - last, 0)[:, None] * step
    return transform_points(invert_T(T[start]), pts)


def poses_from_waypoints(waypoints_ego: np.ndarray, num_frames: int, dt_s: float, fps: float) -> np.ndarray:
    """(num_frames, 4, 4) T_world_from_ego (world = first frame's ego) at 1/fps from waypoints spaced
    ``dt_s`` (first one at dt_s), positions interpolated linearly and yaw along the motion: the chord
    to the position ``dt_s`` later, or, within ``dt_s`` of the last waypoint, the last ``dt_s`` of the
    path (so a frame at the end of the waypoints turns with them instead of keeping the heading of
    the frame before)."""
    w = np.concatenate([np.zeros((1, 3)), np.asarray(waypoints_ego, dtype=np.float64)])
    way_t = np.arange(len(w)) * dt_s
    t = np.arange(num_frames) / fps
    p = np.stack([np.interp(t, way_t, w[:, k]) for k in range(3)], axis=1)
    t_ahead = np.minimum(t + dt_s, way_t[-1])
    behind = np.stack([np.interp(t_ahead - dt_s, way_t, w[:, k]) for k in range(2)], axis=1)
    ahead = np.stack([np.interp(t_ahead, way_t, w[:, k]) for k in range(2)], axis=1) - behind
    moving = np.linalg.norm(ahead, axis=1) > 1e-3
    yaw = np.where(moving, np.arctan2(ahead[:, 1], ahead[:, 0]), 0.0)
    for i in range(1, num_frames):  # a stopped ego keeps its last heading
        if not moving[i]:
            yaw[i] = yaw[i - 1]
    return np.stack([T_from_xyz_yaw(*p[i], yaw[i]) for i in range(num_frames)])


def load_waypoints(path: str | Path) -> np.ndarray:
    """(N, 3) waypoints from ``.npy`` or ``.json`` ([[x, y, z], ...] or {"trajectory_ego": [...]}),
    finite, real and within :data:`MAX_WAYPOINT_M` of the first frame."""
    path = Path(path)
    try:
        if path.suffix == ".npy":
            data = np.load(path, allow_pickle=False)
        else:
            raw = json.loads(path.read_text())
            data = raw["trajectory_ego"] if isinstance(raw, dict) else raw
        data = np.asarray(data)
        if data.dtype.kind not in "iuf":  # strings, complex numbers, booleans are no positions
            raise ValueError(f"{data.dtype} values are not numbers of metres")
        data = data.astype(np.float64)
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise DrivewmError(
            f"{path}: cannot read waypoints ({exc.__class__.__name__}: {exc}); expected a .npy array or a .json "
            'file of [[x, y, z], ...] or {"trajectory_ego": [...]} (metres, in the first frame\'s ego frame)'
        ) from None
    check_waypoints(data, str(path))
    return data


def check_waypoints(waypoints: np.ndarray, where: str) -> None:
    """Refuse waypoints that are not a finite (N >= 1, 3) array within :data:`MAX_WAYPOINT_M`."""
    if waypoints.ndim != 2 or waypoints.shape[1] != 3 or len(waypoints) == 0:
        raise DrivewmError(f"{where}: waypoints must be a finite (N, 3) array, got shape {waypoints.shape}")
    if not np.all(np.isfinite(waypoints)):
        row = np.argwhere(~np.isfinite(waypoints))[0][0]
        raise DrivewmError(f"{where}: waypoints must be finite, got NaN or inf in row {row}")
    if np.abs(waypoints).max() > MAX_WAYPOINT_M:  # far ones overflow float32 in the network: a black video
        raise DrivewmError(
            f"{where}: waypoints must lie within {MAX_WAYPOINT_M:g} m of the first frame, "
            f"got {np.abs(waypoints).max():g} m"
        )


def resolve_trajectory(spec: str, num: int, dt_s: float, speed_mps: float = 15.0) -> np.ndarray:
    """``straight|left|right|stop`` or a waypoint file -> (num, 3) waypoints (resampled to ``num`` if needed)."""
    if spec in NAMED:
        return waypoints_from_poses(named_poses(spec, num + 1, dt_s, speed_mps), 0, num)
    return resample_waypoints(load_waypoints(spec), num)


def resample_waypoints(waypoints: np.ndarray, num: int) -> np.ndarray:
    """(N, 3) -> (num, 3) by linear interpolation over the same time span (unchanged when N == num)."""
    if len(waypoints) == num:
        return waypoints
    src_t, dst_t = np.linspace(0, 1, len(waypoints)), np.linspace(0, 1, num)
    return np.stack([np.interp(dst_t, src_t, waypoints[:, k]) for k in range(3)], axis=1)
