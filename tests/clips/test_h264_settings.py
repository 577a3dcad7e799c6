"""H.264 settings of the curation recipes: the fleet recipe's faster preset keeps (or beats) the
default's PSNR against the source frames, and one encoder thread gives the same bytes every time."""

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
    assert (fleet.h264_preset, fleet.h264_threads, fleet.crf) == ("ultrafast", 1, default.crf)
    for video in videos:
        psnr = {}
        for name, cfg in (("default", default), ("fleet", fleet)):
            mp4 = encode_mp4(video, 10.0, cfg.crf, cfg.h264_preset, cfg.h264_threads)
            psnr[name] = _psnr(decode_mp4(mp4, len(video)), video)
        assert psnr["default"] > 35.0 and psnr["fleet"] >= psnr["default"], psnr
    one = encode_mp4(videos[0], 10.0, 18, "ultrafast", 1)
    assert encode_mp4(videos[0], 10.0, 18, "ultrafast", 1) == one


def test_unknown_preset_is_refused():
    with pytest.raises(DrivewmError, match="h264_preset 'turbo'"):
        load_curate_config("default", ["h264_preset=turbo"])
