"""Run recipes: the one way every stage's config is built (presets, recipe files, ``--set``).

A stage describes its runs with a :class:`RecipeBook`: the config dataclass, named presets (nested
dicts of field values: copy-and-change of the dataclass defaults, torchtitan style) and the default
preset. A run's config is resolved in one order, later wins::

    dataclass defaults  <-  preset  <-  recipe file "config"  <-  recipe file "overrides"  <-  --set

A recipe file is YAML with three optional keys (``--recipe`` takes its path, or the name of one of
the stage's packaged recipes, ``drivewm/recipes/<stage>/NAME.yaml``)::

    preset: small                       # a preset name of the stage
    config: {train: {steps: 2000}}      # nested field values
    overrides: [train.lr=1e-4]          # KEY=VALUE strings, exactly as --set takes them

A stage whose presets have a second axis beside the size (the tokenizer's compression and quantizer)
names it with a :class:`PresetAxis`: a flag (``--compression 8x8x8``, ``--fsq``) and a recipe key of
the same name, which change the size's fields before the recipe's ``config`` applies; ``--preset``
stays the size alone, as in every other stage.

The result is validated once, by :func:`drivewm.config.from_dict` (unknown keys, wrong types and
each config's ``validate()`` give a :class:`DrivewmError` naming the field), and printed by
``--dry-run``. Command modules add the same flags through :meth:`RecipeBook.add_arguments`, with
``--preset`` choices read from the book (and no ``--preset`` where a stage has one preset) and the
packaged recipe names in ``--recipe``'s help, so the CLI never repeats a registry by hand.
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, Generic, TypeVar

from drivewm import resources
from drivewm.config import apply_overrides, load_yaml, to_dict
from drivewm.errors import DrivewmError

C = TypeVar("C")
RECIPE_KEYS = ("preset", "config", "overrides")


@dataclasses.dataclass(frozen=True)
class PresetAxis:
    """An axis of a stage's presets beside the size: ``--NAME VALUE`` (or the switch ``--NAME`` /
    ``--no-NAME`` when there are no ``choices``), or the recipe key ``NAME``."""

    name: str
    """Flag and recipe key (``compression``: ``--compression``)."""
    default: str | bool
    """The value when neither the command line nor the recipe names one."""
    apply: Callable[[str, dict, Any], dict]
    """(preset name, the preset's fields, value) -> the fields for that value."""
    help: str
    """What the flag picks (its help line)."""
    choices: tuple[str, ...] = ()
    """The values the flag takes; () makes it an on/off switch."""
    metavar: str | None = None
    """How the help writes the flag's value (``TxHxW``)."""

    def check(self, value: Any, where: str) -> Any:
        """``value`` if the axis takes it, else a DrivewmError naming ``where``."""
        ok = value in self.choices if self.choices else isinstance(value, bool)
        if not ok:
            takes = ", ".join(self.choices) if self.choices else "true or false"
            raise DrivewmError(f"{where}: {self.name} must be one of {takes}, got {value!r}")
        return value


@dataclasses.dataclass(frozen=True)
class RecipeBook(Generic[C]):
    """How one stage's run config is made."""

    stage: str
    """Stage name used in messages (e.g. ``pretrain``)."""
    config: type[C]
    """The run's config dataclass."""
    presets: Mapping[str, dict]
    """Preset name -> nested field values applied over the dataclass defaults."""
    default: str
    """Preset used when neither the command line nor the recipe names one."""
    recipes: str = ""
    """Folder of the stage's packaged recipes, ``drivewm/recipes/<recipes>/NAME.yaml`` ('' = none)."""
    axes: tuple[PresetAxis, ...] = ()
    """Axes of the presets beside the size (:class:`PresetAxis`); most stages have none."""

    def resolve(
        self,
        preset: str | None = None,
        recipe: str | Path | None = None,
        overrides: list[str] = (),
        axes: Mapping[str, Any] | None = None,
    ) -> C:
        """The validated config of a run (see the module docstring for the order); ``axes``: the
        values of :attr:`axes` given on the command line (None or absent: the recipe's, else the default)."""
        path = self.recipe_path(recipe) if recipe is not None else None
        data = load_recipe(path, [a.name for a in self.axes]) if path is not None else {}
        name = preset or data.get("preset") or self.default
        if name not in self.presets:
            raise DrivewmError(f"{self.stage}: unknown preset {name!r}; known: {sorted(self.presets)}")
        where = f"{self.stage} recipe {path}" if path is not None else self.stage
        fields = self.preset_fields(name)
        for axis in self.axes:
            value = (axes or {}).get(axis.name)
            value = data.get(axis.name, axis.default) if value is None else value
            fields = axis.apply(name, fields, axis.check(value, where))
        base = deep_merge(fields, data.get("config", {}))
        return apply_overrides(self.config, base, [*data.get("overrides", []), *overrides], where)

    def preset_fields(self, name: str) -> dict:
        """The preset's field values (a deep copy), with ``preset`` recorded when the config has that field."""
        fields = deep_merge({}, self.presets[name])
        if "preset" in {f.name for f in dataclasses.fields(self.config)}:
            fields["preset"] = name
        return fields

    def recipe_path(self, recipe: str | Path) -> Path:
        """The recipe file: a path as given, else a packaged recipe of the stage by name."""
        if not self.recipes:
            return Path(recipe)
        return resources.find(f"recipes/{self.recipes}", recipe, f"{self.stage} recipe")

    def recipe_names(self) -> list[str]:
        """Names of the stage's packaged recipes."""
        return resources.names(f"recipes/{self.recipes}") if self.recipes else []

    def add_arguments(self, parser: argparse.ArgumentParser) -> None:
        """``--preset`` (choices from the book, if several), a flag per axis, ``--recipe``, ``--set
        KEY=VALUE`` and ``--dry-run``."""
        packaged = self.recipe_names() if self.recipes else None
        add_recipe_arguments(parser, self.presets, self.default, packaged, self.axes)

    def from_args(self, args: argparse.Namespace, overrides: Iterable[str] = ()) -> C:
        """The config named by the flags of :meth:`add_arguments`, then ``overrides`` (``KEY=VALUE``)."""
        axes = {a.name: getattr(args, a.name) for a in self.axes}
        return self.resolve(getattr(args, "preset", None), args.recipe, [*args.overrides, *overrides], axes)


def add_override_arguments(parser: argparse.ArgumentParser, what: str = "a config field", run: str = "run") -> None:
    """``--set KEY=VALUE`` (repeatable, into ``args.overrides``) and ``--dry-run``: the same in every stage."""
    parser.add_argument(
        "--set", dest="overrides", action="append", default=[], metavar="KEY=VALUE", help=f"override {what}"
    )
    parser.add_argument("--dry-run", action="store_true", help=f"print the resolved config of the {run} and exit")


def add_recipe_arguments(
    parser: argparse.ArgumentParser,
    presets: Iterable[str],
    default: str,
    packaged: list[str] | None = None,
    axes: Iterable[PresetAxis] = (),
) -> None:
    """The recipe flags with ``--preset`` choices ``presets`` (omitted when there is only one), a flag
    per preset axis, and the stage's ``packaged`` recipe names in the help. Command modules that must
    not import a stage's (heavy) config classes to build the parser call it with the preset names;
    handlers resolve through the book."""
    presets, axes = list(presets), list(axes)
    if len(presets) > 1:
        help_text = f"size (default: the recipe's, else {default})"
        parser.add_argument("--preset", choices=presets, metavar="SIZE", help=f"{help_text}: %(choices)s")
    for axis in axes:
        if axis.choices:
            help_text = f"{axis.help} (default: the recipe's, else {axis.default}): %(choices)s"
            parser.add_argument(f"--{axis.name}", choices=axis.choices, metavar=axis.metavar, help=help_text)
        else:
            help_text = f"{axis.help} (default: the recipe's, else {'on' if axis.default else 'off'})"
            parser.add_argument(f"--{axis.name}", action=argparse.BooleanOptionalAction, help=help_text)
    keys = ", ".join(["preset", *(a.name for a in axes), "config", "overrides"])
    names = f"; packaged: {', '.join(packaged)}" if packaged else ""
    parser.add_argument("--recipe", help=f"recipe YAML (keys: {keys}) or a packaged recipe's name{names}")
    add_override_arguments(parser)


def load_recipe(path: str | Path, axes: Iterable[str] = ()) -> dict:
    """Read a recipe YAML (keys :data:`RECIPE_KEYS` and the stage's preset ``axes``); unknown keys or
    badly typed values give a DrivewmError naming the file."""
    data = load_yaml(path)
    keys = [*RECIPE_KEYS, *axes]
    unknown = sorted(set(data) - set(keys))
    if unknown:
        raise DrivewmError(
            f"{path}: unknown recipe key(s) {unknown}; a recipe has {keys} (config fields go under 'config:')"
        )
    if "preset" in data and not isinstance(data["preset"], str):
        raise DrivewmError(f"{path}: 'preset' must be a preset name")
    if not isinstance(data.get("config", {}), dict):
        raise DrivewmError(f"{path}: 'config' must be a mapping of config fields")
    overrides = data.get("overrides", [])
    if not isinstance(overrides, list) or not all(isinstance(o, str) for o in overrides):
        raise DrivewmError(f"{path}: 'overrides' must be a list of KEY=VALUE strings")
    return data


def deep_merge(base: Mapping[str, Any], update: Mapping[str, Any]) -> dict:
    """``base`` with ``update`` merged in, recursing into mappings (neither input is modified)."""
    out = {k: deep_merge(v, {}) if isinstance(v, Mapping) else v for k, v in base.items()}
    for key, value in update.items():
        if isinstance(value, Mapping) and isinstance(out.get(key), Mapping):
            out[key] = deep_merge(out[key], value)
        else:
            out[key] = deep_merge(value, {}) if isinstance(value, Mapping) else value
    return out


def describe(cfg: Any) -> dict:
    """The resolved config as a plain dict (what ``--dry-run`` prints and every run saves)."""
    return to_dict(cfg)
