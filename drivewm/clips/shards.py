"""WebDataset tar shards of clips, and the dataset manifest.

Tars are written with the standard library's ``tarfile`` (members ``KEY.CAMERA.mp4``,
``KEY.json``, ``KEY.ego.npy``, grouped by key as WebDataset expects) to a temporary name and
renamed when complete, so a killed run never leaves a partial shard. Readers refuse members
with unsafe paths and never unpickle (``np.load(allow_pickle=False)``).
"""

from __future__ import annotations

import contextlib
import io
import json
import tarfile
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from drivewm.atomic import atomic_path, write_text
from drivewm.clips.format import Clip, ClipMeta, validate_meta
from drivewm.errors import DrivewmError

MANIFEST_NAME = "manifest.jsonl"


class ShardWriter:
    """Write clips into ``OUT/NAME-000000.tar``, ``NAME-000001.tar``, ... (``max_clips`` per tar).

    Use as a context manager. Each clip's members are appended to the open shard as it is
    written (nothing is held per clip), and the shard appears atomically when it is full or on
    close; leaving on an exception discards the open shard. ``written`` lists (shard path, clip
    key) of the shards that appeared, for the manifest.
    """

    def __init__(self, out_dir: str | Path, name: str, max_clips: int = 64):
        self.out_dir = Path(out_dir)
        self.name = name
        self.max_clips = max_clips
        self.written: list[tuple[str, str]] = []
        self._open: tuple[contextlib.ExitStack, tarfile.TarFile, Path] | None = None
        self._keys: list[str] = []
        self._index = 0

    def __enter__(self) -> ShardWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.flush()
        elif self._open is not None:
            stack, tar, _ = self._open
            tar.close()
            stack.__exit__(exc_type, exc, tb)  # atomic_path removes the temporary
            self._open = None

    def write(self, clip: Clip) -> None:
        validate_meta(clip.meta)
        missing = [c for c in clip.meta.cameras if c not in clip.mp4]
        if missing:
            raise DrivewmError(f"clip {clip.key}: no video for cameras {missing}")
        if self._open is None:
            path = self.out_dir / f"{self.name}-{self._index:06d}.tar"
            stack = contextlib.ExitStack()
            tmp = stack.enter_context(atomic_path(path))
            self._open = (stack, tarfile.open(tmp, "w"), path)
        _add_clip(self._open[1], clip)
        self._keys.append(clip.key)
        if len(self._keys) >= self.max_clips:
            self.flush()

    def flush(self) -> None:
        """Close the open shard (renaming it into place)."""
        if self._open is None:
            return
        stack, tar, path = self._open
        tar.close()
        stack.close()
        self.written += [(path.name, key) for key in self._keys]
        self._open, self._keys = None, []
        self._index += 1


def _add_member(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    info.mtime = 0  # same clips, same bytes: reruns produce identical shards
    tar.addfile(info, io.BytesIO(data))


def _add_clip(tar: tarfile.TarFile, clip: Clip) -> None:
    key = clip.key
    _add_member(tar, f"{key}.json", json.dumps(clip.meta.to_json()).encode())
    ego = io.BytesIO()
    np.save(ego, np.asarray(clip.T_world_from_ego, dtype=np.float64), allow_pickle=False)
    _add_member(tar, f"{key}.ego.npy", ego.getvalue())
    for cam in clip.meta.cameras:
        _add_member(tar, f"{key}.{cam}.mp4", clip.mp4[cam])


def list_shards(location: str | Path | Iterable[str | Path]) -> list[Path]:
    """Tar files of a dataset folder (sorted), a single tar, or a list of either."""
    if isinstance(location, (str, Path)):
        location = [location]
    shards: list[Path] = []
    for loc in location:
        loc = Path(loc)
        if loc.is_dir():
            shards += sorted(p for p in loc.glob("*.tar") if not p.name.startswith("."))
        elif loc.is_file() and loc.suffix == ".tar":
            shards.append(loc)
        else:
            raise DrivewmError(f"{loc}: not a clip shard (.tar) or a folder of shards")
    return shards


def _safe_member(name: str, shard: Path) -> str:
    if name.startswith("/") or ".." in Path(name).parts or "/" in name or "\\" in name:
        raise DrivewmError(f"{shard}: refusing unsafe member path {name!r}")
    return name


def iter_shard(shard: Path) -> Iterator[Clip]:
    """Clips of one tar in order. A corrupt tar or clip raises DrivewmError naming the shard."""
    groups: dict[str, dict[str, bytes]] = {}
    order: list[str] = []
    try:
        with tarfile.open(shard, "r") as tar:
            for member in tar:
                if not member.isfile():
                    continue
                name = _safe_member(member.name, shard)
                key, _, suffix = name.partition(".")
                if key not in groups:
                    groups[key] = {}
                    order.append(key)
                groups[key][suffix] = tar.extractfile(member).read()
    except (tarfile.TarError, OSError, EOFError) as exc:
        raise DrivewmError(f"{shard}: corrupt or truncated shard ({exc})") from None
    for key in order:
        yield _clip_from_members(key, groups[key], shard)


def _clip_from_members(key: str, members: dict[str, bytes], shard: Path) -> Clip:
    where = f"{shard}: clip {key}"
    if "json" not in members or "ego.npy" not in members:
        raise DrivewmError(f"{where}: missing {key}.json or {key}.ego.npy")
    meta = ClipMeta.from_json(json.loads(members["json"]), where)
    ego = np.load(io.BytesIO(members["ego.npy"]), allow_pickle=False)
    if ego.shape != (meta.num_frames, 4, 4):
        raise DrivewmError(f"{where}: ego poses have shape {ego.shape}, expected ({meta.num_frames}, 4, 4)")
    missing = [c for c in meta.cameras if f"{c}.mp4" not in members]
    if missing:
        raise DrivewmError(f"{where}: missing camera video(s) {missing}")
    return Clip(meta, {c: members[f"{c}.mp4"] for c in meta.cameras}, ego)


def iter_clips(location: str | Path | Iterable[str | Path]) -> Iterator[Clip]:
    """Every clip of a dataset folder, tar or list of them, in shard order."""
    for shard in list_shards(location):
        yield from iter_shard(shard)


def write_manifest(out_dir: str | Path, rows: list[dict]) -> Path:
    """Write ``manifest.jsonl`` (one JSON row per clip; atomic)."""
    path = Path(out_dir) / MANIFEST_NAME
    write_text(path, "".join(json.dumps(r, sort_keys=True) + "\n" for r in rows))
    return path


def read_manifest(out_dir: str | Path) -> list[dict]:
    """Rows of ``manifest.jsonl``; a missing manifest raises DrivewmError."""
    path = Path(out_dir) / MANIFEST_NAME
    if not path.is_file():
        raise DrivewmError(f"{out_dir}: no {MANIFEST_NAME} (not a curated clip folder?)")
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
