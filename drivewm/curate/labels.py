"""A log's label maps (``drivewm simulate --labels``) as they stream past, parked for the clips that need them.

Each label map is logged at the time of the image it labels, so a clip frame's label map is the
one at that frame's image timestamp (the sync table's ``frame_ns``). Maps arrive in log order, not
necessarily before their window is final; :meth:`LabelFrames.ready` says when every map a window
needs is in, and a log without label maps is always ready (its clips are made as soon as they are
final).
"""

from __future__ import annotations

import numpy as np

from drivewm.curate.sync import SyncResult
from drivewm.layout.labels import labels_from_png, labels_to_npz, resize_labels
from drivewm.logs.types import ImageFrame


class LabelFrames:
    """Label maps by (tick, camera index) for the ``needed`` ticks of ``table``, of the cameras whose
    label timestamps (``label_ns``: camera name -> (L,) int64) cover them."""

    def __init__(self, table: SyncResult, label_ns: dict[str, np.ndarray], needed: np.ndarray):
        self.cameras = list(table.cameras)
        self.slot: dict[tuple[str, int], list[tuple[int, int]]] = {}  # (camera, ns) -> [(tick, v)]
        for v, cam in enumerate(self.cameras):
            stamps = set(np.asarray(label_ns.get(cam, []), dtype=np.int64).tolist())
            for t in np.flatnonzero(needed & (table.frame_index[:, v] >= 0)):
                ns = int(table.frame_ns[t, v])
                if ns in stamps:
                    self.slot.setdefault((cam, ns), []).append((int(t), v))
        self.expected = {key for keys in self.slot.values() for key in keys}
        self.frames: dict[tuple[int, int], ImageFrame] = {}

    @property
    def any(self) -> bool:
        return bool(self.expected)

    def add(self, camera: str, frame: ImageFrame) -> None:
        for key in self.slot.get((camera, int(frame.timestamp_ns)), []):
            self.frames.setdefault(key, frame)  # a repeated timestamp: the first map keeps it

    def ready(self, start: int, end: int) -> bool:
        """Whether every label map ticks [start, end) expect has arrived."""
        return all(
            (t, v) in self.frames
            for t in range(start, end)
            for v in range(len(self.cameras))
            if (t, v) in self.expected
        )

    def window(self, start: int, end: int) -> dict[int, list[ImageFrame]]:
        """Camera index -> the label map of each tick of [start, end), for the cameras that have all."""
        out = {}
        for v in range(len(self.cameras)):
            frames = [self.frames.get((t, v)) for t in range(start, end)]
            if all(f is not None for f in frames):
                out[v] = frames
        return out

    def forget_before(self, tick: int) -> None:
        """Drop the maps of ticks before ``tick`` (no window left needs them)."""
        for key in [k for k in self.frames if k[0] < tick]:
            del self.frames[key]


def labels_member(frames: list[ImageFrame], size_wh: tuple[int, int], times_ns: list[int], where: str) -> bytes:
    """``KEY.CAMERA.labels.npz`` of one camera's label maps (PNG frames), at the clip's image size
    (nearest label at each output pixel's centre); undecodable bytes raise DrivewmError."""
    maps = [resize_labels(labels_from_png(f.data, f"{where} at {f.timestamp_ns} ns"), size_wh) for f in frames]
    return labels_to_npz(np.stack(maps), times_ns)
