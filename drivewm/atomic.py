"""Atomic, durable writes: the one helper every writer uses (docs/DESIGN.md section 7).

- :func:`atomic_path` (and :func:`write_bytes`, :func:`write_text`, :func:`write_json`): write to a
  temporary name in the same folder, flush it to disk (``fsync``), rename it onto the target, and
  flush the folder entry. A killed run leaves the old file or the new one, never half of one, and a
  power cut after the call returns loses neither. A folder replacing a folder is swapped in with one
  atomic exchange (Linux ``renameat2(RENAME_EXCHANGE)``), so readers never see the path missing.
  The temporary, ``.NAME.HOST-PIDNS-PID.XXXX.tmp``, names its maker: :func:`remove_dead_temporaries` deletes
  those whose maker was killed outright (``kill -9``, a lost node) and leaves live writers' alone. Every
  writer does so for each folder it writes into, on its first write there (:func:`atomic_path`), so a
  rerun leaves no dead temporary behind wherever it writes; readers never list hidden names
  (drivewm.paths.visible_entries), so a torn file inside a temporary is never read.
- :class:`JsonlAppender` (and :func:`read_jsonl`): JSON-lines logs such as ``metrics.jsonl``, which
  grow by appends. Each row is one ``write`` of ``json + "\\n"`` to a file opened ``O_APPEND``; a
  kill mid-append can tear only the last row, which readers drop and the next appender cuts off
  (an atomic rewrite) before it appends again. A symlink at the log's name is refused, never followed.
- Written JSON is strict (:func:`strict_json`): NaN and infinity become ``null``, as the metrics files
  document, so every reader, not only Python's, parses it.
- An ``OSError`` of a write (a full disk, a read-only folder) names the final path it was writing, so the
  CLI's one-line error (drivewm.errors.storage_message) says where.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import json
import math
import os
import re
import shutil
import socket
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from drivewm.errors import STORAGE_ERRNOS, DrivewmError
from drivewm.paths import check_confined

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
    for scratch data). On error the temporary is removed and ``path`` is untouched; an ``OSError``
    (a full disk, a read-only folder) leaves naming ``path``. The first write of this process into a
    folder removes the temporaries that killed writers left there (:func:`remove_dead_temporaries`).
    """
    path = Path(path)
    check_confined(path)
    tmp = None
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        _sweep_once(path.parent)
        owner = f"{_HOST}-{_PIDNS}-{os.getpid()}"  # per call: a forked worker is its own owner
        tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.{owner}.", suffix=".tmp", dir=path.parent))
        target = tmp / path.name
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
    except OSError as exc:
        name_final_path(exc, path)
        raise
    except DrivewmError:
        raise
    except Exception as exc:
        # Writers in other languages (the MCAP writer, torch.save, safetensors) report a full or read-only
        # disk as their own error, without errno: asked while the temporary still holds its space.
        if (storage := _storage_failure(path, exc)) is None:
            raise
        raise storage from exc
    finally:
        if tmp is not None:
            shutil.rmtree(tmp, ignore_errors=True)


#: How a writer in another language names the errno it failed on: Rust's ``(os error 28)``, a C library's
#: ``[Errno 28]``.
_ERRNO_IN_TEXT = re.compile(r"\(os error (\d+)\)|\[Errno (\d+)\]")
#: Free space below which a write that failed without an errno is taken to have found the disk full.
_NEARLY_FULL_BYTES = 1 << 20


def _storage_failure(path: Path, exc: Exception) -> OSError | None:
    """An ``OSError`` naming ``path`` when ``exc`` (an error without errno) came from a full or read-only file
    system: the errno its text names, else what the folder's file system says (read-only, or under 1 MiB or
    no inode left for this user); None for any other error."""
    if match := _ERRNO_IN_TEXT.search(str(exc)):
        code = int(match[1] or match[2])
        return OSError(code, os.strerror(code), str(path)) if code in STORAGE_ERRNOS else None
    try:
        fs = os.statvfs(path.parent)
    except OSError:
        return None
    if fs.f_flag & os.ST_RDONLY:
        code = errno.EROFS
    elif fs.f_bavail * fs.f_frsize < _NEARLY_FULL_BYTES or fs.f_favail == 0:
        code = errno.ENOSPC
    else:
        return None
    return OSError(code, os.strerror(code), str(path))


def finish_held(stack: contextlib.ExitStack, finish: Callable[[], object] = lambda: None) -> None:
    """Finish a writer that streams into the temporary of an :func:`atomic_path` held in ``stack`` across calls
    (a drive log, a shard): ``finish()`` (e.g. closing the writer), then move the file into place. If ``finish``
    raises, the temporary is removed and the error goes on, as a storage ``OSError`` naming the path when the
    disk is full or read-only (an error raised outside the ``with`` would have skipped both)."""
    try:
        finish()
    except BaseException as exc:
        discard_held(stack, exc)
    stack.close()


def discard_held(stack: contextlib.ExitStack, exc: BaseException) -> None:
    """Remove the temporary of the :func:`atomic_path` held in ``stack`` after ``exc`` and raise ``exc`` (see
    :func:`finish_held`)."""
    if not stack.__exit__(type(exc), exc, exc.__traceback__):
        raise exc


def name_final_path(exc: OSError, path: str | Path) -> None:
    """Make ``exc`` name ``path`` when it names no file or one of drivewm's temporaries: the user knows the
    final name, never the temporary (a file object's ``write`` raises without a name)."""
    if exc.filename is None or any(_TEMPORARY.fullmatch(part) for part in Path(str(exc.filename)).parts):
        exc.filename, exc.filename2 = str(path), None


#: Folders this process has swept of dead temporaries (absolute paths): one sweep per folder and process.
_SWEPT: set[str] = set()


def _sweep_once(folder: Path) -> None:
    key = os.path.abspath(folder)
    if key not in _SWEPT:
        _SWEPT.add(key)
        remove_dead_temporaries(folder)


def remove_dead_temporaries(folder: str | Path) -> list[Path]:
    """Delete the temporaries in ``folder`` that a process killed outright (``kill -9``, a lost node, a
    power cut) left behind: an unfinished log, shard or checkpoint under ``.NAME.HOST-PIDNS-PID.XXXX.tmp``.
    Only those made on this host and in this PID namespace by a process that no longer runs go; a live
    writer's (this host's or another's sharing the folder) stay, so any run may call this on its output
    folder without a lock.
    Returns what was deleted."""
    gone = []
    if not Path(folder).is_dir():
        return gone
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
    """Atomically write ``obj`` as indented, strict JSON (:func:`strict_json`)."""
    write_text(path, json.dumps(strict_json(obj), indent=2, sort_keys=False, allow_nan=False) + "\n")


def strict_json(obj: object) -> object:
    """``obj`` for strict JSON: NaN and infinity as None (``null``), numpy scalars and arrays as Python numbers
    and lists, keys as strings. Python's ``json`` writes a bare ``NaN``, which is not JSON: other readers (jq, a
    browser, pandas' strict mode) refuse the whole file."""
    if isinstance(obj, dict):
        return {k if isinstance(k, str) else str(k): strict_json(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict_json(v) for v in obj]
    if hasattr(obj, "tolist"):  # numpy arrays and scalars (np.float32 is no float), tensors
        return strict_json(obj.tolist())
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj


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
        self._fd = -1
        if self.path.is_symlink():  # appends would land wherever it points, outside the run folder
            raise DrivewmError(f"{self.path}: is a symlink; a log is appended to in its own folder only (remove it)")
        check_confined(self.path)
        rows, torn = _read_rows(self.path)
        kept = [r for r in rows if keep is None or keep(r)]
        if torn or len(kept) != len(rows):
            write_text(self.path, "".join(_row_line(r) for r in kept))
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._fd = os.open(self.path, os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW, 0o644)
        except OSError as exc:
            name_final_path(exc, self.path)
            raise

    def write(self, row: dict) -> None:
        """Append ``row`` as one line of strict JSON (one ``write`` call: concurrent readers see whole rows)."""
        data = _row_line(row).encode()
        try:
            while data:
                data = data[os.write(self._fd, data) :]
        except OSError as exc:
            name_final_path(exc, self.path)
            raise

    def close(self) -> None:
        if self._fd >= 0:
            fd, self._fd = self._fd, -1
            try:
                os.fsync(fd)
            except OSError as exc:
                name_final_path(exc, self.path)
                raise
            finally:
                os.close(fd)

    def __enter__(self) -> JsonlAppender:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close()


def _row_line(row: dict) -> str:
    return json.dumps(strict_json(row), allow_nan=False) + "\n"


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
