"""Clip windows of a tick stream, emitted as soon as no later frame can change them.

Batch form (``split``): inside each valid run [a, b) long enough for a clip, shot boundaries of
the reference camera cut the run into segments, and windows of ``clip_frames`` start every
``stride_frames`` from each segment's start. Streamed, the shot detector sees one reference
frame per tick and reports a cut at frame c only after frame c + lag (AdaptiveDetector compares
a frame with ``window_width`` neighbours on each side: ``event_buffer_length``). A window
[s, s + clip_frames) is final once every cut up to its last frame is known, or the run has
ended; a known cut inside it starts a new segment at the cut instead. The windows and their
order are exactly the batch ones (tests/curate/batch_split.py; test_streaming.py checks), and the
oldest tick a future window can use (:attr:`WindowStream.oldest_needed`) bounds what the caller
must keep.
"""

from __future__ import annotations

import bisect
from collections.abc import Callable

import cv2
import numpy as np


class WindowStream:
    """Feed ticks in increasing order with :meth:`push`; it returns the windows that became final.

    ``runs``: the valid runs [a, b) of ticks at least ``clip_frames`` long (ticks outside them are
    never pushed). ``shot_threshold`` 0 disables shot detection. ``blank_frame``: what the shot
    detector sees for an undecodable first frame of a run.
    """

    def __init__(
        self,
        runs: list[tuple[int, int]],
        clip_frames: int,
        stride_frames: int,
        fps: float,
        shot_threshold: float,
        shot_min_frames: int,
        blank_frame: np.ndarray,
    ):
        self.runs = list(runs)
        self.T, self.stride, self.fps = clip_frames, stride_frames, fps
        self.threshold, self.min_frames, self.blank = shot_threshold, shot_min_frames, blank_frame
        self._run = -1  # index of the current run
        self._segment = 0  # start of the current segment
        self._start = 0  # candidate start of the next window
        self._cuts: list[int] = []  # known cuts (absolute ticks) after the current segment's start
        self._detector = None
        self._last_frame: np.ndarray | None = None

    @property
    def oldest_needed(self) -> int:
        """No future window starts before this tick."""
        if self._run < 0:
            return self.runs[0][0] if self.runs else 0
        return self._start

    def push(self, tick: int, reference_frame: Callable[[], np.ndarray | None]) -> list[tuple[int, int]]:
        """Advance to ``tick``; ``reference_frame()`` gives its reference-camera frame (uint8 RGB,
        at most 320 px wide) for shot detection, or None if undecodable (the previous frame is
        repeated, as in batch). Returns the windows [start, end) made final by this tick."""
        if self._run < 0 or tick >= self.runs[self._run][1]:
            self._enter_run(tick)
        a, b = self.runs[self._run]
        known_through = tick
        if self.threshold > 0:
            frame = reference_frame()
            self._last_frame = frame if frame is not None else self._last_frame
            if self._last_frame is None:
                self._last_frame = self.blank
            self._add_cuts(a, self._detector.process_frame(self._timecode(tick - a), _bgr(self._last_frame)))
            known_through = tick - self._detector.event_buffer_length
            if tick == b - 1:
                self._add_cuts(a, self._detector.post_process(self._timecode(tick - a + 1)))
        if tick == b - 1:
            known_through = tick
        return self._emit(b, known_through)

    def _enter_run(self, tick: int) -> None:
        self._run = next(i for i, (a, b) in enumerate(self.runs) if a <= tick < b)
        self._segment = self._start = self.runs[self._run][0]
        self._cuts, self._last_frame = [], None
        if self.threshold > 0:
            from scenedetect import AdaptiveDetector

            self._detector = AdaptiveDetector(adaptive_threshold=self.threshold, min_scene_len=self.min_frames)

    def _timecode(self, n: int):
        from scenedetect import FrameTimecode

        return FrameTimecode(n, float(self.fps))

    def _add_cuts(self, run_start: int, timecodes) -> None:
        for tc in timecodes:
            c = run_start + int(tc.frame_num)
            if c > self._segment and c not in self._cuts:
                bisect.insort(self._cuts, c)

    def _emit(self, run_end: int, known_through: int) -> list[tuple[int, int]]:
        out = []
        while True:
            cut = self._cuts[0] if self._cuts and self._cuts[0] < run_end else None
            s, e = self._start, self._start + self.T
            if e <= (cut if cut is not None else run_end) and e - 1 <= known_through:
                out.append((s, e))
                self._start += self.stride
            elif cut is not None and e > cut:  # the window would cross a known cut: a new segment starts there
                self._segment = self._start = cut
                self._cuts = [c for c in self._cuts if c > cut]
            else:
                return out


def _bgr(frame_rgb: np.ndarray) -> np.ndarray:
    return cv2.cvtColor(frame_rgb, cv2.COLOR_RGB2BGR)
