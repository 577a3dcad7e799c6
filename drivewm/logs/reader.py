"""Read a drive log (MCAP file, or a folder of split-bag files): whole, or streamed in bounded memory.

Accepted: drivewm's own Foxglove protobuf logs, Foxglove JSON-encoded logs and ROS 2 logs
(sensor_msgs CompressedImage/Image + CameraInfo, tf2_msgs/TFMessage, and optionally a
PoseStamped/Odometry ego pose), mapped onto cameras and frames by a topic map
(:mod:`drivewm.logs.topicmap`). The flow: route each channel to a kind by schema and topic
map, decode only those channels, collect, then assemble the rig, poses and images.

Two ways in: :func:`read_log` holds the whole drive (:class:`DriveLog`, for small logs and
tests). :class:`LogStream` reads an hour-long log in bounded memory: :meth:`LogStream.index`
collects everything but image payloads and agent boxes (calibration, transforms, ego poses,
scene, and each image's camera and timestamp: a few bytes per image; on request the road users
as columns, the static objects and the road lines, :mod:`drivewm.logs.scene_objects`), then
:meth:`LogStream.stream` yields the images one message at a time in log order,
so a consumer holds only what its own window needs. Both share the routing and assembly below.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.geometry import Camera, Rig
from drivewm.logs import decode_foxglove as fox
from drivewm.logs import decode_ros2 as ros
from drivewm.logs import names, scene_objects
from drivewm.logs.frames import FrameGraph
from drivewm.logs.mcap_source import ChannelInfo, Message, iter_messages, list_channels, log_files, read_metadata
from drivewm.logs.scene_objects import SceneObjects
from drivewm.logs.topicmap import TopicMap, load_topic_map
from drivewm.logs.types import DriveLog, ImageFrame, LogIndex, SceneInfo

_IMAGE_SCHEMAS = (fox.IMAGE,) + ros.COMPRESSED_IMAGE + ros.RAW_IMAGE
_CALIBRATION_SCHEMAS = (fox.CALIBRATION,) + ros.CAMERA_INFO
_TF_SCHEMAS = (fox.TRANSFORMS, fox.TRANSFORM) + ros.TF_MESSAGE
_ALWAYS = ("image", "labels", "calibration", "tf", "pose", "scene")  # kinds every pass reads; the others on request


@dataclasses.dataclass
class _Calibration:
    frame_id: str
    K: np.ndarray  # (9,) row-major
    D: np.ndarray
    width: int
    height: int


@dataclasses.dataclass
class _Collected:
    """Everything read from the messages, before assembly. ``keep``: the optional kinds whose
    payloads are decoded and kept ("image", "labels", "agents", "static", "road"); image and label
    timestamps are always recorded."""

    keep: tuple[str, ...] = ("image", "labels", "agents", "static", "road")
    image_stamps: dict[str, list[int]] = dataclasses.field(default_factory=dict)
    images: dict[str, list[ImageFrame]] = dataclasses.field(default_factory=dict)
    label_stamps: dict[str, list[int]] = dataclasses.field(default_factory=dict)
    labels: dict[str, list[ImageFrame]] = dataclasses.field(default_factory=dict)
    calibrations: dict[str, _Calibration] = dataclasses.field(default_factory=dict)
    frames: FrameGraph = dataclasses.field(default_factory=FrameGraph)
    poses: list[tuple[int, np.ndarray]] = dataclasses.field(default_factory=list)
    objects: SceneObjects = dataclasses.field(default_factory=SceneObjects)  # agents, static, road as logged
    scene: dict | None = None
    ros2: bool = False  # any CDR channel: ROS 2 frame names by default


def read_log(path: str | Path, topic_map: str | Path | TopicMap | None = None, require_images: bool = True) -> DriveLog:
    """Read one whole drive into memory. ``topic_map``: a TopicMap, a YAML path or a name in drivewm/topicmaps/.

    ``require_images``: raise unless the log has camera images and ego poses (the contract of
    :meth:`DriveLog.validate`); False loads pose-only or sensor-only logs as they are.
    Raises DrivewmError naming the file for non-MCAP, truncated or corrupt files, a topic map
    naming a topic the log lacks, and images of a camera without calibration.
    """
    reader = LogStream(path, topic_map)
    col = reader.collect(keep=("image", "labels", *scene_objects.KINDS))
    index = reader.assemble(col)
    images = {name: sorted(col.images.get(name, []), key=lambda f: f.timestamp_ns) for name in index.rig.names}
    labels = {name: sorted(frames, key=lambda f: f.timestamp_ns) for name, frames in col.labels.items()}
    agents = index.agents.as_messages()
    log = DriveLog(
        index.path,
        index.rig,
        images,
        index.pose_timestamps_ns,
        index.T_world_from_ego,
        index.scene,
        agents,
        index.road,
        index.warnings,
        index.static,
        labels,
        index.label_classes,
    )
    if require_images:
        log.validate()
    return log


class LogStream:
    """One drive log read in passes, holding no images: :meth:`index` first, then :meth:`stream`.

    ``topic_map``: a TopicMap, a YAML path or a name in drivewm/topicmaps/. Errors are those of
    :func:`read_log`, raised by :meth:`index`.
    """

    def __init__(self, path: str | Path, topic_map: str | Path | TopicMap | None = None):
        self.path = path
        tm = topic_map
        self.tmap = tm if isinstance(tm, TopicMap) else load_topic_map(tm) if tm else TopicMap()
        self.files = log_files(path)
        self._route = _router(self.tmap)

    def index(self, require_images: bool = True, layout: bool = False) -> LogIndex:
        """Calibration, poses, scene and every image's (camera, timestamp), without payloads; the
        road users (as columns), static objects and road lines only if ``layout`` (curation and the
        viewer use them; they cost about as much as the poses)."""
        index = self.assemble(self.collect(keep=scene_objects.KINDS if layout else ()))
        if require_images:
            index.validate()
        return index

    def stream(self, kinds: tuple[str, ...] = ("image",)) -> Iterator[tuple[str, Any]]:
        """Messages of ``kinds`` one at a time in log order: ("image", (camera, ImageFrame)) and
        ("labels", (camera, ImageFrame)) (a label map's PNG). A camera's images come in the order
        :meth:`index` recorded their timestamps."""
        for f in self.files:
            for msg in iter_messages(f, lambda info: (self._route(info) or ("",))[0] in kinds):
                kind, camera = self._route(msg.channel)
                yield kind, _image(camera, msg, self.tmap)

    def collect(self, keep: tuple[str, ...]) -> _Collected:
        """One pass over every routed message (payloads kept for the kinds in ``keep``)."""
        channels = {c for f in self.files for c in list_channels(f)}
        col = _Collected(keep=keep)
        kinds = set(_ALWAYS) | set(keep)  # other kinds' messages are not even decoded
        for f in self.files:
            for msg in iter_messages(f, lambda info: (self._route(info) or ("",))[0] in kinds):
                _handle(col, self._route(msg.channel), msg, self.tmap)
                channels.add(msg.channel)
        _check_topics(self.path, self.tmap, {c.topic for c in channels})
        col.ros2 = any(c.encoding == "cdr" for c in channels)
        return col

    def assemble(self, col: _Collected) -> LogIndex:
        """The index of the log from what one pass collected."""
        # ROS 2 frame names by default (REP 105)
        world = self.tmap.world_frame or ("map" if col.ros2 else names.WORLD_FRAME)
        ego = self.tmap.ego_frame or ("base_link" if col.ros2 else names.EGO_FRAME)
        return _assemble(self.path, self.files, col, self.tmap, world, ego)


# ----------------------------------------------------------------------------- routing


def _router(tmap: TopicMap):
    """channel -> (kind, camera name or None), or None for channels the reader skips."""
    image_topics = {c.image: name for name, c in tmap.cameras.items()}
    calib_topics = {c.calibration: name for name, c in tmap.cameras.items()}
    pose_topic = tmap.ego_pose.topic if tmap.ego_pose else None

    def route(info: ChannelInfo) -> tuple[str, str | None] | None:
        s = info.schema_name
        if s == fox.IMAGE and names.labels_camera(info.topic):  # drivewm's label maps, not images
            return "labels", names.labels_camera(info.topic)
        if info.topic == pose_topic:
            return _mapped(tmap, info, "ego_pose", ros.POSE_TYPES, ("pose", None))
        if tmap.cameras and info.topic in image_topics:
            return _mapped(tmap, info, "image", _IMAGE_SCHEMAS, ("image", image_topics[info.topic]))
        if tmap.cameras and info.topic in calib_topics:
            return _mapped(tmap, info, "calibration", _CALIBRATION_SCHEMAS, ("calibration", calib_topics[info.topic]))
        if not tmap.cameras and s in _IMAGE_SCHEMAS:
            return "image", None
        if not tmap.cameras and s in _CALIBRATION_SCHEMAS:
            return "calibration", None
        if s in _TF_SCHEMAS:
            return "tf", None
        if s == names.SCENE_SCHEMA_NAME or (info.topic == names.SCENE_TOPIC and info.encoding == "json"):
            return "scene", None
        for kind in scene_objects.KINDS:
            if info.topic == getattr(tmap.layout, kind) and s in scene_objects.SCHEMAS[kind]:
                return kind, None
        return None

    return route


def _mapped(tmap: TopicMap, info: ChannelInfo, role: str, schemas: tuple[str, ...], routed: tuple) -> tuple:
    """``routed`` for a topic the topic map names as ``role``, if its schema is one that role reads: a
    map naming e.g. a TF topic as an image had passed transforms off as images, or as an ego pose had
    ended in an AttributeError traceback."""
    if info.schema_name not in schemas:
        raise DrivewmError(
            f"topic map {tmap.source}: {role} topic {info.topic} has schema {info.schema_name!r}, "
            f"expected one of {list(schemas)}"
        )
    return routed


def _stamp(tmap: TopicMap, stamp_ns: int, msg: Message) -> int:
    """The message's own stamp, or its log time (topic map ``timestamps``, or stamp unset)."""
    return stamp_ns if tmap.timestamps == "header" and stamp_ns > 0 else msg.log_time_ns


def _handle(col: _Collected, routed: tuple[str, str | None], msg: Message, tmap: TopicMap) -> None:
    kind, camera = routed
    schema, data = msg.channel.schema_name, msg.data
    if kind in ("image", "labels"):
        name, frame = _image(camera, msg, tmap)
        stamps, kept = (col.image_stamps, col.images) if kind == "image" else (col.label_stamps, col.labels)
        stamps.setdefault(name, []).append(frame.timestamp_ns)
        if kind in col.keep:
            kept.setdefault(name, []).append(frame)
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
    elif kind in scene_objects.KINDS and kind in col.keep:
        items = scene_objects.decode(schema, data)
        stamp = next((item[1] for item in items), 0)
        col.objects.add(kind, items, _stamp(tmap, stamp, msg), tmap.layout.classes)


def _image(camera: str | None, msg: Message, tmap: TopicMap) -> tuple[str, ImageFrame]:
    """(camera name, frame) of an image message; unmapped cameras are named by their frame_id."""
    frame_id, stamp, payload, fmt = _decode_image(msg.channel.schema_name, msg.data)
    return camera or frame_id, ImageFrame(_stamp(tmap, stamp, msg), payload, fmt)


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


def _assemble(path: str | Path, files: list[Path], col: _Collected, tmap: TopicMap, world: str, ego: str) -> LogIndex:
    metadata = read_metadata(files[0])
    meta = metadata.get(names.METADATA_NAME, {})
    without = sorted(set(col.image_stamps) - set(col.calibrations))
    if without:
        raise DrivewmError(f"{path}: images of camera(s) {without} have no calibration")
    order = _camera_order(meta, tmap, col)
    cameras = [_camera(path, name, col, tmap, ego) for name in order]
    rig = Rig(meta.get("rig") or tmap.rig_name or Path(path).stem, cameras)
    warnings = _order_warnings(col, order)
    listed = [n for n in meta.get("cameras", "").split(",") if n and n not in col.calibrations]
    if listed:
        warnings.append(f"the log's metadata lists camera(s) {listed} but it has no calibration or images for them")
    stamps = {name: np.asarray(col.image_stamps.get(name, []), dtype=np.int64) for name in order}
    pose_ts, T_world_from_ego = _ego_poses(col, world, ego)
    if not len(pose_ts):
        warnings.append(_no_poses(col, tmap, world, ego))
    place = scene_objects.placer(col.frames, pose_ts, T_world_from_ego, world, ego)
    agents, static, road, lost = col.objects.place(place, world)
    label_stamps = {name: np.asarray(t, dtype=np.int64) for name, t in col.label_stamps.items()}
    label_classes = tuple(n for n in metadata.get(names.LABELS_METADATA_NAME, {}).get("classes", "").split(",") if n)
    return LogIndex(
        str(path),
        rig,
        stamps,
        pose_ts,
        T_world_from_ego,
        _scene(col, tmap),
        road,
        warnings + lost,
        static,
        agents,
        label_stamps,
        label_classes,
    )


def _order_warnings(col: _Collected, cameras: list[str]) -> list[str]:
    """One line per camera (and the ego poses) whose timestamps go backwards in log order: the reader
    sorts them by time, which mends swapped stamps but interleaves a clock that jumped back."""
    series = {f"camera {c}": col.image_stamps.get(c, []) for c in cameras}
    series["ego poses"] = [t for t, _ in col.poses]
    out = []
    for what, stamps in series.items():
        back = int((np.diff(np.asarray(stamps, dtype=np.int64)) < 0).sum()) if len(stamps) > 1 else 0
        if back:
            out.append(f"{what}: timestamps go backwards {back} time(s) in log order; sorted by time")
    return out


def _camera_order(meta: dict, tmap: TopicMap, col: _Collected) -> list[str]:
    """Rig order: the file's own record, else the topic map's, else first calibration seen."""
    listed = [n for n in meta.get("cameras", "").split(",") if n]
    if listed and set(col.calibrations) <= set(listed):  # cameras listed but absent are warned about
        return [n for n in listed if n in col.calibrations]
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
    try:
        return Camera(name, cal.K.reshape(3, 3), cal.width, cal.height, T_ego_from_cam, cal.D)
    except DrivewmError as exc:  # a singular K, an unusable camera name, ...
        raise DrivewmError(f"{path}: {exc}") from None


def _ego_poses(col: _Collected, world: str, ego: str) -> tuple[np.ndarray, np.ndarray]:
    """T_world_from_ego per tick from the pose topic if mapped, else from the world -> ego TF."""
    series = col.poses or col.frames.series(world, ego)
    series = sorted(series, key=lambda p: p[0])
    ts = np.array([s[0] for s in series], dtype=np.int64)
    Ts = np.stack([s[1] for s in series]) if series else np.zeros((0, 4, 4))
    return ts, Ts


def _no_poses(col: _Collected, tmap: TopicMap, world: str, ego: str) -> str:
    """Why the log gave no ego poses, and what to set: curation then treats the ego motion as unknown."""
    if tmap.ego_pose:
        return f"no ego poses: the pose topic {tmap.ego_pose.topic!r} has no messages"
    frames = col.frames.frames()
    if not frames:
        return "no ego poses: the log has no transforms; map its pose topic with ego_pose.topic in a topic map"
    return (
        f"no ego poses: no transform from world frame {world!r} to ego frame {ego!r} (the log's transform "
        f"frames: {', '.join(frames)}); name them with world_frame and ego_frame in a topic map"
    )


def _scene(col: _Collected, tmap: TopicMap) -> SceneInfo:
    own = col.scene or {}
    tags = {**tmap.tags, **{str(k): str(v) for k, v in own.get("tags", {}).items()}}
    return SceneInfo(tags, own.get("description") or tmap.description)
