"""Numpy archives as shard members: ``.npz`` bytes that load with ``np.load(allow_pickle=False)``.

Written member by member with a fixed date, so the same arrays give the same bytes (a rerun of a
stage writes identical shards); read into plain arrays, a damaged or pickled archive being a
one-line DrivewmError.
"""

from __future__ import annotations

import io
import zipfile

import numpy as np

from drivewm.errors import DrivewmError


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """A compressed ``.npz`` of ``arrays`` (name -> array, no objects), members in the given order."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", zipfile.ZIP_DEFLATED) as npz:
        for name, values in arrays.items():
            member = io.BytesIO()
            np.lib.format.write_array(member, np.asarray(values), allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            npz.writestr(info, member.getvalue(), zipfile.ZIP_DEFLATED)
    return out.getvalue()


def load_npz(data: bytes, where: str) -> dict[str, np.ndarray]:
    """The arrays of ``.npz`` bytes; anything but a plain archive raises DrivewmError naming ``where``."""
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            return {name: npz[name] for name in npz.files}
    except (ValueError, OSError, EOFError, zipfile.BadZipFile) as exc:
        raise DrivewmError(f"{where} is not a plain .npz ({exc.__class__.__name__})") from None
