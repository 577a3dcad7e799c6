"""Prompts into per-view captions of the form the multi-view models were trained on."""

from __future__ import annotations

import numpy as np

from drivewm.curate.captions import camera_direction, classify_manoeuvre, prompt_view_captions
from drivewm.geometry import Rig
from drivewm.text.conditions import named_values

#: What a prompt that names no time of day is completed with: the captioner's own phrase for daylight.
DEFAULT_TIME_PHRASE = "during the day"


def view_captions(prompt: str, rig: Rig) -> list[str]:
    """Per-view captions in the curated clips' form ("The front-left camera view of ..."), unless
    the prompt already names a camera view (then it is every view's caption as it is).

    Every caption the models train on names its time of day (drivewm.curate.captions), so a prompt
    that names none ("steady rain on the motorway") left the model between day, dusk and night, and
    rain came out as a dark, night-like blur; such a prompt asks for daylight, as a driver would read
    it, and is completed with :data:`DEFAULT_TIME_PHRASE`. The eval still scores only what the prompt itself names."""
    if "camera view" in prompt:
        return [prompt] * len(rig.cameras)
    scene = prompt.strip().rstrip(".")
    scene = scene[:1].lower() + scene[1:]
    if not named_values(scene, "time_of_day"):
        scene = f"{scene}, {DEFAULT_TIME_PHRASE}"
    return [f"The {camera_direction(c)} camera view of {scene}." for c in rig.cameras]


def template_view_captions(prompt: str, rig: Rig, waypoints: np.ndarray, dt_s: float) -> list[str]:
    """``prompt`` rewritten into the curated clips' own template (``prompt_template``;
    drivewm.curate.captions.prompt_view_captions), its manoeuvre and speed those of ``waypoints``
    (W, 3) m, spaced ``dt_s`` from the ego's first position, as the captioner reads a logged clip's."""
    xyz = np.vstack([np.zeros((1, 3)), np.asarray(waypoints, dtype=np.float64)])
    step = np.diff(xyz[:, :2], axis=0)
    speed = np.linalg.norm(step, axis=1) / dt_s
    yaw = np.unwrap(np.arctan2(step[:, 1], step[:, 0]))
    manoeuvre = classify_manoeuvre(xyz, np.concatenate([yaw[:1], yaw]), np.concatenate([speed[:1], speed]))
    return prompt_view_captions(prompt, rig.cameras, manoeuvre, float(speed.mean()))
