"""Layouts to generate from: the clips' own (``drivewm generate --layout CLIPS``), or a scenario whose
traffic is simulated without rendering a pixel (``drivewm generate --scenario NAME|FILE``).

Each :class:`LayoutSource` is one drive window: its layout (drivewm.layout.ClipLayout), the ego
waypoints the generator is conditioned on (``ClipMeta.trajectory_ego`` convention) and the pair id that
ties a generated clip to the simulator's true clip of the same window in any condition
(drivewm.sim.paired), so the benchmark can score it against that truth.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from drivewm.clips.shards import BadClip, read_clips
from drivewm.errors import DrivewmError
from drivewm.geometry import Rig
from drivewm.layout.clip_layout import ClipLayout
from drivewm.layout.recording import layout_from_recording
from drivewm.layout.render import render_layout
from drivewm.sim.config import ALL_SCENARIOS, SCENARIOS, SimConfig
from drivewm.sim.paired import drive_id


@dataclasses.dataclass
class LayoutSource:
    """One drive window to generate: ``waypoints`` (N, 3) m in its first ego frame, ``dt_s`` apart."""

    key: str
    layout: ClipLayout
    waypoints: np.ndarray
    dt_s: float
    pair_id: str = ""
    tags: dict[str, str] = dataclasses.field(default_factory=dict)


def layouts_from_clips(clip_dir: str | Path, limit: int | None = None) -> list[LayoutSource]:
    """The layout of every clip of ``clip_dir`` (at most ``limit``). A clip without layout, an
    unreadable one, or one without ego waypoints is a one-line DrivewmError naming it: ``--layout``
    regenerates the clips' drive, so none may be silently left out."""
    out = []
    for clip in read_clips(clip_dir):
        if isinstance(clip, BadClip):
            raise DrivewmError(f"--layout {clip_dir}: {clip.reason}")
        layout = clip.layout()  # validated: NaN poses, unknown classes are named
        if layout is None:
            raise DrivewmError(
                f"--layout {clip_dir}: clip {clip.key} has no layout (its log had no /agents or /road); "
                "curate logs with boxes and road lines"
            )
        if not clip.meta.trajectory_ego:
            raise DrivewmError(f"--layout {clip_dir}: clip {clip.key} has no trajectory_ego to drive along")
        waypoints = np.asarray(clip.meta.trajectory_ego, dtype=np.float64)
        tags = {k: v for k, v in clip.meta.tags.items() if k in ("scenario", "source", "road_type")}
        out.append(LayoutSource(clip.key, layout, waypoints, clip.meta.trajectory_dt_s, clip.meta.pair_id, tags))
        if limit is not None and len(out) >= limit:
            break
    if not out:
        raise DrivewmError(f"--layout {clip_dir}: no clips found")
    return out


def scenario_config(scenario: str, seed: int, duration_s: float, fps: float) -> SimConfig:
    """The drive of ``--scenario``: a scenario name (drivewm.sim.config.SCENARIOS) or a simulate recipe
    YAML whose first drive is taken."""
    if scenario in ALL_SCENARIOS:
        source = next(s for s, names in SCENARIOS.items() if scenario in names)
        cfg = SimConfig(source=source, scenario=scenario, seed=seed, duration_s=duration_s, fps=fps)
    elif Path(scenario).suffix in (".yaml", ".yml"):
        from drivewm.sim.recipe import load_recipe

        cfg = load_recipe(scenario)[0][0]
    else:
        raise DrivewmError(f"--scenario {scenario!r}: not one of {list(ALL_SCENARIOS)} and not a recipe YAML")
    cfg.validate()
    return cfg


def layouts_from_scenario(cfg: SimConfig, num_frames: int, clips: int, num_waypoints: int) -> list[LayoutSource]:
    """``clips`` consecutive windows of ``num_frames`` ticks of the drive ``cfg``, its traffic simulated
    (highway-env or SUMO) and nothing rendered; the ego's own path is each window's trajectory."""
    from drivewm.multiview.trajectories import waypoints_from_poses
    from drivewm.sim.drives import record

    rec = record(cfg)
    if len(rec.ticks) < num_frames:
        raise DrivewmError(f"--scenario {cfg.scenario}: {len(rec.ticks)} ticks, a clip needs {num_frames}")
    poses = np.stack([t.T_world_from_ego for t in rec.ticks])
    name = drive_id(cfg)
    out = []
    for start in range(0, min(clips, len(rec.ticks) // num_frames) * num_frames, num_frames):
        layout = layout_from_recording(rec, cfg, start, num_frames)
        waypoints = waypoints_from_poses(poses, start, num_waypoints)
        tags = {"scenario": str(cfg.scenario), "source": cfg.source}
        key = f"{name}-t{start:06d}"  # curation's pair id of this window (drivewm.curate.stage.pair_id)
        out.append(LayoutSource(key, layout, waypoints, 1.0 / cfg.fps, key, tags))
    return out


def layout_video(rig: Rig, source: LayoutSource) -> np.ndarray:
    """The window's layout drawn into ``rig``'s cameras: uint8 RGB (V, T, H, W, 3). A layout that no
    camera sees is a one-line DrivewmError naming the window."""
    source.layout.check_seen_by(rig, f"layout {source.key}")
    return render_layout(rig, source.layout)


def layout_frames(rig: Rig, source: LayoutSource, size_wh: tuple[int, int], num_frames: int) -> np.ndarray:
    """The window's first ``num_frames`` layout frames drawn into ``rig`` scaled to ``size_wh`` (the
    generator's frame size): uint8 RGB (V, T, H, W, 3)."""
    if source.layout.num_frames < num_frames:
        raise DrivewmError(f"layout {source.key}: {source.layout.num_frames} frames, the model makes {num_frames}")
    return layout_video(rig.scaled(*size_wh), source)[:, :num_frames]
