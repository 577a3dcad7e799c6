"""WebDataset tar shards of clips, and the dataset manifest.

Tars are written with the standard library's ``tarfile`` (members ``KEY.CAMERA.mp4``,
``KEY.json``, ``KEY.ego.npy`` and, when the clip has them, ``KEY.layout.npz`` and
``KEY.CAMERA.labels.npz``, grouped by key as WebDataset expects) to a temporary name and
renamed when complete, so a killed run never leaves a partial shard. Readers refuse members
with unsafe paths, check that ``KEY.json`` names the key of its members (a key becomes a file name
downstream, so it must be a safe name: drivewm.paths) and never unpickle
(``np.load(allow_pickle=False)``). Batch readers use :func:`read_clips`, which puts a
:class:`BadClip` in place of each unreadable clip (or damaged rest of a shard) and goes on.
"""

from __future__ import annotations

import contextlib
import dataclasses
import io
import json
import tarfile
from collections.abc import Iterable, Iterator
from pathlib import Path

import numpy as np

from drivewm.atomic import atomic_path, discard_held, finish_held, write_text
from drivewm.clips.format import Clip, ClipMeta, validate_meta
from drivewm.errors import DrivewmError
from drivewm.paths import check_name, child_path, file_name, visible_entries

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
        self.name = check_name(name, "shard name")
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
        elif self._open is not None:  # the open shard is discarded (its temporary removed)
            stack, tar, _ = self._open
            self._open = None
            with contextlib.suppress(Exception):  # a full disk fails this too
                tar.close()
            discard_held(stack, exc)  # raises exc, as a storage OSError naming the shard on a full disk

    def write(self, clip: Clip) -> None:
        validate_meta(clip.meta)
        missing = [c for c in clip.meta.cameras if c not in clip.mp4]
        if missing:
            raise DrivewmError(f"clip {clip.key}: no video for cameras {missing}")
        if self._open is None:
            path = child_path(self.out_dir, f"{self.name}-{self._index:06d}", ext="tar")
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
        self._open = None
        finish_held(stack, tar.close)
        self.written += [(path.name, key) for key in self._keys]
        self._keys = []
        self._index += 1


def _add_member(tar: tarfile.TarFile, name: str, data: bytes) -> None:
    info = tarfile.TarInfo(name)
    info.size = len(data)
    info.mtime = 0  # same clips, same bytes: reruns produce identical shards
    tar.addfile(info, io.BytesIO(data))


def _add_clip(tar: tarfile.TarFile, clip: Clip) -> None:
    key = clip.key
    _add_member(tar, file_name(key, ext="json"), json.dumps(clip.meta.to_json()).encode())
    ego = io.BytesIO()
    np.save(ego, np.asarray(clip.T_world_from_ego, dtype=np.float64), allow_pickle=False)
    _add_member(tar, file_name(key, "ego", ext="npy"), ego.getvalue())
    for cam in clip.meta.cameras:
        _add_member(tar, file_name(key, cam, ext="mp4"), clip.mp4[cam])
    if clip.layout_npz is not None:
        _add_member(tar, file_name(key, "layout", ext="npz"), clip.layout_npz)
    for cam in clip.meta.cameras:
        if cam in clip.labels_npz:
            _add_member(tar, file_name(key, cam, "labels", ext="npz"), clip.labels_npz[cam])


def list_shards(location: str | Path | Iterable[str | Path]) -> list[Path]:
    """Tar files of a dataset folder (sorted), a single tar, or a list of either. A folder's hidden entries
    are never listed (drivewm.paths.visible_entries): a killed writer's torn shard lies in one."""
    if isinstance(location, (str, Path)):
        location = [location]
    shards: list[Path] = []
    for loc in location:
        loc = Path(loc)
        if loc.is_dir():
            shards += [p for p in visible_entries(loc, "*.tar") if p.is_file()]
        elif loc.is_file() and loc.suffix == ".tar":
            shards.append(loc)
        else:
            raise DrivewmError(f"{loc}: not a clip shard (.tar) or a folder of shards")
    return shards


def shard_folders(location: str | Path) -> list[Path]:
    """The sub-folders of ``location`` that hold clip shards (e.g. ``drivewm generate`` outputs, one folder per
    prompt), sorted; hidden ones (a writer's temporary, which holds a torn shard) are never among them."""
    return [p for p in visible_entries(location) if p.is_dir() and list_shards(p)]


def _safe_member(name: str, shard: Path) -> str:
    if name.startswith("/") or ".." in Path(name).parts or "/" in name or "\\" in name:
        raise DrivewmError(f"{shard}: refusing unsafe member path {name!r}")
    return name


@dataclasses.dataclass
class BadClip:
    """A clip that could not be read (``name``: its key), or the damaged rest of a shard (``name``: the
    shard's file name); ``reason`` is the one-line error."""

    name: str
    reason: str


def read_shard(shard: Path, keys: set[str] | None = None) -> Iterator[Clip | BadClip]:
    """Clips of one tar in order, a :class:`BadClip` in place of each one that cannot be read. A
    truncated or corrupt tar yields the clips before the damage, then one BadClip (named after the
    shard's stem) for the rest; an unsafe member path refuses the whole shard. ``keys``: only these
    clips are parsed and yielded (checking a clip's metadata and rig costs more than reading its bytes)."""
    groups: dict[str, dict[str, bytes]] = {}
    damage = None
    try:
        with tarfile.open(shard, "r") as tar:
            for member in tar:
                if member.isfile():
                    key, _, suffix = _safe_member(member.name, shard).partition(".")
                    groups.setdefault(key, {})[suffix] = tar.extractfile(member).read()
    except (tarfile.TarError, OSError, EOFError) as exc:
        damage = BadClip(shard.stem, f"{shard}: corrupt or truncated shard ({exc})")
        if groups:
            groups.popitem()  # the clip being read when the damage came is part of the damage
    except DrivewmError as exc:
        yield BadClip(shard.stem, str(exc))
        return
    for key, members in groups.items():
        if keys is not None and key not in keys:
            continue
        try:
            yield _clip_from_members(key, members, shard)
        except DrivewmError as exc:
            yield BadClip(key, str(exc))
    if damage is not None:
        yield damage


def iter_shard(shard: Path, keys: set[str] | None = None) -> Iterator[Clip]:
    """Clips of one tar in order (only ``keys``, if given). A corrupt tar or clip raises DrivewmError
    naming the shard."""
    for item in read_shard(shard, keys):
        if isinstance(item, BadClip):
            raise DrivewmError(item.reason)
        yield item


def _clip_from_members(key: str, members: dict[str, bytes], shard: Path) -> Clip:
    where = f"{shard}: clip {key}"
    check_name(key, f"{shard}: member key")
    if "json" not in members or "ego.npy" not in members:
        raise DrivewmError(f"{where}: missing {key}.json or {key}.ego.npy")
    try:
        data = json.loads(members["json"])
    except (ValueError, RecursionError):  # JSONDecodeError and UnicodeDecodeError are ValueErrors
        raise DrivewmError(f"{where}: {key}.json is not valid JSON") from None
    meta = ClipMeta.from_json(data, where)
    if meta.key != key:  # the key names output files downstream: it must be the one the members carry
        raise DrivewmError(f"{where}: {key}.json names key {meta.key!r}, not its members' {key!r}")
    try:
        ego = np.load(io.BytesIO(members["ego.npy"]), allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise DrivewmError(f"{where}: {key}.ego.npy is not a plain numpy array ({exc.__class__.__name__})") from None
    if ego.shape != (meta.num_frames, 4, 4) or ego.dtype.kind != "f":
        raise DrivewmError(f"{where}: ego poses are {ego.dtype} {ego.shape}, expected float ({meta.num_frames}, 4, 4)")
    missing = [c for c in meta.cameras if f"{c}.mp4" not in members]
    if missing:
        raise DrivewmError(f"{where}: missing camera video(s) {missing}")
    labels = {c: members[f"{c}.labels.npz"] for c in meta.cameras if f"{c}.labels.npz" in members}
    return Clip(
        meta,
        {c: members[f"{c}.mp4"] for c in meta.cameras},
        ego,
        layout_npz=members.get("layout.npz"),
        labels_npz=labels,
    )


def read_clips(location: str | Path | Iterable[str | Path]) -> Iterator[Clip | BadClip]:
    """Every clip of a dataset folder, tar or list of them, in shard order, with a :class:`BadClip` in
    place of each unreadable clip or damaged shard: what batch commands (encode, decode, eval) read."""
    for shard in list_shards(location):
        yield from read_shard(shard)


def iter_clips(location: str | Path | Iterable[str | Path]) -> Iterator[Clip]:
    """Every clip of a dataset folder, tar or list of them, in shard order; any unreadable clip raises."""
    for shard in list_shards(location):
        yield from iter_shard(shard)


def spread(items: list, n: int | None) -> list:
    """``n`` items evenly spaced over ``items`` (all of them when n is None or not smaller): the
    clips ``--max-clips N`` takes (``drivewm eval``, ``drivewm tokenizer eval``), so a subset spans
    every drive of a sorted input rather than its first."""
    if n is None or n >= len(items):
        return items
    if n < 1:
        raise DrivewmError(f"max_clips must be >= 1, got {n}")
    return [items[i * len(items) // n] for i in range(n)]


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
    try:
        return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    except ValueError:
        raise DrivewmError(f"{path}: not valid JSON lines") from None
