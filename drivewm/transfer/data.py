"""Paired training samples from the latent cache: the same window of a drive in two conditions.

Clips are paired by ``ClipMeta.pair_id`` (drivewm.sim.paired, drivewm.curate): every ordered pair
(source, target) of clips with the same id in different conditions is a sample per camera view,
so any rig works and views are folded into the batch. A clip whose window a curation filter
dropped in the other conditions (a dark night window, say) has no partner and is not used.
The prompt of a sample is the source clip's caption retold in the target condition
(drivewm.transfer.retarget), exactly what ``drivewm transfer`` prompts with.
"""

from __future__ import annotations

import dataclasses
from collections import defaultdict
from pathlib import Path

import torch

from drivewm.clips.format import ClipMeta
from drivewm.clips.latents import LatentCache, LatentClip
from drivewm.diffusion.data import normalize_latents
from drivewm.errors import DrivewmError
from drivewm.transfer.retarget import TargetCondition, target_captions


@dataclasses.dataclass
class TransferSample:
    """One view of one (source, target) pair: normalised latents (c, t, h, w) of both, the prompt."""

    source: torch.Tensor
    target: torch.Tensor
    caption: str
    condition: TargetCondition
    fps: float


def clip_pairs(metas: list[ClipMeta], targets: list[TargetCondition] | None = None) -> list[tuple[int, int]]:
    """(source index, target index) of every ordered pair of clips with the same non-empty pair id and
    different conditions, in index order; ``targets`` (optional) keeps pairs whose target is one of them."""
    groups: dict[str, list[int]] = defaultdict(list)
    for i, meta in enumerate(metas):
        if meta.pair_id and TargetCondition.of(meta) is not None:
            groups[meta.pair_id].append(i)
    pairs = []
    for members in groups.values():
        for s in members:
            for t in members:
                cond_s, cond_t = TargetCondition.of(metas[s]), TargetCondition.of(metas[t])
                if cond_s != cond_t and (targets is None or cond_t in targets):
                    pairs.append((s, t))
    return sorted(pairs)


class PairDataset:
    """Samples (source clip, target clip, view) of a latent cache; all clips share one latent shape."""

    def __init__(
        self,
        cache_dir: str | Path,
        sigma_data: float = 0.5,
        targets: list[TargetCondition] | None = None,
        repeat: dict[TargetCondition, int] | None = None,
    ):
        """``targets``: keep the pairs whose target is one of them (None: all); ``repeat``: the samples of
        pairs whose target is a key there appear that many times (a rare or hard target drawn more
        often, every other target still in the batches)."""
        self.cache = LatentCache(cache_dir)
        self.sigma_data = sigma_data
        self.metas = [ClipMeta.from_json(r["meta"], f"{self.cache.dir} clip {r['key']}") for r in self.cache.rows]
        self.pairs = clip_pairs(self.metas, targets)
        if not self.pairs:
            raise DrivewmError(
                f"{self.cache.dir}: no clip pairs (clips of one pair_id in different conditions); simulate with "
                "--conditions and curate with --recipe transfer"
            )
        self._clips: dict[int, LatentClip] = {}
        repeat = repeat or {}
        self.items = [
            (s, t, v)
            for s, t in self.pairs
            for _ in range(repeat.get(TargetCondition.of(self.metas[t]), 1))
            for v in range(len(self.metas[s].cameras))
        ]
        first = self._clip(self.pairs[0][0])
        self.latent_shape = tuple(first.latents.shape[1:])  # (c, t, h, w)
        self.fps = float(first.meta.fps)
        self.num_frames = first.meta.num_frames

    def __len__(self) -> int:
        return len(self.items)

    def _clip(self, i: int) -> LatentClip:
        """Clip ``i`` of the cache, read once (a clip's latents are ~100 kB at the debug size)."""
        if i not in self._clips:
            clip = self.cache[i]
            if self._clips and tuple(clip.latents.shape[1:]) != self.latent_shape:
                raise DrivewmError(
                    f"{self.cache.dir}: clip {clip.meta.key} latents {tuple(clip.latents.shape[1:])} differ from "
                    f"{self.latent_shape}; encode every clip at one resolution"
                )
            self._clips[i] = clip
        return self._clips[i]

    def _normalized(self, i: int, view: int) -> torch.Tensor:
        z = self._clip(i).latents[view]
        return normalize_latents(z, self.cache.latent_mean, self.cache.latent_std, self.sigma_data)

    def __getitem__(self, i: int) -> TransferSample:
        s, t, view = self.items[i]
        src, tgt = self.metas[s], self.metas[t]
        camera = src.cameras[view]
        if tgt.cameras[view] != camera:
            raise DrivewmError(f"{self.cache.dir}: paired clips {src.key} and {tgt.key} have other cameras")
        condition = TargetCondition.of(tgt)
        _, views = target_captions(src, condition)
        return TransferSample(self._normalized(s, view), self._normalized(t, view), views[camera], condition, self.fps)
