"""Export a drive log as a ROS 2 MCAP bag (CDR), laid out the way a ROS 2 car records one: the
ROS 2 reader's test bags.

Per camera ``X`` (lower-cased name ``x``): ``/x/image_raw/compressed`` (sensor_msgs/CompressedImage)
or ``/x/image_raw`` (sensor_msgs/Image rgb8, for ``raw_cameras``) and ``/x/camera_info``; frames
``base_link -> x_link`` (the mount, x forward) ``-> x_optical_frame`` (OpenCV axes, REP 103) on
``/tf_static``. The ego pose goes on ``/tf`` (map -> base_link), or on ``/ego/pose``
(PoseStamped) or ``/ego/odom`` (Odometry). Header stamps carry the drive's times; MCAP log times
are the stamps plus ``receive_delay_ns``, as a recorder sees them. :func:`ros2_topic_map` gives
the topic map that reads such a bag back.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from mcap_ros2.writer import Writer
from ros2_msgdefs import msgdef

from drivewm.atomic import atomic_path
from drivewm.geometry import R_BODY_FROM_OPENCV, invert_T, make_T
from drivewm.logs.topicmap import CameraTopics, EgoPoseTopic, TopicMap
from drivewm.logs.transforms import ns_to_sec_nsec, split_T
from drivewm.logs.types import DriveLog
from drivewm.logs.writer import distortion_model, drive_events

WORLD, EGO = "map", "base_link"
EGO_POSE_TOPICS = {"tf": None, "pose_stamped": "/ego/pose", "odometry": "/ego/odom"}
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


def ros2_topic_map(log: DriveLog, raw_cameras: tuple[str, ...] = (), ego_pose: str = "tf") -> TopicMap:
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


def write_log_ros2(
    log: DriveLog, path: str | Path, raw_cameras: tuple[str, ...] = (), ego_pose: str = "tf", receive_delay_ns: int = 0
) -> Path:
    """Write ``log`` as a ROS 2 bag at ``path`` (atomic). Agents are not exported (no standard message)."""
    events = [e for e in drive_events(log) if e[1] != "agents"]
    t0 = events[0][0] if events else 0
    messages = [(t0, *m) for m in _static_messages(log, t0)]
    for ts, kind, payload in events:
        if kind == "pose":
            messages.append((ts, *_pose_message(ts, payload[0], ego_pose)))
        else:
            messages.append((ts, *_image_message(payload[0], ts, payload[1], payload[0] in raw_cameras)))
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        writer, schemas = Writer(f), {}
        for ts, topic, datatype, msg in messages:
            if datatype not in schemas:
                schemas[datatype] = writer.register_msgdef(datatype, msgdef(datatype))
            writer.write_message(topic, schemas[datatype], msg, log_time=ts + receive_delay_ns)
        writer.finish()
    return Path(path)
