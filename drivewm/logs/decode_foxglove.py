"""Foxglove messages (protobuf or JSON encoding) -> drivewm values.

Protobuf messages come from mcap-protobuf-support (attributes; times are
``google.protobuf.Timestamp`` with ``seconds``/``nanos``); JSON messages are dicts (times are
``{"sec", "nsec"}``, bytes are base64 strings), per the Foxglove schema docs.
"""

from __future__ import annotations

import base64
from typing import Any

import numpy as np

from drivewm.geometry import quat_xyzw_to_R
from drivewm.logs.transforms import join_T, sec_nsec_to_ns, yaw_from_quat_xyzw
from drivewm.logs.types import AgentBox, RoadLine

IMAGE = "foxglove.CompressedImage"
CALIBRATION = "foxglove.CameraCalibration"
TRANSFORMS = "foxglove.FrameTransforms"
TRANSFORM = "foxglove.FrameTransform"
SCENE_UPDATE = "foxglove.SceneUpdate"


def field(msg: Any, name: str, default: Any = None) -> Any:
    """A field of a protobuf message or a JSON dict."""
    if isinstance(msg, dict):
        return msg.get(name, default)
    return getattr(msg, name, default)


def time_ns(stamp: Any) -> int:
    """Foxglove time (protobuf Timestamp or JSON {sec, nsec}) -> ns; 0 if unset."""
    if stamp is None:
        return 0
    if isinstance(stamp, dict):
        return sec_nsec_to_ns(stamp.get("sec", 0), stamp.get("nsec", 0))
    return sec_nsec_to_ns(stamp.seconds, stamp.nanos)


def as_bytes(value: Any) -> bytes:
    """A bytes field: raw in protobuf, base64 text in JSON."""
    return base64.b64decode(value) if isinstance(value, str) else bytes(value)


def vec3(v: Any) -> np.ndarray:
    return np.array([field(v, "x", 0.0), field(v, "y", 0.0), field(v, "z", 0.0)], dtype=np.float64)


def quat_xyzw(q: Any) -> np.ndarray:
    return np.array([field(q, k, 0.0) for k in "xyzw"], dtype=np.float64)


def image(msg: Any) -> tuple[str, int, bytes, str]:
    """CompressedImage -> (frame_id, stamp_ns, data, format)."""
    return (
        field(msg, "frame_id", ""),
        time_ns(field(msg, "timestamp")),
        as_bytes(field(msg, "data", b"")),
        field(msg, "format", ""),
    )


def calibration(msg: Any) -> tuple[str, np.ndarray, np.ndarray, int, int]:
    """CameraCalibration -> (frame_id, K (3, 3), D (n,), width, height)."""
    K = np.asarray(list(field(msg, "K", [])), dtype=np.float64)
    D = np.asarray(list(field(msg, "D", [])), dtype=np.float64)
    return field(msg, "frame_id", ""), K, D, int(field(msg, "width", 0)), int(field(msg, "height", 0))


def transforms(msg: Any, schema_name: str) -> list[tuple[int, str, str, np.ndarray]]:
    """FrameTransforms or FrameTransform -> [(stamp_ns, parent, child, T_parent_from_child)]."""
    items = field(msg, "transforms", []) if schema_name == TRANSFORMS else [msg]
    out = []
    for tf in items:
        T = join_T(vec3(field(tf, "translation", {})), quat_xyzw(field(tf, "rotation", {})))
        out.append(
            (time_ns(field(tf, "timestamp")), field(tf, "parent_frame_id", ""), field(tf, "child_frame_id", ""), T)
        )
    return out


def agents(msg: Any) -> tuple[int, list[AgentBox]]:
    """SceneUpdate of cube entities -> (stamp_ns, boxes); the first cube of each entity is its box."""
    placed = scene_boxes(msg)
    return (placed[0][1] if placed else 0), [box for _, _, box, _ in placed]


def scene_boxes(msg: Any) -> list[tuple[str, int, AgentBox, np.ndarray]]:
    """SceneUpdate of cube entities -> [(frame_id, stamp_ns, box, its length axis (3,) in the frame)]:
    the first cube of each entity, its ``id`` the track id and its metadata ``category`` the category."""
    out = []
    for ent in field(msg, "entities", []):
        cubes = list(field(ent, "cubes", []))
        if not cubes:
            continue
        cube = cubes[0]
        pose = field(cube, "pose", {})
        meta = {field(kv, "key"): field(kv, "value") for kv in field(ent, "metadata", [])}
        color = field(cube, "color", {})
        q = quat_xyzw(field(pose, "orientation", {"w": 1.0}))
        box = AgentBox(
            track_id=field(ent, "id", ""),
            category=meta.get("category", "unknown"),
            center_xyz=vec3(field(pose, "position", {})),
            size_lwh=vec3(field(cube, "size", {})),
            yaw_rad=yaw_from_quat_xyzw(q),
            color_rgb=(float(field(color, "r", 0.5)), float(field(color, "g", 0.5)), float(field(color, "b", 0.5))),
        )
        axis = quat_xyzw_to_R(q)[:, 0] if np.any(q) else np.array([1.0, 0.0, 0.0])
        out.append((field(ent, "frame_id", ""), time_ns(field(ent, "timestamp")), box, axis))
    return out


def road_lines(msg: Any) -> list[RoadLine]:
    """SceneUpdate of line entities -> road polylines (kind and line type from metadata)."""
    return [line for _, _, line, _ in scene_lines(msg)]


def scene_lines(msg: Any) -> list[tuple[str, int, RoadLine, None]]:
    """SceneUpdate of line entities -> [(frame_id, stamp_ns, polyline, None)], kind and line type from
    the entity's metadata; each line primitive's pose applies to its points."""
    out = []
    for ent in field(msg, "entities", []):
        meta = {field(kv, "key"): field(kv, "value") for kv in field(ent, "metadata", [])}
        frame, stamp = field(ent, "frame_id", ""), time_ns(field(ent, "timestamp"))
        for line in field(ent, "lines", []):
            points = np.array([vec3(p) for p in field(line, "points", [])], dtype=np.float64).reshape(-1, 3)
            pose = field(line, "pose", None)
            if pose is not None:
                T = join_T(vec3(field(pose, "position", {})), quat_xyzw(field(pose, "orientation", {"w": 1.0})))
                points = points @ T[:3, :3].T + T[:3, 3] if np.isfinite(T).all() else points
            out.append((frame, stamp, RoadLine(meta.get("kind", "line"), points, meta.get("line_type", "")), None))
    return out
