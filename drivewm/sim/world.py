"""From a scene recording to a ready renderer: the drawn area, the props, the condition."""

from __future__ import annotations

import numpy as np

from drivewm.geometry import Rig, load_rig
from drivewm.sim.conditions import condition_for
from drivewm.sim.config import SimConfig
from drivewm.sim.props import place_props
from drivewm.sim.render import Renderer
from drivewm.sim.scene import SceneRecording

#: Ground texture extends this far around the ego's path (m); beyond, the ground is one colour
#: (at grazing angles that far away a texel is far below a pixel anyway).
TEXTURE_MARGIN_M = 110.0


def sim_rig(cfg: SimConfig) -> Rig:
    """The rig of ``cfg`` at the configured image size."""
    rig = load_rig(cfg.rig)
    # The renderer draws with the K it logs, so any aspect is self-consistent; stretch keeps the
    # rig's fields of view on both axes (fx != fy when the aspect changes).
    return rig if cfg.width is None else rig.scaled(cfg.width, cfg.height, fit="stretch")


def place_world_props(cfg: SimConfig, rec: SceneRecording) -> tuple[np.ndarray, np.ndarray]:
    """Place the props (lamps, buildings, trees) along the recording's roads into ``rec.road.props``
    (seeded: the same drive gets the same props, rendered or not); returns the drawn area (lo_xy, hi_xy)."""
    xy = rec.ego_xy()
    lo, hi = xy.min(axis=0) - TEXTURE_MARGIN_M, xy.max(axis=0) + TEXTURE_MARGIN_M
    rec.road.props = place_props(rec.road, lo, hi, cfg.seed, cfg.source == "sumo")
    return lo, hi


def build_renderer(cfg: SimConfig, rec: SceneRecording, rig: Rig, labels: bool = False) -> Renderer:
    """Place props along the recording's roads and build the renderer for its condition (``labels``:
    one that also draws label maps)."""
    lo, hi = place_world_props(cfg, rec)
    cond = condition_for(cfg.weather, cfg.time_of_day)
    return Renderer(rig, rec.road, cond, cfg.seed, lo, hi, cfg.source == "sumo", cfg.max_range_m, labels)
