"""Import plain video: a folder of mp4 files + a one-camera calibration YAML -> drive logs.

For single-camera users (dashcams, phone videos). Each ``NAME.mp4`` becomes ``OUT/NAME.mcap``
written by :class:`drivewm.logs.writer.LogWriter`: every decoded frame at its presentation time,
resized to the calibration's image size (the K in the YAML is for that size), and one NaN ego
pose per frame meaning "unknown". Curation then marks the clips' ego motion as unknown and
uses the static-camera filter instead of the ego-motion filter.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import av
import cv2
import numpy as np
from tqdm import tqdm

from drivewm.errors import BatchError, DrivewmError
from drivewm.geometry import Rig, load_rig
from drivewm.logs.types import SceneInfo
from drivewm.logs.writer import LogWriter
from drivewm.paths import child_path, distinct_paths, unique_names

UNKNOWN_TAGS = {
    "weather": "unknown",
    "time_of_day": "unknown",
    "road_type": "unknown",
    "traffic_density": "unknown",
    "source": "video",
}


def list_videos(inputs: list[Path]) -> list[Path]:
    """mp4 files given directly or found (sorted) in given folders."""
    videos: list[Path] = []
    for p in map(Path, inputs):
        if p.is_dir():
            videos += sorted(q for q in p.iterdir() if q.suffix.lower() == ".mp4")
        elif p.is_file():
            videos.append(p)
        else:
            raise DrivewmError(f"{p}: no such video file or folder")
    if not videos:
        raise DrivewmError(f"{[str(p) for p in inputs]}: no .mp4 files found")
    return videos


def import_video(
    video: Path, calibration: str | Path, out_path: Path, tags: dict[str, str] | None = None, description: str = ""
) -> tuple[Path, list[str]]:
    """Write one video as a single-camera drive log; returns ``out_path`` and warnings (one line each)."""
    rig = calibration_rig(calibration)
    cam = rig.cameras[0]
    scene = SceneInfo({**UNKNOWN_TAGS, **(tags or {})}, description or f"imported from {Path(video).name}")
    nan_pose = np.full((4, 4), np.nan)
    stamps = []
    with LogWriter(out_path, rig, scene) as writer:
        for t_ns, rgb in _frames(video):
            if rgb.shape[:2] != (cam.height, cam.width):
                rgb = cv2.resize(rgb, (cam.width, cam.height), interpolation=cv2.INTER_AREA)
            writer.write_image(cam.name, t_ns, rgb)
            writer.write_pose(t_ns, nan_pose)
            stamps.append(t_ns)
        if not stamps:
            raise DrivewmError(f"{video}: no video frames")
    back = int((np.diff(stamps) <= 0).sum())
    warnings = (
        [f"{video}: presentation times go backwards or repeat {back} time(s); curation sorts them"] if back else []
    )
    return Path(out_path), warnings


def calibration_rig(calibration: str | Path) -> Rig:
    """A video calibration YAML: a rig file with exactly one camera."""
    rig = load_rig(calibration)
    if len(rig.cameras) != 1:
        raise DrivewmError(f"{calibration}: a video calibration has exactly one camera, found {rig.names}")
    return rig


def _frames(video: Path):
    """(timestamp_ns from the presentation time, uint8 RGB frame) in display order."""
    try:
        with av.open(str(video)) as container:
            stream = container.streams.video[0]
            for frame in container.decode(stream):
                t = frame.time if frame.time is not None else frame.index / float(stream.average_rate or 25)
                yield int(round(t * 1e9)), frame.to_ndarray(format="rgb24")
    except (av.error.FFmpegError, IndexError, ValueError) as exc:
        raise DrivewmError(f"{video}: cannot decode video ({exc.__class__.__name__})") from None


@dataclasses.dataclass
class ImportReport:
    """What :func:`import_videos` did: ``logs`` written, ``failed`` and ``warnings`` one line each."""

    logs: list[Path]
    failed: list[str]
    warnings: list[str]


def import_videos(
    inputs: list[Path], calibration: str | Path, out_dir: Path, tags: dict[str, str] | None = None
) -> ImportReport:
    """Import every mp4 of ``inputs`` (files or folders) into ``out_dir/NAME.mcap`` (NAME: the file stem
    made a safe name, distinct per video). A video that cannot be imported is skipped and reported;
    when none is, :class:`BatchError` lists them all."""
    calibration_rig(calibration)  # a bad calibration fails the whole batch, before any video
    videos, warnings = distinct_paths(list_videos(inputs))
    names = unique_names([v.stem for v in videos], [str(v.resolve()) for v in videos], "video")
    report = ImportReport([], [], warnings)
    for video, name in tqdm(list(zip(videos, names)), desc="import-video", unit="video"):
        try:
            log, notes = import_video(video, calibration, child_path(out_dir, name, ext="mcap"), tags)
        except DrivewmError as exc:
            report.failed.append(str(exc))
            continue
        report.logs.append(log)
        report.warnings += notes
    if not report.logs:
        raise BatchError(f"import-video: no video could be imported ({len(report.failed)} failed)", report.failed)
    return report
