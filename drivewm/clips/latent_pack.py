"""A latent cache packed to 8 bits per value, to carry it where bandwidth or a size limit is tight
(a GPU machine reached through a copy limit; the last GPU run carried its latents this way).

Each clip's latents are quantised per view and channel over that clip's own range: ``q = round((z -
lo) / scale)`` in uint8, ``scale = (max - lo) / 255``, so every value comes back within ``scale / 2``
of what was packed, a quarter of the float32 size. Poses and the index (clip metadata, the
tokenizer and its latent statistics) travel exact. ``unpack`` writes an ordinary latent cache
(drivewm.clips.latents) that every diffusion stage reads as it reads one written by ``drivewm
tokenizer encode``::

    python -m drivewm.clips.latent_pack pack CLIPDIR/latents/tokenizer PACK [--max-mb 18] [--part K/N]
    python -m drivewm.clips.latent_pack unpack PACK [PACK ...] CACHE

``--max-mb`` keeps the clips that fit, spread over the cache, and says how many it kept; the limit
holds for the whole pack folder, its index included (about 12 KB a six-camera clip). ``--part K/N``
packs every N-th clip of that spread order from the K-th, so parts travel one at a time (a copy
limit per transfer) and ``unpack`` takes them all back into one cache.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import torch
from safetensors.torch import load_file, save

from drivewm.atomic import atomic_path, write_json
from drivewm.clips.format import ClipMeta
from drivewm.clips.latents import LatentCache, write_latent_clip, write_latent_index
from drivewm.errors import DrivewmError
from drivewm.paths import child_path

PACK_INDEX = "pack.json"
PACK_VERSION = 1
LEVELS = 255


def quantise(latents: torch.Tensor) -> dict[str, torch.Tensor]:
    """(V, c, t, h, w) float -> uint8 ``q`` with per-(view, channel) ``lo`` and ``scale`` (float32)."""
    flat = latents.detach().to(torch.float32).flatten(2)  # (V, c, thw)
    lo, hi = flat.min(dim=2).values, flat.max(dim=2).values
    scale = ((hi - lo) / LEVELS).clamp_min(1e-12)
    q = ((flat - lo[..., None]) / scale[..., None]).round().clamp(0, LEVELS).to(torch.uint8)
    return {"q": q.reshape(latents.shape).contiguous(), "lo": lo.contiguous(), "scale": scale.contiguous()}


def dequantise(packed: dict[str, torch.Tensor]) -> torch.Tensor:
    """The inverse of :func:`quantise` up to ``scale / 2`` per value: (V, c, t, h, w) float32."""
    q = packed["q"].to(torch.float32)
    return q * packed["scale"][..., None, None, None] + packed["lo"][..., None, None, None]


def pack(
    cache_dir: str | Path, out_dir: str | Path, max_mb: float | None = None, part: tuple[int, int] = (1, 1)
) -> dict:
    """Pack the cache at ``cache_dir`` into ``out_dir``; returns ``{"clips", "of", "bytes",
    "max_error_in_std"}`` (the largest packing error over the clips, in units of each channel's latent
    std). ``part`` (K, N): only every N-th clip of the spread order from the K-th, so N packs made with
    K = 1..N hold disjoint clips, each spread over the whole cache, and together all of it."""
    k, n = part
    if not 1 <= k <= n:
        raise DrivewmError(f"--part must be K/N with 1 <= K <= N, got {k}/{n}")
    cache = LatentCache(cache_dir)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    std = cache.latent_std
    rows, worst = [], 0.0
    empty = _index_bytes(cache.tokenizer, [])
    total = empty  # the pack counts whole: clip files and the index that lists them
    budget = None if max_mb is None else max_mb * 1e6
    for i in _spread_order(len(cache))[k - 1 :: n]:
        clip = cache[i]
        packed = quantise(clip.latents)
        data = save({**packed, "T_world_from_ego": torch.as_tensor(clip.T_world_from_ego)})
        size = len(data) + _index_bytes(cache.tokenizer, [cache.rows[i]]) - empty + 2
        if budget is not None and total + size > budget:  # + 2: the separator between two index rows
            continue
        path = child_path(out, clip.meta.key, ext="safetensors", what="clip key")
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)
        worst = max(worst, float(((packed["scale"] / 2) / std[None, :]).max()))
        rows.append((i, cache.rows[i]))
        total += size
    if not rows:
        raise DrivewmError(f"{cache_dir}: no clip fits in {max_mb} MB")
    rows = [row for _, row in sorted(rows, key=lambda pair: pair[0])]  # the cache's own order
    write_json(out / PACK_INDEX, _index(cache.tokenizer, rows))
    total = sum(child_path(out, r["key"], ext="safetensors").stat().st_size for r in rows)
    total += (out / PACK_INDEX).stat().st_size
    return {"clips": len(rows), "of": len(cache), "bytes": total, "max_error_in_std": worst}


def _index(tokenizer: dict, rows: list[dict]) -> dict:
    return {"format_version": PACK_VERSION, "tokenizer": tokenizer, "clips": rows}


def _index_bytes(tokenizer: dict, rows: list[dict]) -> int:
    """Size of ``pack.json`` listing ``rows``, as write_json writes it."""
    return len((json.dumps(_index(tokenizer, rows), indent=2) + "\n").encode())


def _spread_order(n: int) -> list[int]:
    """0..n-1 in an order whose every prefix spreads over the range (halving strides), so a size
    limit keeps clips from all of the cache rather than its first drives."""
    seen, out, stride = set(), [], n
    while stride >= 1:
        for i in range(0, n, stride):
            if i not in seen:
                seen.add(i)
                out.append(i)
        stride //= 2
    return out


def unpack(pack_dirs: str | Path | list[str | Path], cache_dir: str | Path) -> int:
    """Write the packed clips of one pack folder, or of several packed from one cache (``--part``), as a
    latent cache at ``cache_dir``; returns the clip count. Packs of different tokenizers, or holding one
    clip twice, are refused before anything is written."""
    pack_dirs = [Path(p) for p in (pack_dirs if isinstance(pack_dirs, list) else [pack_dirs])]
    cache_dir = Path(cache_dir)
    indexes = [_read_index(p) for p in pack_dirs]
    for p, index in zip(pack_dirs[1:], indexes[1:]):
        if index["tokenizer"] != indexes[0]["tokenizer"]:
            raise DrivewmError(f"{p}: packed from latents of another tokenizer than {pack_dirs[0]}")
    seen: dict[str, Path] = {}
    for p, index in zip(pack_dirs, indexes):
        for row in index["clips"]:
            if row["key"] in seen:
                raise DrivewmError(f"{p}: clip {row['key']} is in {seen[row['key']]} too (pack parts with --part K/N)")
            seen[row["key"]] = p
    cache_dir.mkdir(parents=True, exist_ok=True)
    rows = []
    for pack_dir, index in zip(pack_dirs, indexes):
        for row in index["clips"]:
            path = child_path(pack_dir, row["key"], ext="safetensors", what="clip key")
            try:
                tensors = load_file(str(path))
            except Exception as exc:  # safetensors raises several types for bad files
                raise DrivewmError(f"{path}: cannot read the packed clip ({exc.__class__.__name__})") from None
            meta = ClipMeta.from_json(row["meta"], str(path))
            rows.append(write_latent_clip(cache_dir, meta, dequantise(tensors), tensors["T_world_from_ego"].numpy()))
    write_latent_index(cache_dir, indexes[0]["tokenizer"], rows)
    return len(rows)


def _read_index(pack_dir: Path) -> dict:
    try:
        index = json.loads((pack_dir / PACK_INDEX).read_text())
    except (OSError, ValueError) as exc:
        raise DrivewmError(f"{pack_dir}: not a latent pack ({exc.__class__.__name__}: {PACK_INDEX})") from None
    if not isinstance(index, dict) or index.get("format_version") != PACK_VERSION:
        raise DrivewmError(f"{pack_dir / PACK_INDEX}: not a latent pack of version {PACK_VERSION}")
    return index


def _part(text: str) -> tuple[int, int]:
    """argparse type of ``--part K/N``."""
    try:
        k, n = (int(x) for x in text.split("/"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected K/N (e.g. 2/3), got {text!r}") from None
    if not 1 <= k <= n:
        raise argparse.ArgumentTypeError(f"expected K/N with 1 <= K <= N, got {text!r}")
    return k, n


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("pack", help="latent cache -> 8-bit pack")
    p.add_argument("cache")
    p.add_argument("out")
    p.add_argument(
        "--max-mb",
        type=float,
        default=None,
        help="keep the clips that fit in this many MB (1e6 bytes), the index included",
    )
    p.add_argument(
        "--part", type=_part, default=(1, 1), metavar="K/N", help="every N-th clip from the K-th: N disjoint packs"
    )
    u = sub.add_parser("unpack", help="8-bit packs -> one latent cache")
    u.add_argument("pack", nargs="+", help="pack folders (parts of one cache: --part)")
    u.add_argument("cache")
    args = parser.parse_args(argv)
    try:
        if args.command == "pack":
            r = pack(args.cache, args.out, args.max_mb, args.part)
            print(
                f"packed {r['clips']} of {r['of']} clips, {r['bytes'] / 1e6:.1f} MB, largest error "
                f"{r['max_error_in_std']:.4f} latent std"
            )
        else:
            print(f"unpacked {unpack(args.pack, args.cache)} clips into {args.cache}")
    except DrivewmError as exc:
        raise SystemExit(f"latent_pack: {exc}") from None


if __name__ == "__main__":
    main()
