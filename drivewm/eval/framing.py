"""Where the generated views sit in a published video: a crop box, a frame range, grid cell borders.

Published outputs of driving world models are rarely bare views: a grid of six cameras with
separator lines, a caption band, conditioning frames before the generated ones. :class:`Framing`
says which part of each decoded video is scored. The crop box is where the view (or the whole
grid) lies in the frame; the rig is fitted to that box as to an uncropped video of its size
(drivewm.geometry.Camera.scaled), so borders and captions outside it never reach a metric.
Every check fails as one :class:`DrivewmError` line (exit 2 at the CLI).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from drivewm.errors import DrivewmError


@dataclasses.dataclass(frozen=True)
class Framing:
    """The part of a published video that holds the generated views."""

    crop_xywh: tuple[int, int, int, int] | None = None
    """Pixel box (x, y, width, height) of the decoded frame that holds the view(s); None: the whole frame."""
    frame_start: int = 0
    """First frame scored (0-based; conditioning frames before it are left out)."""
    frame_end: int | None = None
    """One past the last frame scored; None: to the end."""
    cell_border_px: int = 0
    """Grid videos: pixels cut from every edge of every cell (separator lines drawn between views)."""

    def __post_init__(self) -> None:
        if self.crop_xywh is not None:
            x, y, w, h = self.crop_xywh
            if x < 0 or y < 0 or w <= 0 or h <= 0:
                raise DrivewmError(f"--crop {x},{y},{w},{h}: needs x, y >= 0 and a positive width and height")
        if self.frame_start < 0 or (self.frame_end is not None and self.frame_end <= self.frame_start):
            raise DrivewmError(f"--frames {self.frame_start}:{self.frame_end}: an empty frame range")
        if self.cell_border_px < 0:
            raise DrivewmError(f"--grid-border {self.cell_border_px}: must be >= 0")

    def box(self, width: int, height: int, where: str) -> tuple[int, int, int, int]:
        """The crop box inside a ``width`` x ``height`` frame (the whole frame when none is set)."""
        if self.crop_xywh is None:
            return 0, 0, width, height
        x, y, w, h = self.crop_xywh
        if x + w > width or y + h > height:
            raise DrivewmError(f"{where}: --crop {x},{y},{w},{h} reaches outside the {width}x{height} frame")
        return x, y, w, h

    def apply(self, frames: np.ndarray, where: str) -> np.ndarray:
        """Uint8 (T, H, W, 3) frames -> the crop box over the frame range."""
        T, H, W, _ = frames.shape
        x, y, w, h = self.box(W, H, where)
        end = T if self.frame_end is None else self.frame_end
        if end > T or self.frame_start >= T:
            raise DrivewmError(f"{where}: --frames {self.frame_start}:{end} but the video has {T} frames")
        return np.ascontiguousarray(frames[self.frame_start : end, y : y + h, x : x + w])

    @property
    def is_default(self) -> bool:
        return self == WHOLE_VIDEO


WHOLE_VIDEO = Framing()
"""Every pixel of every frame, one view per cell without borders."""


def parse_crop(text: str) -> tuple[int, int, int, int]:
    """``"X,Y,W,H"`` in pixels of the decoded frame."""
    try:
        x, y, w, h = (int(v) for v in text.split(","))
    except ValueError:
        raise DrivewmError(f"--crop {text!r}: expected X,Y,W,H in pixels, e.g. 0,40,1920,1040") from None
    return x, y, w, h


def parse_frames(text: str) -> tuple[int, int | None]:
    """``"START:END"`` (END exclusive, may be left out: ``"8:"``), as a Python slice."""
    start, sep, end = text.partition(":")
    try:
        if not sep:
            raise ValueError
        return int(start or 0), (int(end) if end else None)
    except ValueError:
        raise DrivewmError(f"--frames {text!r}: expected START:END, e.g. 9:33 (END exclusive)") from None


def cell_bounds(size_px: int, cells: int) -> list[tuple[int, int]]:
    """(start, end) of ``cells`` equal-as-possible cells along an axis of ``size_px`` (a grid whose size
    does not divide, e.g. 1601 px in 3 columns, gets cells of 533-534 px at the rounded boundaries)."""
    edges = [round(i * size_px / cells) for i in range(cells + 1)]
    return list(zip(edges[:-1], edges[1:]))


def grid_cells(width: int, height: int, rows: int, cols: int, border_px: int) -> list[tuple[int, int, int, int]]:
    """Row-major (x, y, w, h) of every cell of a ``rows`` x ``cols`` grid over a ``width`` x ``height``
    image, ``border_px`` cut from each cell edge."""
    cells = []
    for y0, y1 in cell_bounds(height, rows):
        for x0, x1 in cell_bounds(width, cols):
            w, h = x1 - x0 - 2 * border_px, y1 - y0 - 2 * border_px
            if w <= 0 or h <= 0:
                raise DrivewmError(f"--grid-border {border_px}: leaves no pixel of a {x1 - x0}x{y1 - y0} grid cell")
            cells.append((x0 + border_px, y0 + border_px, w, h))
    return cells


def input_record(location, rig, grid: str | None, cameras: list[str] | None, fit: str, framing: Framing) -> dict:
    """How an input was read (metrics.json ``input``): enough for ``load_items`` to read the same views
    again, from any working folder (paths made absolute)."""
    rig_value = rig.to_dict() if hasattr(rig, "to_dict") else (None if rig is None else str(rig))
    if isinstance(rig_value, str) and Path(rig_value).is_file():
        rig_value = str(Path(rig_value).resolve())
    return {
        "location": str(Path(location).resolve()),
        "rig": rig_value,
        "grid": grid,
        "cameras": cameras,
        "rig_fit": fit,
        "framing": dataclasses.asdict(framing),
    }


def framing_from_record(record: dict) -> Framing:
    """The :class:`Framing` of an ``input`` record (lists back to tuples)."""
    d = dict(record)
    if d.get("crop_xywh") is not None:
        d["crop_xywh"] = tuple(d["crop_xywh"])
    return Framing(**d)
