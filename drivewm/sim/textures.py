"""Face textures of boxes (vehicles, buildings, lamps, trees), lit for the drive's condition.

Each object gets one texture per face (front, back, left, right, top, bottom) laid out as in
:mod:`drivewm.sim.boxes`: texel (0, 0) is the face's top-left corner seen from outside, rows go
down. Textures are built once per object per drive from a seeded generator, so the same
object looks the same from every camera and tick. Light sources are emissive (see conditions).
"""

from __future__ import annotations

import cv2
import numpy as np

from drivewm.logs.types import AgentBox
from drivewm.sim.conditions import Condition, to_uint8

GLASS = (0.10, 0.13, 0.17)
TYRE = (0.05, 0.05, 0.05)
SNOW = (0.93, 0.94, 0.97)
HEADLIGHT_DAY, HEADLIGHT_GLOW = (0.85, 0.86, 0.82), (1.0, 0.97, 0.85)
TAIL_DAY, TAIL_GLOW = (0.55, 0.05, 0.05), (1.0, 0.15, 0.10)
WINDOW_GLOW = (1.0, 0.82, 0.50)
LAMP_GLOW = (1.0, 0.92, 0.72)
BLINDS = ((0.85, 0.82, 0.72), (0.70, 0.70, 0.68), (0.55, 0.35, 0.25), (0.90, 0.90, 0.88), (0.40, 0.45, 0.55))


class _Canvas:
    """A face texture under construction: albedo (h, w, 3) float and emissive colour/mask.
    ``lamp`` marks emission of street lamps and windows (dusk and night only) as opposed to
    vehicle lights (also on in fog and rain)."""

    def __init__(self, width_m: float, height_m: float, px_per_m: float, rgb, lamp: bool = False):
        self.s, self.lamp = px_per_m, lamp
        self.w, self.h = max(2, int(round(width_m * px_per_m))), max(2, int(round(height_m * px_per_m)))
        self.albedo = np.empty((self.h, self.w, 3), np.float32)
        self.albedo[:] = rgb
        self.emissive = np.zeros((self.h, self.w, 3), np.float32)
        self.glow = np.zeros((self.h, self.w), bool)

    def rect(self, a0: float, b0: float, a1: float, b1: float, rgb, glow=None) -> None:
        """Fill the face rectangle from (a0, b0) to (a1, b1) metres (a across, b down)."""
        c0, r0 = int(round(a0 * self.s)), int(round(b0 * self.s))
        c1, r1 = max(c0 + 1, int(round(a1 * self.s))), max(r0 + 1, int(round(b1 * self.s)))
        self.albedo[r0:r1, c0:c1] = rgb
        if glow is not None:
            self.emissive[r0:r1, c0:c1] = glow
            self.glow[r0:r1, c0:c1] = True

    def circle(self, a: float, b: float, r: float, rgb) -> None:
        cv2.circle(
            self.albedo,
            (int(round(a * self.s)), int(round(b * self.s))),
            max(1, int(round(r * self.s))),
            rgb,
            -1,
            cv2.LINE_AA,
        )

    def grain(self, rng: np.random.Generator, amp: float) -> None:
        self.albedo *= 1.0 + amp * rng.standard_normal((self.h, self.w, 1)).astype(np.float32)

    def lit(self, cond: Condition) -> np.ndarray:
        out = cond.light(np.clip(self.albedo, 0, 1))
        if cond.lamps_on if self.lamp else cond.lights_on:
            out[self.glow] = self.emissive[self.glow]
        return to_uint8(out)


def object_textures(box: AgentBox, cond: Condition, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Lit uint8 RGB textures for the faces of ``box``, by its category."""
    builder = {
        "building": _building,
        "pole": _plain,
        "marker": _plain,
        "trunk": _trunk,
        "crown": _crown,
        "lamp": _lamp,
    }.get(box.category, _vehicle)
    return builder(box, cond, rng)


def face_size_m(face: str, size_lwh: np.ndarray) -> tuple[float, float]:
    """(width, height) in metres of a face of a box with size (length, width, height)."""
    length, width, height = size_lwh
    return {
        "front": (width, height),
        "back": (width, height),
        "left": (length, height),
        "right": (length, height),
        "top": (width, length),
        "bottom": (width, length),
    }[face]


def _vehicle(box: AgentBox, cond: Condition, rng: np.random.Generator) -> dict[str, np.ndarray]:
    length, width, height = box.size_lwh
    body = np.asarray(box.color_rgb, np.float32)
    van = box.category in ("van", "truck")
    side = _Canvas(length, height, 24, body)
    glass_from = 0.08 * length if van else 0.27 * length
    side.rect(glass_from, 0.12 * height, 0.85 * length, 0.45 * height, GLASS)
    for a in (0.5, 0.68) if not van else (0.3,):
        side.rect(a * length, 0.10 * height, a * length + 0.10, 0.47 * height, body * 0.9)  # pillars
        side.rect(a * length - 0.02, 0.47 * height, a * length + 0.02, 0.86 * height, body * 0.45)  # door gaps
    side.rect(0.0, 0.86 * height, length, height, (0.08, 0.08, 0.08))
    for a in (0.18 * length, 0.80 * length):
        side.circle(a, height - 0.33, 0.33, TYRE)
        side.circle(a, height - 0.33, 0.16, (0.55, 0.55, 0.57))
    side.rect(0.0, 0.55 * height, 0.06, 0.62 * height, HEADLIGHT_DAY, HEADLIGHT_GLOW)
    side.rect(length - 0.06, 0.55 * height, length, 0.62 * height, TAIL_DAY, TAIL_GLOW)
    side.grain(rng, 0.03)
    left = side.lit(cond)
    return {
        "left": left,
        "right": left[:, ::-1].copy(),
        "front": _vehicle_end(box, cond, rng, True),
        "back": _vehicle_end(box, cond, rng, False),
        "top": _top(width, length, body * 0.95, cond, rng, 24),
        "bottom": _plain_tex(width, length, (0.06, 0.06, 0.06), cond, rng, 8),
    }


def _vehicle_end(box: AgentBox, cond: Condition, rng: np.random.Generator, front: bool) -> np.ndarray:
    _, width, height = box.size_lwh
    body = np.asarray(box.color_rgb, np.float32)
    c = _Canvas(width, height, 24, body)
    c.rect(0.08 * width, 0.06 * height, 0.92 * width, (0.42 if front else 0.38) * height, GLASS)
    lamp, glow = (HEADLIGHT_DAY, HEADLIGHT_GLOW) if front else (TAIL_DAY, TAIL_GLOW)
    c.rect(0.04 * width, 0.52 * height, 0.24 * width, 0.62 * height, lamp, glow)
    c.rect(0.76 * width, 0.52 * height, 0.96 * width, 0.62 * height, lamp, glow)
    if front:
        c.rect(0.32 * width, 0.55 * height, 0.68 * width, 0.68 * height, (0.07, 0.07, 0.08))  # grille
    c.rect(0.38 * width, 0.72 * height, 0.62 * width, 0.80 * height, (0.92, 0.92, 0.90))  # plate
    c.rect(0.0, 0.86 * height, width, height, (0.08, 0.08, 0.08))
    c.grain(rng, 0.03)
    return c.lit(cond)


def _top(width: float, length: float, rgb, cond: Condition, rng: np.random.Generator, px_per_m: float) -> np.ndarray:
    return _plain_tex(width, length, SNOW if cond.snow else rgb, cond, rng, px_per_m, 0.04)


def _plain_tex(width, height, rgb, cond, rng, px_per_m, grain=0.06) -> np.ndarray:
    c = _Canvas(width, height, px_per_m, rgb)
    c.grain(rng, grain)
    return c.lit(cond)


def _plain(box: AgentBox, cond: Condition, rng: np.random.Generator) -> dict[str, np.ndarray]:
    return {
        f: _plain_tex(*face_size_m(f, box.size_lwh), box.color_rgb, cond, rng, 16)
        for f in ("front", "back", "left", "right", "top", "bottom")
    }


def _lamp(box: AgentBox, cond: Condition, rng: np.random.Generator) -> dict[str, np.ndarray]:
    tex = _plain(box, cond, rng)
    c = _Canvas(*face_size_m("bottom", box.size_lwh), 16, (0.85, 0.85, 0.80), lamp=True)
    c.rect(0.05, 0.2, box.size_lwh[1] - 0.05, box.size_lwh[0] - 0.1, (0.9, 0.9, 0.85), LAMP_GLOW)
    tex["bottom"] = c.lit(cond)
    return tex


def _trunk(box: AgentBox, cond: Condition, rng: np.random.Generator) -> dict[str, np.ndarray]:
    out = {}
    for f in ("front", "back", "left", "right", "top", "bottom"):
        c = _Canvas(*face_size_m(f, box.size_lwh), 20, box.color_rgb)
        c.albedo *= 1.0 + 0.25 * rng.standard_normal((1, c.w, 1)).astype(np.float32)  # vertical bark streaks
        c.grain(rng, 0.08)
        out[f] = c.lit(cond)
    return out


def _crown(box: AgentBox, cond: Condition, rng: np.random.Generator) -> dict[str, np.ndarray]:
    out = {}
    for f in ("front", "back", "left", "right", "top", "bottom"):
        c = _Canvas(*face_size_m(f, box.size_lwh), 12, box.color_rgb)
        blobs = cv2.GaussianBlur(rng.standard_normal((c.h, c.w)).astype(np.float32), (0, 0), 1.2)
        c.albedo *= (1.0 + 1.6 * blobs)[..., None]
        if cond.snow and f != "bottom":
            c.albedo[blobs > (0.1 if f == "top" else 0.35)] = SNOW
        out[f] = c.lit(cond)
    return out


def _building(box: AgentBox, cond: Condition, rng: np.random.Generator) -> dict[str, np.ndarray]:
    out = {
        f: _facade(*face_size_m(f, box.size_lwh), box.color_rgb, cond, rng) for f in ("front", "back", "left", "right")
    }
    out["top"] = _top(box.size_lwh[1], box.size_lwh[0], (0.40, 0.40, 0.41), cond, rng, 6)
    out["bottom"] = _plain_tex(box.size_lwh[1], box.size_lwh[0], (0.2, 0.2, 0.2), cond, rng, 2)
    return out


def _facade(width: float, height: float, wall_rgb, cond: Condition, rng: np.random.Generator) -> np.ndarray:
    """A wall with floors of windows (3.2 m apart) and a ground-floor door; some windows lit at night."""
    c = _Canvas(width, height, 10, wall_rgb, lamp=True)
    c.albedo *= (
        1.0
        + 0.08
        * cv2.resize(
            rng.standard_normal((max(2, c.h // 8), max(2, c.w // 8))).astype(np.float32),
            (c.w, c.h),
            interpolation=cv2.INTER_CUBIC,
        )
    )[..., None]
    c.grain(rng, 0.06)
    n_cols = max(1, int((width - 1.0) // 2.8))
    margin = (width - n_cols * 2.8) / 2
    for floor_top in np.arange(height - 3.2, 0.4, -3.2):
        for k in range(n_cols):
            a0 = margin + k * 2.8 + 0.8
            c.rect(a0 - 0.12, floor_top + 0.7, a0 + 1.32, floor_top + 2.42, np.asarray(wall_rgb) * 0.6)  # frame
            glass = np.asarray(GLASS) * (0.8 + 0.9 * rng.uniform())
            lit = WINDOW_GLOW if rng.uniform() < 0.35 else None
            c.rect(a0, floor_top + 0.82, a0 + 1.2, floor_top + 2.3, glass, lit)
            if rng.uniform() < 0.6:  # a blind or curtain, lowered by a random amount: no two windows alike
                blind = np.asarray(BLINDS[int(rng.integers(len(BLINDS)))]) * rng.uniform(0.8, 1.1)
                c.rect(a0, floor_top + 0.82, a0 + 1.2, floor_top + 0.82 + rng.uniform(0.15, 1.3), blind)
    door = margin + 0.8 + 2.8 * int(rng.integers(n_cols))
    c.rect(door, height - 2.3, door + 1.3, height, (0.25, 0.18, 0.12))
    return c.lit(cond)
