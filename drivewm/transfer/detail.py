"""Restore the source's fine detail on a transferred clip.

A latent transfer can only return what the tokenizer decodes, and the tokenizer drops fine detail
(lane-marking edges, vehicle outlines): measured on held-out pairs, SIFT matches between a source
frame and its transfer sat 4-18 px apart, and 3 px even between a true target render and its own
tokenizer reconstruction. The detail the tokenizer dropped from the source is known exactly: the
residual ``source - decode(encode(source))``. It is added back to the transfer, scaled per pixel by
how much local contrast the target condition keeps (``local std of the transfer / local std of the
source reconstruction``, clipped to ``[0, max_gain]``): fog and night scale it down, a clear target
keeps it whole. The pixel-level analogue of Cosmos-Transfer's edge control, at no network
evaluations: one tokenizer decode per clip. Measured (docs/transfer.md): SIFT shift 4-18 px to
0.3 px, PSNR to the true target +0.0 to +0.7 dB; adding the residual unscaled lost 2-3 dB on fog
and night.

With ``band_px`` > 0 (the default of ``drivewm transfer``, ``--detail-band``) the split moves below
the tokenizer's: the transfer keeps only what is coarser than a Gaussian of ``band_px``, and all the
source's structure finer than that comes back, scaled the same way::

    out = G(transfer) + gain * (source - G(source_coded))

Each view is transferred on its own, so the transfer's mid-scale content (what SIFT describes in
the overlap of two cameras) differs between views; at ``band_px`` 0 only 48 % of camera pairs kept
enough cross-view matches. The band keeps the source's there and leaves the condition's colour,
light and haze to the transfer (docs/transfer.md, "Detail band").

The gain is read over ``WINDOW_PX`` (17 px at the model's size, about two tokenizer cells). Over one
cell (9 px, the first default) it followed the transfer's own per-view texture as much as the
condition's contrast, so the same source structure came back at different strengths in two cameras'
overlap and the pair lost verified matches; over two it follows the condition more (haze, night).
Wider still (33 px) kept more pairs at 320x192 but gave back enough of the source's contrast in
far haze for the adherence classifier to read fog as snow at 160x96 (docs/transfer.md, "Gain window").

Given the rig (``drivewm transfer``'s default, ``--no-shared-look`` to skip), the transfer's look,
``G(transfer)`` and ``gain``, is shared between cameras: at each pixel it is the feathered mean of
every camera that sees its point of the flat world (drivewm.views.blend.feathering, the blend of
the ``stitch`` post-step), another camera counting only as far as the two coded sources'
``G(source_coded)`` agree there (within LOOK_TOLERANCE levels: one surface, not a building the flat
world puts at infinity), while ``source - G(source_coded)`` stays the view's own. Two cameras then
give one point one light and bring its structure back at one strength. Measured on the 9 held-out
pairs at 320x192: CSE 1.61x to 1.01x the source's, every camera pair kept, PSNR +0.06 dB; on the
first 3 validation drives 1.84x to 1.53x, on all 6 1.32x (docs/transfer.md, "The look shared between
cameras").
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from drivewm.geometry import Rig
from drivewm.multiview.coding import resize_views
from drivewm.views.blend import check_views, feathered_mean, feathering

WINDOW_PX = 17  # local-contrast window at the model's size: about two tokenizer cells (measured: docs/transfer.md)
BAND_PX = 8.0  # default band at the model's size: one tokenizer cell (measured: docs/transfer.md)
WIDE_BLUR_PX = 16.0  # px: a band blur at least twice this wide runs shrunk (band_blur)
LOOK_TOLERANCE = 30.0  # levels: cameras share a look where their coded sources agree this closely (share_look)
LOOK_MAX_WIDTH = 320  # px: the look is shared across cameras at most this wide (look_size)
FLOOR = 2.0  # added to both local stds (uint8 levels) so flat regions neither explode nor vanish


def local_std(gray: np.ndarray, window: int = WINDOW_PX) -> np.ndarray:
    """Standard deviation of ``gray`` float32 (H, W) over a ``window`` box around each pixel."""
    mean = cv2.blur(gray, (window, window))
    return np.sqrt(np.maximum(cv2.blur(gray * gray, (window, window)) - mean * mean, 0.0))


def restore_detail(
    transferred: np.ndarray,
    source: np.ndarray,
    source_coded: np.ndarray,
    max_gain: float = 1.5,
    window: int = WINDOW_PX,
    band_px: float = 0.0,
    min_gain: float = 0.0,
    rig: Rig | None = None,
) -> np.ndarray:
    """``transferred`` plus the detail the tokenizer dropped from ``source``, scaled by the contrast
    ratio over a ``window`` px box; all uint8 (V, T, H, W, 3) of one size, ``source_coded`` the source
    decoded from its latents (at a larger size than the model's: upsampled, drivewm.transfer.resolution).
    ``band_px`` > 0: the source's structure finer than a Gaussian of that sigma (px) replaces the
    transfer's (the gain still from the unblurred contrast). ``min_gain``: a floor on the gain (0, the
    default: none; floors up to 0.4 kept no more camera pairs, docs/transfer.md "Detail band").
    ``rig`` (the views' cameras, rig order; None: each view on its own): the transfer's look, its gain
    and (with a band) its colour coarser than the band, is shared between cameras where they see one
    point of the flat world and their coded sources agree there (:func:`share_look`); the source's
    structure finer than the band stays each view's own."""
    if not transferred.shape == source.shape == source_coded.shape:
        raise ValueError(f"shapes differ: {transferred.shape}, {source.shape}, {source_coded.shape}")
    if not (math.isfinite(band_px) and band_px >= 0):
        raise ValueError(f"band_px must be a finite number >= 0, got {band_px}")
    if not 0 <= min_gain <= max_gain:
        raise ValueError(f"min_gain must lie in [0, max_gain={max_gain}], got {min_gain}")
    views, frames, h, w, _ = transferred.shape
    share = rig is not None and len(rig.cameras) > 1
    if rig is not None:
        check_views(transferred, rig)
    plan = feathering(rig, look_size(h, w)) if share else None
    out = np.empty_like(transferred)
    for t in range(frames):
        look = np.empty((views, h, w, 4), dtype=np.float32)  # the transfer's: colour coarser than the band, gain
        coded = np.empty((views, h, w, 3), dtype=np.float32)  # the coded source's, coarser than the band
        for v in range(views):
            x, r = (a[v, t].astype(np.float32) for a in (transferred, source_coded))
            look[v, ..., 3] = (local_std(x.mean(-1), window) + FLOOR) / (local_std(r.mean(-1), window) + FLOOR)
            look[v, ..., :3], coded[v] = (band_blur(a, band_px) for a in (x, r)) if band_px > 0 else (x, r)
        if share:  # where the coded sources agree, the cameras see one surface: one look there
            look = share_look(look, plan, slice(None) if band_px > 0 else slice(3, 4), guide=coded)
        structure = source[:, t].astype(np.float32) - coded  # the source's, finer than the band
        y = look[..., :3] + np.clip(look[..., 3:], min_gain, max_gain) * structure
        out[:, t] = np.clip(np.rint(y), 0, 255).astype(np.uint8)
    return out


def band_blur(image: np.ndarray, sigma: float) -> np.ndarray:
    """cv2.GaussianBlur of ``image`` (float32 (H, W, C)) at ``sigma`` px. A wide blur, sigma >=
    2 * WIDE_BLUR_PX (the band of a frame 4x the model's size or more: 77 px at 1600x900), runs on
    the image shrunk k = sigma // WIDE_BLUR_PX times (area) and is brought back bilinearly: 0.01 s a
    1600x900 frame instead of 1.5 s (about 5 minutes of blurs a fleet clip), within 2 levels of the
    exact blur and 0.03 on average (tests/transfer/test_resolution.py); narrower blurs (16 px at
    320x192) are the exact one."""
    k = int(sigma // WIDE_BLUR_PX)
    if k < 2:
        return cv2.GaussianBlur(image, (0, 0), sigma)
    h, w = image.shape[:2]
    small = cv2.resize(image, (max(1, w // k), max(1, h // k)), interpolation=cv2.INTER_AREA)
    blurred = cv2.resize(cv2.GaussianBlur(small, (0, 0), sigma / k), (w, h), interpolation=cv2.INTER_LINEAR)
    return blurred.reshape(image.shape)  # cv2 drops a single channel's axis


def look_size(h: int, w: int) -> tuple[int, int]:
    """(H, W) at which :func:`share_look` blends a look of ``h`` x ``w``: the frames' own up to
    LOOK_MAX_WIDTH px wide, else scaled down to it (the look is smooth: a band and a window of
    tokenizer cells, 16 and 35 px at 320x192; 1600x900 fleet frames then cost what 320x180 ones do)."""
    return (h, w) if w <= LOOK_MAX_WIDTH else (max(1, round(h * LOOK_MAX_WIDTH / w)), LOOK_MAX_WIDTH)


def share_look(
    look: np.ndarray, plan: list, shared_channels: slice = slice(None), guide: np.ndarray | None = None
) -> np.ndarray:
    """float32 (V, H, W, C) of one frame's views (:func:`restore_detail`: the transfer's colour coarser
    than the band and its gain) -> the same with ``shared_channels`` the feathered mean of every camera
    that sees each pixel's flat-world point (drivewm.views.blend.feathered_mean of a ``plan`` made
    at :func:`look_size`), a camera counting only where ``guide`` (V, H, W, C', the coded source's
    colour there) agrees with the view's own within LOOK_TOLERANCE levels. At a smaller size only the
    change is upsampled and added, so a pixel no other camera sees keeps its own value (exactly at the
    frames' own size; beside an overlap it takes the upsampled change of its neighbours there)."""
    views, h, w, _ = look.shape
    small_hw = look_size(h, w)

    def shrunk(a: np.ndarray) -> np.ndarray:
        small = a if small_hw == (h, w) else resize_views(a[:, None], small_hw, cv2.INTER_AREA)[:, 0]
        return small.reshape(views, *small_hw, a.shape[-1])[:, None]  # cv2 drops a single channel's axis

    part = look[..., shared_channels]
    small = shrunk(part)
    hint = None if guide is None else shrunk(guide)
    change = (feathered_mean(small, plan, hint, LOOK_TOLERANCE) - small)[:, 0].astype(np.float32)
    if small_hw != (h, w):
        change = resize_views(change[:, None], (h, w), cv2.INTER_LINEAR)[:, 0]
    out = look.copy()
    out[..., shared_channels] += change.reshape(part.shape)
    return out
