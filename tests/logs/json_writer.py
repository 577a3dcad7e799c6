"""Write a drive log with JSON-encoded Foxglove messages (the same topics as
:mod:`drivewm.logs.writer`): the reader's tests of JSON-encoded logs.

Some recorders log Foxglove schemas as JSON rather than protobuf; no package ships those JSON
schemas, so the subset drivewm uses is written out here, following the Foxglove schema docs
(bytes fields are base64 strings, times are ``{"sec", "nsec"}``). Written with the plain
``mcap`` writer, so the reader is also checked against a second, independent writer. Non-finite
numbers (pose gaps) are written as ``null``: strict JSON has no NaN.
"""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
from mcap.writer import IndexType, Writer

from drivewm.atomic import atomic_path
from drivewm.logs import names
from drivewm.logs.transforms import ns_to_sec_nsec, quat_xyzw_from_yaw, split_T
from drivewm.logs.types import AgentBox, DriveLog, RoadLine
from drivewm.logs.writer import SCENE_JSON_SCHEMA, distortion_model, drive_events

_TIME = {"type": "object", "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}}}
_VEC3 = {"type": "object", "properties": {k: {"type": "number"} for k in "xyz"}}
_QUAT = {"type": "object", "properties": {k: {"type": "number"} for k in "xyzw"}}
_NUMBERS = {"type": "array", "items": {"type": "number"}}
_TRANSFORM = {
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "parent_frame_id": {"type": "string"},
        "child_frame_id": {"type": "string"},
        "translation": _VEC3,
        "rotation": _QUAT,
    },
}
JSON_SCHEMAS = {
    "foxglove.CompressedImage": {
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "data": {"type": "string", "contentEncoding": "base64"},
            "format": {"type": "string"},
        },
    },
    "foxglove.CameraCalibration": {
        "type": "object",
        "properties": {
            "timestamp": _TIME,
            "frame_id": {"type": "string"},
            "width": {"type": "integer"},
            "height": {"type": "integer"},
            "distortion_model": {"type": "string"},
            "D": _NUMBERS,
            "K": _NUMBERS,
            "R": _NUMBERS,
            "P": _NUMBERS,
        },
    },
    "foxglove.FrameTransforms": {
        "type": "object",
        "properties": {"transforms": {"type": "array", "items": _TRANSFORM}},
    },
    "foxglove.SceneUpdate": {
        "type": "object",
        "properties": {"deletions": {"type": "array"}, "entities": {"type": "array", "items": {"type": "object"}}},
    },
    names.SCENE_SCHEMA_NAME: SCENE_JSON_SCHEMA,
}


def _time(timestamp_ns: int) -> dict:
    sec, nsec = ns_to_sec_nsec(timestamp_ns)
    return {"sec": sec, "nsec": nsec}


def _num(v: float) -> float | None:
    return float(v) if np.isfinite(v) else None


def _transform(timestamp_ns: int, parent: str, child: str, T: np.ndarray) -> dict:
    t, q = split_T(T)
    return {
        "timestamp": _time(timestamp_ns),
        "parent_frame_id": parent,
        "child_frame_id": child,
        "translation": dict(zip("xyz", map(_num, t))),
        "rotation": dict(zip("xyzw", map(_num, q))),
    }


def _entity(timestamp_ns: int, box: AgentBox) -> dict:
    pose = {
        "position": dict(zip("xyz", map(float, box.center_xyz))),
        "orientation": dict(zip("xyzw", map(float, quat_xyzw_from_yaw(box.yaw_rad)))),
    }
    color = dict(zip("rgba", [*map(float, box.color_rgb), 1.0]))
    cube = {"pose": pose, "size": dict(zip("xyz", map(float, box.size_lwh))), "color": color}
    return {
        "timestamp": _time(timestamp_ns),
        "frame_id": names.WORLD_FRAME,
        "id": box.track_id,
        "metadata": [{"key": "category", "value": box.category}],
        "cubes": [cube],
    }


def _road_message(lines: list[RoadLine], t0: int) -> dict:
    entities = [
        {
            "timestamp": _time(t0),
            "frame_id": names.WORLD_FRAME,
            "id": f"{line.kind}/{i}",
            "metadata": [{"key": "kind", "value": line.kind}, {"key": "line_type", "value": line.line_type}],
            "lines": [
                {
                    "type": 1 if line.kind == "road_surface" else 0,  # LINE_LOOP for a polygon outline, else LINE_STRIP
                    "thickness": 0.15,
                    "points": [dict(zip("xyz", map(float, p))) for p in line.points_xyz],
                }
            ],
        }
        for i, line in enumerate(lines)
    ]
    return {"deletions": [], "entities": entities}


def _static_messages(log: DriveLog, t0: int) -> list[tuple[str, dict, int]]:
    """(topic, message, t0) for calibrations, tf_static and the scene, all at time t0."""
    out = []
    for cam in log.rig.cameras:
        P = np.concatenate([cam.K, np.zeros((3, 1))], axis=1)
        out.append(
            (
                names.calibration_topic(cam.name),
                {
                    "timestamp": _time(t0),
                    "frame_id": cam.name,
                    "width": cam.width,
                    "height": cam.height,
                    "distortion_model": distortion_model(cam.distortion),
                    "D": cam.distortion.tolist(),
                    "K": cam.K.reshape(-1).tolist(),
                    "R": np.eye(3).reshape(-1).tolist(),
                    "P": P.reshape(-1).tolist(),
                },
                t0,
            )
        )
    statics = [_transform(t0, names.EGO_FRAME, c.name, c.T_ego_from_cam) for c in log.rig.cameras]
    out.append((names.TF_STATIC_TOPIC, {"transforms": statics}, t0))
    out.append((names.SCENE_TOPIC, {"tags": dict(log.scene.tags), "description": log.scene.description}, t0))
    if log.road:
        out.append((names.ROAD_TOPIC, _road_message(log.road, t0), t0))
    if log.static:
        out.append((names.STATIC_TOPIC, {"deletions": [], "entities": [_entity(t0, b) for b in log.static]}, t0))
    return out


def _event_message(ts: int, kind: str, payload: tuple) -> tuple[str, dict]:
    if kind == "pose":
        return names.TF_TOPIC, {"transforms": [_transform(ts, names.WORLD_FRAME, names.EGO_FRAME, payload[0])]}
    if kind == "agents":
        return names.AGENTS_TOPIC, {
            "deletions": [{"timestamp": _time(ts), "type": 1, "id": ""}],
            "entities": [_entity(ts, b) for b in payload[0]],
        }
    camera, frame = payload
    return names.image_topic(camera), {
        "timestamp": _time(ts),
        "frame_id": camera,
        "data": base64.b64encode(frame.data).decode("ascii"),
        "format": frame.format,
    }


def _schema_of(topic: str) -> str:
    if topic.endswith("/image"):
        return "foxglove.CompressedImage"
    if topic.endswith("/calibration"):
        return "foxglove.CameraCalibration"
    return {
        names.TF_TOPIC: "foxglove.FrameTransforms",
        names.TF_STATIC_TOPIC: "foxglove.FrameTransforms",
        names.AGENTS_TOPIC: "foxglove.SceneUpdate",
        names.ROAD_TOPIC: "foxglove.SceneUpdate",
        names.STATIC_TOPIC: "foxglove.SceneUpdate",
        names.SCENE_TOPIC: names.SCENE_SCHEMA_NAME,
    }[topic]


def write_log_json(log: DriveLog, path: str | Path, indexed: bool = True) -> Path:
    """Write ``log`` to ``path`` (atomic) with JSON-encoded Foxglove messages.

    ``indexed=False`` writes the bare layout some recorders produce: no chunks, no indexes and
    no summary section (readers must scan the file).
    """
    events = [e for e in drive_events(log) if e[1] != "labels"]  # label maps stay drivewm's own logs'
    t0 = events[0][0] if events else 0
    messages = _static_messages(log, t0) + [(*_event_message(ts, k, p), ts) for ts, k, p in events]
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        bare = dict(
            use_chunking=False,
            index_types=IndexType.NONE,
            repeat_channels=False,
            repeat_schemas=False,
            use_statistics=False,
            use_summary_offsets=False,
        )
        writer = Writer(f, **({} if indexed else bare))
        writer.start(profile="", library="drivewm json_writer")
        writer.add_metadata(names.METADATA_NAME, {"rig": log.rig.name, "cameras": ",".join(log.rig.names)})
        schema_ids, channel_ids = {}, {}
        for topic, msg, ts in messages:
            schema = _schema_of(topic)
            if schema not in schema_ids:
                schema_ids[schema] = writer.register_schema(
                    schema, "jsonschema", json.dumps(JSON_SCHEMAS[schema]).encode()
                )
            if topic not in channel_ids:
                channel_ids[topic] = writer.register_channel(topic, "json", schema_ids[schema])
            data = json.dumps(msg, allow_nan=False).encode()
            writer.add_message(channel_ids[topic], log_time=ts, data=data, publish_time=ts)
        writer.finish()
    return Path(path)
