"""Dataset recipes (drivewm/recipes/simulate/*.yaml): several kinds of drives in one file.

Layout::

    common: {rig: nuscenes6, duration_s: 20.0, fps: 10.0}     # SimConfig fields for every entry
    drives:
      - {source: highway, scenario: highway, weather: clear, seed: 0, count: 2}
      - {source: sumo, scenario: grid, time_of_day: night, seed: 100}
      - {source: highway, scenario: merge, seed: 200, conditions: [clear:day, snow:day, clear:night]}

``count`` (default 1) drives per entry, seeds seed, seed + 1, ...; ``conditions`` (optional, in
``common`` or an entry) renders each of those drives once per WEATHER:TIME with the same seed, so
the same traffic and geometry (drivewm.sim.paired); every other key is a SimConfig field. A dataset
is a list of runs rather than one run, so this is not a :class:`drivewm.recipe.RecipeBook` recipe,
but it resolves the same way: ``--recipe`` takes a path or a packaged name, and the command line's
fields and ``--set KEY=VALUE`` overrides apply to every entry through
:func:`drivewm.config.apply_overrides` (unknown keys and bad values are one-line errors naming the
file and the entry).
"""

from __future__ import annotations

from pathlib import Path

from drivewm import resources
from drivewm.config import MAX_SEED, apply_overrides, load_yaml
from drivewm.errors import DrivewmError
from drivewm.sim.config import SimConfig
from drivewm.sim.paired import in_conditions, parse_conditions

#: Where packaged dataset recipes live: drivewm/recipes/simulate/NAME.yaml.
RECIPES = "recipes/simulate"


def plan_drives(
    fields: dict, overrides: list[str] = (), drives: int = 1, conditions: str | None = None
) -> list[tuple[SimConfig, int]]:
    """One kind of drive (SimConfig ``fields`` with ``KEY=VALUE`` overrides), ``drives`` of it, once per
    WEATHER:TIME of ``conditions`` when given (same seeds, so the same drives)."""
    cfg = apply_overrides(SimConfig, fields, list(overrides), "drivewm simulate")
    _check_seeds(cfg, drives, "drivewm simulate")
    if conditions is None:  # "" is not "none given": it names no condition, an error
        return [(cfg, drives)]
    return [(c, drives) for c in in_conditions(cfg, parse_conditions(conditions))]


def load_recipe(
    name_or_path: str | Path, fields: dict | None = None, overrides: list[str] = ()
) -> list[tuple[SimConfig, int]]:
    """(config, drive count) per entry of a dataset recipe (a path or a packaged name), one per
    condition of an entry with ``conditions``; ``fields`` (e.g. the command line's flags, and
    ``conditions``) and then ``overrides`` replace fields in every entry."""
    path = resources.find(RECIPES, name_or_path, "simulate recipe")
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
        entry = {**common, **entry, **(fields or {})}
        count = entry.pop("count", 1)
        conditions = entry.pop("conditions", None)
        if not isinstance(count, int) or isinstance(count, bool) or count < 1:
            raise DrivewmError(f"{path}: drives[{i}].count must be a positive integer, got {count!r}")
        cfg = apply_overrides(SimConfig, entry, list(overrides), f"{path}: drives[{i}]")
        _check_seeds(cfg, count, f"{path}: drives[{i}]")
        variants = [cfg] if conditions is None else in_conditions(cfg, _conditions(conditions, f"{path}: drives[{i}]"))
        out += [(one, count) for one in variants]
    return out


def _check_seeds(cfg: SimConfig, drives: int, where: str) -> None:
    """Drive i uses seed + i, so the last seed must fit too: it had failed after the earlier drives were
    simulated and written (``--seed 2147483647 --drives 2``)."""
    last = cfg.seed + drives - 1
    if last > MAX_SEED:
        raise DrivewmError(
            f"{where}: {drives} drives from seed {cfg.seed} use seeds up to {last}, past the largest seed {MAX_SEED}"
        )


def _conditions(value, where: str) -> list[tuple[str, str]]:
    if not isinstance(value, (str, list)):
        raise DrivewmError(f"{where}.conditions: expected a list of WEATHER:TIME, got {value!r}")
    try:
        return parse_conditions(value)
    except DrivewmError as exc:
        raise DrivewmError(f"{where}.conditions: {exc}") from None
