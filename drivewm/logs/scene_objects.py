"""The scene's structure in a log: road users, static objects and road lines, in the world frame.

A log may carry them as foxglove.SceneUpdate (drivewm's ``/agents``, ``/static``, ``/road``),
visualization_msgs/MarkerArray or (road users) vision_msgs/Detection3DArray, on the topics a topic
map's ``layout`` names (:class:`drivewm.logs.topicmap.LayoutTopics`), in the world frame, the ego
frame or a sensor frame. This module decodes any of them, renames categories and line kinds
through the map's ``layout.classes``, and places everything in the world frame once the ego poses
are known (:meth:`SceneObjects.place`): the ego frame with the ego pose nearest the object's stamp,
a sensor frame through its static transform to the ego (or to the world).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from drivewm.logs import decode_foxglove as fox
from drivewm.logs import decode_ros2 as ros
from drivewm.logs.agent_table import AgentTable, AgentTableBuilder, Placer
from drivewm.logs.frames import FrameGraph
from drivewm.logs.types import AgentBox, RoadLine

KINDS = ("agents", "static", "road")
#: The message types each kind is read from.
SCHEMAS = {
    "agents": (fox.SCENE_UPDATE,) + ros.MARKER_ARRAY + ros.DETECTION3D_ARRAY,
    "static": (fox.SCENE_UPDATE,) + ros.MARKER_ARRAY,
    "road": (fox.SCENE_UPDATE,) + ros.MARKER_ARRAY,
}


def decode(schema: str, data: Any) -> list[tuple[str, int, AgentBox | RoadLine, np.ndarray | None]]:
    """Any accepted message -> [(frame_id, stamp_ns, box or line, a box's length axis (3,) in its frame
    or None)] as the log states them."""
    if schema in ros.MARKER_ARRAY:
        return ros.markers(data)
    if schema in ros.DETECTION3D_ARRAY:
        return ros.detections(data)
    return fox.scene_boxes(data) + fox.scene_lines(data)


def renamed(item: AgentBox | RoadLine, classes: dict[str, str]) -> AgentBox | RoadLine:
    """A box's category, or a line's ``KIND[/PAINT]``, through a topic map's ``layout.classes``."""
    if isinstance(item, AgentBox):
        return dataclasses.replace(item, category=classes.get(item.category, item.category))
    name = f"{item.kind}/{item.line_type}" if item.line_type else item.kind
    kind, _, paint = classes.get(name, classes.get(item.kind, name)).partition("/")
    return dataclasses.replace(item, kind=kind, line_type=paint or item.line_type)


@dataclasses.dataclass
class SceneObjects:
    """What one pass collected, in the frames the log gave: road users per message (kept as columns,
    :class:`drivewm.logs.agent_table.AgentTable`), static boxes, road lines."""

    agents: AgentTableBuilder = dataclasses.field(default_factory=AgentTableBuilder)
    static: list[tuple[str, int, tuple[AgentBox, np.ndarray]]] = dataclasses.field(default_factory=list)
    road: list[tuple[str, int, RoadLine]] = dataclasses.field(default_factory=list)

    def add(self, kind: str, items: list[tuple], stamp_ns: int, classes: dict[str, str]) -> None:
        """One message of ``kind`` (items as :func:`decode` gives them); ``stamp_ns``: the message's time
        as the reader takes it."""
        boxes = [(f, (renamed(b, classes), axis)) for f, _, b, axis in items if isinstance(b, AgentBox)]
        if kind == "agents":
            by_frame: dict[str, list[tuple[AgentBox, np.ndarray]]] = {}
            for frame, box in boxes:
                by_frame.setdefault(frame, []).append(box)
            for frame, framed in by_frame.items():
                self.agents.add(stamp_ns, [b for b, _ in framed], frame, [a for _, a in framed])
            if not by_frame:
                self.agents.add(stamp_ns, [])  # an empty scene at this tick is news too
        elif kind == "static":
            self.static += [(f, stamp_ns, box) for f, box in boxes]
        else:
            self.road += [(f, stamp_ns, renamed(r, classes)) for f, _, r, _ in items if isinstance(r, RoadLine)]

    def place(self, place: Placer, world: str) -> tuple[AgentTable, list[AgentBox], list[RoadLine], list[str]]:
        """Everything in the world frame (objects given in ``world`` as read), and one warning per frame
        that could not be placed."""
        agents, lost = self.agents.build(place, world)
        static, lost_static = _placed(self.static, place, _move_box, world)
        road, lost_road = _placed(self.road, place, _move_line, world)
        frames = sorted(set(lost) | lost_static | lost_road)
        warnings = [
            f"scene objects in frame {f!r} left out: no transform from it to the world or ego frame" for f in frames
        ]
        return agents, static, road, warnings


def _placed(items: list[tuple[str, int, Any]], place: Placer, move, world: str) -> tuple[list, set[str]]:
    out, lost = [], set()
    for frame in dict.fromkeys(f for f, _, _ in items):
        mine = [(t, item) for f, t, item in items if f == frame]
        if frame in ("", world):
            out += [item[0] if isinstance(item, tuple) else item for _, item in mine]
            continue
        T = place(frame, np.array([t for t, _ in mine], dtype=np.int64))
        if T is None:
            lost.add(frame)
            continue
        out += [move(item, T_k) for (_, item), T_k in zip(mine, T) if np.isfinite(T_k).all()]
    return out, lost


def _move_box(framed: tuple[AgentBox, np.ndarray], T: np.ndarray) -> AgentBox:
    """The box moved by T, its yaw the heading of its length axis in the new frame."""
    box, axis = framed
    axis = T[:3, :3] @ axis
    center = T[:3, :3] @ box.center_xyz + T[:3, 3]
    return dataclasses.replace(box, center_xyz=center, yaw_rad=float(np.arctan2(axis[1], axis[0])))


def _move_line(line: RoadLine, T: np.ndarray) -> RoadLine:
    return dataclasses.replace(line, points_xyz=line.points_xyz @ T[:3, :3].T + T[:3, 3])


def placer(frames: FrameGraph, pose_ts: np.ndarray, T_world_from_ego: np.ndarray, world: str, ego: str) -> Placer:
    """``T_world_from(frame, stamps)``: identity for the world frame; the ego pose nearest each stamp
    (times the frame's static transform to the ego) for the ego frame and frames fixed to it; a
    frame's static transform to the world; else None (or when the log has no ego poses)."""

    def T_world_from(frame: str, stamps: np.ndarray) -> np.ndarray | None:
        if frame == world:
            return np.tile(np.eye(4), (len(stamps), 1, 1))
        T_ego_from_frame = frames.static_transform(ego, frame) if frame != ego else np.eye(4)
        if T_ego_from_frame is not None and len(pose_ts):
            nearest = _nearest(pose_ts, stamps)
            return T_world_from_ego[nearest] @ T_ego_from_frame
        T_world_from_frame = frames.static_transform(world, frame)
        return None if T_world_from_frame is None else np.tile(T_world_from_frame, (len(stamps), 1, 1))

    return T_world_from


def _nearest(sorted_ts: np.ndarray, stamps: np.ndarray) -> np.ndarray:
    i = np.clip(np.searchsorted(sorted_ts, stamps), 1, max(len(sorted_ts) - 1, 1))
    before = np.clip(i - 1, 0, len(sorted_ts) - 1)
    after = np.clip(i, 0, len(sorted_ts) - 1)
    return np.where(np.abs(stamps - sorted_ts[before]) <= np.abs(sorted_ts[after] - stamps), before, after)
