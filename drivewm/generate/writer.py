"""Writing generated samples (multi-view: :func:`write_samples`; Text2World: :func:`write_single_view`):
clips in the clip format (so ``drivewm eval`` scores them directly), a grid mp4 of all views per
sample, and a contact sheet laid out as curation's (a row per camera in
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

from drivewm.atomic import write_bytes
from drivewm.clips.format import clip_from_arrays
from drivewm.clips.shards import ShardWriter, write_manifest
from drivewm.clips.video import encode_mp4
from drivewm.curate.contact_sheet import write_clips_sheet
from drivewm.diffusion.generate import clip_meta, write_grid_png
from drivewm.geometry import Rig
from drivewm.layout.clip_layout import ClipLayout, layout_to_npz
from drivewm.multiview.trajectories import poses_from_waypoints
from drivewm.text.conditions import caption_conditions
from drivewm.views.grid import grid_layout, tile_views


@dataclasses.dataclass
class GeneratedSample:
    """One generated clip: ``videos`` uint8 (V, T, H, W, 3) in rig order and what conditioned it."""

    videos: np.ndarray
    rig: Rig
    caption: str
    view_captions: list[str]
    trajectory_ego: np.ndarray | None
    """(W, 3) m waypoints the sample was conditioned on (None: no trajectory, Text2World)."""
    trajectory_dt_s: float
    extra: dict
    """What the clip's metadata records (model, prompt, seed, sampling, ``post_processing``; a layout
    window's ``pair_id``)."""
    layout: ClipLayout | None = None
    """The layout it was generated from (kept in the clip, ``KEY.layout.npz``); None: none."""


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
        pair_id=str(s.extra.get("pair_id", "")),  # a layout window's: the simulator's truth in any condition
    )
    poses = poses_from_waypoints(s.trajectory_ego, t, s.trajectory_dt_s, fps)
    clip = clip_from_arrays(meta, dict(zip(rig.names, s.videos)), poses)
    if s.layout is not None:
        clip = dataclasses.replace(clip, layout_npz=layout_to_npz(s.layout))
    return clip


def write_single_view(out_dir: str | Path, samples: list[GeneratedSample], fps: float) -> list[Path]:
    """Text2World samples (one view each, no trajectory): clips (shards + manifest), one mp4 per sample
    and a contact sheet of a row per sample; returns the written files."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    rows, files = [], []
    videos = np.stack([s.videos[0] for s in samples])
    prompts = [s.caption for s in samples]
    with ShardWriter(out_dir, "generated") as writer:
        for i, s in enumerate(samples):
            video, camera, (h, w) = s.videos[0], s.rig.cameras[0], s.videos.shape[2:4]
            rig_i = s.rig.to_dict()
            rig_i["cameras"] = [{**rig_i["cameras"][0], "width": w, "height": h}]
            meta = clip_meta(f"sample_{i:03d}", rig_i, fps, len(video), s.caption, s.extra)
            writer.write(clip_from_arrays(meta, {camera.name: video}, np.tile(np.eye(4), (len(video), 1, 1))))
            write_bytes(out_dir / f"sample_{i:03d}.mp4", encode_mp4(video, fps))
            files.append(out_dir / f"sample_{i:03d}.mp4")
            rows.append({"key": meta.key, "caption": s.caption, **s.extra})
    for (shard, _key), row in zip(writer.written, rows):
        row["shard"] = Path(shard).name
    files.append(write_manifest(out_dir, rows))
    files.append(write_grid_png(videos, out_dir / "contact_sheet.png", prompts))
    return files
