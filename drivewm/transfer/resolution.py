"""Transfer at the source's resolution: the model works at its own small size, the clip keeps its own.

The transfer model (and the tokenizer under it) works at one image size (160x96 for the shipped
model); a user's clips are larger (the team's 320x192 sim clips, 1600x900 fleet cameras). Writing
the clip back at the model's size loses the user's resolution and ties the labels to another
image size. Here the source is resized down to the model's size (cv2.INTER_AREA, as the curator
does), coded and transferred there; the decoded frames are upsampled back to the source's size
(bicubic) and the detail the round trip lost is restored at full resolution:

    detail = source_full - upsample(decode(encode(source_small)))

which holds both what the tokenizer drops at the model's size and everything above the model's
resolution, scaled by the local contrast the transfer keeps (drivewm.transfer.detail, its window
of WINDOW_PX model pixels scaled to the source's size). Cost: two bicubic resizes and one tokenizer
decode per clip, no network evaluations. Videos are uint8 (V, T, H, W, 3) in rig order throughout.
"""

from __future__ import annotations

import cv2
import numpy as np

from drivewm.geometry import Rig
from drivewm.multiview.coding import resize_views
from drivewm.transfer.detail import BAND_PX, WINDOW_PX, restore_detail

UPSAMPLE = cv2.INTER_CUBIC  # Keys' bicubic: sharper than bilinear, no LANCZOS ringing on dark night skies


def output_size_hw(source_hw: tuple[int, int], model_hw: tuple[int, int], model_resolution: bool) -> tuple[int, int]:
    """(H, W) a transferred clip is written at: the source's when it is larger than the model's size in
    either axis (unless ``model_resolution``), else the model's (a smaller source is upsampled to it)."""
    larger = source_hw[0] > model_hw[0] or source_hw[1] > model_hw[1]
    return tuple(source_hw) if larger and not model_resolution else tuple(model_hw)


def rig_at_size(rig: Rig, source_hw: tuple[int, int], size_hw: tuple[int, int]) -> Rig:
    """The rig of frames resized from ``source_hw`` to ``size_hw`` (H, W): stretched like the frames
    (cv2.resize, no crop), so a 16:9 dashcam at 160x96 gets fx != fy rather than a silently wrong
    calibration; ``rig`` itself at the source's size."""
    return rig if tuple(size_hw) == tuple(source_hw) else rig.scaled(size_hw[1], size_hw[0], fit="stretch")


def upsampling(size_hw: tuple[int, int], model_hw: tuple[int, int]) -> float:
    """How much larger ``size_hw`` is than ``model_hw`` (mean of both axes), at least 1."""
    return max(0.5 * (size_hw[0] / model_hw[0] + size_hw[1] / model_hw[1]), 1.0)


def detail_window_px(size_hw: tuple[int, int], model_hw: tuple[int, int], window_px: int = WINDOW_PX) -> int:
    """The contrast window at ``size_hw``: ``window_px`` model pixels (default WINDOW_PX, about two
    tokenizer cells) times the upsampling factor, odd so it centres on the pixel."""
    return int(window_px * upsampling(size_hw, model_hw)) // 2 * 2 + 1


def to_output_size(
    transferred: np.ndarray,
    source: np.ndarray,
    source_coded: np.ndarray | None,
    band_px: float = BAND_PX,
    window_px: int = WINDOW_PX,
    min_gain: float = 0.0,
    rig: Rig | None = None,
) -> np.ndarray:
    """The decoded transfer (at the model's size) upsampled to ``source``'s size, plus the source detail
    the round trip lost, its gain computed at that size; ``source_coded`` is the source decoded from its
    latents (model's size), None for no detail (upsampled only). ``band_px`` (in the model's pixels,
    scaled like the window; 0: the tokenizer's residual only): the source's structure finer than it
    replaces the transfer's (drivewm.transfer.detail); ``window_px`` (model pixels, scaled alike): the
    window of the contrast gain; ``rig`` (the views' cameras): the transfer's look is shared between
    cameras where they overlap (drivewm.transfer.detail.restore_detail; None: each view on its own)."""
    size_hw, model_hw = source.shape[2:4], transferred.shape[2:4]
    out = resize_views(transferred, size_hw, UPSAMPLE)
    if source_coded is None:
        return out
    coded = resize_views(source_coded, size_hw, UPSAMPLE)
    band = band_px * upsampling(size_hw, model_hw)
    return restore_detail(
        out,
        source,
        coded,
        window=detail_window_px(size_hw, model_hw, window_px),
        band_px=band,
        min_gain=min_gain,
        rig=rig,
    )
