"""Time synchronization across cameras: one reference clock, each camera's nearest frame per tick.

The reference clock is a uniform grid at the clip rate, anchored at the first frame of the first
camera once every camera has started (so cameras that start late just shorten the usable span).
A tick keeps a camera's frame only within ``tolerance_ns`` of it; ticks where any camera has no
such frame (a dropped frame, a camera that stopped) are invalid and later split clips apart.
Duplicated timestamps keep their first frame. With a tolerance below half a tick, two ticks can
never pick the same frame, so resampling never repeats frames.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass
class SyncResult:
    """The synchronized tick table of one log.

    ``tick_ns`` (N,) reference times; ``frame_index`` (N, V) index into each camera's de-duplicated
    frame list (-1 where missing); ``valid`` (N,) every camera present; ``skew_ns`` (N,) worst
    |camera time - tick| per tick; ``stats`` per camera: duplicates, late start, missing ticks.
    """

    cameras: list[str]
    tick_ns: np.ndarray
    frame_index: np.ndarray
    valid: np.ndarray
    skew_ns: np.ndarray
    stats: dict[str, dict[str, int]]

    @property
    def worst_skew_ns(self) -> int:
        return int(self.skew_ns[self.valid].max()) if self.valid.any() else 0


def dedupe_timestamps(timestamps_ns: np.ndarray) -> tuple[np.ndarray, int]:
    """Indices of the first frame at each distinct timestamp (input sorted), and how many were duplicates."""
    keep = np.ones(len(timestamps_ns), dtype=bool)
    keep[1:] = np.diff(timestamps_ns) > 0
    return np.flatnonzero(keep), int((~keep).sum())


def nearest_frames(frame_ns: np.ndarray, tick_ns: np.ndarray, tolerance_ns: float) -> tuple[np.ndarray, np.ndarray]:
    """Nearest frame to each tick: (index or -1 beyond tolerance, |dt| in ns)."""
    right = (
        np.clip(np.searchsorted(frame_ns, tick_ns), 1, len(frame_ns) - 1)
        if len(frame_ns) > 1
        else np.zeros(len(tick_ns), int)
    )
    left = np.maximum(right - 1, 0)
    dl, dr = np.abs(tick_ns - frame_ns[left]), np.abs(frame_ns[right] - tick_ns)
    idx = np.where(dr < dl, right, left)
    dt = np.minimum(dl, dr)
    return np.where(dt <= tolerance_ns, idx, -1), dt


def reference_ticks(
    first_ns: list[int], last_ns: list[int], ref_first_ns: np.ndarray, period_ns: float, tolerance_ns: float
) -> np.ndarray:
    """The uniform tick grid over the span where every camera runs (int64 ns)."""
    start_min = max(first_ns) - tolerance_ns
    start = (
        int(ref_first_ns[np.searchsorted(ref_first_ns, start_min)]) if ref_first_ns[-1] >= start_min else max(first_ns)
    )
    end = min(last_ns) + tolerance_ns
    if end < start:
        return np.zeros(0, dtype=np.int64)
    count = int(np.floor((end - start) / period_ns)) + 1
    return start + np.round(np.arange(count) * period_ns).astype(np.int64)


def synchronize(
    camera_timestamps_ns: dict[str, np.ndarray], cameras: list[str], period_ns: float, tolerance_ns: float
) -> SyncResult:
    """Build the tick table for ``cameras`` (the first is the reference) from each camera's sorted frame times.

    ``frame_index`` refers to the de-duplicated frame order: use :func:`dedupe_timestamps` on the
    same arrays to map back to the log's frames.
    """
    unique = {
        c: np.asarray(camera_timestamps_ns[c], dtype=np.int64)[
            dedupe_timestamps(np.asarray(camera_timestamps_ns[c]))[0]
        ]
        for c in cameras
    }
    if any(len(unique[c]) == 0 for c in cameras):
        empty = [c for c in cameras if len(unique[c]) == 0]
        return _empty(cameras, {c: {"frames": len(unique[c]), "missing_camera": int(c in empty)} for c in cameras})
    ticks = reference_ticks(
        [int(unique[c][0]) for c in cameras],
        [int(unique[c][-1]) for c in cameras],
        unique[cameras[0]],
        period_ns,
        tolerance_ns,
    )
    index = np.full((len(ticks), len(cameras)), -1, dtype=np.int64)
    dts = np.zeros((len(ticks), len(cameras)), dtype=np.int64)
    for v, cam in enumerate(cameras):
        index[:, v], dts[:, v] = nearest_frames(unique[cam], ticks, tolerance_ns)
    valid = (index >= 0).all(axis=1)
    skew = np.where(index >= 0, dts, 0).max(axis=1) if len(ticks) else np.zeros(0, dtype=np.int64)
    return SyncResult(list(cameras), ticks, index, valid, skew, _stats(camera_timestamps_ns, cameras, unique, index))


def _stats(
    raw: dict[str, np.ndarray], cameras: list[str], unique: dict[str, np.ndarray], index: np.ndarray
) -> dict[str, dict[str, int]]:
    start = min(int(unique[c][0]) for c in cameras)
    return {
        cam: {
            "frames": int(len(raw[cam])),
            "duplicate_timestamps": int(len(raw[cam]) - len(unique[cam])),
            "late_start_ns": int(unique[cam][0] - start),
            "missing_ticks": int((index[:, v] < 0).sum()),
        }
        for v, cam in enumerate(cameras)
    }


def _empty(cameras: list[str], stats: dict) -> SyncResult:
    z = np.zeros(0, dtype=np.int64)
    return SyncResult(list(cameras), z, np.zeros((0, len(cameras)), dtype=np.int64), np.zeros(0, dtype=bool), z, stats)
