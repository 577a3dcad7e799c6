"""The same drive in several conditions: paired renders for weather and time-of-day transfer.

A drive is fixed by everything in its :class:`SimConfig` except the condition (``weather``,
``time_of_day``): the traffic (highway-env / SUMO, seeded by ``seed`` alone), the props and the
world textures' random draws (seeded, drawn in the same order in every condition) do not depend
on it, so two configs that differ only in the condition render the same traffic, ego poses and
world geometry (tests/sim/test_paired.py). :func:`drive_id` names that drive; it is written as the
scene tag ``drive_id`` of every simulated log, so curation can pair clips across conditions
(``ClipMeta.pair_id``).
"""

from __future__ import annotations

import dataclasses
import hashlib
import json

from drivewm.errors import DrivewmError
from drivewm.logs.types import TIMES_OF_DAY, WEATHERS
from drivewm.sim.config import SimConfig

#: SimConfig fields that change the look of a drive, not the drive.
CONDITION_FIELDS = ("weather", "time_of_day")
#: SimConfig fields that add outputs to a drive's log, not change the drive.
OUTPUT_FIELDS = ("labels",)


def parse_condition(text: str) -> tuple[str, str]:
    """``"snow:night"`` -> ("snow", "night"); ``"snow"`` -> ("snow", "day"). Bad names raise DrivewmError."""
    weather, _, time_of_day = text.strip().partition(":")
    time_of_day = time_of_day or "day"
    if weather not in WEATHERS or time_of_day not in TIMES_OF_DAY:
        raise DrivewmError(
            f"condition {text!r}: expected WEATHER[:TIME] with weather in {list(WEATHERS)} "
            f"and time in {list(TIMES_OF_DAY)}"
        )
    return weather, time_of_day


def parse_conditions(spec: str | list[str]) -> list[tuple[str, str]]:
    """``"clear:day,snow:day"`` (or a list of such items) -> [(weather, time_of_day), ...], no repeats."""
    items = spec.split(",") if isinstance(spec, str) else list(spec)
    conditions = [parse_condition(str(item)) for item in items if str(item).strip()]
    if not conditions:
        raise DrivewmError(f"conditions {spec!r}: name at least one WEATHER:TIME")
    if len(set(conditions)) != len(conditions):
        raise DrivewmError(f"conditions {spec!r}: a condition is named twice")
    return conditions


def drive_id(cfg: SimConfig) -> str:
    """Name of the drive ``cfg`` renders, the same in every condition: source, scenario and seed for
    people, then a hash of every other field that changes the drive (rig, duration, size, traffic, ...;
    not the condition, not the extra outputs such as label maps)."""
    fields = {k: v for k, v in dataclasses.asdict(cfg).items() if k not in CONDITION_FIELDS + OUTPUT_FIELDS}
    digest = hashlib.sha256(json.dumps(fields, sort_keys=True).encode()).hexdigest()[:8]
    return f"{cfg.source}-{cfg.scenario}-s{cfg.seed:04d}-{digest}"


def in_conditions(cfg: SimConfig, conditions: list[tuple[str, str]]) -> list[SimConfig]:
    """``cfg`` rendered in each condition (same seed, so the same drive)."""
    return [dataclasses.replace(cfg, weather=w, time_of_day=t) for w, t in conditions]
