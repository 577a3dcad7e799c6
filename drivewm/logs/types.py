"""The in-memory drive log every reader returns and every writer takes.

Simulated logs, Foxglove (protobuf or JSON) logs and ROS 2 logs all become the same
:class:`DriveLog`, so curation never knows where a drive came from.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from drivewm.errors import DrivewmError
from drivewm.geometry import Rig
from drivewm.logs.agent_table import AgentBox, AgentTable

#: Scene tag keys every log carries (values are free strings; these are the known ones).
SCENE_TAG_KEYS = ("weather", "time_of_day", "road_type", "traffic_density", "source")
WEATHERS = ("clear", "overcast", "rain", "snow", "fog")
TIMES_OF_DAY = ("day", "dusk", "night")
TRAFFIC_DENSITIES = ("low", "medium", "high")


@dataclasses.dataclass
class ImageFrame:
    """One compressed camera image as stored in the log (``data`` is JPEG or PNG bytes)."""

    timestamp_ns: int
    data: bytes
    format: str = "jpeg"

    def decode(self) -> np.ndarray:
        """The image as uint8 RGB, H x W x 3. Undecodable bytes raise DrivewmError."""
        buf = np.frombuffer(self.data, dtype=np.uint8)
        bgr = cv2.imdecode(buf, cv2.IMREAD_COLOR)
        if bgr is None:
            raise DrivewmError(f"image at {self.timestamp_ns} ns: cannot decode {self.format} data")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


@dataclasses.dataclass
class RoadLine:
    """A piece of static road geometry as a polyline in the world frame (optional in logs).

    ``kind``: lane_center | lane_boundary | road_edge | road_surface; ``line_type``: how it is
    painted (solid, dashed, none; "" where it does not apply); ``points_xyz`` (N, 3) metres. A
    ``road_surface`` is the closed outline of a paved polygon (the last point joins the first; the
    union of a log's surfaces is its paved area).
    """

    kind: str
    points_xyz: np.ndarray
    line_type: str = ""


@dataclasses.dataclass
class SceneInfo:
    """The scene channel: tags (weather, time_of_day, road_type, traffic_density, source, ...)
    and a free-text description."""

    tags: dict[str, str]
    description: str = ""


@dataclasses.dataclass
class DriveLog:
    """One drive, as read from (or to be written to) one MCAP file.

    ``rig``: calibration of every camera (K, size, distortion, static ``T_ego_from_cam``), in
    the log's camera order. ``images``: camera name -> frames sorted by ``timestamp_ns``.
    ``pose_timestamps_ns`` (N,) int64 and ``T_world_from_ego`` (N, 4, 4): the per-tick ego pose.
    ``agents``: optional (timestamp_ns, boxes) per tick: the other road users (simulated logs have them).
    ``road``: optional static road polylines (lane centres, boundaries, edges, surface outlines).
    ``static``: optional static objects as boxes (buildings, poles, lamps, tree trunks and crowns).
    ``warnings``: what the reader repaired or left out (e.g. frames sorted back into time order), one
    line each; curation reports them per log.
    ``labels``: optional label maps, camera name -> grey PNG frames (drivewm.layout.labels) sorted by
    ``timestamp_ns``, each at the time of the image it labels; ``label_classes`` the names of their ids.
    """

    path: str
    rig: Rig
    images: dict[str, list[ImageFrame]]
    pose_timestamps_ns: np.ndarray
    T_world_from_ego: np.ndarray
    scene: SceneInfo
    agents: list[tuple[int, list[AgentBox]]] = dataclasses.field(default_factory=list)
    road: list[RoadLine] = dataclasses.field(default_factory=list)
    warnings: list[str] = dataclasses.field(default_factory=list)
    static: list[AgentBox] = dataclasses.field(default_factory=list)
    labels: dict[str, list[ImageFrame]] = dataclasses.field(default_factory=dict)
    label_classes: tuple[str, ...] = ()

    @property
    def camera_names(self) -> list[str]:
        return self.rig.names

    def validate(self) -> None:
        """Raise DrivewmError naming the file if the log breaks the contract."""
        counts = {n: len(f) for n, f in self.images.items()}
        _check_contract(self.path, self.rig, counts, self.pose_timestamps_ns, self.T_world_from_ego)


@dataclasses.dataclass
class LogIndex:
    """A drive without its image payloads: what a streaming reader knows before the images.

    As :class:`DriveLog`, but ``image_timestamps_ns``: camera name -> (M,) int64 timestamps of its
    images in log (arrival) order, where DriveLog has the frames; and the road users as columns
    (``agents``, in the world frame). ``agents``, ``road`` and ``static`` are filled when the index
    was asked for them (``LogStream.index(layout=True)``). ``label_timestamps_ns``: camera name -> (L,)
    int64 timestamps of its label maps (always; empty without labels), ``label_classes`` their ids' names.
    """

    path: str
    rig: Rig
    image_timestamps_ns: dict[str, np.ndarray]
    pose_timestamps_ns: np.ndarray
    T_world_from_ego: np.ndarray
    scene: SceneInfo
    road: list[RoadLine] = dataclasses.field(default_factory=list)
    warnings: list[str] = dataclasses.field(default_factory=list)
    """What the reader repaired or left out, one line each (as :class:`DriveLog`)."""
    static: list[AgentBox] = dataclasses.field(default_factory=list)
    agents: AgentTable | None = None
    label_timestamps_ns: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)
    label_classes: tuple[str, ...] = ()

    @property
    def has_layout(self) -> bool:
        """Whether the log knows any of the scene's structure (road users, static objects, road lines)."""
        return bool(self.road or self.static or (self.agents is not None and len(self.agents)))

    def validate(self) -> None:
        """Raise DrivewmError naming the file if the log breaks the contract."""
        counts = {n: len(t) for n, t in self.image_timestamps_ns.items()}
        _check_contract(self.path, self.rig, counts, self.pose_timestamps_ns, self.T_world_from_ego)


def _check_contract(
    path: str, rig: Rig, image_counts: dict[str, int], pose_timestamps_ns: np.ndarray, T_world_from_ego: np.ndarray
) -> None:
    """Images of some calibrated camera, none of an uncalibrated one, and (N, 4, 4) ego poses, N > 0."""
    if not any(image_counts.get(n) for n in rig.names):
        raise DrivewmError(f"{path}: log has no camera images")
    for name in image_counts:
        if name not in rig.names:
            raise DrivewmError(f"{path}: images for camera {name!r} without calibration")
    if len(pose_timestamps_ns) == 0:
        raise DrivewmError(f"{path}: log has no ego poses (T_world_from_ego)")
    if T_world_from_ego.shape != (len(pose_timestamps_ns), 4, 4):
        raise DrivewmError(f"{path}: ego pose array has shape {T_world_from_ego.shape}")
