"""Writing multi-view samples: clips in the clip format (so ``drivewm eval`` scores them directly),
a grid mp4 of all views per sample, and a contact sheet laid out as curation's (a row per camera in
rig order, first/middle/last frame, the caption above), so generated and real sheets compare row for row.

Each generated clip carries its rig (at the decoded image size), per-view captions, the
conditioned trajectory (``trajectory_ego``, ``trajectory_dt_s``), as ego poses that trajectory
integrated at the video frame rate, and as scene ``tags`` the weather and time of day its prompt
names (``drivewm.text.conditions.caption_conditions``; so ``drivewm eval`` scores adherence to them,
as it does for curated clips' tags).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
from einops import rearrange

from drivewm.atomic import write_bytes
from drivewm.clips.format import clip_from_arrays
from drivewm.clips.shards import ShardWriter, write_manifest
from drivewm.clips.video import encode_mp4
from drivewm.curate.contact_sheet import write_clips_sheet
from drivewm.diffusion.generate import clip_meta
from drivewm.geometry import Rig
from drivewm.multiview.cross_view import viewing_azimuth_rad
from drivewm.multiview.trajectories import poses_from_waypoints
from drivewm.text.conditions import caption_conditions


@dataclasses.dataclass
class GeneratedSample:
    """One generated clip: ``videos`` uint8 (V, T, H, W, 3) in rig order and what conditioned it."""

    videos: np.ndarray
    rig: Rig
    caption: str
    view_captions: list[str]
    trajectory_ego: np.ndarray
    trajectory_dt_s: float
    extra: dict


def grid_layout(rig: Rig) -> list[list[int]]:
    """View indices per row of the grid video: one row for up to 3 cameras; otherwise the forward-
    facing cameras on top (left to right as a driver sees them) and the others below (as seen looking back)."""
    az = viewing_azimuth_rad(rig)
    order = sorted(range(len(az)), key=lambda i: -az[i])
    if len(az) <= 3:
        return [order]
    front = [i for i in order if abs(az[i]) <= np.pi / 2]
    back = sorted((i for i in range(len(az)) if abs(az[i]) > np.pi / 2), key=lambda i: az[i] % (2 * np.pi))
    return [row for row in (front, back) if row]


def tile_views(videos: np.ndarray, layout: list[list[int]]) -> np.ndarray:
    """uint8 (V, T, H, W, 3) -> (T, rows*H, cols*W, 3), views placed by ``layout`` (black where empty)."""
    v, t, h, w, _ = videos.shape
    cols = max(len(row) for row in layout)
    grid = np.zeros((len(layout), cols, t, h, w, 3), dtype=np.uint8)
    for r, row in enumerate(layout):
        for c, view in enumerate(row):
            grid[r, c] = videos[view]
    return rearrange(grid, "r c t h w x -> t (r h) (c w) x")


def write_samples(
    out_dir: str | Path, samples: list[GeneratedSample], fps: float, name: str = "generated"
) -> list[Path]:
    """Clip shards + manifest, ``sample_XXX.mp4`` grid videos and ``contact_sheet.png``; returns the files."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows, files, clips = [], [], []
    with ShardWriter(out_dir, name) as writer:
        for i, s in enumerate(samples):
            clip = sample_clip(f"sample_{i:03d}", s, fps)
            writer.write(clip)
            clips.append(clip)
            grid = tile_views(s.videos, grid_layout(s.rig))
            write_bytes(out_dir / f"sample_{i:03d}.mp4", encode_mp4(grid, fps))
            files.append(out_dir / f"sample_{i:03d}.mp4")
            rows.append({"key": clip.key, "caption": s.caption, "cameras": s.rig.names, **s.extra})
    for (shard, _), row in zip(writer.written, rows):
        row["shard"] = shard
    files.append(write_manifest(out_dir, rows))
    files.append(write_clips_sheet(clips, out_dir / "contact_sheet.png"))
    return files


def sample_clip(key: str, s: GeneratedSample, fps: float):
    """A :class:`drivewm.clips.Clip` of one sample (rig scaled to the decoded image size)."""
    _, t, h, w, _ = s.videos.shape
    rig = s.rig.scaled(w, h, fit="stretch")  # samples are made at the size of the (cv2.resize-d) training clips
    meta = clip_meta(key, rig.to_dict(), fps, t, s.caption, s.extra)
    meta = dataclasses.replace(
        meta,
        view_captions=dict(zip(rig.names, s.view_captions)),
        trajectory_ego=np.asarray(s.trajectory_ego).tolist(),
        trajectory_dt_s=s.trajectory_dt_s,
        tags={**meta.tags, **caption_conditions(s.caption)},  # what was asked for, for eval's adherence
    )
    poses = poses_from_waypoints(s.trajectory_ego, t, s.trajectory_dt_s, fps)
    return clip_from_arrays(meta, dict(zip(rig.names, s.videos)), poses)
