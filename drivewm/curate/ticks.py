"""Streamed camera frames -> complete ticks of the sync table, in tick order, in bounded memory.

The sync table (:mod:`drivewm.curate.sync`) is built from the timestamps alone, before any image
is read; it names, per tick and camera, one frame of the camera's sorted, de-duplicated
timestamps. While the log streams, each frame is looked up by its timestamp (the first frame
at a timestamp claims it, as the de-duplication keeps the first) and parked under its tick;
a tick is released once all its cameras' frames are in. Only ticks some clip may use are
parked (``needed``), and a released tick's frames are the caller's, so what is held is the few
ticks between the newest frame and the oldest incomplete tick: a clock disagreement between
cameras, not the log length.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drivewm.curate.images import analysis_grey, decode_rgb, fit
from drivewm.curate.sync import SyncResult
from drivewm.errors import DrivewmError
from drivewm.geometry import Camera
from drivewm.logs.types import ImageFrame


class TickAssembler:
    """Feed (camera, frame) in log order with :meth:`add`; it returns the ticks completed, in order.

    ``table``: the sync table over ``cameras``; ``sorted_ns``: per camera its sorted, de-duplicated
    frame timestamps (what ``table.frame_index`` indexes); ``needed`` (N,) bool: ticks to assemble.
    """

    def __init__(self, table: SyncResult, sorted_ns: dict[str, np.ndarray], needed: np.ndarray):
        self.cameras = table.cameras
        self.sorted_ns = sorted_ns
        self.needed = np.asarray(needed, dtype=bool)
        self.tick_of = {}  # camera -> (M,) tick using each frame, -1 for none
        for v, cam in enumerate(self.cameras):
            tick_of = np.full(len(sorted_ns[cam]), -1, dtype=np.int64)
            used = np.flatnonzero(table.frame_index[:, v] >= 0)
            tick_of[table.frame_index[used, v]] = used  # a frame serves one tick at most (tolerance < half a tick)
            self.tick_of[cam] = tick_of
        self.claimed = {cam: np.zeros(len(sorted_ns[cam]), dtype=bool) for cam in self.cameras}
        self.pending: dict[int, list[ImageFrame | None]] = {}
        self.next_tick = 0

    def add(self, camera: str, frame: ImageFrame) -> list[tuple[int, list[ImageFrame]]]:
        """Park one frame; returns [(tick, frames in camera order)] for the ticks now complete."""
        if camera not in self.tick_of:
            return []
        stamps = self.sorted_ns[camera]
        i = int(np.searchsorted(stamps, frame.timestamp_ns))
        if i == len(stamps) or stamps[i] != frame.timestamp_ns or self.claimed[camera][i]:
            return []  # a duplicated timestamp: the first frame keeps it
        self.claimed[camera][i] = True
        tick = int(self.tick_of[camera][i])
        if tick < 0 or not self.needed[tick]:
            return []
        slots = self.pending.setdefault(tick, [None] * len(self.cameras))
        slots[self.cameras.index(camera)] = frame
        return self._release()

    def _release(self) -> list[tuple[int, list[ImageFrame]]]:
        out = []
        while self.next_tick < len(self.needed):
            t = self.next_tick
            if self.needed[t]:
                slots = self.pending.get(t)
                if slots is None or any(f is None for f in slots):
                    break
                out.append((t, self.pending.pop(t)))
            self.next_tick += 1
        return out

    def finish(self, where: str) -> None:
        """Raise DrivewmError if the stream ended before every needed tick was complete."""
        self._release()
        if self.next_tick < len(self.needed):
            raise DrivewmError(
                f"{where}: the log's images changed between the index and the stream (tick {self.next_tick})"
            )


class TickImages:
    """One tick's frames, decoded on first use (uint8 RGB at the output camera size, JPEGs at a reduced
    DCT scale when ``scales`` allow: :mod:`drivewm.curate.images`) and kept while the tick is buffered,
    so a frame shared by shot detection, filters and clips is decoded once; likewise its grey analysis
    thumbnail. ``timed(step)`` charges the CPU to a step (drivewm.curate.timing)."""

    def __init__(
        self, frames: list[ImageFrame], cameras: list[Camera], timed: Callable[[str], object], scales: list[int]
    ):
        self.frames, self.cameras, self.timed, self.scales = frames, cameras, timed, scales
        self._decoded: list[np.ndarray | DrivewmError | None] = [None] * len(frames)
        self._grey: list[np.ndarray | None] = [None] * len(frames)

    def image(self, v: int) -> np.ndarray:
        """Camera ``v``'s image (H, W, 3) uint8 RGB; raises DrivewmError for undecodable bytes (every time)."""
        got = self._decoded[v]
        if got is None:
            got = self._decoded[v] = self._decode(v)
        if isinstance(got, DrivewmError):
            raise got
        return got

    def grey(self, v: int) -> np.ndarray:
        """Camera ``v``'s grey analysis thumbnail (h, 160) uint8 (images.analysis_grey); raises as :meth:`image`."""
        if self._grey[v] is None:
            self._grey[v] = analysis_grey(self.image(v))
        return self._grey[v]

    def _decode(self, v: int) -> np.ndarray | DrivewmError:
        size = (self.cameras[v].width, self.cameras[v].height)
        try:
            with self.timed("decode"):
                img = decode_rgb(self.frames[v], size, self.scales[v])
        except DrivewmError as exc:
            return exc
        if img.shape[:2] != (size[1], size[0]):
            with self.timed("resize"):
                img = fit(img, size)
        return img
