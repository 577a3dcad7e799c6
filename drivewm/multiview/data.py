"""Multi-view training samples from the latent cache: one sample per clip, all views of a rig.

The cameras are picked by name (the ``--rig`` given to ``drivewm posttrain``, in its order) from
each clip; their geometry is the clip's own calibration (``ClipMeta.rig``), so clips from vehicles
with different mounting still get the right camera rays.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path

import numpy as np
import torch

from drivewm.clips.latents import LatentCache
from drivewm.diffusion.data import normalize_latents
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig
from drivewm.multiview.trajectories import resample_waypoints, waypoints_from_poses


@dataclasses.dataclass
class MultiViewSample:
    """One clip: ``latents`` (V, c, t, h, w) normalised, captions per view, waypoints (W, 3) m, rig, fps, layout;
    ``trajectory_known`` False for a clip without ego poses (its waypoints are zeros: post-training
    treats it as a trajectory-dropped clip)."""

    latents: torch.Tensor
    view_captions: list[str]
    trajectory: np.ndarray
    rig: Rig
    fps: float
    trajectory_known: bool = True
    layout: torch.Tensor | None = None
    """(V, c, t, h, w) the clip's layout video latents, normalised as ``latents``; None = no layout."""


class MultiViewDataset:
    """Clips of a latent cache restricted to ``camera_names`` (None = the first clip's cameras)."""

    def __init__(
        self, cache_dir: str | Path, camera_names: list[str] | None, num_waypoints: int, sigma_data: float = 0.5
    ):
        self.cache = LatentCache(cache_dir)
        self.sigma_data = sigma_data
        self.num_waypoints = num_waypoints
        first = self.cache[0]
        self.camera_names = list(camera_names or first.meta.cameras)
        self.latent_shape = tuple(first.latents.shape[1:])  # (c, t, h, w)
        self.fps = float(first.meta.fps)
        self.rig = self[0].rig
        self.trajectory_dt_s = float(first.meta.trajectory_dt_s or 1.0 / self.fps)
        t = self.latent_shape[1]
        self.temporal_compression = max(1, (first.meta.num_frames - 1) // (t - 1)) if t > 1 else 1

    def median_speed_mps(self, default: float) -> float:
        """Median speed over the first waypoint step of every clip whose ego motion is known (the named
        trajectories' default); ``default`` when no clip's is."""
        known = [s for s in (self[i] for i in range(len(self))) if s.trajectory_known and len(s.trajectory)]
        if not known:
            return default
        return float(np.median([np.linalg.norm(s.trajectory[0, :2]) / self.trajectory_dt_s for s in known]))

    def __len__(self) -> int:
        return len(self.cache)

    @functools.lru_cache(maxsize=256)  # noqa: B019 (bounded; a dataset lives as long as its training run)
    def __getitem__(self, i: int) -> MultiViewSample:
        clip = self.cache[i]
        where = f"{self.cache.dir} clip {clip.meta.key}"
        missing = [c for c in self.camera_names if c not in clip.meta.cameras]
        if missing:
            raise DrivewmError(f"{where}: no cameras {missing} (has {clip.meta.cameras}); choose another --rig")
        if tuple(clip.latents.shape[1:]) != self.latent_shape:
            raise DrivewmError(
                f"{where}: latents {tuple(clip.latents.shape[1:])} differ from the first clip's {self.latent_shape}"
            )
        views = [clip.meta.cameras.index(c) for c in self.camera_names]
        z = self._normalized(clip.latents[views])
        layout = None if clip.layout_latents is None else self._normalized(clip.layout_latents[views])
        captions = [clip.meta.view_captions.get(c) or clip.meta.caption for c in self.camera_names]
        rig = clip.meta.get_rig().subset(self.camera_names)
        known = clip.meta.ego_motion_known
        trajectory = self._trajectory(clip, where) if known else np.zeros((self.num_waypoints, 3))
        return MultiViewSample(z, captions, trajectory, rig, float(clip.meta.fps), known, layout)

    def _normalized(self, latents: torch.Tensor) -> torch.Tensor:
        return normalize_latents(latents, self.cache.latent_mean, self.cache.latent_std, self.sigma_data)

    def _trajectory(self, clip, where: str) -> np.ndarray:
        """(W, 3) ClipMeta.trajectory_ego resampled to W; from the ego poses when the clip has none."""
        if clip.meta.trajectory_ego:
            return resample_waypoints(np.asarray(clip.meta.trajectory_ego, dtype=np.float64), self.num_waypoints)
        if len(clip.T_world_from_ego) < 2 or not np.all(np.isfinite(clip.T_world_from_ego)):
            raise DrivewmError(f"{where}: no trajectory_ego and no usable ego poses to condition on")
        return waypoints_from_poses(clip.T_world_from_ego, 0, self.num_waypoints)
