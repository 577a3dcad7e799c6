"""A future's files: its drive log (MCAP with /agents and /road, through LogWriter) and one mp4 per camera."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from drivewm.atomic import write_bytes
from drivewm.clips.video import encode_mp4
from drivewm.logs.types import SceneInfo
from drivewm.logs.writer import LogWriter, encode_image
from drivewm.multiverse.branch import Branch
from drivewm.sim.scene import SceneTick

JPEG_QUALITY = 92


def encode_frames(frames: dict[str, np.ndarray]) -> dict[str, list[bytes]]:
    """JPEG bytes per camera and frame (the past is encoded once and written into every future's log)."""
    return {c: [encode_image(f, "jpeg", JPEG_QUALITY) for f in v] for c, v in frames.items()}


def write_future_log(
    path: Path, branch: Branch, plan_name: str, past_jpeg: dict[str, list[bytes]], future: list[SceneTick], frames
) -> Path:
    """The past and one future as a drive log: poses, road users, road, static objects and images."""
    scene = SceneInfo({**branch.tags, "multiverse_plan": plan_name}, branch.description)
    with LogWriter(path, branch.rig, scene, "jpeg", JPEG_QUALITY) as writer:
        writer.write_road(branch.past[0].timestamp_ns, branch.road.road_lines())
        writer.write_static(branch.past[0].timestamp_ns, branch.road.props)
        for k, tick in enumerate(branch.past):
            for cam, jpegs in past_jpeg.items():
                writer.write_encoded_image(cam, tick.timestamp_ns, jpegs[k], "jpeg")
            _write_state(writer, tick)
        for k, tick in enumerate(future):
            writer.write_images(tick.timestamp_ns, {c: v[k] for c, v in frames.items()})
            _write_state(writer, tick)
    return path


def _write_state(writer: LogWriter, tick: SceneTick) -> None:
    writer.write_pose(tick.timestamp_ns, tick.T_world_from_ego)
    writer.write_agents(tick.timestamp_ns, tick.agents)


def write_camera_videos(folder: Path, frames: dict[str, np.ndarray], fps: float) -> dict[str, str]:
    """One H.264 mp4 per camera (encoded on one thread: the same bytes on every machine); camera -> path."""
    paths = {}
    for cam, video in frames.items():
        paths[cam] = str(folder / f"{cam}.mp4")
        write_bytes(paths[cam], encode_mp4(video, fps, threads=1))
    return paths
