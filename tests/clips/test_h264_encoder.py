"""One libx264 encoder kept open over a log's clip videos (drivewm.clips.video.H264Encoder): its first
video is byte for byte what a fresh encoder writes, every video decodes alone from a key frame with
its own frame count and timestamps from 0, the same sequence of videos gives the same bytes (a rerun
of a log, a retried Ray task), later videos keep the fresh encoder's quality, and decoding
only some frames gives exactly those frames of a full decode."""

import io

import av
import numpy as np
import pytest

from drivewm.clips.video import H264Encoder, decode_mp4, encode_mp4
from drivewm.errors import DrivewmError
from drivewm.logs.reader import read_log


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(255.0**2 / np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)))


@pytest.fixture(scope="module")
def rendered(sim_log_dir) -> np.ndarray:
    """51 frames (T, 192, 320, 3) of a simulated camera."""
    log = read_log(sim_log_dir / "highway_clear.mcap")
    return np.stack([f.decode() for f in log.images["CAM_FRONT"][:51]])


@pytest.mark.parametrize("settings", [(18, "ultrafast", 1, "opencv"), (18, "veryfast", 0, "swscale")])
def test_kept_encoder_writes_independent_videos(rendered, settings):
    clips = [rendered[i : i + 17] for i in range(0, 51, 17)]
    with H264Encoder(320, 192, 10.0, *settings) as encoder:
        kept = [encoder.encode(c) for c in clips]
    with H264Encoder(320, 192, 10.0, *settings) as again:
        assert [again.encode(c) for c in clips] == kept  # the same videos in the same order: the same bytes
    fresh = [encode_mp4(c, 10.0, *settings) for c in clips]
    assert kept[0] == fresh[0]  # the first video: the same bytes as a fresh encoder's
    for mp4, mp4_fresh, clip in zip(kept, fresh, clips):
        with av.open(io.BytesIO(mp4)) as container:
            packets = [p for p in container.demux(video=0) if p.size]
        assert [p.pts for p in packets] == [1024 * i for i in range(17)]  # 10 fps in mp4's 1/10240 s
        assert [p.is_keyframe for p in packets] == [True] + [False] * 16  # a forced IDR frame starts each video
        assert abs(_psnr(decode_mp4(mp4, 17), clip) - _psnr(decode_mp4(mp4_fresh, 17), clip)) < 0.3


def test_kept_encoder_refuses_another_size(rendered):
    with H264Encoder(320, 192, 10.0) as encoder, pytest.raises(DrivewmError, match="differ from the encoder"):
        encoder.encode(rendered[:3, :96, :160].copy())


def test_decode_keep_gives_those_frames_of_a_full_decode(rendered):
    mp4 = encode_mp4(rendered[:17], 10.0)
    full = decode_mp4(mp4, 17)
    assert np.array_equal(decode_mp4(mp4, 17, keep=[0, 8, 16]), full[[0, 8, 16]])
    with pytest.raises(DrivewmError, match="asked for frames"):
        decode_mp4(mp4, 17, keep=[0, 17])


def _encode_copying(frames: np.ndarray, crf: int, preset: str) -> bytes:
    """The swscale path as it was before frames wrapped the array's memory: PyAV's copying
    ``VideoFrame.from_ndarray``, one fresh libx264 per video, the same options as H264Encoder."""
    buf = io.BytesIO()
    with av.open(buf, mode="w", format="mp4") as container:
        stream = container.add_stream("libx264", rate=10)
        stream.width, stream.height, stream.pix_fmt = frames.shape[2], frames.shape[1], "yuv420p"
        stream.options = {"crf": str(crf), "preset": preset, "bf": "0", "tune": "zerolatency", "forced-idr": "1"}
        stream.options = {**stream.options, "threads": "1"}
        for i, rgb in enumerate(frames):
            frame = av.VideoFrame.from_ndarray(rgb, format="rgb24")
            frame.pts, frame.pict_type = i, av.video.frame.PictureType.I if i == 0 else av.video.frame.PictureType.NONE
            for packet in stream.encode(frame):
                container.mux(packet)
    return buf.getvalue()


@pytest.mark.parametrize("size_wh", [(320, 192), (170, 96)])  # 170 x 3 bytes: rows not 32-byte aligned
def test_swscale_path_wrapping_the_array_writes_the_copying_paths_video(rendered, size_wh):
    """Frames wrap the array's memory (no copy): the H.264 frames are those of PyAV's copying path, and a
    view whose rows are not contiguous (a BGR flip) encodes as its contiguous copy does."""
    import cv2

    frames = np.stack([cv2.resize(f, size_wh, interpolation=cv2.INTER_AREA) for f in rendered[:17]])
    want = decode_mp4(_encode_copying(frames, 18, "ultrafast"))
    with H264Encoder(*size_wh, 10.0, 18, "ultrafast", 1, "swscale") as encoder:
        got = decode_mp4(encoder.encode(frames))
    assert np.array_equal(got, want)  # the same decoded pixels, bit for bit
    flipped = frames[..., ::-1]  # strides (.., .., -1): not C-contiguous rows
    bgr = encode_mp4(flipped, 10.0, 18, "ultrafast", 1, "swscale")
    assert bgr == encode_mp4(np.ascontiguousarray(flipped), 10.0, 18, "ultrafast", 1, "swscale")
