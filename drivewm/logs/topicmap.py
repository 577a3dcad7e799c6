"""Topic maps: how a fleet log's topics and frames become drivewm cameras and ego poses.

A topic map is a YAML file in ``drivewm/topicmaps/`` (see its README). Without one, the reader
finds cameras by schema (Foxglove: ``foxglove.CompressedImage`` + ``foxglove.CameraCalibration``;
ROS 2: ``sensor_msgs`` images + ``CameraInfo``) and names each camera by its ``frame_id``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from drivewm import resources
from drivewm.config import from_dict, load_yaml
from drivewm.errors import DrivewmError


@dataclasses.dataclass
class CameraTopics:
    """Where one camera lives in the log."""

    image: str
    """Image topic (foxglove.CompressedImage, sensor_msgs/CompressedImage or sensor_msgs/Image)."""
    calibration: str
    """Calibration topic (foxglove.CameraCalibration or sensor_msgs/CameraInfo)."""
    frame: str | None = None
    """TF frame of the (OpenCV-convention) camera; None: the calibration message's frame_id."""


@dataclasses.dataclass
class EgoPoseTopic:
    """A topic carrying the ego pose directly instead of TF."""

    topic: str
    """geometry_msgs/PoseStamped, geometry_msgs/PoseWithCovarianceStamped or nav_msgs/Odometry."""


@dataclasses.dataclass
class LayoutTopics:
    """Where a log keeps the scene's structure (the layout of its clips, drivewm.layout). Each topic
    carries foxglove.SceneUpdate, visualization_msgs/MarkerArray or (road users only)
    vision_msgs/Detection3DArray; objects may be in the world frame, the ego frame or any frame with
    a static transform to the ego."""

    agents: str | None = "/agents"
    """Road users, one message per tick (the boxes of that instant)."""
    static: str | None = "/static"
    """Static objects (buildings, poles, trees, ...), all boxes ever sent."""
    road: str | None = "/road"
    """Road lines (lane centres, lane borders, kerbs, surface outlines): line strips whose kind (and
    paint) a SceneUpdate names in metadata ``kind`` (``line_type``) and a marker in its ``ns``, as
    ``KIND`` or ``KIND/PAINT``."""
    classes: dict[str, str] = dataclasses.field(default_factory=dict)
    """The log's names -> drivewm's: a box category (entity ``category``, marker ``ns``, detection
    ``class_id``) -> a layout class (drivewm.layout.classes), a marker ``ns`` -> ``KIND`` or ``KIND/PAINT``."""


@dataclasses.dataclass
class TopicMap:
    """Mapping of one family of logs (one vehicle/recorder) onto the drivewm drive-log contract."""

    rig_name: str = ""
    """Rig name given to the cameras read (default: the file's own record, or the log's stem)."""
    cameras: dict[str, CameraTopics] = dataclasses.field(default_factory=dict)
    """Camera name -> topics, in rig order. Empty: discover cameras by schema, named by frame_id."""
    world_frame: str | None = None
    """TF frame of the world (default: "world" for Foxglove logs, "map" for ROS 2, REP 105)."""
    ego_frame: str | None = None
    """TF frame of the vehicle (default: "ego" for Foxglove logs, "base_link" for ROS 2)."""
    ego_pose: EgoPoseTopic | None = None
    """Read T_world_from_ego from this topic instead of the world -> ego TF."""
    timestamps: str = "header"
    """"header": message stamps (falling back to log time when zero); "log_time": MCAP log time."""
    tags: dict[str, str] = dataclasses.field(default_factory=dict)
    """Scene tags for logs without a scene channel (e.g. source: fleet); the log's own tags win."""
    description: str = ""
    """Scene description for logs without a scene channel."""
    layout: LayoutTopics = dataclasses.field(default_factory=LayoutTopics)
    """Topics of the road users, static objects and road lines (default: drivewm's /agents, /static, /road)."""
    source: str = dataclasses.field(default="(in code)", init=False)
    """Where the map came from (set by :func:`load_topic_map`), for error messages."""

    def validate(self) -> None:
        if self.timestamps not in ("header", "log_time"):
            raise DrivewmError(f"topic map {self.source}: timestamps must be 'header' or 'log_time'")

    def required_topics(self) -> list[str]:
        """Every topic the map names that must exist in the log."""
        topics = [t for c in self.cameras.values() for t in (c.image, c.calibration)]
        return topics + ([self.ego_pose.topic] if self.ego_pose else [])


def load_topic_map(name_or_path: str | Path) -> TopicMap:
    """Load a topic map by path or by name (``reductstore_demo`` -> drivewm/topicmaps/reductstore_demo.yaml)."""
    path = resources.find("topicmaps", name_or_path, "topic map")
    tmap = from_dict(TopicMap, load_yaml(path), str(path))
    tmap.source = str(path)
    return tmap
