"""Camera renderers of the futures (``--renderer``): each turns a future's layout (ego poses, road users'
boxes, the road) into one video per camera.

- ``sim``: the simulator's own renderer (drivewm.sim.render), the stand-in for the world model;
- ``model``: the world model generating each future from its layout. It plugs in here as another
  :class:`FutureCameras` (the same ``frames`` call); layout-conditioned generation is not in this
  version, so choosing it is refused before anything runs.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.multiverse.branch import Branch
from drivewm.sim.scene import SceneRecording, SceneTick


class FutureCameras(Protocol):
    """Renders ticks of a branch into camera frames."""

    name: str
    """What the reports call it."""

    def frames(self, ticks: list[SceneTick]) -> dict[str, np.ndarray]:
        """uint8 RGB (T, H, W, 3) per camera of the branch's rig, one frame per tick."""
        ...


class SimCameras:
    """The simulator's renderer over the road and props of the whole branch (past and every future), so
    every future is drawn in the same world."""

    name = "sim"

    def __init__(self, branch: Branch):
        from drivewm.sim.world import build_renderer

        ticks = branch.past + [t for f in branch.futures for t in f]
        self.renderer = build_renderer(branch.sim, SceneRecording(branch.road, ticks, branch.tags), branch.rig)
        self.cameras = branch.rig.names

    def frames(self, ticks: list[SceneTick]) -> dict[str, np.ndarray]:
        shots = [self.renderer.render(t.T_world_from_ego, t.agents, t.timestamp_ns) for t in ticks]
        return {c: np.stack([s[c] for s in shots]) for c in self.cameras}


def check_renderer(name: str) -> None:
    """Refuse a renderer this version cannot run, before any simulation."""
    if name == "model":
        raise DrivewmError(
            "renderer model: generating cameras from a future's layout needs a layout-conditioned world model, "
            "which this version does not have; use --renderer sim"
        )


def make_cameras(name: str, branch: Branch) -> FutureCameras:
    """The renderer called ``name`` for ``branch``."""
    check_renderer(name)
    return SimCameras(branch)
