"""The batch split of a run of ticks into clip windows: the reference that the streamed windows
(drivewm.curate.windows.WindowStream) must equal (test_streaming.py, test_sync_split.py).

Shot boundaries come from scenedetect-headless's AdaptiveDetector run on the reference camera:
it scores each frame's HSV + edge change (ContentDetector's score) against the rolling average
of its neighbours, so steady fast camera motion (driving, where ContentDetector alone fires
every few frames on textured scenes) is not a cut, while a hard cut still stands out. Clips are
windows of ``clip_frames`` consecutive valid ticks inside one segment, starting every ``stride_frames``.
"""

from __future__ import annotations

from collections.abc import Iterable

import cv2
import numpy as np
from scenedetect import AdaptiveDetector, FrameTimecode


def shot_boundaries(frames_rgb: Iterable[np.ndarray], fps: float, threshold: float, min_frames: int) -> list[int]:
    """Indices i where a new shot starts at frame i (i > 0), from uint8 RGB (H, W, 3) frames in order.

    ``threshold``: AdaptiveDetector's ratio of a frame's change score to its neighbours' average.
    """
    detector = AdaptiveDetector(adaptive_threshold=threshold, min_scene_len=min_frames)
    cuts: list[int] = []
    n = 0
    for n, frame in enumerate(frames_rgb):
        cuts += [
            int(tc.frame_num)
            for tc in detector.process_frame(FrameTimecode(n, float(fps)), cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
        ]
    cuts += [int(tc.frame_num) for tc in detector.post_process(FrameTimecode(n + 1, float(fps)))]
    return sorted(c for c in set(cuts) if c > 0)


def split_segment(start: int, end: int, cuts: list[int]) -> list[tuple[int, int]]:
    """Cut the range [start, end) at the (absolute) boundary indices in ``cuts``."""
    bounds = [start] + [c for c in sorted(cuts) if start < c < end] + [end]
    return [(a, b) for a, b in zip(bounds[:-1], bounds[1:]) if b > a]


def clip_windows(segments: list[tuple[int, int]], clip_frames: int, stride_frames: int) -> list[tuple[int, int]]:
    """[start, start + clip_frames) windows inside each segment, every ``stride_frames``."""
    return [(s, s + clip_frames) for a, b in segments for s in range(a, b - clip_frames + 1, stride_frames)]
