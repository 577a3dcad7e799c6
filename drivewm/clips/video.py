"""H.264 mp4 in memory: encode with PyAV (libx264), decode with PyAV.

OpenCV cannot write H.264 (docs/DESIGN.md section 9), so PyAV does both directions here; the
decoder checks the frame count so a truncated video is an error, not a short clip.
"""

from __future__ import annotations

import io
from fractions import Fraction

import av
import numpy as np

from drivewm.errors import DrivewmError


def encode_mp4(frames: np.ndarray, fps: float, crf: int = 18) -> bytes:
    """Encode uint8 RGB frames (T, H, W, 3) as H.264 mp4 bytes (yuv420p; H and W even).

    ``crf`` 18 is visually lossless for these renders (about 40 dB PSNR); every frame is
    decodable independently of B-frames (no B-frames, so decode order = display order).
    """
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise DrivewmError(f"encode_mp4: expected uint8 (T, H, W, 3), got {frames.dtype} {frames.shape}")
    T, H, W, _ = frames.shape
    if H % 2 or W % 2:
        raise DrivewmError(f"encode_mp4: frame size {W}x{H} must be even for yuv420p")
    buf = io.BytesIO()
    with av.open(buf, mode="w", format="mp4") as container:
        rate = Fraction(fps).limit_denominator(1001)
        stream = container.add_stream("libx264", rate=rate)
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        stream.options = {"crf": str(crf), "preset": "veryfast", "bf": "0", "tune": "zerolatency"}
        for frame in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(frame, format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return buf.getvalue()


def decode_mp4(data: bytes, expected_frames: int | None = None, where: str = "video") -> np.ndarray:
    """Decode mp4 bytes to uint8 RGB frames (T, H, W, 3).

    A corrupt stream, or fewer frames than ``expected_frames``, raises DrivewmError naming ``where``.
    """
    try:
        with av.open(io.BytesIO(data), mode="r") as container:
            frames = [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]
    except (av.error.FFmpegError, ValueError, IndexError) as exc:
        raise DrivewmError(f"{where}: cannot decode mp4 ({exc.__class__.__name__})") from None
    if not frames:
        raise DrivewmError(f"{where}: mp4 holds no frames")
    if expected_frames is not None and len(frames) != expected_frames:
        raise DrivewmError(f"{where}: mp4 has {len(frames)} frames, expected {expected_frames} (truncated?)")
    return np.stack(frames)
