"""What the benchmark reads: clip shards, a folder of per-camera mp4 + a rig, or one grid video.

A grid video is any single file FFmpeg (through PyAV) decodes: mp4, mov, mkv, webm, an animated GIF,
or one still image (png, jpg, webp) scored as a one-frame clip (cross-view figures only), as
generators publish their samples.

Every input becomes a list of :class:`EvalItem` (one per clip) that a worker process can decode
on its own: clips keep their encoded mp4 bytes; mp4 folders and grid videos keep file paths.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import av
import numpy as np

from drivewm.clips.format import Clip
from drivewm.clips.shards import BadClip, list_shards, read_shard, shard_folders
from drivewm.clips.video import decode_mp4
from drivewm.errors import DrivewmError
from drivewm.eval.framing import WHOLE_VIDEO, Framing, grid_cells
from drivewm.geometry import Rig, load_rig
from drivewm.paths import visible_entries


@dataclasses.dataclass
class GridLayout:
    """A single video holding ``rows`` x ``cols`` views, cells read row by row, named ``cameras``."""

    rows: int
    cols: int
    cameras: list[str]

    @staticmethod
    def parse(text: str, cameras: list[str]) -> GridLayout:
        """``"2x3"`` plus the camera order (row-major); cells named '-' are skipped."""
        try:
            rows, cols = (int(v) for v in text.lower().split("x"))
        except ValueError:
            raise DrivewmError(f"--grid {text!r}: expected ROWSxCOLS, e.g. 2x3") from None
        if len(cameras) != rows * cols:
            raise DrivewmError(f"--grid {text}: {rows * cols} cells but {len(cameras)} camera names {cameras}")
        return GridLayout(rows, cols, cameras)


@dataclasses.dataclass
class EvalItem:
    """One clip to score. Exactly one of ``clip``, ``mp4_paths`` or ``grid_path`` is set."""

    key: str
    rig: Rig
    fps: float
    T_world_from_ego: np.ndarray | None = None
    tags: dict = dataclasses.field(default_factory=dict)
    trajectory_ego: list = dataclasses.field(default_factory=list)
    trajectory_dt_s: float = 0.0
    clip: Clip | None = None
    mp4_paths: dict[str, str] = dataclasses.field(default_factory=dict)
    grid_path: str = ""
    grid: GridLayout | None = None
    timestamps_ns: list[int] = dataclasses.field(default_factory=list)
    """Time of each frame (and of each ego pose), ns; empty for mp4 inputs."""
    camera_timestamps_ns: dict[str, list[int]] = dataclasses.field(default_factory=dict)
    """Per camera, its frames' own exposure times (ns) when they differ from ``timestamps_ns``."""
    error: str = ""
    """Set when the input could not be read (e.g. a corrupt shard): the item is reported, not scored."""
    framing: Framing = dataclasses.field(default_factory=Framing)
    """mp4 inputs: the crop box and frame range scored, and the grid cells' borders."""

    def videos(self) -> dict[str, np.ndarray]:
        """uint8 RGB (T, H, W, 3) per camera of ``rig``, all with the same frame count."""
        if self.error:
            raise DrivewmError(self.error)
        if self.clip is not None:
            return {c: self.clip.video(c) for c in self.rig.names}
        if self.grid is not None:
            frames = self.framing.apply(_decode_file(self.grid_path), self.grid_path)
            return split_grid(frames, self.grid, self.grid_path, self.framing.cell_border_px)
        videos = {c: self.framing.apply(_decode_file(p), p) for c, p in self.mp4_paths.items()}
        counts = {c: len(v) for c, v in videos.items()}
        if len(set(counts.values())) > 1:  # cutting all to the shortest would score a different clip
            raise DrivewmError(f"{self.key}: the cameras' videos have different frame counts {counts}")
        return videos


GRID_SUFFIXES = (".mp4", ".mov", ".mkv", ".webm", ".gif", ".png", ".jpg", ".jpeg", ".webp")
"""File types read as one grid video (each decoded by FFmpeg through PyAV)."""


def _decode_file(path: str) -> np.ndarray:
    p = Path(path)
    if not p.is_file():
        raise DrivewmError(f"{p}: no such video file")
    return decode_mp4(p.read_bytes(), None, str(p))


def split_grid(frames: np.ndarray, grid: GridLayout, where: str, border_px: int = 0) -> dict[str, np.ndarray]:
    """Cut (T, H, W, 3) frames of a grid video into per-camera views: cells at the rounded boundaries
    ``i W / cols`` (a size that does not divide gives cells one pixel apart in size), ``border_px``
    cut from every cell edge (drivewm.eval.framing.grid_cells)."""
    T, H, W, _ = frames.shape
    cells = grid_cells(W, H, grid.rows, grid.cols, border_px)
    return {
        name: np.ascontiguousarray(frames[:, y : y + h, x : x + w])
        for name, (x, y, w, h) in zip(grid.cameras, cells)
        if name != "-"
    }


def _rig_for(rig: Rig, names: list[str], width: int, height: int, fit: str = "same") -> Rig:
    """The cameras named, at the videos' size; ``fit`` says how the videos were resized from the
    rig's size when the aspect ratio differs (:meth:`drivewm.geometry.Camera.scaled`)."""
    try:
        return rig.subset(names).scaled(width, height, fit)
    except DrivewmError as exc:
        raise DrivewmError(f"{exc} (eval: --rig-fit stretch|crop)") from None


def _video_size(path: Path) -> tuple[int, int, float]:
    try:
        with av.open(str(path)) as c:
            s = c.streams.video[0]
            return s.codec_context.width, s.codec_context.height, float(s.average_rate or 0) or 10.0
    except (av.error.FFmpegError, IndexError) as exc:
        raise DrivewmError(f"{path}: cannot read video ({exc.__class__.__name__})") from None


def items_from_clips(location: Path, rig: Rig | None, fit: str = "same") -> list[EvalItem]:
    """Clip shards (a folder of .tar or one .tar); ``rig`` (optional) overrides the clips' own.
    A clip (or damaged part of a shard) that cannot be read becomes one failed item named after it;
    the others are kept."""
    items, seen = [], set()
    for shard in list_shards(location):
        for clip in read_shard(shard):
            name = clip.name if isinstance(clip, BadClip) else clip.key
            try:
                if name in seen:  # results are keyed by clip: a second clip of one key would replace the first
                    name = f"{shard.stem}/{name}"
                    raise DrivewmError(f"{shard}: clip key {name.split('/')[-1]!r} seen before in this input")
                items.append(_clip_item(clip, rig, fit))
            except DrivewmError as exc:
                items.append(EvalItem(name, rig or Rig("unknown", []), 0.0, error=str(exc)))
            seen.add(name)
    return items


def items_from_clip_folders(location: Path, rig: Rig | None, fit: str = "same") -> list[EvalItem]:
    """A folder of clip-shard folders (e.g. ``drivewm generate`` outputs, one folder per prompt):
    every folder's clips, keyed ``FOLDER/KEY`` so that equal keys of different folders stay apart."""
    items = []
    for folder in shard_folders(location):
        items += [dataclasses.replace(i, key=f"{folder.name}/{i.key}") for i in items_from_clips(folder, rig, fit)]
    return items


def _clip_item(clip: Clip | BadClip, rig: Rig | None, fit: str) -> EvalItem:
    if isinstance(clip, BadClip):
        raise DrivewmError(clip.reason)
    m = clip.meta
    clip_rig = m.get_rig()
    if rig is not None:
        c0, shared = clip_rig.cameras[0], [n for n in rig.names if n in m.cameras]
        if not shared:
            raise DrivewmError(f"clip {m.key}: the rig {rig.name} ({rig.names}) shares no camera with its {m.cameras}")
        clip_rig = _rig_for(rig, shared, c0.width, c0.height, fit)
    return EvalItem(
        m.key,
        clip_rig,
        m.fps,
        clip.T_world_from_ego if m.ego_motion_known else None,  # identity placeholders are no reference
        dict(m.tags),
        list(m.trajectory_ego),
        m.trajectory_dt_s,
        clip=clip,
        timestamps_ns=list(m.timestamps_ns),
        camera_timestamps_ns=dict(m.camera_timestamps_ns),
    )


def items_from_mp4_folder(location: Path, rig: Rig, fit: str = "same", framing: Framing = WHOLE_VIDEO) -> list:
    """A folder of ``CAMERA.mp4`` (one clip), or a folder of such folders (one clip each)."""
    folders = [location] if visible_entries(location, "*.mp4") else [p for p in visible_entries(location) if p.is_dir()]
    items = []
    for folder in folders:
        try:
            items.append(_folder_item(folder, rig, fit, framing))
        except DrivewmError as exc:  # one bad folder is one failed item
            items.append(EvalItem(folder.name, rig, 0.0, error=str(exc)))
    return items


def _folder_item(folder: Path, rig: Rig, fit: str, framing: Framing) -> EvalItem:
    paths = {c: folder / f"{c}.mp4" for c in rig.names if (folder / f"{c}.mp4").is_file()}
    if not paths:
        raise DrivewmError(f"{folder}: no mp4 named after the rig's cameras {rig.names}")
    first = next(iter(paths.values()))
    W, H, fps = _video_size(first)
    _, _, w, h = framing.box(W, H, str(first))
    mp4_paths = {c: str(p) for c, p in paths.items()}
    return EvalItem(folder.name, _rig_for(rig, list(paths), w, h, fit), fps, mp4_paths=mp4_paths, framing=framing)


def items_from_grid(path: Path, rig: Rig, grid: GridLayout, fit: str = "same", framing: Framing = WHOLE_VIDEO) -> list:
    """One mp4 holding a grid of views (inside ``framing``'s crop box); each camera is fitted to its own cell."""
    W, H, fps = _video_size(path)
    _, _, w, h = framing.box(W, H, str(path))
    cells = grid_cells(w, h, grid.rows, grid.cols, framing.cell_border_px)
    named = [(n, cell) for n, cell in zip(grid.cameras, cells) if n != "-"]
    try:
        cameras = [rig.camera(n).scaled(cw, ch, fit) for n, (_, _, cw, ch) in named]
    except DrivewmError as exc:
        raise DrivewmError(f"{path}: {exc} (eval: --rig-fit stretch|crop)") from None
    item_rig = Rig(rig.name, cameras)
    return [EvalItem(path.stem, item_rig, fps, grid_path=str(path), grid=grid, framing=framing)]


def load_items(
    location: str | Path,
    rig: str | Path | Rig | None = None,
    grid: str | None = None,
    cameras: list[str] | None = None,
    fit: str = "same",
    framing: Framing = WHOLE_VIDEO,
) -> list[EvalItem]:
    """Items of any supported input. ``grid`` ('2x3') and ``cameras`` (row-major order, default the
    rig's) describe a grid video; mp4 folders and grid videos need ``rig``. ``fit`` ('same',
    'stretch', 'crop'): how videos of another aspect ratio than ``rig`` were resized from it.
    ``framing``: mp4 inputs' crop box, frame range and grid cell borders (drivewm.eval.framing)."""
    location = Path(location)
    rig_obj = load_rig(rig) if isinstance(rig, (str, Path)) else rig
    if not location.exists():
        raise DrivewmError(f"{location}: no such file or folder")
    is_clips = location.suffix == ".tar" or (location.is_dir() and (list_shards(location) or shard_folders(location)))
    if is_clips and not framing.is_default:  # a clip's frames carry poses and times: cut them at curation
        raise DrivewmError(f"{location}: --crop, --frames and --grid-border apply to mp4 inputs, not clip shards")
    if location.suffix == ".tar" or (location.is_dir() and list_shards(location)):
        return items_from_clips(location, rig_obj, fit)
    if location.is_dir() and shard_folders(location):
        return items_from_clip_folders(location, rig_obj, fit)
    if rig_obj is None:
        raise DrivewmError(f"{location}: mp4 inputs need --rig (camera names, intrinsics and extrinsics)")
    if location.is_file() and location.suffix.lower() in GRID_SUFFIXES:
        if not grid:
            if len(rig_obj.cameras) != 1:
                raise DrivewmError(
                    f"{location}: a single mp4 with a {len(rig_obj.cameras)}-camera rig needs --grid ROWSxCOLS"
                )
            grid = "1x1"
        return items_from_grid(location, rig_obj, GridLayout.parse(grid, cameras or rig_obj.names), fit, framing)
    if location.is_dir():
        return items_from_mp4_folder(location, rig_obj, fit, framing)
    raise DrivewmError(
        f"{location}: expected clip shards, a folder of per-camera mp4, or a grid video ({', '.join(GRID_SUFFIXES)})"
    )
