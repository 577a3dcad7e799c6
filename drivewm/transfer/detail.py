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
"""

from __future__ import annotations

import math

import cv2
import numpy as np

WINDOW_PX = 17  # local-contrast window at the model's size: about two tokenizer cells (measured: docs/transfer.md)
BAND_PX = 8.0  # default band at the model's size: one tokenizer cell (measured: docs/transfer.md)
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
) -> np.ndarray:
    """``transferred`` plus the detail the tokenizer dropped from ``source``, scaled by the contrast
    ratio over a ``window`` px box; all uint8 (V, T, H, W, 3) of one size, ``source_coded`` the source
    decoded from its latents (at a larger size than the model's: upsampled, drivewm.transfer.resolution).
    ``band_px`` > 0: the source's structure finer than a Gaussian of that sigma (px) replaces the
    transfer's (the gain still from the unblurred contrast). ``min_gain``: a floor on the gain (0, the
    default: none; floors up to 0.4 kept no more camera pairs, docs/transfer.md "Detail band")."""
    if not transferred.shape == source.shape == source_coded.shape:
        raise ValueError(f"shapes differ: {transferred.shape}, {source.shape}, {source_coded.shape}")
    if not (math.isfinite(band_px) and band_px >= 0):
        raise ValueError(f"band_px must be a finite number >= 0, got {band_px}")
    if not 0 <= min_gain <= max_gain:
        raise ValueError(f"min_gain must lie in [0, max_gain={max_gain}], got {min_gain}")
    out = np.empty_like(transferred)
    for v, t in np.ndindex(*transferred.shape[:2]):
        x, s, r = (a[v, t].astype(np.float32) for a in (transferred, source, source_coded))
        gain = (local_std(x.mean(-1), window) + FLOOR) / (local_std(r.mean(-1), window) + FLOOR)
        if band_px > 0:
            x, r = (cv2.GaussianBlur(a, (0, 0), band_px) for a in (x, r))
        y = x + np.clip(gain, min_gain, max_gain)[..., None] * (s - r)
        out[v, t] = np.clip(np.rint(y), 0, 255).astype(np.uint8)
    return out
