"""Write drive logs as MCAP with the Foxglove SDK (protobuf Foxglove schemas, docs/DESIGN.md section 4).

Topics (see :mod:`drivewm.logs.names`): ``/CAMERA/image`` (foxglove.CompressedImage, frame_id =
camera), ``/CAMERA/calibration`` (foxglove.CameraCalibration), ``/tf_static`` (FrameTransforms
ego -> CAMERA, i.e. ``T_ego_from_cam``), ``/tf`` (FrameTransforms world -> ego per tick, i.e.
``T_world_from_ego``), ``/scene`` (JSON tags + description), ``/agents`` (foxglove.SceneUpdate cubes) and, optionally,
``/road`` (foxglove.SceneUpdate line strips, and line loops for the road surface outlines) and ``/static``
(foxglove.SceneUpdate cubes of the static objects, logged once).
Every message's MCAP log time is its ``timestamp_ns``. Static messages (calibration, tf_static,
scene) are logged at the first timestamp the writer sees.

Each writer owns a private ``foxglove.Context``, so several logs can be written at once in one
process, and writes to a temporary name that is renamed onto ``path`` on a clean close.
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path

import cv2
import foxglove
import numpy as np
from foxglove import channels, messages
from foxglove.mcap import MCAPCompression, MCAPWriteOptions

from drivewm.atomic import atomic_path, discard_held, finish_held
from drivewm.errors import DrivewmError
from drivewm.geometry import Camera, Rig
from drivewm.layout.labels import label_png
from drivewm.logs import names
from drivewm.logs.transforms import ns_to_sec_nsec, quat_xyzw_from_yaw, split_T
from drivewm.logs.types import AgentBox, DriveLog, RoadLine, SceneInfo

IMAGE_FORMATS = ("jpeg", "png")
SCENE_JSON_SCHEMA = {
    "type": "object",
    "title": names.SCENE_SCHEMA_NAME,
    "properties": {
        "tags": {"type": "object", "additionalProperties": {"type": "string"}},
        "description": {"type": "string"},
    },
}


class LogWriter:
    """Write one drive to ``path`` (atomic: temp name, renamed on close).

    ``rig``: the cameras (their order is kept in the file's ``drivewm`` metadata record).
    ``scene``: tags + description for the ``/scene`` channel. ``image_format``: "jpeg" or "png"
    for :meth:`write_images`; ``jpeg_quality``: OpenCV JPEG quality 0-100. ``label_classes``: the
    log carries label maps (:meth:`write_labels`) with ids of these classes (a metadata record).
    Use as a context manager; leaving the block on an exception discards the file.
    """

    def __init__(
        self,
        path: str | Path,
        rig: Rig,
        scene: SceneInfo,
        image_format: str = "jpeg",
        jpeg_quality: int = 92,
        label_classes: tuple[str, ...] = (),
    ):
        if image_format not in IMAGE_FORMATS:
            raise DrivewmError(f"{path}: image_format must be one of {IMAGE_FORMATS}, got {image_format!r}")
        self.path = Path(path)
        self.rig, self.scene = rig, scene
        self.image_format, self.jpeg_quality = image_format, int(jpeg_quality)
        self.label_classes = tuple(label_classes)
        self._stack = contextlib.ExitStack()
        tmp = self._stack.enter_context(atomic_path(self.path))
        try:
            self._open(tmp)
        except BaseException as exc:  # e.g. a full disk: the temporary goes, the error names the log
            with contextlib.suppress(Exception):  # a writer left open panics when the interpreter exits
                self._mcap.close()
            discard_held(self._stack, exc)
        self._static_written = False
        self._closed = False

    # ------------------------------------------------------------------ set-up

    def _open(self, tmp: Path) -> None:
        self._ctx = foxglove.Context()
        # LZ4: the payload is mostly JPEG/PNG, which no codec shrinks; LZ4 costs least (bench_logs.py).
        options = MCAPWriteOptions(compression=MCAPCompression.Lz4, compression_threads=0)
        self._mcap = foxglove.open_mcap(tmp, context=self._ctx, writer_options=options)
        ctx = self._ctx
        self._image_ch = {
            c.name: channels.CompressedImageChannel(names.image_topic(c.name), context=ctx) for c in self.rig.cameras
        }
        self._calib_ch = {
            c.name: channels.CameraCalibrationChannel(names.calibration_topic(c.name), context=ctx)
            for c in self.rig.cameras
        }
        self._tf_static_ch = channels.FrameTransformsChannel(names.TF_STATIC_TOPIC, context=ctx)
        self._tf_ch = channels.FrameTransformsChannel(names.TF_TOPIC, context=ctx)
        self._agents_ch = channels.SceneUpdateChannel(names.AGENTS_TOPIC, context=ctx)
        self._road_ch = channels.SceneUpdateChannel(names.ROAD_TOPIC, context=ctx)
        self._static_ch = channels.SceneUpdateChannel(names.STATIC_TOPIC, context=ctx)
        schema = foxglove.Schema(
            name=names.SCENE_SCHEMA_NAME, encoding="jsonschema", data=json.dumps(SCENE_JSON_SCHEMA).encode()
        )
        self._scene_ch = foxglove.Channel(names.SCENE_TOPIC, schema=schema, message_encoding="json", context=ctx)
        self._mcap.write_metadata(names.METADATA_NAME, {"rig": self.rig.name, "cameras": ",".join(self.rig.names)})
        self._labels_ch = {}
        if self.label_classes:
            self._labels_ch = {
                c.name: channels.CompressedImageChannel(names.labels_topic(c.name), context=ctx)
                for c in self.rig.cameras
            }
            self._mcap.write_metadata(names.LABELS_METADATA_NAME, {"classes": ",".join(self.label_classes)})

    def _timestamp(self, timestamp_ns: int):
        sec, nsec = ns_to_sec_nsec(timestamp_ns)
        return messages.Timestamp(sec, nsec)

    def _ensure_static(self, timestamp_ns: int) -> None:
        """Log calibration, tf_static and scene once, at the first timestamp seen."""
        if self._static_written:
            return
        self._static_written = True
        for cam in self.rig.cameras:
            self._calib_ch[cam.name].log(self._calibration_msg(cam, timestamp_ns), log_time=timestamp_ns)
        statics = [
            self._transform_msg(timestamp_ns, names.EGO_FRAME, c.name, c.T_ego_from_cam) for c in self.rig.cameras
        ]
        self._tf_static_ch.log(messages.FrameTransforms(transforms=statics), log_time=timestamp_ns)
        scene = {"tags": dict(self.scene.tags), "description": self.scene.description}
        self._scene_ch.log(scene, log_time=timestamp_ns)

    # ------------------------------------------------------------------ messages

    def _calibration_msg(self, cam: Camera, timestamp_ns: int):
        P = np.concatenate([cam.K, np.zeros((3, 1))], axis=1)
        return messages.CameraCalibration(
            timestamp=self._timestamp(timestamp_ns),
            frame_id=cam.name,
            width=cam.width,
            height=cam.height,
            distortion_model=distortion_model(cam.distortion),
            D=[float(v) for v in cam.distortion],
            K=[float(v) for v in cam.K.reshape(-1)],
            R=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
            P=[float(v) for v in P.reshape(-1)],
        )

    def _transform_msg(self, timestamp_ns: int, parent: str, child: str, T_parent_from_child: np.ndarray):
        t, q = split_T(T_parent_from_child)
        return messages.FrameTransform(
            timestamp=self._timestamp(timestamp_ns),
            parent_frame_id=parent,
            child_frame_id=child,
            translation=messages.Vector3(x=float(t[0]), y=float(t[1]), z=float(t[2])),
            rotation=messages.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
        )

    def _cube_entity(self, timestamp_ns: int, box: AgentBox):
        m = messages
        c, s, q = box.center_xyz, box.size_lwh, quat_xyzw_from_yaw(box.yaw_rad)
        pose = m.Pose(
            position=m.Vector3(x=float(c[0]), y=float(c[1]), z=float(c[2])),
            orientation=m.Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
        )
        r, g, b = (float(v) for v in box.color_rgb)
        cube = m.CubePrimitive(
            pose=pose, size=m.Vector3(x=float(s[0]), y=float(s[1]), z=float(s[2])), color=m.Color(r=r, g=g, b=b, a=1.0)
        )
        meta = [m.KeyValuePair(key="category", value=box.category)]
        return m.SceneEntity(
            timestamp=self._timestamp(timestamp_ns),
            frame_id=names.WORLD_FRAME,
            id=box.track_id,
            cubes=[cube],
            metadata=meta,
        )

    def _line_entity(self, timestamp_ns: int, index: int, line: RoadLine):
        m = messages
        points = [m.Point3(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in line.points_xyz]
        closed = line.kind == "road_surface"  # a polygon outline: the last point joins the first
        primitive = m.LinePrimitive(
            type=m.LinePrimitiveLineType.LineLoop if closed else m.LinePrimitiveLineType.LineStrip,
            thickness=0.15,
            points=points,
            color=m.Color(r=1.0, g=1.0, b=1.0, a=1.0),
        )
        meta = [m.KeyValuePair(key="kind", value=line.kind), m.KeyValuePair(key="line_type", value=line.line_type)]
        return m.SceneEntity(
            timestamp=self._timestamp(timestamp_ns),
            frame_id=names.WORLD_FRAME,
            id=f"{line.kind}/{index}",
            lines=[primitive],
            metadata=meta,
        )

    # ------------------------------------------------------------------ public API

    def write_image(self, camera: str, timestamp_ns: int, image: np.ndarray) -> None:
        """Encode one camera's uint8 RGB H x W x 3 image (the rig's size) and log it."""
        cam = self.rig.camera(camera)
        image = np.asarray(image)
        if image.dtype != np.uint8 or image.shape != (cam.height, cam.width, 3):
            raise DrivewmError(
                f"{self.path}: image for {camera} must be uint8 ({cam.height}, {cam.width}, 3), got {image.dtype} "
                f"{image.shape}"
            )
        self.write_encoded_image(
            camera, timestamp_ns, encode_image(image, self.image_format, self.jpeg_quality), self.image_format
        )

    def write_images(self, timestamp_ns: int, images: dict[str, np.ndarray]) -> None:
        """Log one image per camera name (uint8 RGB H x W x 3) at ``timestamp_ns``."""
        for camera, image in images.items():
            self.write_image(camera, timestamp_ns, image)

    def write_encoded_image(
        self, camera: str, timestamp_ns: int, data: bytes, format: str, log_time_ns: int | None = None
    ) -> None:
        """Log already-compressed image bytes (``format`` "jpeg" or "png") unchanged. ``log_time_ns``:
        the MCAP log time when the recorder's clock differs from the image stamp (default: the stamp)."""
        if camera not in self._image_ch:
            raise DrivewmError(f"{self.path}: camera {camera!r} is not in rig {self.rig.name} ({self.rig.names})")
        self._ensure_static(timestamp_ns)
        msg = messages.CompressedImage(
            timestamp=self._timestamp(timestamp_ns), frame_id=camera, data=bytes(data), format=format
        )
        self._image_ch[camera].log(msg, log_time=int(timestamp_ns if log_time_ns is None else log_time_ns))

    def write_label_png(self, camera: str, timestamp_ns: int, png: bytes) -> None:
        """Log one camera's label map (grey PNG bytes, drivewm.layout.labels) for its image at ``timestamp_ns``."""
        if camera not in self._labels_ch:
            raise DrivewmError(
                f"{self.path}: no label channel for camera {camera!r} (open the writer with label_classes)"
            )
        self._ensure_static(timestamp_ns)
        msg = messages.CompressedImage(
            timestamp=self._timestamp(timestamp_ns), frame_id=camera, data=bytes(png), format="png"
        )
        self._labels_ch[camera].log(msg, log_time=int(timestamp_ns))

    def write_labels(self, timestamp_ns: int, labels: dict[str, np.ndarray]) -> None:
        """Log one label map (H, W) uint8 per camera name at ``timestamp_ns``."""
        for camera, label_map in labels.items():
            self.write_label_png(camera, timestamp_ns, label_png(label_map))

    def write_pose(self, timestamp_ns: int, T_world_from_ego: np.ndarray, log_time_ns: int | None = None) -> None:
        """Log the ego pose (4x4, NaN allowed for a gap) as a world -> ego FrameTransform (``log_time_ns``
        as for :meth:`write_encoded_image`)."""
        self._ensure_static(timestamp_ns)
        tf = self._transform_msg(timestamp_ns, names.WORLD_FRAME, names.EGO_FRAME, T_world_from_ego)
        log_time = int(timestamp_ns if log_time_ns is None else log_time_ns)
        self._tf_ch.log(messages.FrameTransforms(transforms=[tf]), log_time=log_time)

    def write_agents(self, timestamp_ns: int, boxes: list[AgentBox]) -> None:
        """Log the other road users at one tick: the scene is replaced (delete all, then cubes)."""
        self._ensure_static(timestamp_ns)
        m = messages
        deletion = m.SceneEntityDeletion(timestamp=self._timestamp(timestamp_ns), type=m.SceneEntityDeletionType.All)
        update = m.SceneUpdate(deletions=[deletion], entities=[self._cube_entity(timestamp_ns, b) for b in boxes])
        self._agents_ch.log(update, log_time=int(timestamp_ns))

    def write_road(self, timestamp_ns: int, lines: list[RoadLine]) -> None:
        """Log the static road polylines once (optional; viewers draw them)."""
        self._ensure_static(timestamp_ns)
        update = messages.SceneUpdate(
            entities=[self._line_entity(timestamp_ns, i, line) for i, line in enumerate(lines)]
        )
        self._road_ch.log(update, log_time=int(timestamp_ns))

    def write_static(self, timestamp_ns: int, boxes: list[AgentBox]) -> None:
        """Log the static objects (buildings, poles, trees, ...) once as cubes (optional)."""
        self._ensure_static(timestamp_ns)
        update = messages.SceneUpdate(entities=[self._cube_entity(timestamp_ns, b) for b in boxes])
        self._static_ch.log(update, log_time=int(timestamp_ns))

    def close(self) -> Path:
        """Finish the MCAP file and rename it onto ``path``."""
        if not self._closed:
            self._closed = True
            finish_held(self._stack, lambda: (self._ensure_static(0), self._mcap.close()))
        return self.path

    def abort(self, exc: BaseException | None = None) -> None:
        """Stop writing and discard the file (``path`` is left as it was); with ``exc`` (what stopped the writing),
        raise it again (as a storage OSError naming the path when the disk is full: drivewm.atomic.finish_held)."""
        if not self._closed:
            self._closed = True
            with contextlib.suppress(Exception):  # a full disk fails this too; the file is discarded anyway
                self._mcap.close()
            if exc is None:
                self._stack.__exit__(DrivewmError, DrivewmError("aborted"), None)
            else:
                discard_held(self._stack, exc)

    def __enter__(self) -> LogWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort(exc)


def distortion_model(distortion: np.ndarray) -> str:
    """ROS/Foxglove name of OpenCV coefficients: plumb_bob (k1 k2 p1 p2 k3) or rational_polynomial (8)."""
    return "rational_polynomial" if len(distortion) > 5 else "plumb_bob"


def encode_image(image_rgb: np.ndarray, image_format: str = "jpeg", jpeg_quality: int = 92) -> bytes:
    """uint8 RGB H x W x 3 -> JPEG or PNG bytes (OpenCV)."""
    bgr = cv2.cvtColor(image_rgb, cv2.COLOR_RGB2BGR)
    ext, params = (".jpg", [cv2.IMWRITE_JPEG_QUALITY, int(jpeg_quality)]) if image_format == "jpeg" else (".png", [])
    ok, buf = cv2.imencode(ext, bgr, params)
    if not ok:
        raise DrivewmError(f"cannot encode image of shape {image_rgb.shape} as {image_format}")
    return buf.tobytes()


def drive_events(log: DriveLog) -> list[tuple[int, str, tuple]]:
    """A DriveLog as time-ordered (timestamp_ns, kind, payload) events for a writer:
    ("pose", (T_world_from_ego,)), ("agents", (boxes,)), ("labels", (camera, ImageFrame)), ("image",
    (camera, ImageFrame)); at equal times poses come first, then agents, then label maps, then images."""
    rank = {"pose": 0, "agents": 1, "labels": 2, "image": 3}
    events = [(int(ts), "pose", (T,)) for ts, T in zip(log.pose_timestamps_ns, log.T_world_from_ego)]
    events += [(int(ts), "agents", (boxes,)) for ts, boxes in log.agents]
    events += [(int(f.timestamp_ns), "labels", (cam, f)) for cam, frames in log.labels.items() for f in frames]
    events += [(int(f.timestamp_ns), "image", (cam, f)) for cam, frames in log.images.items() for f in frames]
    return sorted(events, key=lambda e: (e[0], rank[e[1]]))


def write_log(log: DriveLog, path: str | Path) -> Path:
    """Write an in-memory :class:`DriveLog` to ``path``; images are copied as stored (no re-encoding)."""
    with LogWriter(path, log.rig, log.scene, label_classes=log.label_classes) as w:
        events = drive_events(log)
        if log.road:
            w.write_road(events[0][0] if events else 0, log.road)
        if log.static:
            w.write_static(events[0][0] if events else 0, log.static)
        for ts, kind, payload in events:
            if kind == "pose":
                w.write_pose(ts, payload[0])
            elif kind == "agents":
                w.write_agents(ts, payload[0])
            elif kind == "labels":
                w.write_label_png(payload[0], ts, payload[1].data)
            else:
                w.write_encoded_image(payload[0], ts, payload[1].data, payload[1].format)
    return Path(path)
