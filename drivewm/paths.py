"""One validated path for every name that becomes part of a file path (DESIGN.md section 7).

Clip keys, camera names, shard and log names, latent-cache names: each ends up in a file name
(``KEY.CAMERA.mp4``, ``CLIPDIR/latents/NAME/KEY.safetensors``, ``OUT/NAME-000000.tar``), and each
can come from a file someone else wrote or from the command line, so it may hold ``..``, a slash
or an absolute path. Every writer and reader builds such paths with :func:`child_path`, which takes
only *safe names* (letters, digits, ``_`` and ``-``; no dots, so ``KEY.CAMERA.mp4`` splits back
unambiguously) and checks that the result stays inside its folder. Names derived from user files
(a log's file stem) go through :func:`sanitize_name` first.

The other direction too: readers list a folder of data with :func:`visible_entries`, which leaves out
hidden names (a writer's temporary holds a half-written file under its final name), and an output
folder, resolved once where ``--out`` is parsed (:func:`confine_to`), is never left through a symlink
inside it (:func:`check_confined`, called by every atomic write). Nor does any write enter the installed
shipped weights (:data:`SHIPPED_WEIGHTS_DIR`), except inside :func:`replacing_shipped` (drivewm.product.release).
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import re
from collections.abc import Iterator
from pathlib import Path

from drivewm.errors import DrivewmError

#: A safe name: one path component without dots, at most 128 characters.
NAME_PATTERN = re.compile(r"[A-Za-z0-9_\-]{1,128}")
_UNSAFE_CHARS = re.compile(r"[^A-Za-z0-9_\-]")


def check_name(name: object, what: str = "name") -> str:
    """``name`` when it is a safe name, else a DrivewmError saying which ``what`` it was."""
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise DrivewmError(f"{what} {name!r}: use 1-128 letters, digits, '_' or '-' (no dots, slashes or spaces)")
    return name


def file_name(*names: str, ext: str = "", what: str = "name") -> str:
    """``"a.b.ext"`` from safe names (``file_name(key, camera, ext="mp4")`` -> ``KEY.CAMERA.mp4``)."""
    stem = ".".join(check_name(n, what) for n in names)
    return f"{stem}.{check_name(ext, 'extension')}" if ext else stem


def child_path(folder: str | Path, *names: str, ext: str = "", what: str = "name") -> Path:
    """``folder / file_name(*names, ext)``, refusing any name that is not safe; the result is inside ``folder``."""
    folder = Path(folder)
    path = folder / file_name(*names, ext=ext, what=what)
    if path.resolve().parent != folder.resolve():  # a symlink named like a safe name can still point away
        raise DrivewmError(f"{path}: resolves outside {folder}")
    return path


def visible_entries(folder: str | Path, pattern: str = "*") -> list[Path]:
    """The entries of ``folder`` matching ``pattern`` (one level, sorted), hidden names left out: a writer's
    temporary (``.NAME.HOST-PIDNS-PID.XXXX.tmp``, drivewm.atomic), which holds a half-written shard, log or
    video under its final name, the folder lock (``.drivewm.lock``) and every other dot file. Every reader that
    lists a folder of data (clip shards, logs, videos) lists it with this, so nothing half-written is read."""
    return sorted(p for p in Path(folder).glob(pattern) if not p.name.startswith("."))


#: The installed shipped model folders (drivewm.model_folders): read-only to every command.
SHIPPED_WEIGHTS_DIR = Path(__file__).resolve().parent / "weights"
#: Whether this process is replacing the shipped weights now (:func:`replacing_shipped`).
_REPLACING_SHIPPED = [False]

#: The output folders of this process's commands: the path as given (absolute) -> where it resolved when the
#: command line was parsed (:func:`confine_to`).
_OUTPUT_FOLDERS: dict[str, str] = {}


def confine_to(folder: str | Path) -> None:
    """Take ``folder`` as an output folder of this process, resolved now and once: every write under it
    (drivewm.atomic) must stay inside where it resolved (:func:`check_confined`). Called where ``--out`` is parsed."""
    given = os.path.abspath(folder)
    _OUTPUT_FOLDERS[given] = os.path.realpath(given)


@contextlib.contextmanager
def replacing_shipped() -> Iterator[None]:
    """Let writes enter the shipped weights for the ``with`` block: drivewm.product.release replacing them."""
    _REPLACING_SHIPPED[0] = True
    try:
        yield
    finally:
        _REPLACING_SHIPPED[0] = False


def check_confined(path: str | Path) -> None:
    """Refuse (DrivewmError) a write to ``path`` under an output folder (:func:`confine_to`) whose folder resolves
    outside it: a symlink inside the run folder (``RUN/samples -> /elsewhere``) is never followed out of it; and
    a write that resolves into the shipped weights (outside :func:`replacing_shipped`)."""
    target = os.path.abspath(path)
    shipped = os.path.realpath(SHIPPED_WEIGHTS_DIR)
    if not _REPLACING_SHIPPED[0] and os.path.realpath(target).startswith(shipped + os.sep):
        raise DrivewmError(f"{path}: lies in drivewm's shipped weights ({shipped}), which no command writes")
    for given, real in _OUTPUT_FOLDERS.items():
        if target.startswith(given + os.sep):
            parent = os.path.realpath(os.path.dirname(target))
            if parent != real and not parent.startswith(real + os.sep):
                raise DrivewmError(f"{path}: a symlink inside {given} leads out of it (to {parent}); not followed")


def sanitize_name(text: str, fallback: str = "item") -> str:
    """A safe name derived from free text (e.g. a file stem): unsafe characters become ``_``; a name
    that had to be cut to 128 characters keeps a short hash of the original so distinct texts stay distinct."""
    name = _UNSAFE_CHARS.sub("_", text) or fallback
    if len(name) > 128:
        name = f"{name[:119]}_{hashlib.sha1(text.encode()).hexdigest()[:8]}"
    return name


def distinct_paths(paths: list[str | Path]) -> tuple[list[Path], list[str]]:
    """``paths`` with each file (by resolved path) once, in first-seen order, and a warning per repeat."""
    seen: dict[Path, Path] = {}
    warnings = []
    for p in map(Path, paths):
        if p.resolve() in seen:
            warnings.append(f"{p}: given twice (as {seen[p.resolve()]}); used once")
        else:
            seen[p.resolve()] = p
    return list(seen.values()), warnings


def unique_names(texts: list[str], keys: list[str], fallback: str = "item") -> list[str]:
    """Safe, pairwise distinct names for items described by ``texts`` (e.g. file stems) and identified
    by ``keys`` (e.g. resolved paths, all distinct): the sanitized text, plus a short hash of the key
    wherever two items would otherwise share a name (``drive a`` and ``drive_a`` both sanitize to
    ``drive_a``). Deterministic: the same inputs always give the same names."""
    if len(set(keys)) != len(keys):
        raise DrivewmError(f"unique_names: duplicate keys {sorted({k for k in keys if keys.count(k) > 1})}")
    base = [sanitize_name(t, fallback) for t in texts]
    names = [
        b if base.count(b) == 1 else f"{b[:119]}_{hashlib.sha1(k.encode()).hexdigest()[:8]}" for b, k in zip(base, keys)
    ]
    taken = [n for n in names if names.count(n) > 1]  # a hashed name equal to another item's plain name
    if taken:
        raise DrivewmError(f"cannot give distinct names to {texts}: {sorted(set(taken))} repeat")
    return names
