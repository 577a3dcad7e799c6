"""Dataset recipes (datasets/scenarios/*.yaml): several kinds of drives in one file.

Layout::

    common: {rig: nuscenes6, duration_s: 20.0, fps: 10.0}     # SimConfig fields for every entry
    drives:
      - {source: highway, scenario: highway, weather: clear, seed: 0, count: 2}
      - {source: sumo, scenario: grid, time_of_day: night, seed: 100}

``count`` (default 1) drives per entry, seeds seed, seed + 1, ...; every other key is a
SimConfig field, checked like any config (unknown keys and bad values are errors).
"""

from __future__ import annotations

from pathlib import Path

from drivewm.config import from_dict, load_yaml
from drivewm.errors import DrivewmError
from drivewm.sim.config import SimConfig


def load_recipe(path: str | Path, overrides: dict | None = None) -> list[tuple[SimConfig, int]]:
    """(config, drive count) per entry of the recipe at ``path``; ``overrides`` replace fields in all."""
    data = load_yaml(path)
    unknown = sorted(str(k) for k in data if k not in ("common", "drives"))
    common = data.get("common") or {}
    if unknown or not isinstance(data.get("drives"), list) or not data["drives"] or not isinstance(common, dict):
        raise DrivewmError(
            f"{path}: a recipe has 'common' (optional mapping) and a non-empty 'drives' list; unknown keys {unknown}"
        )
    out = []
    for i, entry in enumerate(data["drives"]):
        if not isinstance(entry, dict):
            raise DrivewmError(f"{path}: drives[{i}] must be a mapping")
        fields = {**common, **entry, **(overrides or {})}
        count = fields.pop("count", 1)
        if not isinstance(count, int) or isinstance(count, bool) or count < 1:
            raise DrivewmError(f"{path}: drives[{i}].count must be a positive integer, got {count!r}")
        out.append((from_dict(SimConfig, fields, f"{path}: drives[{i}]"), count))
    return out
