"""A drive log as a Rerun recording (``.rrd``), in the spirit of Rerun's nuScenes example.

Entity tree (world z up; timeline ``log_time`` = the log's ``timestamp_ns``):

- ``world``: view coordinates right-hand z-up (static);
- ``world/ego``: ``T_world_from_ego`` per tick (Transform3D; NaN gaps are skipped);
- ``world/ego/CAMERA``: ``T_ego_from_cam`` (static Transform3D) + Pinhole (K, size, OpenCV
  RDF axes; static) + the camera's images (EncodedImage per frame, stored bytes, not decoded);
- ``world/ego/CAMERA/labels``: the camera's label maps, if the log has them (SegmentationImage per
  frame, class names and colours from the static AnnotationContext on ``world``);
- ``world/ego_trajectory``: the ego path as line strips (static; split at pose gaps);
- ``world/agents``: the other road users per tick (Boxes3D, labelled category:id);
- ``world/static``: the static objects (buildings, poles, trees, ...) if the log has them (static Boxes3D);
- ``world/road/KIND``: the road polylines of each kind, if the log has them (static; a
  ``road_surface`` outline is drawn closed);
- ``scene``: the tags and description (static TextDocument).

The log is streamed (:class:`drivewm.logs.reader.LogStream`): images go to the recording one
message at a time, so an hour-long log needs no more memory than its index (the agent boxes are
kept as columns, :mod:`drivewm.logs.agent_table`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import rerun as rr

from drivewm.atomic import atomic_path
from drivewm.errors import DrivewmError
from drivewm.layout.labels import labels_from_png
from drivewm.logs.reader import LogStream
from drivewm.logs.transforms import quat_xyzw_from_yaw
from drivewm.logs.types import LogIndex

TIMELINE = "log_time"  # the MCAP log time; Rerun's own wall-clock "log_time"/"log_tick" are switched off
MEDIA_TYPES = {"jpeg": "image/jpeg", "png": "image/png"}
#: Colours of the label classes (drivewm.layout.classes.LABEL_CLASSES), Cityscapes-like.
LABEL_RGB = {
    "sky": (70, 130, 180),
    "road": (128, 64, 128),
    "lane_paint": (255, 255, 255),
    "sidewalk": (244, 35, 232),
    "kerb": (196, 196, 196),
    "terrain": (152, 251, 152),
    "vehicle": (0, 0, 142),
    "pedestrian": (220, 20, 60),
    "building": (70, 70, 70),
    "vegetation": (107, 142, 35),
    "pole": (153, 153, 153),
    "barrier": (190, 153, 153),
    "sign": (220, 220, 0),
}
ROAD_COLORS = {
    "lane_center": [80, 160, 255],
    "lane_boundary": [255, 255, 255],
    "road_edge": [255, 120, 0],
    "road_surface": [110, 110, 120],
}


def _set_time(rec, timestamp_ns: int) -> None:
    rec.set_time(TIMELINE, timestamp=np.datetime64(int(timestamp_ns), "ns"))


def log_static(rec, log: LogIndex) -> None:
    """World axes, camera mounts and pinholes, ego trajectory, scene text."""
    rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
    if log.label_classes:
        classes = [
            rr.ClassDescription(info=(i, name, LABEL_RGB.get(name, (255, 255, 255))))
            for i, name in enumerate(log.label_classes)
        ]
        rec.log("world", rr.AnnotationContext(classes), static=True)
    for cam in log.rig.cameras:
        T = cam.T_ego_from_cam
        rec.log(f"world/ego/{cam.name}", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]), static=True)
        pinhole = rr.Pinhole(
            image_from_camera=cam.K, resolution=[cam.width, cam.height], camera_xyz=rr.ViewCoordinates.RDF
        )
        rec.log(f"world/ego/{cam.name}", pinhole, static=True)
    rec.log(
        "world/ego_trajectory",
        rr.LineStrips3D(trajectory_strips(log.T_world_from_ego), colors=[[255, 200, 0]]),
        static=True,
    )
    for kind in sorted({line.kind for line in log.road}):
        strips = [_strip(line) for line in log.road if line.kind == kind]
        rec.log(
            f"world/road/{kind}", rr.LineStrips3D(strips, colors=[ROAD_COLORS.get(kind, [200, 200, 200])]), static=True
        )
    if log.static:
        rec.log("world/static", _boxes(log.static), static=True)
    tags = "\n".join(f"- **{k}**: {v}" for k, v in log.scene.tags.items())
    rec.log(
        "scene", rr.TextDocument(f"{tags}\n\n{log.scene.description}", media_type=rr.MediaType.MARKDOWN), static=True
    )


def _strip(line) -> np.ndarray:
    """A road polyline's points (N, 3); a surface outline closed by repeating its first point."""
    if line.kind == "road_surface" and len(line.points_xyz):
        return np.concatenate([line.points_xyz, line.points_xyz[:1]])
    return line.points_xyz


def trajectory_strips(T_world_from_ego: np.ndarray) -> list[np.ndarray]:
    """Ego positions (N, 3) split into runs of finite poses (runs of one point are dropped)."""
    xyz = T_world_from_ego[:, :3, 3] if len(T_world_from_ego) else np.zeros((0, 3))
    finite = np.isfinite(xyz).all(axis=1)
    breaks = np.flatnonzero(~finite)
    runs = np.split(np.arange(len(xyz)), breaks)
    return [xyz[r[finite[r]]] for r in runs if finite[r].sum() > 1]


def log_ticks(rec, log: LogIndex, stream: LogStream) -> dict[str, int]:
    """Ego poses and agent boxes (from the index, placed in the world frame), then the images as
    streamed, on the ``log_time`` timeline; returns how many images and agent ticks were logged."""
    for ts, T in zip(log.pose_timestamps_ns, log.T_world_from_ego):
        if np.all(np.isfinite(T)):
            _set_time(rec, ts)
            rec.log("world/ego", rr.Transform3D(translation=T[:3, 3], mat3x3=T[:3, :3]))
    agents = log.agents.as_messages() if log.agents is not None else []
    for ts, boxes in agents:
        _set_time(rec, ts)
        rec.log("world/agents", _boxes(boxes))
    counts = {"image": 0, "agents": len(agents)}
    for kind, (name, frame) in stream.stream(("image", "labels") if log.label_classes else ("image",)):
        counts[kind] = counts.get(kind, 0) + 1
        _set_time(rec, frame.timestamp_ns)
        if kind == "labels":
            rec.log(f"world/ego/{name}/labels", rr.SegmentationImage(labels_from_png(frame.data, f"{name} labels")))
        else:
            media = MEDIA_TYPES.get(frame.format)
            rec.log(f"world/ego/{name}", rr.EncodedImage(contents=frame.data, media_type=media))
    return counts


def _boxes(boxes):
    if not boxes:
        return rr.Boxes3D(centers=np.zeros((0, 3)), sizes=np.zeros((0, 3)))
    return rr.Boxes3D(
        centers=np.stack([b.center_xyz for b in boxes]),
        sizes=np.stack([b.size_lwh for b in boxes]),
        quaternions=[rr.Quaternion(xyzw=quat_xyzw_from_yaw(b.yaw_rad)) for b in boxes],
        colors=np.array([b.color_rgb for b in boxes], dtype=np.float32),
        labels=[f"{b.category}:{b.track_id}" for b in boxes],
    )


def write_recording(stream: LogStream, out_path: str | Path) -> tuple[dict[str, int], list[str]]:
    """Write the streamed log as a Rerun recording at ``out_path`` (atomic); returns the counts of
    cameras, images, poses and agent ticks, and the reader's warnings about the log."""
    out_path = Path(out_path)
    if out_path.resolve() in {f.resolve() for f in stream.files}:  # the rename had replaced the log itself
        raise DrivewmError(f"{out_path}: is the drive log being read; write the recording elsewhere")
    log = stream.index(require_images=False, layout=True)
    with atomic_path(out_path) as tmp:
        rec = rr.RecordingStream("drivewm", recording_id=Path(log.path).stem)
        rec.set_log_time_enabled(False)  # else Rerun stamps every row with the wall clock under the same name
        rec.set_log_tick_enabled(False)
        rec.save(tmp)
        log_static(rec, log)
        counts = log_ticks(rec, log, stream)
        rec.flush()
        rec.disconnect()
    return {"cameras": len(log.rig.cameras), "poses": len(log.pose_timestamps_ns), **counts}, list(log.warnings)
