"""Falling snow and rain in front of the lens: a few precomputed overlays per camera.

Each camera gets ``VARIANTS`` sparse overlays (pixel indices, alpha, colour) drawn once per
drive; each frame picks one by a hash of (seed, camera, timestamp), so frames differ, drives
repeat exactly, and a frame costs one sparse blend.
"""

from __future__ import annotations

import cv2
import numpy as np

from drivewm.geometry import Rig
from drivewm.sim.conditions import Condition
from drivewm.sim.road_edges import stable_unit

VARIANTS = 6


class ParticleOverlays:
    """Snow flakes (white discs) or rain streaks (slanted light lines) per camera."""

    def __init__(self, rig: Rig, cond: Condition, seed: int):
        self.kind = "snow" if cond.snow else "rain" if cond.wet else None
        self.seed = seed
        self.overlays: dict[str, list[tuple[np.ndarray, np.ndarray, np.ndarray]]] = {}
        if self.kind is None:
            return
        bright = 1.0 if cond.time_of_day == "day" else 0.45 if cond.time_of_day == "dusk" else 0.25
        for cam in rig.cameras:
            rng = np.random.default_rng([seed, 505, int(stable_unit(cam.name) * 2**32)])
            self.overlays[cam.name] = [self._make(cam.width, cam.height, rng, bright) for _ in range(VARIANTS)]

    def _make(self, width: int, height: int, rng: np.random.Generator, bright: float):
        alpha = np.zeros((height, width), np.float32)
        scale = width / 320.0
        if self.kind == "snow":
            for _ in range(int(260 * scale)):
                r = max(1, int(round(rng.uniform(0.6, 2.4) * scale)))
                cv2.circle(
                    alpha,
                    (int(rng.uniform(0, width)), int(rng.uniform(0, height))),
                    r,
                    float(rng.uniform(0.5, 0.95)),
                    -1,
                    cv2.LINE_AA,
                )
            color = np.array([245, 246, 250], np.float32) * bright
        else:
            for _ in range(int(160 * scale)):
                x, y = rng.uniform(0, width), rng.uniform(0, height)
                length = rng.uniform(6, 18) * scale
                cv2.line(
                    alpha,
                    (int(x), int(y)),
                    (int(x + 0.25 * length), int(y + length)),
                    float(rng.uniform(0.15, 0.35)),
                    1,
                    cv2.LINE_AA,
                )
            color = np.array([210, 215, 222], np.float32) * bright
        idx = np.flatnonzero(alpha > 0.02)
        return idx, alpha.reshape(-1)[idx, None], color

    def apply(self, img: np.ndarray, camera: str, timestamp_ns: int) -> None:
        """Blend this frame's overlay into ``img`` (H, W, 3) uint8 in place."""
        if self.kind is None:
            return
        variants = self.overlays[camera]
        idx, a, color = variants[int(stable_unit(self.seed, camera, timestamp_ns) * len(variants))]
        flat = img.reshape(-1, 3)
        flat[idx] = (flat[idx] * (1 - a) + color * a + 0.5).astype(np.uint8)
