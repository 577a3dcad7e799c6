"""Exact per-pixel label maps: what the simulator drew at every pixel, in a log and in a clip.

A label map is (H, W) uint8, each pixel the id of its class in
:data:`drivewm.layout.classes.LABEL_CLASSES` (:data:`drivewm.layout.classes.UNLABELLED` for a box of a
category without one). In a drive log it is a lossless grey PNG per camera and tick
(:func:`label_png`, ``foxglove.CompressedImage`` on ``/CAMERA/labels``, ``drivewm simulate --labels``);
in a clip shard the member ``KEY.CAMERA.labels.npz`` holds one camera's maps of every frame
(:func:`labels_to_npz` / :func:`labels_from_npz`), frame t being the map of that camera's image t.
"""

from __future__ import annotations

import cv2
import numpy as np

from drivewm.errors import DrivewmError
from drivewm.layout.classes import LABEL_CLASSES, UNLABELLED
from drivewm.npz import load_npz, npz_bytes

LABELS_FORMAT_VERSION = 1


def label_png(labels: np.ndarray) -> bytes:
    """A label map (H, W) uint8 as grey 8-bit PNG bytes (lossless)."""
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(labels, dtype=np.uint8))
    if not ok:
        raise DrivewmError(f"cannot encode a label map of shape {labels.shape} as PNG")
    return buf.tobytes()


def labels_from_png(data: bytes, where: str) -> np.ndarray:
    """The label map (H, W) uint8 of :func:`label_png` bytes; anything else raises DrivewmError."""
    labels = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if labels is None or labels.ndim != 2 or labels.dtype != np.uint8:
        raise DrivewmError(f"{where}: not a grey 8-bit PNG label map")
    return labels


def resize_labels(labels: np.ndarray, size_wh: tuple[int, int]) -> np.ndarray:
    """``labels`` (H, W) at ``size_wh`` (W, H): each output pixel the label at its centre's position in
    the input (``INTER_NEAREST_EXACT``: pixel centres at integers, as images resize), or as it is."""
    if labels.shape == (size_wh[1], size_wh[0]):
        return labels
    return cv2.resize(labels, size_wh, interpolation=cv2.INTER_NEAREST_EXACT)


def labels_to_npz(labels: np.ndarray, timestamps_ns: list[int] | np.ndarray) -> bytes:
    """``KEY.CAMERA.labels.npz`` bytes: ``labels`` (T, H, W) uint8, the frames' ``timestamps_ns`` (T,)
    and the ``classes`` the ids index."""
    return npz_bytes(
        {
            "format_version": np.int64(LABELS_FORMAT_VERSION),
            "labels": np.asarray(labels, dtype=np.uint8),
            "timestamps_ns": np.asarray(timestamps_ns, dtype=np.int64),
            "classes": np.array(LABEL_CLASSES, dtype=np.str_),
        }
    )


def labels_from_npz(data: bytes, where: str) -> np.ndarray:
    """The label maps (T, H, W) uint8 of ``KEY.CAMERA.labels.npz`` bytes, checked: format, class list,
    ids. A damaged or foreign member raises a one-line DrivewmError naming ``where``."""
    arrays = load_npz(data, f"{where}: labels")
    version = arrays.get("format_version")
    if version is None or int(version) != LABELS_FORMAT_VERSION:
        raise DrivewmError(f"{where}: labels format_version {version}, this drivewm reads {LABELS_FORMAT_VERSION}")
    labels, classes = arrays.get("labels"), arrays.get("classes")
    if labels is None or labels.dtype != np.uint8 or labels.ndim != 3:
        raise DrivewmError(f"{where}: labels must be uint8 (T, H, W)")
    if classes is None or classes.tolist() != list(LABEL_CLASSES):
        raise DrivewmError(f"{where}: labels name classes {None if classes is None else classes.tolist()}")
    bad = (labels >= len(LABEL_CLASSES)) & (labels != UNLABELLED)
    if bad.any():
        raise DrivewmError(f"{where}: labels hold id {int(labels[bad][0])}, not a class")
    return labels
