"""H.264 settings of the curation recipes: the fleet recipe's faster preset and colour conversion keep
(or beat) the default's PSNR against the source frames, one encoder thread gives the same bytes every
time, and OpenCV's RGB -> yuv420p conversion has swscale's colours."""

import numpy as np
import pytest

from drivewm.clips.video import decode_mp4, encode_mp4
from drivewm.curate import load_curate_config
from drivewm.errors import DrivewmError
from drivewm.logs.reader import read_log


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(255.0**2 / np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)))


def test_fleet_recipe_keeps_the_default_quality(sim_log_dir):
    log = read_log(sim_log_dir / "highway_clear.mcap")
    videos = [np.stack([f.decode() for f in log.images[cam][:17]]) for cam in ("CAM_FRONT", "CAM_BACK")]
    default = load_curate_config("default")
    fleet = load_curate_config("fleet")
    assert (fleet.h264_preset, fleet.h264_threads, fleet.h264_yuv_converter) == ("ultrafast", 1, "opencv")
    assert (fleet.crf, default.h264_yuv_converter) == (default.crf, "swscale")
    for video in videos:
        psnr = {}
        for name, cfg in (("default", default), ("fleet", fleet)):
            mp4 = encode_mp4(video, 10.0, cfg.crf, cfg.h264_preset, cfg.h264_threads, cfg.h264_yuv_converter)
            psnr[name] = _psnr(decode_mp4(mp4, len(video)), video)
        assert psnr["default"] > 35.0 and psnr["fleet"] >= psnr["default"], psnr
    one = encode_mp4(videos[0], 10.0, 18, "ultrafast", 1, "opencv")
    assert encode_mp4(videos[0], 10.0, 18, "ultrafast", 1, "opencv") == one


def test_opencv_conversion_keeps_swscale_colours(sim_log_dir):
    """Flat 16x16 blocks of primaries, secondaries and greys (so chroma subsampling cannot blur them)
    come back within 3 levels per channel through either converter: a swapped channel order, a
    full-range or BT.709 matrix would miss by tens of levels. On rendered frames OpenCV's 2x2 box
    chroma (centred, where the decoder assumes left-sited chroma) costs ~0.3 dB against swscale's
    filter: bounded at 0.5 dB (the fleet recipe's ultrafast preset gains ~1.2 dB, test above)."""
    colours = np.array(
        [[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 0], [0, 255, 255], [255, 0, 255], [128, 128, 128],
         [30, 60, 200], [220, 180, 40], [16, 16, 16]], dtype=np.uint8,
    )  # fmt: skip
    blocks = np.repeat(np.repeat(colours[None], 16, axis=0), 16, axis=1)  # (16, 160, 3): a row of blocks
    video = np.tile(np.concatenate([blocks, blocks[:, ::-1]], axis=0)[None], (5, 6, 1, 1))  # (5, 192, 160, 3)
    for converter in ("swscale", "opencv"):
        back = decode_mp4(encode_mp4(video, 10.0, 0, "ultrafast", 1, converter), len(video))
        centres = back[:, 8::16, 8::16].astype(int) - video[:, 8::16, 8::16]
        assert np.abs(centres).max() <= 3, (converter, np.abs(centres).max())
    log = read_log(sim_log_dir / "highway_clear.mcap")
    rendered = np.stack([f.decode() for f in log.images["CAM_FRONT_LEFT"][:17]])
    psnr = {
        c: _psnr(decode_mp4(encode_mp4(rendered, 10.0, 18, "ultrafast", 1, c), 17), rendered)
        for c in ("swscale", "opencv")
    }
    assert psnr["opencv"] > psnr["swscale"] - 0.5 and psnr["opencv"] > 35.0, psnr


def test_unknown_preset_or_converter_is_refused():
    with pytest.raises(DrivewmError, match="h264_preset 'turbo'"):
        load_curate_config("default", ["h264_preset=turbo"])
    with pytest.raises(DrivewmError, match="h264_yuv_converter 'numpy'"):
        load_curate_config("default", ["h264_yuv_converter=numpy"])
    with pytest.raises(DrivewmError, match="yuv_converter 'numpy'"):
        encode_mp4(np.zeros((2, 16, 16, 3), np.uint8), 10.0, yuv_converter="numpy")
