"""Where model folders are: the weights drivewm ships, ``shipped:KIND`` names, and folder references.

A *model folder* is ``config.json`` + ``model.safetensors`` (drivewm.train.checkpoint reads and
writes them). drivewm ships one per kind in ``drivewm/weights/KIND``; a command or a config field
names it ``shipped:KIND``, so it works wherever drivewm is installed. A model folder that depends on
another (a diffusion model's tokenizer, a transfer model's Text2World parent) records it so that the
record survives a move (:func:`portable_reference`, read back by :func:`resolve_reference`).

The shipped folders are read-only to drivewm (no ``--out`` may lie in the package, drivewm.choices), and
every load of one checks its files' sizes and sha256 against ``weights/MANIFEST.json``
(:func:`verify_shipped`), so a replaced or damaged file is refused, not used. A file hashed once is
remembered by (path, size, mtime_ns), in this process and in a small file in the user's cache folder
(:func:`verified_cache_path`), so later loads cost a ``stat`` per file.

This module sits below every stage, the CLI and the product: it imports nothing of drivewm but
its errors and paths, so the argparse types (drivewm.choices), the checkpoint code and the models all call
it without importing each other.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

from drivewm.errors import DrivewmError
from drivewm.paths import SHIPPED_WEIGHTS_DIR

#: The two files of a model folder.
CONFIG_NAME = "config.json"
WEIGHTS_NAME = "model.safetensors"

#: Where the installed shipped model folders are, one per kind.
WEIGHTS_DIR = SHIPPED_WEIGHTS_DIR
#: The kinds of model drivewm ships, each a folder under WEIGHTS_DIR.
SHIPPED_KINDS = ("tokenizer", "text2world", "multiview", "transfer", "judge")
#: Prefix of a model folder argument that names a shipped model: ``shipped:multiview``.
SHIPPED_PREFIX = "shipped:"
#: The shipped files' sha256 and sizes (drivewm.product.release writes it).
MANIFEST_NAME = "MANIFEST.json"
#: Files already hashed in this process: (resolved path, size, mtime_ns) -> sha256.
_VERIFIED: dict[tuple[str, int, int], str] = {}


def shipped_model(kind: str) -> Path:
    """The installed model folder ``kind`` (tokenizer, text2world, multiview, transfer or judge)."""
    if kind not in SHIPPED_KINDS:
        raise DrivewmError(f"no shipped model {kind!r}: drivewm ships {', '.join(SHIPPED_KINDS)}")
    path = WEIGHTS_DIR / kind
    if not (path / WEIGHTS_NAME).is_file():
        raise DrivewmError(f"this drivewm has no shipped {kind} weights at {path}; give --model")
    return path


def resolve_model_folder(value: str | Path) -> Path:
    """``shipped:KIND`` is the installed ``drivewm/weights/KIND`` (:func:`shipped_model`; an unknown
    or missing kind raises DrivewmError), anything else a path as given."""
    if not (isinstance(value, str) and value.startswith(SHIPPED_PREFIX)):
        return Path(value)
    return shipped_model(value[len(SHIPPED_PREFIX) :])


def portable_reference(target: str | Path, folder: str | Path, root: str | Path) -> str:
    """How ``folder`` records the folder ``target`` it depends on (a model folder's tokenizer or
    Text2World parent, a latent cache's tokenizer) so that the record survives a move: relative to
    ``folder`` when ``target`` lies under ``root`` (the run folder both belong to: a recipe run,
    copied back from a GPU machine, moves as a whole); ``shipped:KIND`` when it is an installed
    shipped model (a fine-tune of the shipped weights outlives a new virtual environment or
    drivewm's installed path changing); else its absolute path. :func:`resolve_reference` reads it."""
    target, folder, root = (Path(p).resolve() for p in (target, folder, root))
    if target.is_relative_to(root):
        return os.path.relpath(target, folder)
    for kind in SHIPPED_KINDS:
        if target == (WEIGHTS_DIR / kind).resolve():
            return SHIPPED_PREFIX + kind
    return str(target)


def resolve_reference(reference: str, folder: str | Path) -> Path:
    """The folder that ``reference`` (as :func:`portable_reference` writes it, or an absolute path)
    names, recorded in ``folder``: a relative path is read from ``folder``."""
    if reference.startswith(SHIPPED_PREFIX):
        return resolve_model_folder(reference)
    path = Path(reference)
    return path if path.is_absolute() else (Path(folder) / path).resolve()


def shipped_kind_of(folder: str | Path) -> str | None:
    """The kind of shipped model ``folder`` is (resolved through symlinks), or None when it is none."""
    resolved = Path(folder).resolve()
    return resolved.name if resolved.parent == WEIGHTS_DIR.resolve() else None


def verify_shipped(folder: str | Path) -> None:
    """Refuse (DrivewmError) a shipped model folder whose files differ in size or sha256 from
    ``MANIFEST.json``, or which holds a model file the manifest does not list; any other folder passes.
    Each file is hashed once per (path, size, mtime_ns) (:data:`_VERIFIED`, :func:`verified_cache_path`)."""
    kind = shipped_kind_of(folder)
    if kind is None:
        return
    root = WEIGHTS_DIR.resolve()
    entries = _manifest_entries(root, kind)
    for name in (CONFIG_NAME, WEIGHTS_NAME):
        if name not in entries:
            raise DrivewmError(f"{root / kind / name}: not listed in {root / MANIFEST_NAME}; not a shipped file")
    known = _read_verified_cache()
    fresh = dict(_verify_file(root / kind / name, entry, known) for name, entry in entries.items())
    if any(known.get(key) != digest for key, digest in fresh.items()):
        paths = {key[0] for key in fresh}  # a file's older (size, mtime_ns) records are dropped
        _write_verified_cache({**{k: v for k, v in known.items() if k[0] not in paths}, **fresh})


def _manifest_entries(root: Path, kind: str) -> dict[str, dict]:
    """``MANIFEST.json``'s entries of the files of ``kind``: file name -> {"sha256", "bytes"}."""
    try:
        files = json.loads((root / MANIFEST_NAME).read_text())["files"]
        return {name.split("/", 1)[1]: dict(entry) for name, entry in files.items() if name.startswith(f"{kind}/")}
    except (OSError, ValueError, KeyError, TypeError, AttributeError, IndexError) as exc:
        raise DrivewmError(
            f"{root / MANIFEST_NAME}: cannot read the shipped weights' manifest ({exc.__class__.__name__}); "
            "reinstall drivewm"
        ) from None


def _verify_file(path: Path, entry: dict, known: dict) -> tuple[tuple[str, int, int], str]:
    """Check ``path`` against its manifest ``entry``; returns its cache key and sha256."""
    try:
        st = path.stat()
    except OSError:
        raise DrivewmError(f"{path}: missing, but listed in {MANIFEST_NAME}; reinstall drivewm") from None
    if st.st_size != entry.get("bytes"):
        raise DrivewmError(
            f"{path}: {st.st_size} bytes, {MANIFEST_NAME} says {entry.get('bytes')} (a corrupt or replaced "
            "shipped file); reinstall drivewm"
        )
    key = (str(path), st.st_size, st.st_mtime_ns)
    digest = _VERIFIED.get(key) or known.get(key) or file_sha256(path)
    if digest != entry.get("sha256"):
        raise DrivewmError(
            f"{path}: sha256 differs from {MANIFEST_NAME} (a corrupt or replaced shipped file); reinstall drivewm"
        )
    _VERIFIED[key] = digest
    return key, digest


def file_sha256(path: Path) -> str:
    """Hex sha256 of a file, read in 1 MiB blocks."""
    digest = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def verified_cache_path() -> Path:
    """Where hashed shipped files are remembered across processes: ``$DRIVEWM_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/drivewm``, else ``~/.cache/drivewm``; never inside the package."""
    base = os.environ.get("DRIVEWM_CACHE_DIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "drivewm"
    )
    return Path(base) / "verified-weights.json"


def _read_verified_cache() -> dict[tuple[str, int, int], str]:
    """The cross-process record of hashed files; empty when it is missing or unreadable (it is only a cache)."""
    try:
        rows = json.loads(verified_cache_path().read_text())
        return {(str(r[0]), int(r[1]), int(r[2])): str(r[3]) for r in rows}
    except (OSError, ValueError, TypeError, IndexError):
        return {}


def _write_verified_cache(entries: dict[tuple[str, int, int], str]) -> None:
    """Replace the cross-process record (atomically; a read-only or full cache folder only costs a rehash later)."""
    path = verified_cache_path()
    if path.resolve().is_relative_to(Path(__file__).resolve().parent):
        return  # the package is read-only to drivewm, its cache included
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError:
        return
    try:
        with os.fdopen(fd, "w") as f:
            json.dump([[*key, digest] for key, digest in entries.items()], f)
        os.replace(temp, path)
    except OSError:
        Path(temp).unlink(missing_ok=True)
