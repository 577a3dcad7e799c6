"""simulate / simulate_many: scenario source -> renderer -> MCAP drive log (through LogWriter).

The traffic source is imported for the drive that needs it (highway-env takes seconds to import and
brings pygame; libsumo is the other source), not at the top.
"""

from __future__ import annotations

import dataclasses
import os
from concurrent.futures import as_completed
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from drivewm.atomic import remove_dead_temporaries
from drivewm.layout.classes import LABEL_CLASSES
from drivewm.logs.types import SceneInfo
from drivewm.logs.writer import LogWriter
from drivewm.sim.config import SimConfig
from drivewm.sim.exposure import exposure_offsets_ns, state_at
from drivewm.sim.paired import drive_id
from drivewm.sim.scene import SceneRecording
from drivewm.sim.world import build_renderer, sim_rig
from drivewm.workers import process_pool


def record(cfg: SimConfig) -> SceneRecording:
    """Run the traffic simulator of ``cfg`` and return the scene-state stream (no pixels yet)."""
    cfg.validate()
    if cfg.source == "highway":
        os.environ.setdefault("SDL_VIDEODRIVER", "offscreen")  # highway-env imports pygame
        from drivewm.sim.source_highway import record_highway

        rec = record_highway(cfg)
    else:
        from drivewm.sim.source_sumo import record_sumo

        rec = record_sumo(cfg)
    rec.tags.update(
        weather=cfg.weather, time_of_day=cfg.time_of_day, traffic_density=cfg.traffic_density, drive_id=drive_id(cfg)
    )
    rec.description = describe(cfg, rec)
    return rec


def describe(cfg: SimConfig, rec: SceneRecording) -> str:
    """A one-sentence description of the drive from its configuration and what happened in it."""
    road = {
        "highway": "a multi-lane highway",
        "merge": "a highway with a merging on-ramp",
        "roundabout": "a roundabout",
        "intersection": "a four-way intersection",
        "grid": "a city street grid",
        "spider": "radial city streets",
        "random": "irregular city streets",
    }[cfg.scenario]
    light = {"day": "during the day", "dusk": "at dusk", "night": "at night"}[cfg.time_of_day]
    weather = {"clear": "clear weather", "overcast": "overcast weather", "rain": "rain", "snow": "snow", "fog": "fog"}[
        cfg.weather
    ]
    logged = rec.ticks[: cfg.num_ticks]
    speed = np.mean([t.ego_speed_mps for t in logged]) * 3.6
    others = int(np.mean([len(t.agents) for t in logged]))
    return (
        f"The ego car drives through {road} in {weather} {light}, at about {speed:.0f} km/h, "
        f"with {cfg.traffic_density} traffic ({others} other vehicles in the scene)."
    )


def simulate(cfg: SimConfig, out_path: str | Path, progress: bool = True) -> Path:
    """Simulate one drive and write it as an MCAP drive log at ``out_path`` (atomically)."""
    cfg.validate()
    rig = sim_rig(cfg)  # a bad rig fails before any simulation
    rec = record(cfg)
    renderer = build_renderer(cfg, rec, rig, labels=cfg.labels)
    out_path = Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    offsets = exposure_offsets_ns(len(rig.cameras), cfg.exposure_stagger_ms, 1e9 / cfg.fps)
    classes = LABEL_CLASSES if cfg.labels else ()
    scene = SceneInfo(dict(rec.tags), rec.description)
    with LogWriter(out_path, rig, scene, "jpeg", cfg.jpeg_quality, label_classes=classes) as writer:
        writer.write_road(rec.ticks[0].timestamp_ns, rec.road.road_lines())  # the optional /road channel
        writer.write_static(rec.ticks[0].timestamp_ns, rec.road.props)
        logged = rec.ticks[: cfg.num_ticks]
        for k, tick in enumerate(tqdm(logged, desc=out_path.name, unit="tick", disable=not progress, leave=False)):
            if cfg.exposure_stagger_ms > 0:
                _write_staggered(writer, renderer, rec, k, offsets, cfg.labels)
            elif cfg.labels:  # each label map is logged before the image it labels
                images, labels = renderer.render_with_labels(tick.T_world_from_ego, tick.agents, tick.timestamp_ns)
                writer.write_labels(tick.timestamp_ns, labels)
                writer.write_images(tick.timestamp_ns, images)
            else:
                writer.write_images(
                    tick.timestamp_ns, renderer.render(tick.T_world_from_ego, tick.agents, tick.timestamp_ns)
                )
            writer.write_pose(tick.timestamp_ns, tick.T_world_from_ego)
            writer.write_agents(tick.timestamp_ns, tick.agents)
    return out_path


def _write_staggered(writer, renderer, rec: SceneRecording, k: int, offsets_ns: list[int], labels: bool) -> None:
    """Each camera rendered from the world at its own exposure time and logged at that time (its label
    map first, with ``labels``)."""
    for cam, offset in zip(writer.rig.cameras, offsets_ns):
        t = rec.ticks[k].timestamp_ns + offset
        state = state_at(rec.ticks, k, t)
        if labels:
            image, label_map = renderer.render_camera_with_labels(cam.name, state.T_world_from_ego, state.agents, t)
            writer.write_labels(t, {cam.name: label_map})
        else:
            image = renderer.render_camera(cam.name, state.T_world_from_ego, state.agents, t)
        writer.write_image(cam.name, t, image)


def drive_name(cfg: SimConfig) -> str:
    """File name of a drive: source, scenario, conditions, seed (and the exposure stagger if any)."""
    stagger = f"_stagger{cfg.exposure_stagger_ms:g}ms" if cfg.exposure_stagger_ms > 0 else ""
    return f"{cfg.source}_{cfg.scenario}_{cfg.weather}_{cfg.time_of_day}_s{cfg.seed:04d}{stagger}.mcap"


def simulate_many(
    plan: list[tuple[SimConfig, int]], out_dir: str | Path, progress: bool = True, workers: int = 1
) -> list[Path]:
    """Every drive of ``plan`` into ``out_dir``; returns their paths. Each (config, n) entry is n drives
    with seeds cfg.seed, cfg.seed + 1, ... (a dataset recipe is one entry per line).

    A drive whose file already exists is kept (runs are deterministic and writes atomic, so a
    rerun of an interrupted call resumes where it stopped). ``workers`` > 1 simulates the drives of
    all entries in that many processes (each simulator and renderer is single-threaded; libsumo is
    one simulation per process).
    """
    out_dir = Path(out_dir)
    remove_dead_temporaries(out_dir)  # the unfinished logs of a killed run: resumed below from scratch
    todo = {}  # path -> config, in plan order; a drive named twice is simulated once
    for cfg, drives in plan:
        for i in range(drives):
            c = dataclasses.replace(cfg, seed=cfg.seed + i)
            todo.setdefault(out_dir / drive_name(c), c)
    missing = [(c, p) for p, c in todo.items() if not p.is_file()]
    bar = tqdm(total=len(todo), initial=len(todo) - len(missing), desc="drives", unit="drive", disable=not progress)
    if workers <= 1:
        for c, p in missing:
            simulate(c, p, progress)
            bar.update()
    else:
        with process_pool(workers, _worker_init) as pool:
            for future in as_completed([pool.submit(simulate, c, p, False) for c, p in missing]):
                future.result()
                bar.update()
    bar.close()
    return list(todo)


def _worker_init() -> None:
    cv2.setNumThreads(1)  # one process per core
