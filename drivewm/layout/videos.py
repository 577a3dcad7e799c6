"""Layout videos of clip folders: one H.264 mp4 per clip and camera, and a contact sheet of the clips'
own frames beside their layout (``drivewm layout``)."""

from __future__ import annotations

import dataclasses
import sys
from pathlib import Path

from tqdm import tqdm

from drivewm.atomic import write_bytes
from drivewm.clips.format import Clip
from drivewm.clips.shards import BadClip, list_shards, read_shard, spread
from drivewm.clips.video import encode_mp4
from drivewm.curate.contact_sheet import write_pairs_sheet
from drivewm.errors import BatchError, DrivewmError
from drivewm.geometry import Rig
from drivewm.layout.render import render_layout
from drivewm.paths import child_path


@dataclasses.dataclass
class LayoutVideos:
    """What :func:`write_layout_videos` wrote."""

    clips: int
    videos: list[Path]
    sheet: Path | None
    failed: list[str]


def write_layout_videos(
    sources: list[str | Path],
    out_dir: str | Path,
    rig: Rig | None = None,
    max_clips: int | None = None,
    sheet_clips: int = 4,
    progress: bool = True,
) -> LayoutVideos:
    """Render every clip's layout for its own rig (or ``rig``) into ``OUT/KEY.CAMERA.mp4`` (the clip's
    fps) and ``OUT/contact_sheet.png`` (up to ``sheet_clips`` clips: frames beside layout; with another
    rig, the layouts alone). A clip without a layout or that cannot be read is skipped with one
    ``skipped:`` line on stderr; when none could be rendered, :class:`BatchError` lists them."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    items = [item for shard in list_shards(sources) for item in read_shard(shard)]
    items = spread(items, max_clips)
    videos, failed, pairs = [], [], []
    for item in tqdm(items, desc="layout", unit="clip", disable=not progress):
        try:
            clip, shown = _render(item, rig)
        except DrivewmError as exc:
            failed.append(str(exc))
            continue
        for cam, video in zip(shown.meta.cameras, shown.videos()):
            path = child_path(out_dir, clip.key, cam, ext="mp4")
            write_bytes(path, encode_mp4(video, clip.meta.fps))
            videos.append(path)
        pairs.append((clip, shown))
    if not pairs:
        raise BatchError(f"layout: no clip could be rendered ({len(failed)} failed)", failed or ["no clips found"])
    for reason in failed:
        print(f"skipped: {reason}", file=sys.stderr)
    picks = spread(pairs, sheet_clips)
    sheet = write_pairs_sheet([(a if rig is None else None, b) for a, b in picks], out_dir / "contact_sheet.png")
    return LayoutVideos(len(pairs), videos, sheet, failed)


def _render(item: Clip | BadClip, rig: Rig | None) -> tuple[Clip, Clip]:
    """(the clip, its layout video as a clip of the same frames and ``rig``'s cameras)."""
    if isinstance(item, BadClip):
        raise DrivewmError(item.reason)
    layout = item.layout()
    if layout is None:
        raise DrivewmError(f"clip {item.key}: no layout (its log knew no objects or road, or no ego poses)")
    target = rig or item.meta.get_rig()
    layout.check_seen_by(target, f"clip {item.key}")
    frames = render_layout(target, layout)  # (V, T, H, W, 3)
    meta = dataclasses.replace(item.meta, rig=target.to_dict(), caption=f"layout of {item.key}", view_captions={})
    shown = Clip(meta, {}, item.T_world_from_ego)
    shown._decoded.update({c: frames[v] for v, c in enumerate(meta.cameras)})
    return item, shown
