"""contact_sheet.png: a few sample clips, every view, first/middle/last frame, with the caption."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from drivewm.atomic import write_bytes
from drivewm.clips.shards import iter_shard

#: Width (px) of a view on the sheet: wider frames are shrunk to it, narrower ones (160x96 clips) shown as
#: they are (upscaled, they only blurred and cost a third more PNG encoding, the sheet's largest cost after decoding)
THUMB_W = 192


def thumb_width(frame_width: int) -> int:
    """The width of a ``frame_width``-wide view on the sheet."""
    return min(THUMB_W, frame_width)


def _thumb(img: np.ndarray) -> np.ndarray:
    w = thumb_width(img.shape[1])
    if w == img.shape[1]:  # a copy in row order: a frame of an in-memory video may be a strided view
        return np.ascontiguousarray(img)
    return cv2.resize(img, (w, round(img.shape[0] * w / img.shape[1])), interpolation=cv2.INTER_AREA)


def clip_block(clip) -> np.ndarray:
    """One clip: rows = cameras in rig order, columns = first/middle/last frame, caption lines on top."""
    T = clip.meta.num_frames
    shown = [0, T // 2, T - 1]
    rows = []
    for name in clip.meta.cameras:
        row = np.concatenate([_thumb(f) for f in clip.frames(name, shown)], axis=1)
        cv2.putText(row, name, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 0), 1, cv2.LINE_AA)
        rows.append(row)
    grid = np.concatenate(rows, axis=0)
    text = f"{clip.key}: {clip.meta.caption}"
    chars = max(20, grid.shape[1] // 6)
    lines = [text[i : i + chars] for i in range(0, min(len(text), 3 * chars), chars)]
    bar = np.full((14 * len(lines) + 6, grid.shape[1], 3), 255, dtype=np.uint8)
    for i, line in enumerate(lines):
        cv2.putText(bar, line, (4, 14 * i + 13), cv2.FONT_HERSHEY_SIMPLEX, 0.38, (0, 0, 0), 1, cv2.LINE_AA)
    return np.concatenate([bar, grid], axis=0)


def write_contact_sheet(out_dir: Path, rows: list[dict], n_clips: int) -> Path | None:
    """Render up to ``n_clips`` manifest rows (spread over the list) into ``out_dir/contact_sheet.png``."""
    if not rows or n_clips <= 0:
        return None
    picks = [rows[i] for i in sorted(set(np.linspace(0, len(rows) - 1, min(n_clips, len(rows))).round().astype(int)))]
    found = {}
    for shard in sorted({row["shard"] for row in picks}):  # each shard read once, only the picked clips parsed
        found.update({c.key: c for c in iter_shard(Path(out_dir) / shard, {row["key"] for row in picks})})
    clips = [found[row["key"]] for row in picks]
    return write_clips_sheet(clips, Path(out_dir) / "contact_sheet.png")


def write_pairs_sheet(pairs: list[tuple], path: Path) -> Path:
    """Per pair, :func:`clip_block` of both clips side by side (6 px white between; a None left clip is
    left out), pairs stacked top to bottom, into the PNG ``path``: a clip's frames beside what was made
    from them (its layout, its transfer)."""
    blocks = []
    for a, b in pairs:
        parts = [clip_block(c) for c in (a, b) if c is not None]
        height = max(p.shape[0] for p in parts)
        parts = [np.pad(p, ((0, height - p.shape[0]), (0, 6), (0, 0)), constant_values=255) for p in parts]
        blocks.append(np.concatenate(parts, axis=1))
    return _write_sheet(blocks, path)


def write_clips_sheet(clips: list, path: Path) -> Path:
    """Stack :func:`clip_block` of every clip top to bottom (6 px white between) into the PNG ``path``;
    curated and generated clips share this layout, so their sheets compare row for row."""
    return _write_sheet([clip_block(clip) for clip in clips], path)


def _write_sheet(blocks: list[np.ndarray], path: Path) -> Path:
    width = max(b.shape[1] for b in blocks)
    sheet = np.concatenate(
        [np.pad(b, ((0, 6), (0, width - b.shape[1]), (0, 0)), constant_values=255) for b in blocks], axis=0
    )
    ok, png = cv2.imencode(".png", cv2.cvtColor(sheet, cv2.COLOR_RGB2BGR))
    write_bytes(path, png.tobytes())
    return path
