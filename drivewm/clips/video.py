"""H.264 mp4 in memory: encode with PyAV (libx264), decode with PyAV.

OpenCV cannot write H.264 (docs/DESIGN.md section 9), so PyAV does both directions here; the
decoder checks the frame count so a truncated video is an error, not a short clip.
"""

from __future__ import annotations

import io
from fractions import Fraction

import av
import cv2
import numpy as np

from drivewm.errors import DrivewmError

#: libx264 presets, fastest first (x264 --fullhelp).
X264_PRESETS = ("ultrafast", "superfast", "veryfast", "faster", "fast", "medium", "slow", "slower", "veryslow")
#: Who converts RGB to the encoder's yuv420p: FFmpeg's libswscale (through PyAV) or OpenCV.
YUV_CONVERTERS = ("swscale", "opencv")


def encode_mp4(
    frames: np.ndarray,
    fps: float,
    crf: int = 18,
    preset: str = "veryfast",
    threads: int = 0,
    yuv_converter: str = "swscale",
) -> bytes:
    """Encode uint8 RGB frames (T, H, W, 3) as H.264 mp4 bytes (yuv420p; H and W even).

    ``crf`` 18 is visually lossless for these renders (about 37-40 dB PSNR); every frame is
    decodable independently of B-frames (no B-frames, so decode order = display order).
    ``preset``: libx264 speed/size trade-off. ``threads``: 0 lets x264 choose (with
    ``tune=zerolatency`` that is slices over 1.5 x the machine's cores, so the bytes depend on the
    machine); 1 encodes on the caller's core, the same bytes everywhere (use with worker pools).
    ``yuv_converter``: "swscale" (the encoder's own reformat, through PyAV) or "opencv"
    (``cv2.cvtColor`` RGB2YUV_I420): both BT.601 limited range, within 1 level in Y and 3 in chroma of
    each other; OpenCV averages 2x2 blocks for chroma (centred, where decoders assume left-sited
    chroma: ~0.3 dB lower PSNR on rendered frames) and saves ~0.18 ms of CPU per 320x192 frame
    (ultrafast on one thread: 1.02 -> 0.84 ms, measured interleaved under load).
    """
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise DrivewmError(f"encode_mp4: expected uint8 (T, H, W, 3), got {frames.dtype} {frames.shape}")
    T, H, W, _ = frames.shape
    if H % 2 or W % 2:
        raise DrivewmError(f"encode_mp4: frame size {W}x{H} must be even for yuv420p")
    if yuv_converter not in YUV_CONVERTERS:
        raise DrivewmError(f"encode_mp4: yuv_converter {yuv_converter!r} must be one of {list(YUV_CONVERTERS)}")
    buf = io.BytesIO()
    with av.open(buf, mode="w", format="mp4") as container:
        rate = Fraction(fps).limit_denominator(1001)
        stream = container.add_stream("libx264", rate=rate)
        stream.width, stream.height, stream.pix_fmt = W, H, "yuv420p"
        stream.options = {"crf": str(crf), "preset": preset, "bf": "0", "tune": "zerolatency"}
        if threads:
            stream.options = {**stream.options, "threads": str(threads)}
        for frame in frames:
            for packet in stream.encode(_yuv_frame(frame, yuv_converter)):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    return buf.getvalue()


def _yuv_frame(rgb: np.ndarray, converter: str) -> av.VideoFrame:
    """One (H, W, 3) uint8 RGB frame as a PyAV frame the encoder takes; "swscale" leaves the
    conversion to yuv420p to the encoder's reformat."""
    if converter == "opencv":
        return av.VideoFrame.from_ndarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_I420), format="yuv420p")
    return av.VideoFrame.from_ndarray(rgb, format="rgb24")


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
