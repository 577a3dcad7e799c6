"""Time synchronization across cameras: one reference clock, each camera's nearest frame per tick.

The reference clock is a uniform grid at the clip rate, anchored at the first frame of the first
camera once every camera has started (so cameras that start late just shorten the usable span).
Rigs that fire their cameras in turn (nuScenes: as the lidar sweeps past, up to ~40 ms apart)
give each camera a constant exposure offset from the reference camera; it is estimated per camera
(the median time to the reference camera's nearest frame, kept when the interquartile spread is
within the tolerance, i.e. the offset is steady) and the tolerance is applied around
``tick + offset``: camera c keeps its frame at tick k only within ``tolerance_ns`` of
``tick_k + offset_c``. Ticks where any camera has no such frame (a dropped frame, a camera that
stopped) are invalid and later split clips apart. Each kept frame's own timestamp is recorded
(``frame_ns``), so a clip states when every image was exposed. Duplicated timestamps keep their
first frame. With a tolerance below half a tick, two ticks can never pick the same frame, so
resampling never repeats frames.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass
class SyncResult:
    """The synchronized tick table of one log.

    ``tick_ns`` (N,) reference times; ``frame_index`` (N, V) index into each camera's de-duplicated
    frame list (-1 where missing); ``frame_ns`` (N, V) that frame's own timestamp (-1 where
    missing); ``valid`` (N,) every camera present; ``skew_ns`` (N,) worst |camera time - tick| per
    tick (exposure offsets included); ``offsets_ns`` each camera's estimated exposure offset from
    the reference camera; ``stats`` per camera: duplicates, late start, offset, missing ticks.
    """

    cameras: list[str]
    tick_ns: np.ndarray
    frame_index: np.ndarray
    frame_ns: np.ndarray
    valid: np.ndarray
    skew_ns: np.ndarray
    offsets_ns: dict[str, int]
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


def covered_spans(times_ns: list[np.ndarray], max_gap_ns: float) -> list[tuple[int, int]]:
    """[first, last] time spans (ns) where every sequence (sorted) has frames no more than
    ``max_gap_ns`` apart: a longer gap in any camera (a recorder pause, a clock jumping forward)
    ends a span."""
    spans = [(int(times_ns[0][0]), int(times_ns[0][-1]))] if len(times_ns[0]) else []
    for t in times_ns:
        breaks = np.flatnonzero(np.diff(t) > max_gap_ns)
        own = list(zip(t[np.r_[0, breaks + 1]].tolist(), t[np.r_[breaks, len(t) - 1]].tolist()))
        spans = [(max(a, c), min(b, d)) for a, b in spans for c, d in own if max(a, c) <= min(b, d)]
    return spans


def clock_jumps_back(arrival_ns: np.ndarray, threshold_ns: float) -> tuple[np.ndarray, list[tuple[int, int, int]]]:
    """Frames of one camera, in log (arrival) order, whose clock jumped back by more than
    ``threshold_ns`` (a reset, a re-synchronization): each such frame and every later one until
    the clock passes its earlier maximum are dropped (two time bases cannot share one tick grid).
    Returns (keep mask, [(arrival index, from_ns, to_ns) per jump]). Smaller steps back are
    out-of-order delivery and are kept."""
    keep = np.ones(len(arrival_ns), dtype=bool)
    jumps, high, dropping = [], None, False
    for i, t in enumerate(np.asarray(arrival_ns, dtype=np.int64).tolist()):
        if high is not None and (t < high - threshold_ns or (dropping and t <= high)):
            if not dropping:
                jumps.append((i, high, t))
            keep[i], dropping = False, True
            continue
        dropping, high = False, t if high is None else max(high, t)
    return keep, jumps


def exposure_offset_ns(frame_ns: np.ndarray, reference_ns: np.ndarray, tolerance_ns: float) -> int:
    """A camera's steady exposure offset from the reference camera (ns): the median time from each
    reference frame to the camera's nearest frame, or 0 when those times spread (interquartile
    range) beyond the tolerance (another frame rate, no fixed phase). Both inputs sorted, unique."""
    if len(frame_ns) == 0 or len(reference_ns) == 0:
        return 0
    idx, _ = nearest_frames(frame_ns, reference_ns, np.inf)
    dt = frame_ns[idx] - reference_ns
    q25, q50, q75 = np.percentile(dt, [25, 50, 75])
    return int(round(q50)) if q75 - q25 <= tolerance_ns else 0


def synchronize(
    camera_timestamps_ns: dict[str, np.ndarray],
    cameras: list[str],
    period_ns: float,
    tolerance_ns: float,
    per_camera_offsets: bool = True,
    max_gap_ns: float = np.inf,
    exclude_ns: list[tuple[int, int]] = (),
) -> SyncResult:
    """Build the tick table for ``cameras`` (the first is the reference) from each camera's sorted frame times.

    ``per_camera_offsets``: apply the tolerance around each camera's estimated exposure offset
    (False: around the tick for every camera). ``max_gap_ns``: a longer gap in any camera ends a
    span of the grid; the next span starts again at a reference frame (its phase after a clock
    jump is its own), one invalid tick apart, so a jump of hours costs no empty ticks.
    ``exclude_ns``: [start, end] ranges whose ticks are invalid (e.g. times a clock went through
    twice). ``frame_index`` refers to the de-duplicated frame order: use :func:`dedupe_timestamps`
    on the same arrays to map back to the log's frames.
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
    ref = unique[cameras[0]]
    offsets = {c: exposure_offset_ns(unique[c], ref, tolerance_ns) if per_camera_offsets else 0 for c in cameras}
    shifted = {c: unique[c] - offsets[c] for c in cameras}  # each camera's frames on the reference clock
    ticks = _span_ticks(covered_spans([shifted[c] for c in cameras], max_gap_ns), ref, period_ns, tolerance_ns)
    index = np.full((len(ticks), len(cameras)), -1, dtype=np.int64)
    for v, cam in enumerate(cameras):
        index[:, v] = nearest_frames(shifted[cam], ticks, tolerance_ns)[0]
    frame_ns = np.stack([np.where(index[:, v] >= 0, unique[c][index[:, v]], -1) for v, c in enumerate(cameras)], 1)
    excluded = np.zeros(len(ticks), dtype=bool)
    for a, b in exclude_ns:
        excluded |= (ticks >= a - tolerance_ns) & (ticks <= b + tolerance_ns)
    valid = (index >= 0).all(axis=1) & ~excluded
    dts = np.abs(frame_ns - ticks[:, None])
    skew = np.where(index >= 0, dts, 0).max(axis=1) if len(ticks) else np.zeros(0, dtype=np.int64)
    stats = _stats(camera_timestamps_ns, cameras, unique, index, offsets, period_ns, max_gap_ns)
    return SyncResult(list(cameras), ticks, index, frame_ns.reshape(len(ticks), -1), valid, skew, offsets, stats)


def _span_ticks(spans: list[tuple[int, int]], ref_ns: np.ndarray, period_ns: float, tolerance_ns: float) -> np.ndarray:
    """The tick grid of each span (anchored at its first reference frame), one invalid tick
    (a period after the span's last) between consecutive spans."""
    parts = []
    for a, b in spans:
        ticks = reference_ticks([a], [b], ref_ns, period_ns, tolerance_ns)
        if len(ticks):
            parts += [ticks, ticks[-1:] + int(round(period_ns))]
    return np.concatenate(parts[:-1]) if parts else np.zeros(0, dtype=np.int64)


def frame_rate(times_ns: np.ndarray, max_gap_ns: float) -> dict[str, float]:
    """Median rate (Hz) and its 5th-95th percentile range from a camera's frame intervals (gaps
    longer than ``max_gap_ns`` excluded): a real rig's rate drifts and stutters."""
    dt = np.diff(times_ns)
    dt = dt[(dt > 0) & (dt <= max_gap_ns)]
    if len(dt) == 0:
        return {"rate_hz": 0.0, "rate_p5_hz": 0.0, "rate_p95_hz": 0.0}
    p5, p50, p95 = np.percentile(dt, [5, 50, 95])
    return {
        "rate_hz": round(1e9 / float(p50), 3),
        "rate_p5_hz": round(1e9 / float(p95), 3),
        "rate_p95_hz": round(1e9 / float(p5), 3),
    }


def _stats(
    raw: dict[str, np.ndarray],
    cameras: list[str],
    unique: dict[str, np.ndarray],
    index: np.ndarray,
    offsets: dict[str, int],
    period_ns: float,
    max_gap_ns: float,
) -> dict[str, dict]:
    start = min(int(unique[c][0]) for c in cameras)
    return {
        cam: {
            "frames": int(len(raw[cam])),
            "duplicate_timestamps": int(len(raw[cam]) - len(unique[cam])),
            "late_start_ns": int(unique[cam][0] - start),
            "exposure_offset_ns": int(offsets[cam]),
            "missing_ticks": int((index[:, v] < 0).sum()),
            "gaps": int((np.diff(unique[cam]) > max_gap_ns).sum()),
            **frame_rate(unique[cam], max_gap_ns),
        }
        for v, cam in enumerate(cameras)
    }


def _empty(cameras: list[str], stats: dict) -> SyncResult:
    z, table = np.zeros(0, dtype=np.int64), np.zeros((0, len(cameras)), dtype=np.int64)
    return SyncResult(list(cameras), z, table, table, np.zeros(0, dtype=bool), z, dict.fromkeys(cameras, 0), stats)
