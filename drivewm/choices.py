"""Command-line choices read from the registries they name, when argparse first needs them.

``--sampler`` takes the keys of ``drivewm.diffusion.samplers.SAMPLERS``, ``--weather`` the entries
of ``drivewm.logs.types.WEATHERS``, and so on: the CLI never repeats a registry by hand. A model
folder argument (``--model``, ``--init``, ``--tokenizer``) also takes ``shipped:KIND``, the weights
this drivewm ships (:func:`model_folder`; drivewm.model_folders resolves the name), so a command
that names them works wherever drivewm is installed. The registry's module is imported only when a
value is checked or a help page is printed, so building the parser (``drivewm --help``) imports no
stage code and no PyTorch.
"""

from __future__ import annotations

import argparse
import functools
import importlib
from collections.abc import Callable, Iterator
from pathlib import Path

from drivewm.config import MAX_SEED, check_guidance_interval
from drivewm.errors import DrivewmError
from drivewm.model_folders import resolve_model_folder
from drivewm.paths import confine_to


class RegistryChoices:
    """The names in a registry (a mapping's keys or a sequence), given as ``"module:ATTRIBUTE"``."""

    def __init__(self, registry: str):
        self.registry = registry

    @functools.cached_property
    def names(self) -> list[str]:
        module, attribute = self.registry.split(":")
        return list(getattr(importlib.import_module(module), attribute))

    def __contains__(self, name: object) -> bool:
        return name in self.names

    def __iter__(self) -> Iterator[str]:
        return iter(self.names)


def add_registry_argument(parser: argparse.ArgumentParser, flag: str, registry: str, help: str, **kwargs) -> None:
    """``parser.add_argument(flag, ...)`` whose choices are the names in ``registry`` (``"module:ATTRIBUTE"``).

    The metavar keeps argparse from listing the choices while the parser is built; the help page
    lists them (``%(choices)s``), and a bad value is refused with the registry's names.
    """
    metavar = flag.lstrip("-").replace("-", "_").upper()
    parser.add_argument(flag, choices=RegistryChoices(registry), metavar=metavar, help=f"{help}: %(choices)s", **kwargs)


def model_folder(value: str) -> Path:
    """argparse ``type`` of a model folder argument: a path, or ``shipped:KIND``
    (drivewm.model_folders.resolve_model_folder)."""
    try:
        return resolve_model_folder(value)
    except DrivewmError as exc:  # argparse turns this into the CLI's one-line error, exit 2
        raise argparse.ArgumentTypeError(str(exc)) from exc


#: The installed package: no command writes inside it (its ``weights/`` are the shipped models, replaced
#: only by drivewm.release.replace_shipped).
PACKAGE_DIR = Path(__file__).resolve().parent


def output_folder(value: str) -> Path:
    """argparse ``type`` of an ``--out`` folder, resolved once, here: a folder, or a path that can become one.
    Refused before any work: an empty path (``Path("")`` is the current folder), a folder inside the installed
    package (its shipped weights are read-only to drivewm), and a file there or on the way to it (mkdir had
    ended the command in a FileExistsError traceback). Writes under it never follow a symlink out of it
    (drivewm.paths.confine_to)."""
    path = _writable_path(value)
    confine_to(path)
    return path


def _writable_path(value: str) -> Path:
    """``value`` as a path a command may write: not empty, not inside the package, no file on the way to it."""
    if not value.strip():
        raise argparse.ArgumentTypeError("an empty path names no folder; give the output folder")
    path = Path(value)
    if path.resolve().is_relative_to(PACKAGE_DIR):
        raise argparse.ArgumentTypeError(
            f"{value}: lies inside the installed drivewm package ({PACKAGE_DIR}), whose shipped weights no "
            "command may write; choose a folder outside it"
        )
    for part in (path, *path.parents):
        if part.exists():
            if not part.is_dir():
                raise argparse.ArgumentTypeError(f"{value}: {part} is a file, not a folder")
            break
    return path


def output_file(value: str) -> Path:
    """argparse ``type`` of an ``--out`` file: a file, or a path that can become one; a folder there or a
    file on the way to it is refused before any work (``view --out`` had ended in an IsADirectoryError or
    FileExistsError traceback after reading the whole log)."""
    path = Path(value)
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"{value}: is a folder, not a file")
    _writable_path(str(path.parent))
    return path


def whole_number(minimum: int, maximum: int | None = None) -> Callable[[str], int]:
    """argparse ``type`` of a whole number >= ``minimum`` (and <= ``maximum`` when given)."""
    bounds = f">= {minimum}" if maximum is None else f"in [{minimum}, {maximum}]"

    def parse(value: str) -> int:
        try:
            number = int(value)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a whole number {bounds}, got {value!r}") from None
        if number < minimum or (maximum is not None and number > maximum):
            raise argparse.ArgumentTypeError(f"must be {bounds}, got {number}")
        return number

    return parse


#: argparse ``type`` of a count option (``--workers``, ``--max-clips``, ``--num-samples``, ...): ``--workers -3``
#: had run on one process and ``--max-clips -1`` had left out the last clip.
at_least_one = whole_number(1)


#: argparse ``type`` of ``--seed`` (a larger one had ended ``drivewm generate`` in PyTorch's overflow traceback).
seed = whole_number(0, MAX_SEED)


def sigma_interval(value: str) -> tuple[float, float] | None:
    """argparse ``type`` of ``--guidance-interval``: ``LO,HI`` with finite 0 <= LO < HI, or ``all`` (None);
    checked by the library's own check (drivewm.config.check_guidance_interval)."""
    if value.strip().lower() == "all":
        return None
    try:
        return check_guidance_interval("--guidance-interval", value.split(","))
    except DrivewmError:
        raise argparse.ArgumentTypeError(
            f"expected LO,HI with 0 <= LO < HI (noise levels) or 'all', got {value!r}"
        ) from None


def add_guidance_interval_argument(parser: argparse.ArgumentParser | argparse._ArgumentGroup) -> None:
    """``--guidance-interval LO,HI|all`` of generate, rollout and the world-model benchmark."""
    parser.add_argument(
        "--guidance-interval",
        type=sigma_interval,
        default=None,
        metavar="LO,HI",
        help="guide only at noise levels sigma in (LO, HI], one network evaluation elsewhere "
        "(Kynkaenniemi et al. 2024); 'all' (default) guides every step",
    )
