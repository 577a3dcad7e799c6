"""The layout of a simulated drive without rendering a pixel: a :class:`SceneRecording` in, a :class:`ClipLayout` out.

``drivewm.sim.drives.record(cfg)`` runs the traffic (highway-env or SUMO) and gives the scene-state
stream; the props along the road are placed from the same seed as the renderer places them
(:func:`drivewm.sim.world.place_world_props`), so the layout of a recording is the layout of the
drive ``drivewm simulate`` would render, frame for frame.
"""

from __future__ import annotations

from drivewm.layout.build import RADIUS_M, layout_from_world
from drivewm.layout.clip_layout import ClipLayout
from drivewm.sim.config import SimConfig
from drivewm.sim.scene import SceneRecording
from drivewm.sim.world import place_world_props


def layout_from_recording(
    rec: SceneRecording, cfg: SimConfig, start: int = 0, num_frames: int | None = None, radius_m: float = RADIUS_M
) -> ClipLayout:
    """The layout of ticks [start, start + num_frames) of ``rec`` (default: every logged tick from
    ``start``), the first of them being ego0. Places the props into ``rec.road.props`` first if
    none are there."""
    if not rec.road.props:
        place_world_props(cfg, rec)
    end = cfg.num_ticks if num_frames is None else start + num_frames
    ticks = rec.ticks[start:end]
    where = f"recording {rec.tags.get('drive_id', '')} ticks {start}-{end - 1}"
    return layout_from_world(
        [t.timestamp_ns for t in ticks],
        [t.T_world_from_ego for t in ticks],
        [t.agents for t in ticks],
        rec.road.props,
        rec.road.road_lines(),
        where,
        radius_m,
    )
