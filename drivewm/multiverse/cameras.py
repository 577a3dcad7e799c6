"""Camera renderers of the futures (``--renderer``): each turns a future's layout (ego poses, road users'
boxes, the road) into one video per camera.

- ``sim``: the simulator's own renderer (drivewm.sim.render), the stand-in for the world model;
- ``model``: a multi-view world model generating each future from its ego trajectory (and its layout,
  where the model was trained with one; drivewm.multiverse.model_cameras), at the model's frame size.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Protocol

import numpy as np

from drivewm.geometry import Rig
from drivewm.multiverse.branch import Branch
from drivewm.multiverse.config import MultiverseConfig
from drivewm.sim.scene import SceneRecording, SceneTick


class FutureCameras(Protocol):
    """Renders ticks of a branch into camera frames."""

    name: str
    """``sim`` or ``model`` (``--renderer``)."""
    description: str
    """What it is and what it renders each future from, for the reports."""
    rig: Rig
    """The cameras the frames are of (at the size of the frames)."""
    sampling: dict | None
    """The model's sampler settings (drivewm.generate.config.SamplingConfig.record); None: no model."""

    def frames(self, ticks: list[SceneTick]) -> dict[str, np.ndarray]:
        """uint8 RGB (T, H, W, 3) per camera of the branch's rig, one frame per tick."""
        ...

    def futures_frames(self, futures: list[list[SceneTick]]) -> Iterable[dict[str, np.ndarray]]:
        """:meth:`frames` of each future in turn (the model renderer samples them together)."""
        ...


class SimCameras:
    """The simulator's renderer over the road and props of the whole branch (past and every future), so
    every future is drawn in the same world."""

    name = "sim"
    description = "the simulator's renderer (drivewm.sim.render), standing in for the world model"
    sampling = None

    def __init__(self, branch: Branch):
        from drivewm.sim.world import build_renderer

        ticks = branch.past + [t for f in branch.futures for t in f]
        self.renderer = build_renderer(branch.sim, SceneRecording(branch.road, ticks, branch.tags), branch.rig)
        self.rig = branch.rig

    def frames(self, ticks: list[SceneTick]) -> dict[str, np.ndarray]:
        shots = [self.renderer.render(t.T_world_from_ego, t.agents, t.timestamp_ns) for t in ticks]
        return {c: np.stack([s[c] for s in shots]) for c in self.rig.names}

    def futures_frames(self, futures: list[list[SceneTick]]) -> Iterable[dict[str, np.ndarray]]:
        return (self.frames(f) for f in futures)  # one future's frames in memory at a time


def make_cameras(cfg: MultiverseConfig, branch: Branch, generator=None, progress: bool = True) -> FutureCameras:
    """The renderer ``cfg.renderer`` for ``branch`` (``model``: ``generator``, drivewm.multiverse.model_cameras)."""
    if cfg.renderer == "model":
        from drivewm.multiverse.model_cameras import ModelCameras

        return ModelCameras(branch, generator, cfg.prompt, cfg.seed, cfg.model_steps, progress)
    return SimCameras(branch)
