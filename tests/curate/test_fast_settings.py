"""Curation's throughput settings keep the output: with one encoder kept per camera over a log (the
fleet recipe) the first clip's videos are the bytes of one encoder per clip and every clip decodes to
the same quality; clips at half the log's size (JPEGs decoded at 1/2 scale in the DCT domain) stay at
the default recipe's PSNR against the log's frames decoded in full and resized with INTER_AREA."""

import cv2
import numpy as np
import pytest

from drivewm.clips import iter_clips
from drivewm.curate import curate, load_curate_config
from drivewm.logs.reader import read_log


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(255.0**2 / np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)))


def _source(log, clip, size=None) -> dict[str, np.ndarray]:
    """Per camera the log's frames of the clip, decoded in full (and INTER_AREA-resized to ``size``)."""
    out = {}
    for cam in clip.meta.cameras:
        by_t = {f.timestamp_ns: f for f in log.images[cam]}
        full = [by_t[t].decode() for t in clip.meta.camera_times_ns(cam)]
        out[cam] = np.stack([cv2.resize(f, size, interpolation=cv2.INTER_AREA) if size else f for f in full])
    return out


@pytest.mark.slow  # four curations of a 6 s log: ~12 CPU s
def test_kept_encoder_and_reduced_decode_keep_the_quality(sim_log_dir, tmp_path):
    path = sim_log_dir / "roundabout_clear.mcap"
    log = read_log(path)
    runs = {
        "fleet": [],
        "fleet, one encoder per clip": ["h264_keep_encoder=false"],
        "fleet 160x96": ["resolution=[160,96]", "crf=12", "h264_yuv_converter=swscale"],
        "default 320x192": ["crf=18", "h264_preset=veryfast", "h264_threads=1", "h264_yuv_converter=swscale"],
    }
    clips = {}
    for name, overrides in runs.items():
        curate([path], tmp_path / name.replace(" ", "_"), load_curate_config("fleet", overrides), progress=False)
        clips[name] = list(iter_clips(tmp_path / name.replace(" ", "_")))
    kept, fresh = clips["fleet"], clips["fleet, one encoder per clip"]
    assert len(kept) == len(fresh) >= 2 and kept[0].mp4 == fresh[0].mp4
    assert all(a.mp4 != b.mp4 for a, b in zip(kept[1:], fresh[1:]))  # the rate control remembers earlier clips
    psnr = {name: [] for name in runs}
    for i, clip in enumerate(kept):
        source, small = _source(log, clip), _source(log, clip, (160, 96))
        for name in runs:
            ref = small if name == "fleet 160x96" else source
            psnr[name] += [_psnr(clips[name][i].video(c), ref[c]) for c in clip.meta.cameras]
    mean = {name: float(np.mean(v)) for name, v in psnr.items()}
    assert abs(mean["fleet"] - mean["fleet, one encoder per clip"]) < 0.2, mean
    assert mean["fleet 160x96"] >= mean["default 320x192"] > 35.0, mean
