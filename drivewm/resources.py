"""Package data: the rigs, topic maps, default recipes and fitted tables drivewm ships.

They live inside the package, so a wheel installed anywhere finds them (``importlib.resources``;
drivewm installs as plain files, so each is a real path that error messages can name)::

    drivewm/rigs/NAME.yaml              camera rigs                      (--rig NAME)
    drivewm/topicmaps/NAME.yaml         topic maps of fleet logs         (topic_map: NAME)
    drivewm/recipes/STAGE/NAME.yaml     a stage's default recipes        (--recipe NAME)
    drivewm/recipes/quickstart.yaml     quickstart profiles              (drivewm quickstart --profile)
    drivewm/references/NAME.json        reference metrics for reports    (drivewm eval --reference NAME)
    drivewm/tables/NAME.json            fitted tables (the adherence classifier)

:func:`find` resolves what a user gives: an existing file path as it is, else a name looked up in
the user's folders first (``$DRIVEWM_RIGS`` for rigs) and then in the package.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from drivewm.errors import DrivewmError


def package_dir(kind: str) -> Path:
    """The packaged folder ``drivewm/<kind>`` (e.g. ``rigs``, ``recipes/curate``)."""
    return Path(str(resources.files("drivewm").joinpath(kind)))


def names(kind: str, suffix: str = ".yaml") -> list[str]:
    """Names of the packaged files of ``kind`` (file stems), sorted: for CLI help and error messages."""
    folder = package_dir(kind)
    return sorted(p.stem for p in folder.glob(f"*{suffix}")) if folder.is_dir() else []


def env_dirs(variable: str) -> list[Path]:
    """Folders listed in an environment variable (``os.pathsep``-separated), in order."""
    return [Path(p) for p in os.environ.get(variable, "").split(os.pathsep) if p]


def search_dirs(kind: str, env: str | None = None) -> list[Path]:
    """Where a name of ``kind`` is looked up: the folders of ``$env`` (if given), then the package."""
    return [*(env_dirs(env) if env else []), package_dir(kind)]


def find(kind: str, name_or_path: str | Path, what: str, env: str | None = None, suffix: str = ".yaml") -> Path:
    """The file a user means: an existing path as given, else ``NAME<suffix>`` in :func:`search_dirs`.

    ``what`` names the thing in the error (``rig``, ``topic map``, ``curate recipe``); an unknown name
    is a one-line :class:`DrivewmError` listing the folders searched and the packaged names.
    """
    path = Path(name_or_path)
    if path.is_file():
        return path
    dirs = search_dirs(kind, env)
    for folder in dirs:
        if (folder / f"{name_or_path}{suffix}").is_file():
            return folder / f"{name_or_path}{suffix}"
    raise DrivewmError(
        f"{what} {str(name_or_path)!r}: no such file or named {what} in {[str(d) for d in dirs]} "
        f"(packaged: {', '.join(names(kind, suffix))})"
    )
