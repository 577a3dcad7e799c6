"""Typed configs: dataclasses built from dicts/YAML, validated at the boundary, with overrides.

Every stage owns small config dataclasses. ``from_dict`` is the one place a config is checked:
it refuses unknown keys, wrong types and non-finite numbers, then runs the dataclass's own
``validate()`` (ranges: ``lr > 0``, ``steps >= 1``, ...; written with :func:`require`,
:func:`at_least`, :func:`above` and :func:`in_range`), nested configs included. Every failure is a
one-line :class:`DrivewmError` naming the field (``pretrain.train: lr must be > 0, got -0.1``), so a
typo or a bad value in a recipe, a YAML file or a ``--set`` override never runs silently and never
ends in a traceback.
"""

from __future__ import annotations

import dataclasses
import math
import re
import types
import typing
from pathlib import Path
from typing import Any, TypeVar

import yaml

from drivewm.errors import DrivewmError

C = TypeVar("C")
_SCIENTIFIC = re.compile(r"[-+]?\d+(\.\d*)?[eE][-+]?\d+")


#: The most nodes a YAML document may hold once every alias is expanded where it is used. Aliases are
#: welcome (a recipe names a list once and uses it twice), but 370 bytes of nested aliases expand to a
#: billion nodes ("billion laughs"), which every walk over the result (checking, copying, printing) pays for.
MAX_YAML_NODES = 100_000


def load_yaml(path: str | Path) -> dict:
    """Read a YAML mapping (:func:`parse_yaml`); a missing file or a non-mapping gives a clear error. The one
    reader of drivewm's YAML: recipes, rigs, topic maps, quickstart and world-model profiles."""
    path = Path(path)
    if not path.is_file():
        raise DrivewmError(f"{path}: config file not found")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise DrivewmError(f"{path}: not valid YAML (UnicodeDecodeError)") from None
    data = parse_yaml(text, str(path))
    if data is None:
        return {}
    if not isinstance(data, dict):
        raise DrivewmError(f"{path}: expected a mapping at the top level, got {type(data).__name__}")
    return data


def parse_yaml(text: str, where: str) -> Any:
    """The value of a YAML document (safe types only: no Python objects), refused with a DrivewmError naming
    ``where`` when it is not YAML, when an alias refers to a node that contains it (a structure holding itself),
    or when its aliases expand it beyond :data:`MAX_YAML_NODES` nodes. Checked on the composed nodes, where an
    alias is one shared node, before anything is built."""
    loader = None
    try:
        loader = yaml.SafeLoader(text)  # reads the text's first characters: a control character fails here
        node = loader.get_single_node()
        if node is None:
            return None
        _check_expansion(node, where)
        return loader.construct_document(node)
    except (yaml.YAMLError, RecursionError) as exc:
        raise DrivewmError(f"{where}: not valid YAML ({exc.__class__.__name__})") from None
    finally:
        if loader is not None:
            loader.dispose()


def _check_expansion(root: yaml.Node, where: str) -> None:
    """Refuse a node graph with a cycle, or whose tree (every alias expanded) has more than MAX_YAML_NODES nodes.

    Depth-first, each shared node sized once: size(node) = 1 + the sizes of its children."""
    sizes: dict[int, int] = {}
    open_nodes: set[int] = set()  # on the path from the root: meeting one again is a cycle
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, finished = stack.pop()
        children = _yaml_children(node)
        if finished:
            open_nodes.discard(id(node))
            sizes[id(node)] = 1 + sum(sizes[id(c)] for c in children)
            if sizes[id(node)] > MAX_YAML_NODES:
                raise DrivewmError(
                    f"{where}: its aliases expand it to more than {MAX_YAML_NODES:,} values; write the values out"
                )
        elif id(node) in open_nodes:
            raise DrivewmError(f"{where}: an alias refers to a node that contains it (line {node.start_mark.line + 1})")
        elif id(node) not in sizes:
            open_nodes.add(id(node))
            stack.append((node, True))
            stack += [(c, False) for c in children]


def _yaml_children(node: yaml.Node) -> list[yaml.Node]:
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return list(node.value) if isinstance(node, yaml.SequenceNode) else []


def _coerce(value: Any, tp: Any, where: str, finite: bool = True) -> Any:
    """Check ``value`` against the annotation ``tp`` (recursing into dataclasses, lists, dicts);
    ``finite``: refuse NaN and infinity where a float is expected."""
    origin = typing.get_origin(tp)
    if tp is Any:
        return value
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        errors = []
        for arg in args:
            if arg is type(None):
                continue
            try:
                return _coerce(value, arg, where, finite)
            except DrivewmError as exc:
                errors.append(str(exc))
        raise DrivewmError(errors[0] if errors else f"{where}: bad value {value!r}")
    if origin is typing.Literal:
        if value not in typing.get_args(tp):
            raise DrivewmError(f"{where}: {value!r} is not one of {list(typing.get_args(tp))}")
        return value
    if dataclasses.is_dataclass(tp):
        if isinstance(value, tp):
            return value
        if not isinstance(value, dict):
            raise DrivewmError(f"{where}: expected a mapping, got {value!r}")
        return from_dict(tp, value, where, finite)
    if origin in (list, tuple):
        if not isinstance(value, (list, tuple)):
            raise DrivewmError(f"{where}: expected a list, got {value!r}")
        args = typing.get_args(tp)
        item_tp = args[0] if args else Any
        items = [_coerce(v, item_tp, f"{where}[{i}]", finite) for i, v in enumerate(value)]
        return tuple(items) if origin is tuple else items
    if origin is dict:
        if not isinstance(value, dict):
            raise DrivewmError(f"{where}: expected a mapping, got {value!r}")
        k_tp, v_tp = typing.get_args(tp) or (Any, Any)
        return {
            _coerce(k, k_tp, f"{where} key", finite): _coerce(v, v_tp, f"{where}.{k}", finite) for k, v in value.items()
        }
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise DrivewmError(f"{where}: expected a number, got {value!r}")
        try:
            number = float(value)
        except OverflowError:  # an int too large for a float
            raise DrivewmError(f"{where}: number {value} is out of range") from None
        if finite and not math.isfinite(number):
            raise DrivewmError(f"{where}: expected a finite number, got {value!r}")
        return number
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise DrivewmError(f"{where}: expected an integer, got {value!r}")
        return value
    if tp in (str, bool):
        if not isinstance(value, tp):
            raise DrivewmError(f"{where}: expected {tp.__name__}, got {value!r}")
        return value
    return value


def from_dict(cls: type[C], data: dict, where: str = "config", finite: bool = True) -> C:
    """Build dataclass ``cls`` from ``data`` and run its ``validate()``; unknown keys, wrong types,
    non-finite floats (unless ``finite`` is False) and values ``validate()`` refuses raise DrivewmError
    naming the field."""
    if not isinstance(data, dict):
        raise DrivewmError(f"{where}: expected a mapping, got {data!r}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls) if f.init}
    unknown = sorted(str(k) for k in data if k not in names)
    if unknown:
        raise DrivewmError(f"{where}: unknown key(s) {unknown}; known: {sorted(names)}")
    required = [
        f.name
        for f in dataclasses.fields(cls)
        if f.init and f.default is dataclasses.MISSING and f.default_factory is dataclasses.MISSING
    ]
    missing = [k for k in required if k not in data]
    if missing:
        raise DrivewmError(f"{where}: missing key(s) {missing}")
    kwargs = {k: _coerce(v, hints[k], f"{where}.{k}", finite) for k, v in data.items()}
    obj = cls(**kwargs)
    validate = getattr(obj, "validate", None)
    if callable(validate):
        try:
            validate()
        except DrivewmError as exc:
            raise DrivewmError(f"{where}: {exc}") from None
    return obj


def require(ok: bool, field: str, value: Any, rule: str) -> None:
    """For ``validate()`` methods: raise ``DrivewmError("FIELD must be RULE, got VALUE")`` unless ``ok``."""
    if not ok:
        raise DrivewmError(f"{field} must be {rule}, got {value!r}")


def check_guidance_interval(where: str, interval: tuple[float, float] | None) -> tuple[float, float] | None:
    """``interval`` as (lo, hi) floats with 0 <= lo < hi, or None; a clear error otherwise."""
    if interval is None:
        return None
    try:
        lo, hi = (float(v) for v in interval)
    except (TypeError, ValueError):
        raise DrivewmError(
            f"{where}: the guidance interval must be two numbers LO,HI with 0 <= LO < HI, got {interval!r}"
        ) from None
    if not (math.isfinite(lo) and math.isfinite(hi) and 0 <= lo < hi):
        raise DrivewmError(f"{where}: the guidance interval needs finite 0 <= LO < HI, got {lo:g},{hi:g}")
    return lo, hi


def finite_at_least(where: str, low: float, **values: float) -> None:
    """Every value is a finite number >= ``low``, else ``DrivewmError("WHERE: NAME must be a finite number
    >= LOW, got VALUE")``: for run settings that no config loader checked (guidance weights, speeds)."""
    for name, value in values.items():
        if not (math.isfinite(value) and value >= low):
            raise DrivewmError(f"{where}: {name} must be a finite number >= {low:g}, got {value}")


def at_least(cfg: Any, low: float, *fields: str) -> None:
    """Every named field of ``cfg`` is >= ``low`` (NaN fails)."""
    for name in fields:
        value = getattr(cfg, name)
        require(value >= low, name, value, f">= {low}")


def above(cfg: Any, low: float, *fields: str) -> None:
    """Every named field of ``cfg`` is > ``low`` (NaN fails)."""
    for name in fields:
        value = getattr(cfg, name)
        require(value > low, name, value, f"> {low}")


#: Frame rates (Hz) a config may name, from one frame a minute to 1 kHz: beyond is a typo (1e-300 Hz had
#: overflowed the frame period in ns deep inside a run).
FPS_RANGE = (1 / 60, 1000.0)

#: Largest seed a config or command takes (the simulator's, SUMO's ``--seed``); sample, window or view i adds i to it.
MAX_SEED = 2**31 - 1


def frame_rate(cfg: Any, *fields: str) -> None:
    """Every named field of ``cfg`` is a frame rate in :data:`FPS_RANGE` (NaN fails)."""
    for name in fields:
        value = getattr(cfg, name)
        require(FPS_RANGE[0] <= value <= FPS_RANGE[1], name, value, "a frame rate in [1/60, 1000] Hz")


def in_range(cfg: Any, name: str, low: float, high: float, high_open: bool = False) -> None:
    """``low <= cfg.name <= high`` (``< high`` with ``high_open``)."""
    value = getattr(cfg, name)
    ok = low <= value < high if high_open else low <= value <= high
    require(ok, name, value, f"in [{low}, {high}{')' if high_open else ']'}")


def to_dict(obj: Any) -> dict:
    """A dataclass as a plain, JSON/YAML-ready dict."""
    return dataclasses.asdict(obj)


def parse_override(text: str) -> tuple[list[str], Any]:
    """``"model.depth=4"`` -> (["model", "depth"], 4). Values are parsed as YAML scalars."""
    if "=" not in text:
        raise DrivewmError(f"override {text!r}: expected KEY=VALUE (e.g. train.steps=100)")
    key, raw = text.split("=", 1)
    if not key:
        raise DrivewmError(f"override {text!r}: empty key")
    value = parse_yaml(raw, f"override {text!r}: value")
    if isinstance(value, str) and _SCIENTIFIC.fullmatch(value.strip()):
        value = float(value)  # YAML 1.1 reads 1e-3 (no dot) as a string; users mean the number
    return key.split("."), value


def apply_overrides(cls: type[C], base: dict, overrides: list[str], where: str = "config") -> C:
    """Apply ``KEY=VALUE`` overrides to the dict ``base`` and build ``cls`` from the result."""
    data = _deep_copy(base)
    for text in overrides:
        keys, value = parse_override(text)
        node = data
        for k in keys[:-1]:
            node = node.setdefault(k, {})
            if not isinstance(node, dict):
                raise DrivewmError(f"override {text!r}: {k} is not a section")
        node[keys[-1]] = value
    return from_dict(cls, data, where)


def _deep_copy(d: dict) -> dict:
    return {k: _deep_copy(v) if isinstance(v, dict) else v for k, v in d.items()}
