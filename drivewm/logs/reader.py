"""Read a drive log (MCAP file, or a folder of split-bag files) into a :class:`DriveLog`.

Accepted: drivewm's own Foxglove protobuf logs, Foxglove JSON-encoded logs and ROS 2 logs
(sensor_msgs CompressedImage/Image + CameraInfo, tf2_msgs/TFMessage, and optionally a
PoseStamped/Odometry ego pose), mapped onto cameras and frames by a topic map
(:mod:`drivewm.logs.topicmap`). The flow: route each channel to a kind by schema and topic
map, decode only those channels, collect, then assemble the rig, poses and images.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.geometry import Camera, Rig
from drivewm.logs import decode_foxglove as fox
from drivewm.logs import decode_ros2 as ros
from drivewm.logs import names
from drivewm.logs.frames import FrameGraph
from drivewm.logs.mcap_source import ChannelInfo, Message, iter_messages, list_channels, log_files, read_metadata
from drivewm.logs.topicmap import TopicMap, load_topic_map
from drivewm.logs.types import AgentBox, DriveLog, ImageFrame, RoadLine, SceneInfo

_IMAGE_SCHEMAS = (fox.IMAGE,) + ros.COMPRESSED_IMAGE + ros.RAW_IMAGE
_CALIBRATION_SCHEMAS = (fox.CALIBRATION,) + ros.CAMERA_INFO
_TF_SCHEMAS = (fox.TRANSFORMS, fox.TRANSFORM) + ros.TF_MESSAGE


@dataclasses.dataclass
class _Calibration:
    frame_id: str
    K: np.ndarray  # (9,) row-major
    D: np.ndarray
    width: int
    height: int


@dataclasses.dataclass
class _Collected:
    """Everything read from the messages, before assembly."""

    images: dict[str, list[ImageFrame]] = dataclasses.field(default_factory=dict)
    calibrations: dict[str, _Calibration] = dataclasses.field(default_factory=dict)
    frames: FrameGraph = dataclasses.field(default_factory=FrameGraph)
    poses: list[tuple[int, np.ndarray]] = dataclasses.field(default_factory=list)
    agents: list[tuple[int, list[AgentBox]]] = dataclasses.field(default_factory=list)
    road: list[RoadLine] = dataclasses.field(default_factory=list)
    scene: dict | None = None


def read_log(path: str | Path, topic_map: str | Path | TopicMap | None = None, require_images: bool = True) -> DriveLog:
    """Read one drive. ``topic_map``: a TopicMap, a YAML path or a name in drivewm/topicmaps/.

    ``require_images``: raise unless the log has camera images and ego poses (the contract of
    :meth:`DriveLog.validate`); False loads pose-only or sensor-only logs as they are.
    Raises DrivewmError naming the file for non-MCAP, truncated or corrupt files, a topic map
    naming a topic the log lacks, and images of a camera without calibration.
    """
    tmap = topic_map if isinstance(topic_map, TopicMap) else load_topic_map(topic_map) if topic_map else TopicMap()
    files = log_files(path)
    channels = {c for f in files for c in list_channels(f)}
    col = _Collected()
    route = _router(tmap)
    for f in files:
        for msg in iter_messages(f, lambda info: route(info) is not None):
            _handle(col, route(msg.channel), msg, tmap)
            channels.add(msg.channel)
    _check_topics(path, tmap, {c.topic for c in channels})
    ros2 = any(c.encoding == "cdr" for c in channels)  # ROS 2 frame names by default (REP 105)
    world = tmap.world_frame or ("map" if ros2 else names.WORLD_FRAME)
    ego = tmap.ego_frame or ("base_link" if ros2 else names.EGO_FRAME)
    log = _assemble(path, files, col, tmap, world, ego)
    if require_images:
        log.validate()
    return log


# ----------------------------------------------------------------------------- routing


def _router(tmap: TopicMap):
    """channel -> (kind, camera name or None), or None for channels the reader skips."""
    image_topics = {c.image: name for name, c in tmap.cameras.items()}
    calib_topics = {c.calibration: name for name, c in tmap.cameras.items()}
    pose_topic = tmap.ego_pose.topic if tmap.ego_pose else None

    def route(info: ChannelInfo) -> tuple[str, str | None] | None:
        s = info.schema_name
        if tmap.cameras and info.topic in image_topics:
            return "image", image_topics[info.topic]
        if tmap.cameras and info.topic in calib_topics:
            return "calibration", calib_topics[info.topic]
        if not tmap.cameras and s in _IMAGE_SCHEMAS:
            return "image", None
        if not tmap.cameras and s in _CALIBRATION_SCHEMAS:
            return "calibration", None
        if info.topic == pose_topic:
            return "pose", None
        if s in _TF_SCHEMAS:
            return "tf", None
        if s == names.SCENE_SCHEMA_NAME or (info.topic == names.SCENE_TOPIC and info.encoding == "json"):
            return "scene", None
        if s == fox.SCENE_UPDATE and info.topic == names.AGENTS_TOPIC:
            return "agents", None
        if s == fox.SCENE_UPDATE and info.topic == names.ROAD_TOPIC:
            return "road", None
        return None

    return route


def _stamp(tmap: TopicMap, stamp_ns: int, msg: Message) -> int:
    """The message's own stamp, or its log time (topic map ``timestamps``, or stamp unset)."""
    return stamp_ns if tmap.timestamps == "header" and stamp_ns > 0 else msg.log_time_ns


def _handle(col: _Collected, routed: tuple[str, str | None], msg: Message, tmap: TopicMap) -> None:
    kind, camera = routed
    schema, data = msg.channel.schema_name, msg.data
    if kind == "image":
        frame_id, stamp, payload, fmt = _decode_image(schema, data)
        col.images.setdefault(camera or frame_id, []).append(ImageFrame(_stamp(tmap, stamp, msg), payload, fmt))
    elif kind == "calibration":
        frame_id, K, D, w, h = ros.camera_info(data) if schema in ros.CAMERA_INFO else fox.calibration(data)
        col.calibrations.setdefault(camera or frame_id, _Calibration(frame_id, K, D, w, h))
    elif kind == "tf":
        edges = ros.tf_message(data) if schema in ros.TF_MESSAGE else fox.transforms(data, schema)
        for stamp, parent, child, T in edges:
            col.frames.add(parent, child, _stamp(tmap, stamp, msg), T)
    elif kind == "pose":
        stamp, _, T = ros.pose(data, schema)
        col.poses.append((_stamp(tmap, stamp, msg), T))
    elif kind == "scene":
        col.scene = data if col.scene is None else col.scene
    elif kind == "agents":
        stamp, boxes = fox.agents(data)
        col.agents.append((_stamp(tmap, stamp, msg), boxes))
    elif kind == "road":
        col.road += fox.road_lines(data)


def _decode_image(schema: str, data: Any) -> tuple[str, int, bytes, str]:
    if schema in ros.COMPRESSED_IMAGE:
        return ros.compressed_image(data)
    if schema in ros.RAW_IMAGE:
        return ros.raw_image(data)
    return fox.image(data)


def _check_topics(path: str | Path, tmap: TopicMap, topics: set[str]) -> None:
    missing = [t for t in tmap.required_topics() if t not in topics]
    if missing:
        raise DrivewmError(f"{path}: topic map {tmap.source} names topic(s) {missing} that the log does not have")


# ----------------------------------------------------------------------------- assembly


def _assemble(path: str | Path, files: list[Path], col: _Collected, tmap: TopicMap, world: str, ego: str) -> DriveLog:
    meta = read_metadata(files[0]).get(names.METADATA_NAME, {})
    without = sorted(set(col.images) - set(col.calibrations))
    if without:
        raise DrivewmError(f"{path}: images of camera(s) {without} have no calibration")
    order = _camera_order(meta, tmap, col)
    cameras = [_camera(path, name, col, tmap, ego) for name in order]
    rig = Rig(meta.get("rig") or tmap.rig_name or Path(path).stem, cameras)
    images = {name: sorted(col.images.get(name, []), key=lambda f: f.timestamp_ns) for name in order}
    pose_ts, T_world_from_ego = _ego_poses(col, world, ego)
    agents = sorted(col.agents, key=lambda a: a[0])
    return DriveLog(str(path), rig, images, pose_ts, T_world_from_ego, _scene(col, tmap), agents, col.road)


def _camera_order(meta: dict, tmap: TopicMap, col: _Collected) -> list[str]:
    """Rig order: the file's own record, else the topic map's, else first calibration seen."""
    listed = [n for n in meta.get("cameras", "").split(",") if n]
    if listed and set(listed) == set(col.calibrations):
        return listed
    if tmap.cameras:
        return [n for n in tmap.cameras if n in col.calibrations]
    return list(col.calibrations)


def _camera(path: str | Path, name: str, col: _Collected, tmap: TopicMap, ego: str) -> Camera:
    cal = col.calibrations[name]
    if cal.K.size != 9 or not np.all(np.isfinite(cal.K)) or cal.width <= 0 or cal.height <= 0:
        raise DrivewmError(
            f"{path}: calibration of camera {name!r} is incomplete (K has {cal.K.size} values, size "
            f"{cal.width}x{cal.height})"
        )
    mapped = tmap.cameras.get(name)
    frame = (mapped.frame if mapped else None) or cal.frame_id or name
    T_ego_from_cam = col.frames.static_transform(ego, frame)
    if T_ego_from_cam is None:
        raise DrivewmError(f"{path}: camera {name!r}: no transform from {ego!r} to its frame {frame!r} in the log")
    return Camera(name, cal.K.reshape(3, 3), cal.width, cal.height, T_ego_from_cam, cal.D)


def _ego_poses(col: _Collected, world: str, ego: str) -> tuple[np.ndarray, np.ndarray]:
    """T_world_from_ego per tick from the pose topic if mapped, else from the world -> ego TF."""
    series = col.poses or col.frames.series(world, ego)
    series = sorted(series, key=lambda p: p[0])
    ts = np.array([s[0] for s in series], dtype=np.int64)
    Ts = np.stack([s[1] for s in series]) if series else np.zeros((0, 4, 4))
    return ts, Ts


def _scene(col: _Collected, tmap: TopicMap) -> SceneInfo:
    own = col.scene or {}
    tags = {**tmap.tags, **{str(k): str(v) for k, v in own.get("tags", {}).items()}}
    return SceneInfo(tags, own.get("description") or tmap.description)
