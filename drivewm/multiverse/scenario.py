"""Scenarios to branch from: a simulator scenario by name, or a scenario file.

A scenario file (YAML) names the simulated drive, the branch time and any road users to place when the
futures start (a built case: a stopped car ahead, a follower behind)::

    sim: {source: highway, scenario: highway, seed: 1, traffic_density: low}   # SimConfig fields
    at_s: 2.0                                                                  # optional (--at wins)
    placed: [{gap_m: 30.0, speed_mps: 0.0}, {gap_m: -15.0}]                   # PlacedVehicle fields

The drive's length, image size and frame rate come from the run (branch time + horizon); its weather
and time of day from the prompt's words when it names them.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from drivewm.config import apply_overrides, from_dict, load_yaml
from drivewm.errors import DrivewmError
from drivewm.logs.types import TIMES_OF_DAY, WEATHERS
from drivewm.multiverse.config import MultiverseConfig
from drivewm.sim.config import ALL_SCENARIOS, SCENARIOS, SimConfig
from drivewm.sim.ego_plan import PlacedVehicle

DEFAULT_AT_S = 2.0
SCENARIO_KEYS = ("sim", "at_s", "placed")


@dataclasses.dataclass
class Scenario:
    """A simulated drive to branch from."""

    sim: SimConfig
    at_s: float
    placed: list[PlacedVehicle]


def conditions_from_prompt(prompt: str) -> dict[str, str]:
    """The weather and time-of-day words of a prompt ("snow at night" -> weather snow, time_of_day night)."""
    words = prompt.lower().replace(",", " ").split()
    found = {}
    for field, names in (("weather", WEATHERS), ("time_of_day", TIMES_OF_DAY)):
        hits = [w for w in words if w in names]
        if hits:
            found[field] = hits[0]
    return found


def load_scenario(name_or_path: str, cfg: MultiverseConfig) -> Scenario:
    """The scenario of ``--scenario`` (a name of drivewm.sim.config.ALL_SCENARIOS or a YAML file)."""
    if name_or_path in ALL_SCENARIOS:
        source = next(s for s, names in SCENARIOS.items() if name_or_path in names)
        fields, at_s, placed = {"source": source, "scenario": name_or_path, "seed": cfg.seed}, None, []
    else:
        fields, at_s, placed = _read_file(name_or_path)
    at_s = cfg.at_s if cfg.at_s is not None else (DEFAULT_AT_S if at_s is None else at_s)
    if not at_s >= 0:
        raise DrivewmError(f"multiverse: branch time {at_s} s is before the drive starts")
    run = {"rig": cfg.rig, "fps": cfg.fps, "width": cfg.width, "height": cfg.height}
    fields = {**fields, **run, **conditions_from_prompt(cfg.prompt)}
    fields["duration_s"] = at_s + cfg.horizon_s + 1.0 / cfg.fps
    sim = apply_overrides(SimConfig, fields, [], f"scenario {name_or_path}")
    sim.validate()
    return Scenario(sim, float(at_s), placed)


def _read_file(path: str) -> tuple[dict, float | None, list[PlacedVehicle]]:
    if not Path(path).is_file():
        raise DrivewmError(f"scenario {path!r}: not one of {list(ALL_SCENARIOS)} and not a scenario file")
    data = load_yaml(path)
    unknown = sorted(str(k) for k in data if k not in SCENARIO_KEYS)
    if unknown or not isinstance(data.get("sim", {}), dict) or not isinstance(data.get("placed", []), list):
        raise DrivewmError(f"{path}: a scenario has 'sim' (mapping), 'at_s', 'placed' (list); unknown keys {unknown}")
    placed = [from_dict(PlacedVehicle, p, f"{path}: placed[{i}]") for i, p in enumerate(data.get("placed", []))]
    at_s = data.get("at_s")
    if at_s is not None and not isinstance(at_s, (int, float)):
        raise DrivewmError(f"{path}: at_s must be a number of seconds, got {at_s!r}")
    return dict(data.get("sim") or {}), at_s, placed
