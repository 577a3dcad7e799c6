"""The latent cache: tokenizer latents of curated clips, read by the diffusion stages.

Layout, next to the clips: ``CLIPDIR/latents/NAME/`` (NAME defaults to the tokenizer folder's
name) holding ``index.json`` and one ``KEY.safetensors`` per clip with tensors
``latents`` ((V, c, t, h, w) float32, raw tokenizer output, *not* normalised) and
``T_world_from_ego`` ((T, 4, 4) float64), for a clip with layout ``layout_latents`` (the same
tokenizer's code of its layout video, shaped as ``latents``), and in the file's metadata ``source``: a fingerprint of
what made it (the clip's meta, pixels and poses, the tokenizer's files, the tiling), so that
``drivewm tokenizer encode`` keeps a file it would write again byte for byte. ``index.json``::

    {"format_version": 1,
     "tokenizer": {"path": ..., "config": {...}, "latent_mean": [c], "latent_std": [c]},
     "clips": [{"key": ..., "file": "KEY.safetensors", "meta": <ClipMeta json>}, ...]}

The diffusion stages normalise with ``(z - mean) / std`` per channel from the index.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import torch
from safetensors import safe_open
from safetensors.torch import load_file, save_file

from drivewm.atomic import atomic_path, write_json
from drivewm.clips.format import ClipMeta
from drivewm.errors import DrivewmError
from drivewm.paths import check_name, child_path, file_name, sanitize_name

LATENT_CACHE_VERSION = 1


def latent_cache_dir(clip_dir: str | Path, name: str | None = None, model_dir: str | Path | None = None) -> Path:
    """``CLIPDIR/latents/NAME``: ``name`` must be a safe name (drivewm.paths); without one, the
    tokenizer folder's name made safe. Both the writer (encode) and the readers (pretrain, posttrain) use this."""
    if name is None:
        if model_dir is None:
            raise DrivewmError(f"{clip_dir}: name the latent cache or the tokenizer folder")
        name = sanitize_name(Path(model_dir).resolve().name, "latents")
    return child_path(Path(clip_dir) / "latents", check_name(name, "latent cache name"))


@dataclasses.dataclass
class LatentClip:
    """One cached clip: ``latents`` (V, c, t, h, w) float32, ``T_world_from_ego`` (T, 4, 4), and
    ``layout_latents`` (V, c, t, h, w): the tokenizer's code of the clip's layout video
    (drivewm.layout.render), None for a clip without layout."""

    meta: ClipMeta
    latents: torch.Tensor
    T_world_from_ego: np.ndarray
    layout_latents: torch.Tensor | None = None


def write_latent_clip(
    cache_dir: str | Path,
    meta: ClipMeta,
    latents: torch.Tensor,
    T_world_from_ego: np.ndarray,
    source: str = "",
    layout_latents: torch.Tensor | None = None,
) -> dict:
    """Atomically write one clip's latents (and its layout video's, when given), with ``source`` (see
    the module docstring) in the file's metadata; returns its index row."""
    tensors = {
        "latents": _checked(latents, meta.key, "latents", None),
        "T_world_from_ego": torch.as_tensor(np.asarray(T_world_from_ego, dtype=np.float64)),
    }
    if layout_latents is not None:
        tensors["layout_latents"] = _checked(layout_latents, meta.key, "layout_latents", latents.shape)
    path = child_path(cache_dir, meta.key, ext="safetensors", what="clip key")
    with atomic_path(path) as tmp:
        save_file(tensors, str(tmp), metadata={"source": source})
    return {"key": meta.key, "file": path.name, "meta": meta.to_json()}


def _checked(latents: torch.Tensor, key: str, field: str, shape: torch.Size | None) -> torch.Tensor:
    """``latents`` as contiguous float32 on the CPU, refused unless (V, c, t, h, w), finite and ``shape``."""
    if latents.ndim != 5 or (shape is not None and latents.shape != shape):
        want = "(V, c, t, h, w)" if shape is None else f"the clip's {tuple(shape)}"
        raise DrivewmError(f"clip {key}: {field} must be {want}, got {tuple(latents.shape)}")
    if not torch.isfinite(latents).all():  # read back, one NaN turns every weight of a training run NaN
        raise DrivewmError(f"clip {key}: the tokenizer coded NaN or infinite {field}; not cached")
    return latents.detach().to(torch.float32).contiguous().cpu()


def cached_latent_row(cache_dir: str | Path, meta: ClipMeta, source: str) -> dict | None:
    """The index row of the latent file already in ``cache_dir`` for this clip when it was written
    from the same ``source`` fingerprint, else None (no file, an unreadable one, or another source)."""
    path = child_path(cache_dir, meta.key, ext="safetensors", what="clip key")
    if not source or not path.is_file():
        return None
    try:
        with safe_open(str(path), framework="pt") as f:
            written = (f.metadata() or {}).get("source")
    except Exception:  # a damaged file is written again, not trusted
        return None
    return {"key": meta.key, "file": path.name, "meta": meta.to_json()} if written == source else None


def write_latent_index(cache_dir: str | Path, tokenizer_info: dict, rows: list[dict]) -> None:
    """Atomically write ``index.json`` (see module docstring)."""
    write_json(
        Path(cache_dir) / "index.json",
        {"format_version": LATENT_CACHE_VERSION, "tokenizer": tokenizer_info, "clips": rows},
    )


def find_latent_cache(data_dir: Path, tokenizer_dir: Path | None, name: str | None) -> Path:
    """``data_dir`` itself if it is a cache, else ``data_dir/latents/<name or tokenizer folder name>``."""
    if (data_dir / "index.json").is_file():
        return data_dir
    if name is None and tokenizer_dir is None:
        raise DrivewmError(f"{data_dir}: name the latent cache (data.latents=NAME) or the tokenizer")
    cache = latent_cache_dir(data_dir, name, tokenizer_dir)
    if not (cache / "index.json").is_file():
        raise DrivewmError(
            f"{cache}: no latent cache; run 'drivewm tokenizer encode --model TOKDIR --data {data_dir}' first"
        )
    return cache


class LatentCache:
    """Read a latent cache folder. ``len(cache)``, ``cache[i]`` -> :class:`LatentClip`."""

    def __init__(self, cache_dir: str | Path):
        self.dir = Path(cache_dir)
        index_path = self.dir / "index.json"
        if not index_path.is_file():
            raise DrivewmError(f"{self.dir}: not a latent cache (no index.json); run 'drivewm tokenizer encode' first")
        try:
            index = json.loads(index_path.read_text())
        except ValueError:
            raise DrivewmError(f"{index_path}: not valid JSON") from None
        if not isinstance(index, dict) or index.get("format_version") != LATENT_CACHE_VERSION:
            raise DrivewmError(f"{index_path}: not a latent cache index of version {LATENT_CACHE_VERSION}")
        if not isinstance(index.get("tokenizer"), dict) or not isinstance(index.get("clips"), list):
            raise DrivewmError(f"{index_path}: needs 'tokenizer' (a mapping) and 'clips' (a list)")
        self.tokenizer: dict = index["tokenizer"]
        self.rows: list[dict] = [_check_row(row, index_path) for row in index["clips"]]
        if not self.rows:
            raise DrivewmError(f"{self.dir}: latent cache holds no clips")
        _check_stats(self.tokenizer, index_path)  # after: an empty cache has no statistics to name

    def __len__(self) -> int:
        return len(self.rows)

    @property
    def latent_mean(self) -> torch.Tensor:
        return torch.tensor(self.tokenizer["latent_mean"], dtype=torch.float32)

    @property
    def latent_std(self) -> torch.Tensor:
        return torch.tensor(self.tokenizer["latent_std"], dtype=torch.float32)

    def __getitem__(self, i: int) -> LatentClip:
        row = self.rows[i]
        path = child_path(self.dir, row["key"], ext="safetensors", what="clip key")
        try:
            tensors = load_file(str(path))
        except Exception as exc:  # safetensors raises several types for bad files
            raise DrivewmError(f"{path}: cannot read latents ({exc.__class__.__name__})") from None
        meta = ClipMeta.from_json(row["meta"], str(path))
        names = set(tensors) - {"layout_latents"}
        if names != {"latents", "T_world_from_ego"} or tensors["latents"].ndim != 5:
            raise DrivewmError(f"{path}: expected tensors latents (V, c, t, h, w) and T_world_from_ego")
        channels = len(self.tokenizer["latent_mean"])
        if tensors["latents"].shape[1] != channels:
            raise DrivewmError(
                f"{path}: latents have {tensors['latents'].shape[1]} channels, the index's stats {channels}"
            )
        layout = tensors.get("layout_latents")
        if layout is not None and layout.shape != tensors["latents"].shape:
            raise DrivewmError(f"{path}: layout_latents {tuple(layout.shape)} differ from the latents' shape")
        for name in ("latents", "layout_latents"):  # one NaN in a batch turns every weight of a run NaN
            if name in tensors and not torch.isfinite(tensors[name]).all():
                raise DrivewmError(f"{path}: {name} hold NaN or inf (a damaged file); re-encode the clip")
        return LatentClip(meta, tensors["latents"], tensors["T_world_from_ego"].numpy(), layout)


def _check_stats(tokenizer: dict, index_path: Path) -> None:
    """The index's statistics are one finite mean and one std > 0 per latent channel."""
    try:
        mean, std = (np.asarray(tokenizer.get(k), dtype=np.float64) for k in ("latent_mean", "latent_std"))
    except (TypeError, ValueError):  # strings, ragged lists
        mean = std = np.zeros(0)
    same = mean.ndim == std.ndim == 1 and 0 < len(mean) == len(std)
    if not (same and np.isfinite(mean).all() and np.isfinite(std).all() and (std > 0).all()):
        raise DrivewmError(
            f"{index_path}: tokenizer.latent_mean and latent_std must be one finite number per latent channel each, "
            f"every std > 0 (training divides by it); got {tokenizer.get('latent_mean')!r:.80} and "
            f"{tokenizer.get('latent_std')!r:.80}"
        )


def _check_row(row: object, index_path: Path) -> dict:
    """An index row names a clip whose file is exactly ``KEY.safetensors`` inside the cache."""
    if not isinstance(row, dict) or not isinstance(row.get("meta"), dict):
        raise DrivewmError(f"{index_path}: every clip row needs 'key', 'file' and 'meta'")
    key = check_name(row.get("key"), f"{index_path}: clip key")
    if row.get("file") != file_name(key, ext="safetensors") or row["meta"].get("key") != key:
        raise DrivewmError(f"{index_path}: clip {key}: file {row.get('file')!r} or meta key does not match the key")
    return row
