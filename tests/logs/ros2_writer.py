"""Export a drive log as a ROS 2 MCAP bag (CDR), laid out the way a ROS 2 car records one: the
ROS 2 reader's test bags.

Per camera ``X`` (lower-cased name ``x``): ``/x/image_raw/compressed`` (sensor_msgs/CompressedImage)
or ``/x/image_raw`` (sensor_msgs/Image rgb8, for ``raw_cameras``) and ``/x/camera_info``; frames
``base_link -> x_link`` (the mount, x forward) ``-> x_optical_frame`` (OpenCV axes, REP 103) on
``/tf_static``. The ego pose goes on ``/tf`` (map -> base_link), or on ``/ego/pose``
(PoseStamped) or ``/ego/odom`` (Odometry). The scene's structure goes where a car's perception
and map stacks put it: the road users per tick in the ego frame (base_link) on
``/perception/objects`` (vision_msgs/Detection3DArray) or ``/perception/markers``
(visualization_msgs/MarkerArray CUBE markers, ``ns`` = category), the static objects on
``/map/objects`` and the road lines on ``/map/road`` (MarkerArray CUBE and LINE_STRIP markers in
the map frame; a line's ``ns`` is ``KIND`` or ``KIND/PAINT``). Header stamps carry the drive's
times; MCAP log times are the stamps plus ``receive_delay_ns``, as a recorder sees them.
:func:`ros2_topic_map` gives the topic map that reads such a bag back.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mcap_ros2.writer import Writer
from ros2_msgdefs import msgdef

from drivewm.atomic import atomic_path
from drivewm.geometry import R_BODY_FROM_OPENCV, invert_T, make_T
from drivewm.logs.topicmap import CameraTopics, EgoPoseTopic, LayoutTopics, TopicMap
from drivewm.logs.transforms import ns_to_sec_nsec, split_T
from drivewm.logs.types import AgentBox, DriveLog, RoadLine
from drivewm.logs.writer import distortion_model, drive_events

WORLD, EGO = "map", "base_link"
EGO_POSE_TOPICS = {"tf": None, "pose_stamped": "/ego/pose", "odometry": "/ego/odom"}
#: Road users as detections or as markers: their topic and message type.
AGENT_TOPICS = {
    "detections": ("/perception/objects", "vision_msgs/msg/Detection3DArray"),
    "markers": ("/perception/markers", "visualization_msgs/msg/MarkerArray"),
}
STATIC_TOPIC, ROAD_TOPIC = "/map/objects", "/map/road"
_CUBE, _LINE_STRIP = 1, 4
T_LINK_FROM_OPTICAL = make_T(R_BODY_FROM_OPENCV, np.zeros(3))


def _header(timestamp_ns: int, frame_id: str) -> dict:
    sec, nsec = ns_to_sec_nsec(timestamp_ns)
    return {"stamp": {"sec": sec, "nanosec": nsec}, "frame_id": frame_id}


def _pose_fields(T: np.ndarray) -> tuple[dict, dict]:
    t, q = split_T(T)
    return dict(zip("xyz", map(float, t))), dict(zip("xyzw", map(float, q)))


def _transform(timestamp_ns: int, parent: str, child: str, T_parent_from_child: np.ndarray) -> dict:
    translation, rotation = _pose_fields(T_parent_from_child)
    return {
        "header": _header(timestamp_ns, parent),
        "child_frame_id": child,
        "transform": {"translation": translation, "rotation": rotation},
    }


def image_topic(camera: str, raw: bool) -> str:
    return f"/{camera.lower()}/image_raw" + ("" if raw else "/compressed")


def ros2_topic_map(
    log: DriveLog, raw_cameras: tuple[str, ...] = (), ego_pose: str = "tf", agents: str = "detections"
) -> TopicMap:
    """The topic map that reads a bag written by :func:`write_log_ros2` with these options."""
    cameras = {
        c: CameraTopics(image=image_topic(c, c in raw_cameras), calibration=f"/{c.lower()}/camera_info")
        for c in log.rig.names
    }
    pose_topic = EGO_POSE_TOPICS[ego_pose]
    return TopicMap(
        rig_name=log.rig.name,
        cameras=cameras,
        world_frame=WORLD,
        ego_frame=EGO,
        ego_pose=EgoPoseTopic(pose_topic) if pose_topic else None,
        layout=LayoutTopics(agents=AGENT_TOPICS[agents][0], static=STATIC_TOPIC, road=ROAD_TOPIC),
    )


def _static_messages(log: DriveLog, t0: int) -> list[tuple[str, str, dict]]:
    """(topic, datatype, message): camera_info per camera, then the mount chain on /tf_static."""
    out, transforms = [], []
    for cam in log.rig.cameras:
        x = cam.name.lower()
        P = np.concatenate([cam.K, np.zeros((3, 1))], axis=1)
        info = {
            "header": _header(t0, f"{x}_optical_frame"),
            "height": cam.height,
            "width": cam.width,
            "distortion_model": distortion_model(cam.distortion),
            "d": cam.distortion.tolist(),
            "k": cam.K.reshape(-1).tolist(),
            "r": np.eye(3).reshape(-1).tolist(),
            "p": P.reshape(-1).tolist(),
            "binning_x": 0,
            "binning_y": 0,
            "roi": {"x_offset": 0, "y_offset": 0, "height": 0, "width": 0, "do_rectify": False},
        }
        out.append((f"/{x}/camera_info", "sensor_msgs/msg/CameraInfo", info))
        T_ego_from_link = cam.T_ego_from_cam @ invert_T(T_LINK_FROM_OPTICAL)
        transforms.append(_transform(t0, EGO, f"{x}_link", T_ego_from_link))
        transforms.append(_transform(t0, f"{x}_link", f"{x}_optical_frame", T_LINK_FROM_OPTICAL))
    out.append(("/tf_static", "tf2_msgs/msg/TFMessage", {"transforms": transforms}))
    return out


def _image_message(camera: str, ts: int, frame, raw: bool) -> tuple[str, str, dict]:
    header = _header(ts, f"{camera.lower()}_optical_frame")
    if not raw:
        return (
            image_topic(camera, False),
            "sensor_msgs/msg/CompressedImage",
            {"header": header, "format": frame.format, "data": frame.data},
        )
    rgb = frame.decode()
    h, w, _ = rgb.shape
    msg = {
        "header": header,
        "height": h,
        "width": w,
        "encoding": "rgb8",
        "is_bigendian": 0,
        "step": 3 * w,
        "data": rgb.tobytes(),
    }
    return image_topic(camera, True), "sensor_msgs/msg/Image", msg


def _pose_message(ts: int, T: np.ndarray, ego_pose: str) -> tuple[str, str, dict]:
    if ego_pose == "tf":
        return "/tf", "tf2_msgs/msg/TFMessage", {"transforms": [_transform(ts, WORLD, EGO, T)]}
    position, orientation = _pose_fields(T)
    pose = {"position": position, "orientation": orientation}
    if ego_pose == "pose_stamped":
        return EGO_POSE_TOPICS[ego_pose], "geometry_msgs/msg/PoseStamped", {"header": _header(ts, WORLD), "pose": pose}
    zero3, cov = {"x": 0.0, "y": 0.0, "z": 0.0}, [0.0] * 36
    odom = {
        "header": _header(ts, WORLD),
        "child_frame_id": EGO,
        "pose": {"pose": pose, "covariance": cov},
        "twist": {"twist": {"linear": zero3, "angular": zero3}, "covariance": cov},
    }
    return EGO_POSE_TOPICS[ego_pose], "nav_msgs/msg/Odometry", odom


def _box_pose(box: AgentBox, T_frame_from_world: np.ndarray) -> tuple[dict, dict]:
    T_world_from_box = make_T(np.eye(3), box.center_xyz)
    c, s = np.cos(box.yaw_rad), np.sin(box.yaw_rad)
    T_world_from_box[:2, :2] = [[c, -s], [s, c]]
    position, orientation = _pose_fields(T_frame_from_world @ T_world_from_box)
    return {"position": position, "orientation": orientation}, dict(zip("xyz", map(float, box.size_lwh)))


def _marker(header: dict, ns: str, index: int, kind: int, pose: dict, scale: dict, points=(), color=None) -> dict:
    """A visualization_msgs/Marker (ADD) with every field set, as a recorder writes it."""
    zero_time = {"sec": 0, "nanosec": 0}
    r, g, b = color if color is not None else (1.0, 1.0, 1.0)
    return {
        "header": header,
        "ns": ns,
        "id": index,
        "type": kind,
        "action": 0,
        "pose": pose,
        "scale": scale,
        "color": {"r": float(r), "g": float(g), "b": float(b), "a": 1.0},
        "lifetime": zero_time,
        "frame_locked": False,
        "points": [dict(zip("xyz", map(float, p))) for p in points],
        "colors": [],
        "texture_resource": "",
        "texture": {"header": {"stamp": zero_time, "frame_id": ""}, "format": "", "data": b""},
        "uv_coordinates": [],
        "text": "",
        "mesh_resource": "",
        "mesh_file": {"filename": "", "data": b""},
        "mesh_use_embedded_materials": False,
    }


def _cube_markers(ts: int, frame: str, boxes: list[AgentBox], T_frame_from_world: np.ndarray, ids: dict) -> list[dict]:
    """CUBE markers (``ns`` = category, ``id`` = the track's number in ``ids``, kept over ticks)."""
    header = _header(ts, frame)
    return [
        _marker(
            header,
            b.category,
            ids.setdefault(b.track_id, len(ids)),
            _CUBE,
            *_box_pose(b, T_frame_from_world),
            color=b.color_rgb,
        )
        for b in boxes
    ]


def _detections(ts: int, boxes: list[AgentBox], T_ego_from_world: np.ndarray) -> dict:
    header = _header(ts, EGO)
    detections = []
    for b in boxes:
        pose, size = _box_pose(b, T_ego_from_world)
        hypothesis = {
            "hypothesis": {"class_id": b.category, "score": 1.0},
            "pose": {"pose": pose, "covariance": [0.0] * 36},
        }
        detections.append(
            {"header": header, "results": [hypothesis], "bbox": {"center": pose, "size": size}, "id": b.track_id}
        )
    return {"header": header, "detections": detections}


def _road_markers(t0: int, lines: list[RoadLine]) -> dict:
    """One LINE_STRIP marker per line in the map frame (a surface outline is closed by its kind)."""
    header = _header(t0, WORLD)
    identity = {"position": dict.fromkeys("xyz", 0.0), "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
    markers = []
    for i, line in enumerate(lines):
        ns = f"{line.kind}/{line.line_type}" if line.line_type else line.kind
        markers.append(_marker(header, ns, i, _LINE_STRIP, identity, {"x": 0.15, "y": 0.0, "z": 0.0}, line.points_xyz))
    return {"markers": markers}


def _layout_messages(log: DriveLog, t0: int, agents: str) -> list[tuple[int, str, str, dict]]:
    """(time, topic, datatype, message): the static objects and the road once, the road users per tick
    in the ego frame, as perception publishes them (a tick without a finite ego pose has none)."""
    markers, out = "visualization_msgs/msg/MarkerArray", []
    if log.static:
        out.append((t0, STATIC_TOPIC, markers, {"markers": _cube_markers(t0, WORLD, log.static, np.eye(4), {})}))
    if log.road:
        out.append((t0, ROAD_TOPIC, markers, _road_markers(t0, log.road)))
    pose_at = dict(zip(log.pose_timestamps_ns.tolist(), log.T_world_from_ego))
    topic, datatype = AGENT_TOPICS[agents]
    ids: dict[str, int] = {}
    for ts, boxes in log.agents:
        T = pose_at.get(int(ts))
        if T is None or not np.isfinite(T).all():
            continue
        T_ego_from_world = invert_T(T)
        if agents == "markers":
            msg = {"markers": _cube_markers(int(ts), EGO, boxes, T_ego_from_world, ids)}
        else:
            msg = _detections(int(ts), boxes, T_ego_from_world)
        out.append((int(ts), topic, datatype, msg))
    return out


def write_log_ros2(
    log: DriveLog,
    path: str | Path,
    raw_cameras: tuple[str, ...] = (),
    ego_pose: str = "tf",
    receive_delay_ns: int = 0,
    agents: str = "detections",
) -> Path:
    """Write ``log`` as a ROS 2 bag at ``path`` (atomic). ``agents``: the road users as
    ``detections`` (vision_msgs/Detection3DArray) or ``markers`` (visualization_msgs/MarkerArray)."""
    events = [e for e in drive_events(log) if e[1] not in ("agents", "labels")]
    t0 = events[0][0] if events else 0
    messages = [(t0, *m) for m in _static_messages(log, t0)]
    for ts, kind, payload in events:
        if kind == "pose":
            messages.append((ts, *_pose_message(ts, payload[0], ego_pose)))
        else:
            messages.append((ts, *_image_message(payload[0], ts, payload[1], payload[0] in raw_cameras)))
    messages = sorted(messages + _layout_messages(log, t0, agents), key=lambda m: m[0])
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        writer, schemas = Writer(f), {}
        for ts, topic, datatype, msg in messages:
            if datatype not in schemas:
                schemas[datatype] = writer.register_msgdef(datatype, msgdef(datatype))
            writer.write_message(topic, schemas[datatype], msg, log_time=ts + receive_delay_ns)
        writer.finish()
    return Path(path)
