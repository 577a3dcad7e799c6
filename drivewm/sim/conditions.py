"""Weather x time-of-day: how each condition lights textures and what it overlays on the image.

Lighting is baked into the world textures once per drive (they are built per drive anyway),
so a frame costs nothing extra for it; only depth fog, rain streaks, snow flakes and the ego's
headlight pool are per-frame work. Light sources (head/tail lights, street lamps, lit windows)
are emissive: at dusk and night they keep their brightness while everything else darkens.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.logs.types import TIMES_OF_DAY, WEATHERS

SUN_DIR_WORLD = np.array([0.45, 0.30, 0.84]) / np.linalg.norm([0.45, 0.30, 0.84])


@dataclasses.dataclass(frozen=True)
class Condition:
    """Rendering parameters of one weather x time-of-day pair (colours are RGB in [0, 1])."""

    weather: str
    time_of_day: str
    ambient: float  # overall light level multiplying every albedo
    tint: tuple[float, float, float]  # colour of the light
    saturation: float  # 1 = albedo colours, 0 = grey
    directional: float  # 0..1 weight of sun (Lambert) shading on box faces
    sky_top: tuple[float, float, float]
    sky_horizon: tuple[float, float, float]
    visibility_m: float  # Koschmieder visibility: contrast falls to 2% (fog), inf = no haze
    fog_rgb: tuple[float, float, float]
    lights_on: bool  # vehicle head and tail lights glow (dusk, night, fog, rain)
    snow: bool  # snow cover on the ground and roofs, flakes in the air
    wet: bool  # dark wet asphalt, rain streaks

    @property
    def lamps_on(self) -> bool:
        """Street lamps and windows glow (dusk and night only)."""
        return self.time_of_day != "day"

    def tinted(self, albedo: np.ndarray) -> np.ndarray:
        """Albedo (..., 3) in [0, 1] under this light's colour and saturation, before its brightness."""
        grey = albedo.mean(axis=-1, keepdims=True)
        return np.clip((grey + self.saturation * (albedo - grey)) * np.asarray(self.tint), 0.0, 1.0)

    def light(self, albedo: np.ndarray) -> np.ndarray:
        """Light albedo (..., 3) float in [0, 1] -> lit colour float in [0, 1]."""
        return np.clip(self.tinted(albedo) * self.ambient, 0.0, 1.0)

    def face_shade(self, normals_world: np.ndarray) -> np.ndarray:
        """Brightness factors (...) of faces with outward unit normals (..., 3) under this sky:
        ambient sky light plus Lambert's cosine law for the sun (weight ``directional``)."""
        lambert = np.maximum(0.0, normals_world @ SUN_DIR_WORLD)
        return (1.0 - self.directional) * 0.85 + self.directional * (0.55 + 0.5 * lambert)


def condition_for(weather: str, time_of_day: str) -> Condition:
    """The Condition for a weather (clear|overcast|rain|snow|fog) and time of day (day|dusk|night)."""
    if weather not in WEATHERS or time_of_day not in TIMES_OF_DAY:
        raise DrivewmError(
            f"condition {weather}/{time_of_day}: weather must be one of {WEATHERS}, time_of_day one of {TIMES_OF_DAY}"
        )
    w = {
        "clear": dict(
            ambient=1.0,
            saturation=1.0,
            directional=1.0,
            sky_top=(0.30, 0.50, 0.85),
            sky_horizon=(0.70, 0.80, 0.92),
            visibility_m=900.0,
            fog_rgb=(0.75, 0.82, 0.92),
        ),
        "overcast": dict(
            ambient=0.78,
            saturation=0.65,
            directional=0.25,
            sky_top=(0.62, 0.64, 0.67),
            sky_horizon=(0.80, 0.81, 0.82),
            visibility_m=450.0,
            fog_rgb=(0.78, 0.79, 0.80),
        ),
        "rain": dict(
            ambient=0.55,
            saturation=0.55,
            directional=0.15,
            sky_top=(0.36, 0.38, 0.41),
            sky_horizon=(0.52, 0.53, 0.55),
            visibility_m=160.0,
            fog_rgb=(0.50, 0.52, 0.54),
        ),
        "snow": dict(
            ambient=0.90,
            saturation=0.55,
            directional=0.2,
            sky_top=(0.78, 0.80, 0.83),
            sky_horizon=(0.90, 0.91, 0.93),
            visibility_m=140.0,
            fog_rgb=(0.88, 0.89, 0.91),
        ),
        "fog": dict(
            ambient=0.80,
            saturation=0.50,
            directional=0.1,
            sky_top=(0.80, 0.81, 0.82),
            sky_horizon=(0.82, 0.83, 0.84),
            visibility_m=45.0,
            fog_rgb=(0.80, 0.81, 0.82),
        ),
    }[weather]
    t = {"day": (1.0, (1.0, 1.0, 1.0)), "dusk": (0.55, (1.0, 0.78, 0.58)), "night": (0.13, (0.70, 0.78, 1.0))}[
        time_of_day
    ]
    params = dict(w)
    params["ambient"] *= t[0]
    if time_of_day != "day":
        k = 0.5 if time_of_day == "dusk" else 0.12
        dusk_sky = (
            np.array([(0.35, 0.30, 0.45), (0.95, 0.55, 0.30)])
            if time_of_day == "dusk"
            else np.array([(0.01, 0.015, 0.04), (0.05, 0.05, 0.09)])
        )
        params["sky_top"] = tuple((np.array(w["sky_top"]) * k + dusk_sky[0]) / (1 + k))
        params["sky_horizon"] = tuple((np.array(w["sky_horizon"]) * k + dusk_sky[1]) / (1 + k))
        params["fog_rgb"] = tuple(np.array(w["fog_rgb"]) * (0.55 if time_of_day == "dusk" else 0.08))
        params["directional"] *= 0.5 if time_of_day == "dusk" else 0.0
    return Condition(
        weather,
        time_of_day,
        tint=t[1],
        lights_on=time_of_day != "day" or weather in ("fog", "rain"),
        snow=weather == "snow",
        wet=weather == "rain",
        **params,
    )


def fog_weight(distance_m: np.ndarray, visibility_m: float) -> np.ndarray:
    """Transmittance exp(-3.912 d / V) (Koschmieder: 2% contrast left at the visibility V)."""
    if not math.isfinite(visibility_m):
        return np.ones_like(distance_m)
    return np.exp(-3.912 * distance_m / visibility_m)


def to_uint8(rgb01: np.ndarray) -> np.ndarray:
    return np.clip(rgb01 * 255.0 + 0.5, 0, 255).astype(np.uint8)
