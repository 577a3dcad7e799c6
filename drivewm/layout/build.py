"""Build a :class:`ClipLayout` from world-frame objects and the clip's ego poses.

One constructor, three callers: curation (a log's road users, static objects and road lines at a
clip's frames, :func:`layout_from_log`), the simulator without pixels (a
:class:`drivewm.sim.scene.SceneRecording`, :func:`layout_from_recording`) and anything else that
holds boxes and lines in a world frame (a future the multiverse simulates), through
:func:`layout_from_world`. Objects farther than ``radius_m`` from every ego position of the clip
are left out (the simulator draws nothing beyond 150 m); a line is thinned to the points that matter
(Ramer-Douglas-Peucker, :data:`LINE_TOLERANCE_M`) and cut to its runs within reach.
"""

from __future__ import annotations

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.geometry import invert_T
from drivewm.layout.classes import BOX_CLASSES, LINE_KINDS, PAINTS, check_word
from drivewm.layout.clip_layout import STATIC, ClipLayout
from drivewm.logs.types import AgentBox, LogIndex, RoadLine

#: Objects farther than this from every ego position of a clip are not in its layout (m).
RADIUS_M = 200.0
#: Road lines keep the points whose omission would move the line by more than this (m).
LINE_TOLERANCE_M = 0.02


def layout_from_world(
    timestamps_ns: np.ndarray,
    T_world_from_ego: np.ndarray,
    frame_agents: list[list[AgentBox]],
    static: list[AgentBox],
    road: list[RoadLine],
    where: str,
    radius_m: float = RADIUS_M,
    T_world_from_ego0: np.ndarray | None = None,
    thin: bool = True,
) -> ClipLayout:
    """The layout of T frames: ``T_world_from_ego`` (T, 4, 4) the ego poses, ``frame_agents`` the road
    users seen in each frame, ``static`` and ``road`` the drive's static objects and road lines, all
    in one world frame; ``T_world_from_ego0``: the layout's frame (default: the first ego pose);
    ``thin``: thin the road lines (False: ``road`` is :func:`thin_road`'s already).
    Raises a one-line DrivewmError naming ``where`` for non-finite poses, an unknown class, kind or
    paint."""
    T_world_from_ego = np.asarray(T_world_from_ego, dtype=np.float64)
    if len(frame_agents) != len(T_world_from_ego) or len(timestamps_ns) != len(T_world_from_ego):
        raise DrivewmError(f"{where}: layout needs one pose, timestamp and agent list per frame")
    if not np.isfinite(T_world_from_ego).all():
        frame = int(np.flatnonzero(~np.isfinite(T_world_from_ego).all(axis=(1, 2)))[0])
        raise DrivewmError(f"{where}: layout T_world_from_ego is not finite (frame {frame})")
    T_ego0_from_world = invert_T(T_world_from_ego[0] if T_world_from_ego0 is None else T_world_from_ego0)
    path_xy = T_world_from_ego[:, :2, 3]
    rows = [(STATIC, b) for b in static if _reaches(path_xy, b, radius_m)]
    rows += [(t, b) for t, boxes in enumerate(frame_agents) for b in boxes if _reaches(path_xy, b, radius_m)]
    lines = [piece for line in (thin_road(road) if thin else road) for piece in _within(line, path_xy, radius_m)]
    return _assemble(timestamps_ns, T_ego0_from_world @ T_world_from_ego, T_ego0_from_world, rows, lines, where)


def _reaches(path_xy: np.ndarray, box: AgentBox, radius_m: float) -> bool:
    """Whether any of the box comes within ``radius_m`` of an ego position."""
    return bool(_distance(path_xy, box.center_xyz[None, :2])[0] <= radius_m + np.linalg.norm(box.size_lwh[:2]) / 2)


def _distance(path_xy: np.ndarray, points_xy: np.ndarray) -> np.ndarray:
    """Distance (P,) of each point (P, 2) to the nearest ego position (T, 2), m."""
    return np.linalg.norm(points_xy[:, None, :] - path_xy[None, :, :], axis=2).min(axis=1)


def _within(line: RoadLine, path_xy: np.ndarray, radius_m: float) -> list[RoadLine]:
    """The parts of ``line`` within reach: a surface outline whole if any of it is near (it is one
    polygon), a polyline cut into its runs of near points, each with one point more at either end."""
    if len(line.points_xyz) < 2:
        return []
    near = _distance(path_xy, line.points_xyz[:, :2]) <= radius_m
    if line.kind == "road_surface":
        return [line] if near.any() else []
    grown = near | np.r_[near[1:], False] | np.r_[False, near[:-1]]
    runs = np.split(np.arange(len(near)), np.flatnonzero(np.diff(grown.astype(int)) != 0) + 1)
    return [RoadLine(line.kind, line.points_xyz[r], line.line_type) for r in runs if grown[r[0]] and len(r) >= 2]


def _assemble(timestamps_ns, T_ego0_from_ego, T_ego0_from_world, rows, lines, where: str) -> ClipLayout:
    R, t = T_ego0_from_world[:3, :3], T_ego0_from_world[:3, 3]
    boxes = [b for _, b in rows]
    for b in boxes:
        check_word(b.category, BOX_CLASSES, "box_class", where)
    for line in lines:
        check_word(line.kind, LINE_KINDS, "line_kind", where)
        check_word(line.line_type, PAINTS, "line_paint", where)
    centers = np.array([b.center_xyz for b in boxes], dtype=np.float64).reshape(-1, 3)
    axes = np.array([[np.cos(b.yaw_rad), np.sin(b.yaw_rad), 0.0] for b in boxes]).reshape(-1, 3) @ R.T
    points = [line.points_xyz @ R.T + t for line in lines]
    return ClipLayout(
        timestamps_ns=np.asarray(timestamps_ns, dtype=np.int64),
        T_ego0_from_ego=T_ego0_from_ego,
        box_frame=np.array([f for f, _ in rows], dtype=np.int32),
        box_class=np.array([b.category for b in boxes], dtype=np.str_),
        box_track=np.array([b.track_id for b in boxes], dtype=np.str_),
        box_center=centers @ R.T + t,
        box_size=np.array([b.size_lwh for b in boxes], dtype=np.float64).reshape(-1, 3),
        box_yaw=np.arctan2(axes[:, 1], axes[:, 0]),
        line_kind=np.array([line.kind for line in lines], dtype=np.str_),
        line_paint=np.array([line.line_type for line in lines], dtype=np.str_),
        line_start=np.concatenate([[0], np.cumsum([len(p) for p in points], dtype=np.int64)]).astype(np.int64),
        line_points=np.concatenate(points).astype(np.float64) if points else np.zeros((0, 3)),
    )


def thin_road(road: list[RoadLine], tolerance_m: float = LINE_TOLERANCE_M) -> list[RoadLine]:
    """Every line with the points Ramer-Douglas-Peucker keeps (Douglas & Peucker 1973): no dropped point
    lies farther than ``tolerance_m`` from the chord that replaces it. Thinning thinned lines changes
    nothing (each split point is still the farthest of the fewer points); curation thins a log's road
    once and builds every clip's layout from it (:func:`layout_from_log`'s ``road``)."""
    return [RoadLine(line.kind, line.points_xyz[_kept(line.points_xyz, tolerance_m)], line.line_type) for line in road]


def _kept(points: np.ndarray, tolerance_m: float) -> np.ndarray:
    keep = np.zeros(len(points), dtype=bool)
    keep[[0, -1]] = True
    stack = [(0, len(points) - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        chord = points[b] - points[a]
        rel = points[a + 1 : b] - points[a]
        length = float(np.sqrt(chord @ chord))
        along = rel @ chord / length if length > 1e-12 else np.zeros(len(rel))
        off_sq = np.einsum("ij,ij->i", rel, rel) - along**2  # squared distance to the chord's line
        k = int(np.argmax(off_sq))
        if off_sq[k] > tolerance_m**2:
            keep[a + 1 + k] = True
            stack += [(a, a + 1 + k), (a + 1 + k, b)]
    return keep


def layout_from_log(
    log: LogIndex,
    timestamps_ns: np.ndarray,
    T_world_from_ego: np.ndarray,
    where: str,
    radius_m: float = RADIUS_M,
    road: list[RoadLine] | None = None,
) -> ClipLayout | None:
    """The layout of a clip of ``log`` (indexed with ``layout=True``), or None when the log knows no
    layout. ``timestamps_ns`` (T,) and ``T_world_from_ego`` (T, 4, 4) are the clip's frames and its
    (smoothed) ego poses, whose first is ego0, the frame of ``trajectory_ego``. Each frame is placed at
    the log's own ego pose nearest its time (the pose its images were taken at, so the layout lies on
    the pixels), or at the clip's pose when the log has none within half a frame interval. A frame's
    road users are those of the agent message nearest its time within half a frame interval (none
    there: no road users in that frame). ``road``: the log's road lines already thinned by
    :func:`thin_road` (None: ``log.road``, thinned here)."""
    if not log.has_layout:
        return None
    ts = np.asarray(timestamps_ns, dtype=np.int64)
    tolerance = np.diff(ts).min() / 2 if len(ts) > 1 else 0
    frames = []
    for t in ts:
        m = log.agents.nearest(int(t), tolerance) if log.agents is not None else None
        frames.append(log.agents.boxes(m) if m is not None else [])
    poses = _logged_poses(log, ts, tolerance, T_world_from_ego)
    lines = thin_road(log.road) if road is None else road
    return layout_from_world(ts, poses, frames, log.static, lines, where, radius_m, T_world_from_ego[0], thin=False)


def _logged_poses(log: LogIndex, ts: np.ndarray, tolerance: float, fallback: np.ndarray) -> np.ndarray:
    """The log's finite ego pose nearest each time within ``tolerance``, else the ``fallback`` pose."""
    out = np.array(fallback, dtype=np.float64)
    if not len(log.pose_timestamps_ns):
        return out
    i = np.clip(np.searchsorted(log.pose_timestamps_ns, ts), 0, len(log.pose_timestamps_ns) - 1)
    for k, t in enumerate(ts):
        near = [j for j in (i[k] - 1, i[k]) if 0 <= j < len(log.pose_timestamps_ns)]
        j = min(near, key=lambda j: abs(int(log.pose_timestamps_ns[j]) - int(t)))
        if abs(int(log.pose_timestamps_ns[j]) - int(t)) <= tolerance and np.isfinite(log.T_world_from_ego[j]).all():
            out[k] = log.T_world_from_ego[j]
    return out
