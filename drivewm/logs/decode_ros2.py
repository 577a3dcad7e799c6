"""ROS 2 messages (CDR, decoded by mcap-ros2-support) -> drivewm values.

Raw ``sensor_msgs/Image`` frames are stored losslessly as PNG so that every :class:`ImageFrame`
holds compressed bytes, as in drivewm's own logs.
"""

from __future__ import annotations

from typing import Any

import cv2
import numpy as np

from drivewm.errors import DrivewmError
from drivewm.logs.transforms import join_T, sec_nsec_to_ns
from drivewm.logs.types import AgentBox, RoadLine

COMPRESSED_IMAGE = ("sensor_msgs/msg/CompressedImage", "sensor_msgs/CompressedImage")
RAW_IMAGE = ("sensor_msgs/msg/Image", "sensor_msgs/Image")
CAMERA_INFO = ("sensor_msgs/msg/CameraInfo", "sensor_msgs/CameraInfo")
TF_MESSAGE = ("tf2_msgs/msg/TFMessage", "tf2_msgs/TFMessage")
POSE_STAMPED = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/PoseStamped")
POSE_COV_STAMPED = ("geometry_msgs/msg/PoseWithCovarianceStamped", "geometry_msgs/PoseWithCovarianceStamped")
ODOMETRY = ("nav_msgs/msg/Odometry", "nav_msgs/Odometry")
POSE_TYPES = POSE_STAMPED + POSE_COV_STAMPED + ODOMETRY

# sensor_msgs/Image encodings -> (channels, OpenCV conversion to BGR for PNG, or None)
_RAW_ENCODINGS = {
    "rgb8": (3, cv2.COLOR_RGB2BGR),
    "bgr8": (3, None),
    "rgba8": (4, cv2.COLOR_RGBA2BGR),
    "bgra8": (4, cv2.COLOR_BGRA2BGR),
    "mono8": (1, None),
}


def stamp_ns(header: Any) -> int:
    """std_msgs/Header stamp -> ns (0 if unset)."""
    return sec_nsec_to_ns(header.stamp.sec, header.stamp.nanosec)


def image_format(format_field: str) -> str:
    """CompressedImage.format ("jpeg", "png", "rgb8; jpeg compressed bgr8", ...) -> "jpeg" | "png"."""
    return "png" if "png" in format_field.lower() else "jpeg"


def compressed_image(msg: Any) -> tuple[str, int, bytes, str]:
    """sensor_msgs/CompressedImage -> (frame_id, stamp_ns, data, "jpeg"|"png")."""
    return msg.header.frame_id, stamp_ns(msg.header), bytes(msg.data), image_format(msg.format)


def raw_image(msg: Any) -> tuple[str, int, bytes, str]:
    """sensor_msgs/Image (rgb8, bgr8, rgba8, bgra8, mono8) -> (frame_id, stamp_ns, PNG bytes, "png")."""
    if msg.encoding not in _RAW_ENCODINGS:
        raise DrivewmError(f"sensor_msgs/Image encoding {msg.encoding!r} is not supported ({sorted(_RAW_ENCODINGS)})")
    channels, conversion = _RAW_ENCODINGS[msg.encoding]
    rows = np.frombuffer(bytes(msg.data), dtype=np.uint8).reshape(msg.height, msg.step)
    pixels = rows[:, : msg.width * channels].reshape(msg.height, msg.width, channels)
    bgr = cv2.cvtColor(pixels, conversion) if conversion is not None else pixels
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(bgr))
    if not ok:
        raise DrivewmError(f"cannot re-encode a {msg.width}x{msg.height} {msg.encoding} image as PNG")
    return msg.header.frame_id, stamp_ns(msg.header), buf.tobytes(), "png"


def camera_info(msg: Any) -> tuple[str, np.ndarray, np.ndarray, int, int]:
    """sensor_msgs/CameraInfo -> (frame_id, K (9,), D (n,), width, height)."""
    return (
        msg.header.frame_id,
        np.asarray(msg.k, dtype=np.float64),
        np.asarray(msg.d, dtype=np.float64),
        int(msg.width),
        int(msg.height),
    )


def tf_message(msg: Any) -> list[tuple[int, str, str, np.ndarray]]:
    """tf2_msgs/TFMessage -> [(stamp_ns, parent, child, T_parent_from_child)]."""
    out = []
    for tf in msg.transforms:
        t, q = tf.transform.translation, tf.transform.rotation
        T = join_T([t.x, t.y, t.z], [q.x, q.y, q.z, q.w])
        out.append((stamp_ns(tf.header), tf.header.frame_id, tf.child_frame_id, T))
    return out


def pose(msg: Any, schema_name: str) -> tuple[int, str, np.ndarray]:
    """PoseStamped / PoseWithCovarianceStamped / Odometry -> (stamp_ns, frame_id, T_frame_from_body)."""
    p = msg.pose if schema_name in POSE_STAMPED else msg.pose.pose
    T = join_T(
        [p.position.x, p.position.y, p.position.z], [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]
    )
    return stamp_ns(msg.header), msg.header.frame_id, T


MARKER_ARRAY = ("visualization_msgs/msg/MarkerArray", "visualization_msgs/MarkerArray")
DETECTION3D_ARRAY = ("vision_msgs/msg/Detection3DArray", "vision_msgs/Detection3DArray")
_CUBE, _LINE_STRIP, _LINE_LIST = 1, 4, 5  # visualization_msgs/Marker types
_ADD = 0  # visualization_msgs/Marker action (DELETE and DELETEALL markers carry nothing to draw)


def _pose_T(p: Any) -> np.ndarray:
    return join_T(
        [p.position.x, p.position.y, p.position.z], [p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]
    )


def _box(
    track_id: str, category: str, T_frame_from_box: np.ndarray, size: Any, color=(0.5, 0.5, 0.5)
) -> tuple[AgentBox, np.ndarray]:
    """(AgentBox in the pose's frame, its length axis (3,) there) from a box pose and its size (x along
    its length): the axis keeps the heading exact when the frame is tilted against the world."""
    R = T_frame_from_box[:3, :3]
    yaw = float(np.arctan2(R[1, 0], R[0, 0]))
    box = AgentBox(track_id, category, T_frame_from_box[:3, 3].copy(), np.array([size.x, size.y, size.z]), yaw, color)
    return box, R[:, 0].copy()


def markers(msg: Any) -> list[tuple[str, int, AgentBox | RoadLine, np.ndarray | None]]:
    """visualization_msgs/MarkerArray -> [(frame_id, stamp_ns, AgentBox or RoadLine, a box's length axis
    or None)]: CUBE markers are
    boxes (category = ``ns``, track id = ``ns/id``), LINE_STRIP markers road lines and each pair of a
    LINE_LIST one two-point line (``ns`` = "KIND" or "KIND/PAINT", e.g. "lane_boundary/dashed"); the
    marker's pose applies to its points. Other types, and DELETE / DELETEALL markers, are skipped."""
    out = []
    for m in msg.markers:
        if m.action != _ADD or m.type not in (_CUBE, _LINE_STRIP, _LINE_LIST):
            continue
        T = _pose_T(m.pose)
        frame, stamp = m.header.frame_id, stamp_ns(m.header)
        if m.type == _CUBE:
            color = (float(m.color.r), float(m.color.g), float(m.color.b))
            out.append((frame, stamp, *_box(f"{m.ns}/{m.id}", m.ns, T, m.scale, color)))
            continue
        kind, _, paint = m.ns.partition("/")
        points = np.array([[p.x, p.y, p.z] for p in m.points], dtype=np.float64).reshape(-1, 3) @ T[:3, :3].T + T[:3, 3]
        pieces = [points] if m.type == _LINE_STRIP else [points[i : i + 2] for i in range(0, len(points) - 1, 2)]
        out += [(frame, stamp, RoadLine(kind, piece, paint), None) for piece in pieces if len(piece) >= 2]
    return out


def detections(msg: Any) -> list[tuple[str, int, AgentBox, np.ndarray]]:
    """vision_msgs/Detection3DArray -> [(frame_id, stamp_ns, AgentBox, its length axis)]: the box of each detection
    (``bbox.center``, ``bbox.size`` as length, width, height), category = the class id of its best
    hypothesis, track id = its ``id``. A detection's own header wins over the array's when it is set."""
    out = []
    for i, d in enumerate(msg.detections):
        header = d.header if d.header.frame_id else msg.header
        best = max(d.results, key=lambda r: r.hypothesis.score, default=None)
        category = best.hypothesis.class_id if best is not None else "unknown"
        out.append(
            (header.frame_id, stamp_ns(header), *_box(d.id or str(i), category, _pose_T(d.bbox.center), d.bbox.size))
        )
    return out
