"""Synthetic driving-like clips (sky, road with moving dashed lanes, moving car boxes) for tokenizer
tests that must not wait for the simulator; the key tests use the simulated ``sim_clip_dir``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from drivewm.clips import ClipMeta, ShardWriter
from drivewm.clips.format import clip_from_arrays
from drivewm.geometry import load_rig


def road_video(T: int, H: int, W: int, seed: int) -> np.ndarray:
    """uint8 (T, H, W, 3): a road scene moving towards the camera."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    horizon = H * rng.uniform(0.35, 0.5)
    sky = np.stack([110 + 60 * yy / H, 150 + 50 * yy / H, 230 - 20 * yy / H], -1)
    grass = np.stack([60 + 20 * np.sin(xx / 5 + yy / 3), 120 + 15 * np.cos(xx / 4), 50 + 0 * xx], -1)
    cars = [
        (rng.uniform(0.2, 0.8), rng.uniform(0.1, 0.6), rng.uniform(0, 255, 3), rng.uniform(-0.03, 0.03))
        for _ in range(3)
    ]
    frames = []
    for t in range(T):
        depth = np.clip((yy - horizon) / (H - horizon), 1e-3, 1)  # 0 at the horizon, 1 at the bottom
        road = np.abs(xx - W / 2) < (0.05 + 0.55 * depth) * W
        img = np.where((yy < horizon)[..., None], sky, grass)
        img = np.where((road & (yy >= horizon))[..., None], np.array([95.0, 95, 100]), img)
        dash = (np.sin(1 / depth * 6 + t * 0.8) > 0.2) & (np.abs(xx - W / 2) < 1 + 2 * depth) & (yy > horizon)
        img[dash] = 240
        for cx, cy, color, v in cars:
            y = horizon + (cy + 0.02 * t) * (H - horizon) * 0.8
            size = 4 + 20 * (y - horizon) / (H - horizon)
            x = (cx + v * t) * W
            box = (np.abs(xx - x) < size) & (np.abs(yy - y) < size * 0.6)
            img[box] = color
        frames.append(img)
    video = np.stack(frames) + rng.normal(0, 2, (T, H, W, 3))
    return np.clip(video, 0, 255).astype(np.uint8)


def write_synthetic_clips(out: Path, clips: int = 6, T: int = 17, H: int = 96, W: int = 160) -> Path:
    """``clips`` clips of the front3 rig at W x H into ``out`` (shards only)."""
    rig = load_rig("front3").scaled(W, H, fit="stretch")  # any test size, e.g. a height no multiple of 8
    with ShardWriter(out, "synthetic", max_clips=4) as writer:
        for c in range(clips):
            meta = ClipMeta(
                key=f"syn{c:03d}",
                source_log="synthetic",
                start_time_ns=0,
                fps=10.0,
                timestamps_ns=[i * 100_000_000 for i in range(T)],
                rig=rig.to_dict(),
                caption="a road",
            )
            frames = {cam: road_video(T, H, W, seed=100 * c + i) for i, cam in enumerate(rig.names)}
            writer.write(clip_from_arrays(meta, frames, np.repeat(np.eye(4)[None], T, axis=0)))
    return out
