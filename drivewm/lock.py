"""An exclusive lock on an output folder, so two runs never write one dataset at once (DESIGN.md section 7).

Two ``curate`` runs on one ``--out`` would delete each other's shards and leave keys duplicated
across shards. The first run takes ``OUT/.drivewm.lock`` with ``flock`` (non-blocking); a second
run is refused at once with an error naming the folder and the holder's pid, and writes nothing.
The kernel drops the lock when its process ends, however it ends (``kill -9`` included), so a
stale lock file never blocks the next run. ``flock`` is per host: runs on several machines sharing
a network folder must not share an output folder. The lock file is opened without following a
symlink, so a link planted at its name never truncates the file it points to.

``curate`` takes it in the library; ``generate``, ``rollout`` and ``transfer`` declare it to the CLI
(``set_defaults(lock_out=...)``, drivewm.cli), which holds it around the whole command.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

from drivewm.errors import DrivewmError

LOCK_NAME = ".drivewm.lock"


@contextlib.contextmanager
def folder_lock(folder: str | Path, what: str) -> Iterator[None]:
    """Hold ``folder``'s lock for the ``with`` block; if another process holds it, DrivewmError.

    ``what`` names the run in the message (e.g. ``curate``). A folder the lock made is removed again when the
    run leaves nothing else in it (a command that refused its options before any work).
    """
    folder = Path(folder)
    made = not folder.exists()
    folder.mkdir(parents=True, exist_ok=True)
    try:
        fd = os.open(folder / LOCK_NAME, os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW, 0o644)
    except OSError as exc:
        if exc.errno != errno.ELOOP:
            raise
        raise DrivewmError(f"{folder / LOCK_NAME}: is a symlink; remove it (the lock is a plain file)") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 64, 0).decode(errors="replace").strip() or "unknown"
            raise DrivewmError(
                f"{folder}: another {what} run (pid {holder}) is writing this folder; "
                "wait for it to finish or choose another output folder"
            ) from None
        os.ftruncate(fd, 0)
        os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
        try:
            yield
        finally:
            if made and [p.name for p in folder.iterdir()] == [LOCK_NAME]:
                os.unlink(folder / LOCK_NAME)  # still held: no other run can have taken it meanwhile
                folder.rmdir()
    finally:
        os.close(fd)  # closing releases the flock
