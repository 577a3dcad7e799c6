"""Camera images as curation uses them: decoded straight to the clip's size, and the small grey
thumbnail that the filters and de-duplication look at, made once per frame.

Clips are often smaller than the log's images (160x96 clips of 320x192 logs, fleet JPEGs of
1600x900). A JPEG is then decoded at 1/2, 1/4 or 1/8 scale in the DCT domain (libjpeg-turbo's
scaled IDCT, through ``cv2.IMREAD_REDUCED_COLOR_*``: the inverse DCT of only the low-frequency
coefficients, which averages each block as an area resize does), as GPU data loaders such as DALI
do, and resized the rest of the way with ``INTER_AREA``. Halving 320x192 that way costs ~40 % less
CPU than a full decode and comes within 45-46 dB PSNR of full decode + ``INTER_AREA`` on the
simulated nuscenes6 drives (benchmarks/bench_curate.py prints it). Images are decoded straight to
RGB (``IMREAD_COLOR_RGB``: the same pixels as BGR + ``cvtColor``, without the copy).
"""

from __future__ import annotations

import cv2
import numpy as np

from drivewm.errors import DrivewmError
from drivewm.logs.types import ImageFrame

#: Width (px) of the grey thumbnails the filters score (drivewm.curate.filters) and dedup embeds.
ANALYSIS_WIDTH = 160
#: JPEG scale denominators libjpeg-turbo decodes in the DCT domain -> OpenCV's reduced-size bit, to be
#: or-ed with IMREAD_COLOR_RGB (the *_COLOR_* variants carry the BGR bit, which OpenCV 5 refuses beside RGB)
_REDUCED = {
    1: 0,
    2: cv2.IMREAD_REDUCED_GRAYSCALE_2,
    4: cv2.IMREAD_REDUCED_GRAYSCALE_4,
    8: cv2.IMREAD_REDUCED_GRAYSCALE_8,
}


def jpeg_scale(source_wh: tuple[int, int], out_wh: tuple[int, int]) -> int:
    """The largest denominator k in 8, 4, 2 whose decoded size (ceil(W / k), ceil(H / k)) still covers
    ``out_wh`` in both axes, else 1 (full decode): the image is then only ever shrunk further."""
    (W, H), (w, h) = source_wh, out_wh
    return next((k for k in (8, 4, 2) if -(-W // k) >= w and -(-H // k) >= h), 1)


def decode_rgb(frame: ImageFrame, out_wh: tuple[int, int], scale: int = 1) -> np.ndarray:
    """The frame as uint8 RGB (H, W, 3), at least ``out_wh``: a JPEG decoded at 1 / ``scale`` (see
    :func:`jpeg_scale`), other formats in full. Undecodable bytes raise DrivewmError (as ImageFrame.decode)."""
    buf = np.frombuffer(frame.data, dtype=np.uint8)
    img = cv2.imdecode(buf, cv2.IMREAD_COLOR_RGB | (_REDUCED[scale] if frame.format == "jpeg" else 0))
    if img is None:
        raise DrivewmError(f"image at {frame.timestamp_ns} ns: cannot decode {frame.format} data")
    if scale > 1 and (img.shape[1] < out_wh[0] or img.shape[0] < out_wh[1]):  # smaller than its calibration says
        img = cv2.imdecode(buf, cv2.IMREAD_COLOR_RGB)
    return img


def fit(img: np.ndarray, out_wh: tuple[int, int]) -> np.ndarray:
    """``img`` resized to ``out_wh`` (W, H) with ``INTER_AREA`` (docs/DESIGN.md: stretch), or as it is."""
    return img if img.shape[:2] == (out_wh[1], out_wh[0]) else cv2.resize(img, out_wh, interpolation=cv2.INTER_AREA)


def analysis_grey(rgb: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 RGB -> (h, 160) uint8 grey (aspect kept, ``INTER_AREA``): what the filters score."""
    H, W = rgb.shape[:2]
    h = max(2, round(H * ANALYSIS_WIDTH / W))
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY)
    return (
        grey
        if grey.shape == (h, ANALYSIS_WIDTH)
        else cv2.resize(grey, (ANALYSIS_WIDTH, h), interpolation=cv2.INTER_AREA)
    )
