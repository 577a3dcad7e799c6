"""Helpers for the hostile-input tests: small valid clip shards, and rewriting a shard's members."""

from __future__ import annotations

import io
import json
import tarfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from drivewm.clips import ClipMeta, ShardWriter
from drivewm.clips.format import clip_from_arrays
from drivewm.geometry import load_rig

Member = tuple[str, bytes]


def tiny_clip(key: str, T: int = 9, W: int = 64, H: int = 48, cameras: int = 2, seed: int = 0):
    """A clip of smooth moving gradients, ``cameras`` views of the front3 rig at W x H (tokenizer-friendly:
    T = 1 + 4k frames, sizes multiples of 8)."""
    rig = load_rig("front3").scaled(W, H, "stretch").subset(load_rig("front3").names[:cameras])
    yy, xx = np.mgrid[0:H, 0:W]
    frames = {}
    for v, cam in enumerate(rig.names):
        video = [
            np.stack(
                [128 + 90 * np.sin(xx / 7 + t * 0.4 + v + seed), 128 + 90 * np.cos(yy / 5 - t * 0.3), 96 + 0 * xx], -1
            )
            for t in range(T)
        ]
        frames[cam] = np.clip(np.stack(video), 0, 255).astype(np.uint8)
    meta = ClipMeta(key, "test.mcap", 0, 10.0, [i * 100_000_000 for i in range(T)], rig.to_dict(), caption="a road")
    ego = np.repeat(np.eye(4)[None], T, axis=0)
    ego[:, 0, 3] = np.arange(T)
    return clip_from_arrays(meta, frames, ego)


def write_shard(folder: Path, name: str, keys: list[str], **kwargs) -> Path:
    """One shard ``folder/NAME-000000.tar`` holding a tiny clip per key."""
    with ShardWriter(folder, name, max_clips=len(keys) + 1) as writer:
        for i, key in enumerate(keys):
            writer.write(tiny_clip(key, seed=i, **kwargs))
    return folder / f"{name}-000000.tar"


def members(shard: Path) -> list[Member]:
    with tarfile.open(shard) as tar:
        return [(m.name, tar.extractfile(m).read()) for m in tar if m.isfile()]


def write_members(path: Path, items: list[Member]) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    with tarfile.open(path, "w") as tar:
        for name, data in items:
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))
    return path


def edit_json(items: list[Member], key: str, edit: Callable[[dict], None]) -> list[Member]:
    """``items`` with ``KEY.json`` changed in place by ``edit(meta_dict)``."""
    out = []
    for name, data in items:
        if name == f"{key}.json":
            meta = json.loads(data)
            edit(meta)
            data = json.dumps(meta).encode()
        out.append((name, data))
    return out


def files_under(root: Path) -> set[Path]:
    return {p for p in root.rglob("*") if p.is_file()}
