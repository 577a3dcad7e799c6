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
from av.video.frame import PictureType
from av.video.reformatter import VideoReformatter

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
    chroma: ~0.3 dB lower PSNR on rendered frames at 320x192, ~3 dB at 160x96) and saves ~0.18 ms of
    CPU per 320x192 frame (ultrafast on one thread: 1.02 -> 0.84 ms, measured interleaved under load).
    A fresh encoder per call; :class:`H264Encoder` keeps one open over many videos.
    """
    _check_frames(frames)
    T, H, W, _ = frames.shape
    with H264Encoder(W, H, fps, crf, preset, threads, yuv_converter) as encoder:
        return encoder.encode(frames)


class H264Encoder:
    """One libx264 encoder kept open over many videos of one size and rate (a camera's clips of a log).

    :meth:`encode` turns each uint8 RGB (T, H, W, 3) array into its own mp4 whose first frame is a
    forced IDR frame, so every video decodes alone. Opening x264 costs ~3 ms of CPU whatever the size
    (``ultrafast`` rebuilds its CAVLC tables at every open): as much as encoding 17 frames at 160x96,
    a sixth of a 17-frame 320x192 clip (benchmarks/bench_curate.py). The settings are
    :func:`encode_mp4`'s, and the first video's bytes equal its bytes; later videos differ slightly
    (x264's rate control remembers the frames before, ~0.05 dB), the same for the same sequence of videos.
    ``tune=zerolatency`` (no look-ahead, no B-frames) makes every frame's packet come out at once,
    so a video never waits for the next one's frames.
    """

    def __init__(
        self,
        width: int,
        height: int,
        fps: float,
        crf: int = 18,
        preset: str = "veryfast",
        threads: int = 0,
        yuv_converter: str = "swscale",
    ):
        if height % 2 or width % 2:
            raise DrivewmError(f"encode_mp4: frame size {width}x{height} must be even for yuv420p")
        if yuv_converter not in YUV_CONVERTERS:
            raise DrivewmError(f"encode_mp4: yuv_converter {yuv_converter!r} must be one of {list(YUV_CONVERTERS)}")
        self.size, self.yuv_converter = (height, width), yuv_converter
        # the encoder lives in a container that is never written to: mp4's muxer sets the global-header
        # flag (SPS/PPS as extradata), which every clip's container copies from this stream
        self._template = av.open(io.BytesIO(), mode="w", format="mp4")
        self._stream = self._template.add_stream("libx264", rate=Fraction(fps).limit_denominator(1001))
        self._stream.width, self._stream.height, self._stream.pix_fmt = width, height, "yuv420p"
        options = {"crf": str(crf), "preset": preset, "bf": "0", "tune": "zerolatency", "forced-idr": "1"}
        self._stream.options = {**options, "threads": str(threads)} if threads else options
        self._template.start_encoding()
        self._pts = 0  # frames encoded so far: each video's timestamps start at 0 again

    def encode(self, frames: np.ndarray) -> bytes:
        """One mp4 of uint8 RGB ``frames`` (T, H, W, 3) at this encoder's size."""
        _check_frames(frames)
        if frames.shape[1:3] != self.size:
            raise DrivewmError(f"encode_mp4: frames {frames.shape[1:3]} differ from the encoder's (H, W) {self.size}")
        first, buf, muxed = self._pts, io.BytesIO(), 0
        with av.open(buf, mode="w", format="mp4") as container:
            stream = container.add_stream_from_template(self._stream)
            for i, rgb in enumerate(frames):
                frame = _yuv_frame(rgb, self.yuv_converter)
                frame.pts, frame.pict_type = self._pts, PictureType.I if i == 0 else PictureType.NONE
                self._pts += 1
                for packet in self._stream.encode(frame):
                    packet.pts, packet.dts = packet.pts - first, packet.dts - first
                    packet.stream = stream
                    container.mux(packet)
                    muxed += 1
        if muxed != len(frames):  # cannot happen with zerolatency; a late packet would go astray
            raise DrivewmError(f"encode_mp4: libx264 held back frames of a {len(frames)}-frame video")
        return buf.getvalue()

    def close(self) -> None:
        self._template.close()

    def __enter__(self) -> H264Encoder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _check_frames(frames: np.ndarray) -> None:
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8:
        raise DrivewmError(f"encode_mp4: expected uint8 (T, H, W, 3), got {frames.dtype} {frames.shape}")


def _yuv_frame(rgb: np.ndarray, converter: str) -> av.VideoFrame:
    """One (H, W, 3) uint8 RGB frame as a PyAV frame the encoder takes; "swscale" leaves the
    conversion to yuv420p to the encoder's reformat."""
    if converter == "opencv":
        return av.VideoFrame.from_ndarray(cv2.cvtColor(rgb, cv2.COLOR_RGB2YUV_I420), format="yuv420p")
    # the frame wraps the array's memory (PyAV holds a reference; x264 copies each picture in) instead of
    # from_ndarray's row-by-row copy into a new AVFrame: 0.10 -> 0.01 ms per 160x96 frame, the same bytes
    # out (benchmarks/bench_curate.py); the rows must be C-contiguous
    return av.VideoFrame.from_numpy_buffer(np.ascontiguousarray(rgb), format="rgb24")


def decode_mp4(
    data: bytes, expected_frames: int | None = None, where: str = "video", keep: list[int] | None = None
) -> np.ndarray:
    """Decode mp4 bytes to uint8 RGB frames (T, H, W, 3); ``keep``: only these frame indices (every
    frame is still decoded, as H.264 frames depend on earlier ones, but only these are converted).

    A corrupt stream, or fewer frames than ``expected_frames``, raises DrivewmError naming ``where``.
    """
    # one swscale context for every frame: VideoFrame.to_ndarray(format=...) sets up a new one per call,
    # which costs more than the conversion (0.78 -> 0.47 ms per 160x96 frame, decoding included)
    reformatter, frames, count = VideoReformatter(), [], 0
    try:
        with av.open(io.BytesIO(data), mode="r") as container:
            for i, frame in enumerate(container.decode(video=0)):
                if keep is None or i in keep:
                    frames.append(reformatter.reformat(frame, format="rgb24").to_ndarray())
                count += 1
    except (av.error.FFmpegError, ValueError, IndexError) as exc:
        raise DrivewmError(f"{where}: cannot decode mp4 ({exc.__class__.__name__})") from None
    if not count:
        raise DrivewmError(f"{where}: mp4 holds no frames")
    if expected_frames is not None and count != expected_frames:
        raise DrivewmError(f"{where}: mp4 has {count} frames, expected {expected_frames} (truncated?)")
    if keep is not None and len(frames) != len(set(keep)):
        raise DrivewmError(f"{where}: mp4 has {count} frames, asked for frames {sorted(keep)}")
    return np.stack(frames)
