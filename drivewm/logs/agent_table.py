"""A log's road users over time as columns: what a streaming reader keeps of the agent messages.

:class:`drivewm.logs.reader.LogStream` keeps no image payloads in its index, so an hour-long log
fits in memory; the road users it does keep (curation builds each clip's layout from them,
:mod:`drivewm.layout`) are rows of numbers, not objects: about 90 bytes per box, 90 MB for an hour
of 30 boxes at 10 Hz. Rows are in the world frame once the reader has placed them (boxes logged in
the ego frame or a sensor frame are moved with the ego pose at their stamp).
"""

from __future__ import annotations

import array
import dataclasses
from collections.abc import Callable

import numpy as np


@dataclasses.dataclass
class AgentBox:
    """Another road user as an oriented 3D box in the world frame.

    ``center_xyz`` is the box centre (m), ``size_lwh`` length/width/height (m), ``yaw_rad`` its
    heading about +z; ``color_rgb`` in [0, 1]; ``category`` e.g. car, truck, pedestrian.
    """

    track_id: str
    category: str
    center_xyz: np.ndarray
    size_lwh: np.ndarray
    yaw_rad: float
    color_rgb: tuple[float, float, float] = (0.5, 0.5, 0.5)


#: ``T_world_from(frame_id, timestamps_ns (K,)) -> (K, 4, 4)``, or None when the frame cannot be placed.
Placer = Callable[[str, np.ndarray], "np.ndarray | None"]


@dataclasses.dataclass
class AgentTable:
    """Boxes of the road users, one message (tick) after another.

    ``timestamps_ns`` (M,) int64 per message, in time order; message m's boxes are rows
    ``first_row[m]:first_row[m + 1]`` ((M + 1,) int64). Per row: ``center_xyz`` (R, 3) and
    ``size_lwh`` (R, 3) m, ``yaw_rad`` (R,), ``color_rgb`` (R, 3) in [0, 1], and the indices
    ``track`` (R,) into ``track_ids`` and ``category`` (R,) into ``categories``.
    """

    timestamps_ns: np.ndarray
    first_row: np.ndarray
    center_xyz: np.ndarray
    size_lwh: np.ndarray
    yaw_rad: np.ndarray
    color_rgb: np.ndarray
    track: np.ndarray
    category: np.ndarray
    track_ids: list[str]
    categories: list[str]

    @classmethod
    def empty(cls) -> AgentTable:
        return AgentTableBuilder().build()[0]

    def __len__(self) -> int:
        return len(self.timestamps_ns)

    def boxes(self, m: int) -> list[AgentBox]:
        """The boxes of message ``m``."""
        return [self._box(r) for r in range(int(self.first_row[m]), int(self.first_row[m + 1]))]

    def _box(self, r: int) -> AgentBox:
        return AgentBox(
            self.track_ids[self.track[r]],
            self.categories[self.category[r]],
            self.center_xyz[r].copy(),
            self.size_lwh[r].copy(),
            float(self.yaw_rad[r]),
            tuple(float(c) for c in self.color_rgb[r]),
        )

    def nearest(self, timestamp_ns: int, tolerance_ns: float) -> int | None:
        """The message nearest in time to ``timestamp_ns`` if within ``tolerance_ns``, else None."""
        if len(self) == 0:
            return None
        i = int(np.searchsorted(self.timestamps_ns, timestamp_ns))
        near = [j for j in (i - 1, i) if 0 <= j < len(self)]
        best = min(near, key=lambda j: abs(int(self.timestamps_ns[j]) - int(timestamp_ns)))
        return best if abs(int(self.timestamps_ns[best]) - int(timestamp_ns)) <= tolerance_ns else None

    def as_messages(self) -> list[tuple[int, list[AgentBox]]]:
        """Every message as (timestamp_ns, boxes), the form :class:`drivewm.logs.types.DriveLog` holds."""
        return [(int(t), self.boxes(m)) for m, t in enumerate(self.timestamps_ns)]


class AgentTableBuilder:
    """Collects messages (in any order) into an :class:`AgentTable`; numbers go into flat arrays at once."""

    def __init__(self) -> None:
        self._stamps: list[int] = []
        self._frames: list[str] = []
        self._counts: list[int] = []
        self._floats = array.array("d")  # per row: centre 3, size 3, yaw, colour 3, length axis 3
        self._codes = array.array("q")  # per row: track, category
        self._tracks: dict[str, int] = {}
        self._categories: dict[str, int] = {}

    def add(self, timestamp_ns: int, boxes: list[AgentBox], frame_id: str = "", axes: list | None = None) -> None:
        """One message's boxes, given in ``frame_id`` ("" for the world frame); ``axes``: each box's
        length axis (3,) in that frame when it may be tilted (default: horizontal, along its yaw)."""
        self._stamps.append(int(timestamp_ns))
        self._frames.append(frame_id)
        self._counts.append(len(boxes))
        for k, b in enumerate(boxes):
            axis = axes[k] if axes is not None else (np.cos(b.yaw_rad), np.sin(b.yaw_rad), 0.0)
            self._floats.extend([*b.center_xyz[:3], *b.size_lwh[:3], b.yaw_rad, *b.color_rgb[:3], *axis[:3]])
            self._codes.append(self._tracks.setdefault(b.track_id, len(self._tracks)))
            self._codes.append(self._categories.setdefault(b.category, len(self._categories)))

    def build(self, place: Placer | None = None, world: str = "") -> tuple[AgentTable, list[str]]:
        """The table in time order, and the frames whose messages were left out. ``place`` moves the
        boxes of messages in another frame than the world's (``world`` or "", kept as read) into the
        world frame (a frame it maps to None: left out); without it every box is taken as in the world."""
        stamps = np.asarray(self._stamps, dtype=np.int64)
        floats = np.frombuffer(self._floats, dtype=np.float64).reshape(-1, 13).copy()
        codes = np.frombuffer(self._codes, dtype=np.int64).reshape(-1, 2)
        first = np.concatenate([[0], np.cumsum(self._counts, dtype=np.int64)])
        keep, lost = np.ones(len(stamps), dtype=bool), []
        for frame in sorted(set(self._frames) - {"", world}) if place is not None else []:
            msgs = np.flatnonzero(np.array(self._frames) == frame)
            T = place(frame, stamps[msgs])
            if T is None:
                keep[msgs], lost = False, [*lost, frame]
                continue
            for m, T_world_from_frame in zip(msgs, T):
                if np.isfinite(T_world_from_frame).all():
                    _move_rows(floats[first[m] : first[m + 1]], T_world_from_frame)
                else:  # an ego pose gap: the boxes cannot be placed
                    keep[m] = False
        order = np.flatnonzero(keep)[np.argsort(stamps[keep], kind="stable")]
        rows = np.concatenate([np.arange(first[m], first[m + 1]) for m in order]) if len(order) else np.zeros(0, int)
        counts = np.asarray(self._counts, dtype=np.int64)[order]
        table = AgentTable(
            stamps[order],
            np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
            floats[rows, 0:3],
            floats[rows, 3:6],
            floats[rows, 6],
            floats[rows, 7:10],
            codes[rows, 0].astype(np.int32),
            codes[rows, 1].astype(np.int16),
            list(self._tracks),
            list(self._categories),
        )
        return table, lost


def _move_rows(rows: np.ndarray, T_world_from_frame: np.ndarray) -> None:
    """Move rows (K, 13) of (centre, size, yaw, colour, length axis) by a rigid transform, in place:
    the centre as a point, the yaw the heading of the length axis after the rotation."""
    R, t = T_world_from_frame[:3, :3], T_world_from_frame[:3, 3]
    rows[:, 0:3] = rows[:, 0:3] @ R.T + t
    axis = rows[:, 10:13] @ R.T
    rows[:, 6] = np.arctan2(axis[:, 1], axis[:, 0])
