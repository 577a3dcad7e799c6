"""Atomic, durable writes: the one helper every writer uses (docs/DESIGN.md section 7).

- :func:`atomic_path` (and :func:`write_bytes`, :func:`write_text`, :func:`write_json`): write to a
  temporary name in the same folder, flush it to disk (``fsync``), rename it onto the target, and
  flush the folder entry. A killed run leaves the old file or the new one, never half of one, and a
  power cut after the call returns loses neither. A folder replacing a folder is swapped in with one
  atomic exchange (Linux ``renameat2(RENAME_EXCHANGE)``), so readers never see the path missing.
  The temporary, ``.NAME.HOST-PIDNS-PID.XXXX.tmp``, names its maker: :func:`remove_dead_temporaries` deletes
  those whose maker was killed outright (``kill -9``, a lost node) and leaves live writers' alone.
- :class:`JsonlAppender` (and :func:`read_jsonl`): JSON-lines logs such as ``metrics.jsonl``, which
  grow by appends. Each row is one ``write`` of ``json + "\\n"`` to a file opened ``O_APPEND``; a
  kill mid-append can tear only the last row, which readers drop and the next appender cuts off
  (an atomic rewrite) before it appends again.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import json
import os
import re
import shutil
import socket
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from drivewm.errors import DrivewmError

#: A temporary's name carries its maker, ``HOST-PIDNS-PID`` (the host name in letters, digits and dashes, the
#: inode of the maker's PID namespace, so containers sharing a host name and a folder never judge each other's
#: pids), which remove_dead_temporaries reads back.
_HOST = re.sub(r"[^A-Za-z0-9-]", "-", socket.gethostname())[:40]
_TEMPORARY = re.compile(r"\.(?P<name>.+)\.(?P<host>[A-Za-z0-9-]*)-(?P<ns>\d+)-(?P<pid>\d+)\.[^.]+\.tmp")


def _pid_namespace() -> str:
    try:
        return re.sub(r"\D", "", os.readlink("/proc/self/ns/pid")) or "0"
    except OSError:  # no procfs (not Linux): the host name alone
        return "0"


_PIDNS = _pid_namespace()


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


#: The mode a file made with a plain ``open()`` gets; a writer that makes its file private (safetensors'
#: ``save_file`` writes 0600) would otherwise leave weights that no other user, nor a wheel built from the
#: folder, can read.
_FILE_MODE = 0o666 & ~_umask()


@contextlib.contextmanager
def atomic_path(path: str | Path, durable: bool = True) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; on success move it onto ``path`` atomically.

    Works for files and folders. ``durable``: fsync what was written and the parent folder (off only
    for scratch data). On error the temporary is removed and ``path`` is untouched.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    owner = f"{_HOST}-{_PIDNS}-{os.getpid()}"  # per call: a forked worker is its own owner
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.{owner}.", suffix=".tmp", dir=path.parent))
    target = tmp / path.name
    try:
        yield target
        _open_modes(target)
        if durable:
            _fsync_tree(target)
        if target.is_dir() and path.is_dir():
            _replace_folder(target, path)  # the old folder ends up in ``tmp`` and is removed below
        else:
            os.replace(target, path)
        if durable:
            _fsync_dir(path.parent)
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def remove_dead_temporaries(folder: str | Path) -> list[Path]:
    """Delete the temporaries in ``folder`` that a process killed outright (``kill -9``, a lost node, a
    power cut) left behind: an unfinished log, shard or checkpoint under ``.NAME.HOST-PIDNS-PID.XXXX.tmp``.
    Only those made on this host and in this PID namespace by a process that no longer runs go; a live
    writer's (this host's or another's sharing the folder) stay, so any run may call this on its output
    folder without a lock.
    Returns what was deleted."""
    gone = []
    for tmp in Path(folder).glob(".*.tmp"):
        m = _TEMPORARY.fullmatch(tmp.name)
        ours = m and m["host"] == _HOST and m["ns"] == _PIDNS
        if ours and tmp.is_dir() and not _alive(int(m["pid"])):
            shutil.rmtree(tmp, ignore_errors=True)
            gone.append(tmp)
    return gone


def _alive(pid: int) -> bool:
    """Whether a process ``pid`` runs on this host (a reused pid counts as alive: its temporary stays)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # another user's process
        return True
    return True


def write_bytes(path: str | Path, data: bytes) -> None:
    """Atomically write ``data`` to ``path``."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text(path: str | Path, text: str) -> None:
    """Atomically write ``text`` (UTF-8) to ``path``."""
    write_bytes(path, text.encode("utf-8"))


def write_json(path: str | Path, obj: object) -> None:
    """Atomically write ``obj`` as indented JSON."""
    write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n")


def read_jsonl(path: str | Path) -> list[dict]:
    """Rows of a JSON-lines file (none if it does not exist). A torn last row (no final newline, or
    not JSON: a kill mid-append) is dropped; a bad row before it raises DrivewmError naming the line."""
    rows, _ = _read_rows(Path(path))
    return rows


class JsonlAppender:
    """Append rows to a JSON-lines file. Opening drops a torn last row and every row ``keep`` refuses
    (e.g. rows past the step a resumed run restarts from), in one atomic rewrite; each
    :meth:`write` then appends one whole row with a single ``write`` call. Use as a context manager;
    :meth:`close` fsyncs."""

    def __init__(self, path: str | Path, keep: Callable[[dict], bool] | None = None):
        self.path = Path(path)
        rows, torn = _read_rows(self.path)
        kept = [r for r in rows if keep is None or keep(r)]
        if torn or len(kept) != len(rows):
            write_text(self.path, "".join(json.dumps(r) + "\n" for r in kept))
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)

    def write(self, row: dict) -> None:
        """Append ``row`` as one line (one ``write`` call: concurrent readers see whole rows)."""
        data = (json.dumps(row) + "\n").encode()
        while data:
            data = data[os.write(self._fd, data) :]

    def close(self) -> None:
        if self._fd >= 0:
            os.fsync(self._fd)
            os.close(self._fd)
            self._fd = -1

    def __enter__(self) -> JsonlAppender:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()


def _read_rows(path: Path) -> tuple[list[dict], bool]:
    """(rows, whether a torn last row was dropped)."""
    if not path.is_file():
        return [], False
    lines = path.read_bytes().split(b"\n")
    complete, tail = lines[:-1], lines[-1]  # after the last newline: "" when the file ends cleanly
    rows = []
    for i, line in enumerate(complete):
        if not line.strip():
            continue
        try:
            row = json.loads(line)
        except ValueError:
            if i == len(complete) - 1 and not tail:  # a torn row that happened to end in a newline
                return rows, True
            raise DrivewmError(f"{path}: line {i + 1} is not JSON") from None
        if not isinstance(row, dict):
            raise DrivewmError(f"{path}: line {i + 1} is not a JSON object")
        rows.append(row)
    return rows, bool(tail)


def _open_modes(path: Path) -> None:
    """Give every file at or under ``path`` the mode of a plain ``open()`` (executables keep their bits)."""
    files = [Path(r) / n for r, _, names in os.walk(path) for n in names] if path.is_dir() else [path]
    for f in files:
        if f.is_file() and not f.is_symlink() and not os.stat(f).st_mode & 0o111:
            os.chmod(f, _FILE_MODE)


def _fsync_tree(path: Path) -> None:
    """fsync a file, or every file and folder under a folder."""
    if path.is_dir():
        for root, _, files in os.walk(path):
            for name in files:
                _fsync_file(Path(root) / name)
            _fsync_dir(Path(root))
    elif path.is_file():
        _fsync_file(path)


def _fsync_file(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def _fsync_dir(path: Path) -> None:
    try:
        fd = os.open(path, os.O_RDONLY | os.O_DIRECTORY)
    except OSError:  # platforms without directory handles
        return
    try:
        os.fsync(fd)
    except OSError:  # some file systems refuse fsync on folders; the rename itself is still atomic
        pass
    finally:
        os.close(fd)


_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _replace_folder(new: Path, old: Path) -> None:
    """Put folder ``new`` at ``old``'s path; ``old``'s content ends up at ``new``'s path.

    Linux swaps the two in one step (renameat2 RENAME_EXCHANGE, kernel >= 3.15), so ``old`` never
    disappears. Elsewhere (or on file systems without it) ``old`` is renamed aside first, which
    leaves a moment without it.
    """
    renameat2 = getattr(_libc(), "renameat2", None)
    if renameat2 is not None:
        if renameat2(_AT_FDCWD, os.fsencode(new), _AT_FDCWD, os.fsencode(old), _RENAME_EXCHANGE) == 0:
            return
        err = ctypes.get_errno()
        if err not in (errno.EINVAL, errno.ENOSYS, errno.EOPNOTSUPP):
            raise OSError(err, os.strerror(err), str(old))
    aside = new.with_name(new.name + ".old")
    os.replace(old, aside)
    os.replace(new, old)
    os.replace(aside, new)


def _libc():
    try:
        return ctypes.CDLL(None, use_errno=True)
    except OSError:
        return None
