"""Per-camera exposure times from a staggered-exposure log through curation into the clips."""

from pathlib import Path

import numpy as np
import pytest

from drivewm.clips import iter_clips
from drivewm.clips.format import ClipMeta, validate_meta
from drivewm.curate import curate, load_curate_config
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.logs.reader import read_log
from drivewm.sim import SimConfig, simulate

REPO = Path(__file__).resolve().parents[2]
STAGGER_NS = 8_000_000  # 6 cameras over 40 ms, as nuScenes


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float(10 * np.log10(255.0**2 / max(mse, 1e-12)))


@pytest.fixture(scope="module")
def staggered(tmp_path_factory):
    root = tmp_path_factory.mktemp("staggered")
    cfg = SimConfig(source="highway", scenario="highway", duration_s=1.8, seed=2, exposure_stagger_ms=8.0)
    log_path = simulate(cfg, root / "staggered.mcap", progress=False)
    report = curate([log_path], root / "out", load_curate_config("test"), progress=False)
    return read_log(log_path), list(iter_clips(root / "out")), report


@pytest.mark.slow
def test_clips_carry_each_cameras_logged_exposure_times(staggered):
    log, clips, report = staggered
    assert report["kept"] == 1 and len(clips) == 1  # 18 ticks: 1 clip of 17 (the 25 ms tolerance alone keeps none)
    offsets = report["logs"]["staggered"]["sync"]["cameras"]
    assert [offsets[c]["exposure_offset_ns"] for c in log.rig.names] == [i * STAGGER_NS for i in range(6)]
    for clip in clips:
        meta = clip.meta
        assert sorted(meta.camera_timestamps_ns) == sorted(log.rig.names)
        for i, cam in enumerate(log.rig.names):
            times = meta.camera_times_ns(cam)
            logged = {f.timestamp_ns: f for f in log.images[cam]}
            assert all(t in logged for t in times), cam  # exactly the logged stamps
            assert times == [t + i * STAGGER_NS for t in meta.timestamps_ns]
            video = clip.video(cam)
            for j in (0, len(times) - 1):  # the encoded frame is the image logged at that time
                assert _psnr(video[j], logged[times[j]].decode()) > 35.0
        assert meta.sync_error_ns == 5 * STAGGER_NS


def test_synchronized_clips_omit_the_field_and_old_clips_load():
    rig = load_rig("front3").subset(["CAM_FRONT"]).to_dict()
    meta = ClipMeta("k", "log.mcap", 0, 10.0, [0, 100_000_000], rig)
    assert "camera_timestamps_ns" not in meta.to_json()  # as written before the field existed
    old = ClipMeta.from_json(meta.to_json(), "old clip")
    assert old.camera_times_ns("CAM_FRONT") == [0, 100_000_000]
    staggered = ClipMeta(
        "k", "log.mcap", 0, 10.0, [0, 100_000_000], rig, camera_timestamps_ns={"CAM_FRONT": [5, 100_000_005]}
    )
    assert ClipMeta.from_json(staggered.to_json(), "clip").camera_times_ns("CAM_FRONT") == [5, 100_000_005]
    with pytest.raises(DrivewmError, match="camera_timestamps_ns"):
        validate_meta(ClipMeta("k", "log.mcap", 0, 10.0, [0, 1], rig, camera_timestamps_ns={"CAM_FRONT": [5]}))
