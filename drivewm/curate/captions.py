"""Captions: a :class:`Captioner` interface and the built-in template captioner.

A captioner sees a :class:`ClipInfo` (scene tags, measured properties, camera directions) and
returns a clip caption plus one caption per camera. Swap in a vision-language model by
implementing ``caption`` (frames are available in ``ClipInfo.frames``).
"""

from __future__ import annotations

import abc
import dataclasses
import importlib
import re

import numpy as np

from drivewm.errors import DrivewmError
from drivewm.geometry import Camera


@dataclasses.dataclass
class ClipInfo:
    """What a captioner may use. ``frames``: uint8 RGB (V, T, H, W, 3) in ``cameras`` order;
    ``manoeuvre``: from :func:`classify_manoeuvre` or "unknown"; ``speed_mps`` mean ego speed or None."""

    tags: dict[str, str]
    description: str
    cameras: list[Camera]
    manoeuvre: str
    speed_mps: float | None
    frames: np.ndarray | None = None


class Captioner(abc.ABC):
    """Turns a clip into (caption, {camera name: view caption})."""

    @abc.abstractmethod
    def caption(self, clip_info: ClipInfo) -> tuple[str, dict[str, str]]: ...


def classify_manoeuvre(xyz_ego0: np.ndarray, yaw_rad: np.ndarray, speed_mps: np.ndarray) -> str:
    """Ego manoeuvre over a clip from positions (T, 3) in the first frame's ego frame, unwrapped
    yaw (T,) and speed (T,): stopping, left/right turn (heading change > 20 deg), lane change
    (lateral shift > 2 m with little heading change), standing, or straight."""
    dyaw = float(np.degrees(yaw_rad[-1] - yaw_rad[0]))
    if speed_mps.max() < 0.5:
        return "standing"
    if speed_mps[-1] < 0.3 * max(float(speed_mps[0]), 1e-6) and speed_mps[-1] < 2.0:
        return "stopping"
    if abs(dyaw) > 20:
        return "left turn" if dyaw > 0 else "right turn"
    if abs(float(xyz_ego0[-1, 1])) > 2.0:
        return "lane change to the left" if xyz_ego0[-1, 1] > 0 else "lane change to the right"
    return "straight"


def camera_direction(cam: Camera) -> str:
    """Viewing direction of a camera in the ego frame, e.g. 'front-left', from its optical axis azimuth."""
    axis = cam.T_ego_from_cam[:3, 2]
    az = float(np.degrees(np.arctan2(axis[1], axis[0])))
    names = ["front", "front-left", "left", "back-left", "back", "back-right", "right", "front-right"]
    return names[int(np.round(az / 45.0)) % 8]


class TemplateCaptioner(Captioner):
    """Captions from scene tags and measured properties, no model needed."""

    def caption(self, clip_info: ClipInfo) -> tuple[str, dict[str, str]]:
        tags = clip_info.tags
        scene = _scene_phrase(tags)
        motion = _motion_phrase(clip_info.manoeuvre, clip_info.speed_mps)
        caption = f"{scene}{motion}."
        if clip_info.description:
            caption += f" {clip_info.description.strip().rstrip('.')}."
        views = {
            c.name: f"The {camera_direction(c)} camera view of {scene[0].lower()}{scene[1:]}{motion}."
            for c in clip_info.cameras
        }
        return caption, views


def _scene_phrase(tags: dict[str, str]) -> str:
    weather = tags.get("weather", "")
    time = tags.get("time_of_day", "")
    road = tags.get("road_type", "road").replace("_", " ")
    traffic = tags.get("traffic_density", "")
    when = " ".join(x for x in (weather if weather != "clear" else "clear-weather", time) if x and x != "unknown")
    traffic_part = f" in {traffic} traffic" if traffic and traffic != "unknown" else ""
    place = road if road != "unknown" else "road"
    return f"A {when + ' ' if when else ''}drive on {'an' if place[0] in 'aeiou' else 'a'} {place}{traffic_part}"


MANOEUVRE_PHRASES = {
    "straight": "driving straight",
    "left turn": "turning left",
    "right turn": "turning right",
    "lane change to the left": "changing lanes to the left",
    "lane change to the right": "changing lanes to the right",
    "stopping": "slowing to a stop",
}


def _motion_phrase(manoeuvre: str, speed_mps: float | None) -> str:
    if manoeuvre == "unknown" or speed_mps is None:
        return ""
    if manoeuvre == "standing":
        return ", the ego vehicle standing still"
    return f", the ego vehicle {MANOEUVRE_PHRASES[manoeuvre]} at {speed_mps * 3.6:.0f} km/h"


#: Scene tag -> value -> words of a free prompt that name it (whole words, lower case), in the
#: template's vocabulary (the simulator's road types and traffic densities); first match wins.
PROMPT_SCENE_WORDS: dict[str, dict[str, tuple[str, ...]]] = {
    "road_type": {
        "roundabout": ("roundabout", "traffic circle"),
        "merge": ("merge", "merging", "on-ramp", "slip road"),
        "intersection": ("intersection", "junction", "crossroads"),
        "urban_grid": ("city", "town", "urban", "street", "downtown"),
        "highway": ("highway", "motorway", "freeway", "expressway"),
    },
    "traffic_density": {
        "low": ("light traffic", "low traffic", "empty", "quiet"),
        "high": ("heavy traffic", "dense traffic", "congested", "busy", "rush hour"),
    },
}


def prompt_view_captions(prompt: str, cameras: list[Camera], manoeuvre: str, speed_mps: float) -> list[str]:
    """A free prompt rewritten into the template's per-view captions, the only words the shipped
    models were trained on (what a prompt upsampler does for Cosmos; here by keywords, no model):
    the weather and time of day it names (drivewm.text.conditions; default clear, by day), the road
    and traffic it names (:data:`PROMPT_SCENE_WORDS`; default a highway in medium traffic), and the
    ``manoeuvre`` (a :data:`MANOEUVRE_PHRASES` key) and speed of the trajectory it is generated under.
    Words the template has no place for are dropped."""
    from drivewm.text.conditions import caption_conditions

    text = prompt.lower()
    asked = caption_conditions(prompt)
    tags = {"weather": asked.get("weather", "clear"), "time_of_day": asked.get("time_of_day", "day")}
    for tag, values in PROMPT_SCENE_WORDS.items():
        named = [v for v, words in values.items() if any(re.search(rf"\b{re.escape(w)}\b", text) for w in words)]
        tags[tag] = named[0] if named else {"road_type": "highway", "traffic_density": "medium"}[tag]
    _, views = TemplateCaptioner().caption(ClipInfo(tags, "", cameras, manoeuvre, speed_mps))
    return [views[c.name] for c in cameras]


def load_captioner(spec: str) -> Captioner:
    """A captioner from ``"template"`` or an import path ``"package.module:ClassName"`` (constructed
    without arguments), so a recipe can swap in a vision-language model."""
    if spec == "template":
        return TemplateCaptioner()
    module_name, _, class_name = spec.partition(":")
    try:
        cls = getattr(importlib.import_module(module_name), class_name)
    except (ImportError, AttributeError, ValueError):
        raise DrivewmError(f"captioner {spec!r}: not 'template' or an importable 'module:Class'") from None
    captioner = cls()
    if not isinstance(captioner, Captioner):
        raise DrivewmError(f"captioner {spec!r}: {class_name} does not subclass drivewm.curate.captions.Captioner")
    return captioner
