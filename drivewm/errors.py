"""The error types the CLI turns into clear messages without a traceback (docs/DESIGN.md section 7), and
which ``OSError`` s it reports the same way (a full or read-only file system, a folder without permission)."""

from __future__ import annotations

import errno
import os


class DrivewmError(Exception):
    """Bad input or configuration: the message names the file or value and what is wrong.

    The CLI prints ``error: <message>`` and exits with status 2, without a traceback.
    Batch stages catch it per item, record it as the item's reason and go on.
    """


class BatchError(DrivewmError):
    """A batch command (curate, import-video, encode, decode, eval, transfer) produced nothing usable.

    The CLI prints ``error: <message>`` and then one line per failed item (``failures``), and exits 2.
    """

    def __init__(self, message: str, failures: list[str]):
        super().__init__(message)
        self.failures = list(failures)


#: errno values of a file system that cannot take what a command writes: full (ENOSPC, a quota, a file size
#: limit) or read-only. Batch commands stop on them instead of failing item after item.
NO_ROOM_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS})
#: ... and the permission errors the CLI also reports in one line (an output folder the user may not write).
STORAGE_ERRNOS = NO_ROOM_ERRNOS | {errno.EACCES, errno.EPERM}


def no_room(exc: BaseException) -> bool:
    """Whether ``exc`` says the file system is full or read-only (:data:`NO_ROOM_ERRNOS`)."""
    return isinstance(exc, OSError) and exc.errno in NO_ROOM_ERRNOS


def storage_message(exc: OSError) -> str | None:
    """The CLI's one line for a storage ``OSError`` (:data:`STORAGE_ERRNOS`), ``PATH: reason``; None for another
    error (a bug, which keeps its traceback). Writers name their final path (drivewm.atomic.name_final_path)."""
    if isinstance(exc, BrokenPipeError) or exc.errno not in STORAGE_ERRNOS:
        return None
    where = f"{exc.filename}: " if exc.filename is not None else ""
    return f"{where}{exc.strerror or os.strerror(exc.errno)}"
