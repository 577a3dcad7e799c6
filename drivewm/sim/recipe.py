"""Dataset recipes (datasets/scenarios/*.yaml): several kinds of drives in one file.

Layout::

    common: {rig: nuscenes6, duration_s: 20.0, fps: 10.0}     # SimConfig fields for every entry
    drives:
      - {source: highway, scenario: highway, weather: clear, seed: 0, count: 2}
      - {source: sumo, scenario: grid, time_of_day: night, seed: 100}
      - {source: highway, scenario: merge, seed: 200, conditions: [clear:day, snow:day, clear:night]}

``count`` (default 1) drives per entry, seeds seed, seed + 1, ...; ``conditions`` (optional, in
``common`` or an entry) renders each of those drives once per WEATHER:TIME with the same seed, so
the same traffic and geometry (drivewm.sim.paired); every other key is a SimConfig field, checked
like any config (unknown keys and bad values are errors).
"""

from __future__ import annotations

from pathlib import Path

from drivewm.config import from_dict, load_yaml
from drivewm.errors import DrivewmError
from drivewm.sim.config import SimConfig
from drivewm.sim.paired import in_conditions, parse_conditions


def load_recipe(path: str | Path, overrides: dict | None = None) -> list[tuple[SimConfig, int]]:
    """(config, drive count) per entry of the recipe at ``path`` (one per condition of an entry with
    ``conditions``); ``overrides`` replace fields (and ``conditions``) in all."""
    data = load_yaml(path)
    unknown = sorted(set(data) - {"common", "drives"})
    if unknown or not isinstance(data.get("drives"), list) or not data["drives"]:
        raise DrivewmError(
            f"{path}: a recipe has 'common' (optional) and a non-empty 'drives' list; unknown keys {unknown}"
        )
    common = data.get("common") or {}
    out = []
    for i, entry in enumerate(data["drives"]):
        if not isinstance(entry, dict):
            raise DrivewmError(f"{path}: drives[{i}] must be a mapping")
        fields = {**common, **entry, **(overrides or {})}
        count = fields.pop("count", 1)
        conditions = fields.pop("conditions", None)
        if not isinstance(count, int) or count < 1:
            raise DrivewmError(f"{path}: drives[{i}].count must be a positive integer, got {count!r}")
        cfg = from_dict(SimConfig, fields, f"{path}: drives[{i}]")
        for one in in_conditions(cfg, _conditions(conditions, f"{path}: drives[{i}]")) if conditions else [cfg]:
            out.append((one, count))
    return out


def _conditions(value, where: str) -> list[tuple[str, str]]:
    if not isinstance(value, (str, list)):
        raise DrivewmError(f"{where}.conditions: expected a list of WEATHER:TIME, got {value!r}")
    try:
        return parse_conditions(value)
    except DrivewmError as exc:
        raise DrivewmError(f"{where}.conditions: {exc}") from None
