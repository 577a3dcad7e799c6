"""Real video through import-video + curate: Sintel cuts and dark runs, a real dashcam drive."""

import numpy as np
import pytest

from drivewm.curate import curate, load_curate_config
from drivewm.curate.import_video import import_videos

# Facts from ../shared/data/README.md (source frame indices at 24 fps, measured roughly)
SINTEL_DARK_RUNS = [(99, 182), (214, 239)]  # test_clip_10s
SINTEL_CUTS = [348, 372, 523, 573, 610, 624]  # test_video_30s
CALIBRATION = """name: video320
cameras:
  - {name: CAM_FRONT, width: 320, height: 180, hfov_deg: 60, xyz: [1.5, 0.0, 1.3], yaw_deg: 0}
"""


@pytest.fixture(scope="module")
def curated(shared_data, tmp_path_factory):
    root = tmp_path_factory.mktemp("video")
    (root / "cam.yaml").write_text(CALIBRATION)
    videos = [shared_data / "video/sintel_cuts", shared_data / "video/dashcam_highway"]
    logs = import_videos(videos, root / "cam.yaml", root / "logs").logs
    report = curate(logs, root / "out", load_curate_config("video"), progress=False)
    from drivewm.clips import read_manifest

    rows = read_manifest(root / "out")
    return report, rows


def _rows(rows, stem):
    return sorted((r for r in rows if r["key"].startswith(stem)), key=lambda r: r["start_time_ns"])


def _span_s(row):
    t0 = row["start_time_ns"] * 1e-9
    return t0, t0 + (row["num_frames"] - 1) / row["fps"]


@pytest.mark.slow
def test_sintel_loses_dark_runs(curated):
    report, rows = curated
    log = report["logs"]["test_clip_10s"]
    assert log["dropped"].get("bad_exposure", 0) >= 2
    kept = _rows(rows, "test_clip_10s")
    assert kept, "the bright start of the clip is kept"
    for row in kept:
        t = row["start_time_ns"] * 1e-9 + np.arange(row["num_frames"]) / row["fps"]
        dark = sum(((t >= a / 24) & (t <= b / 24)).sum() for a, b in SINTEL_DARK_RUNS)
        assert dark <= 1, (row["key"], dark)
        assert row["tags"]["ego_motion"] == "unknown"


@pytest.mark.slow
def test_sintel_clips_split_at_cuts(curated):
    report, rows = curated
    kept = _rows(rows, "test_video_30s")
    assert len(kept) >= 3
    for row in kept:
        a, b = _span_s(row)
        inside = [c for c in SINTEL_CUTS if a + 0.1 < c / 24 < b - 0.1]
        assert not inside, (row["key"], (a, b), inside)
    # clips restart right after cuts (the 523 cut opens a kept shot)
    starts = [_span_s(r)[0] for r in kept]
    assert any(abs(s - 523 / 24) < 0.2 for s in starts)


@pytest.mark.slow
def test_dashcam_kept_as_consecutive_driving_clips(curated):
    report, rows = curated
    log = report["logs"]["solidWhiteRight"]
    assert log["status"] == "ok" and log["dropped"] == {}
    kept = _rows(rows, "solidWhiteRight")
    assert len(kept) == 5  # 221 frames at 25 fps = 8.8 s -> 88 ticks at 10 fps -> 5 clips of 17
    starts = np.array([r["start_time_ns"] for r in kept])
    np.testing.assert_allclose(np.diff(starts), 1.7e9, atol=1e6)  # back to back: no cut, no gap inside
    assert all(r["quality"]["camera_motion_px"] > 0.5 for r in kept)


def test_import_video_cli_writes_a_log_with_unknown_poses(shared_data, tmp_path):
    from drivewm.cli import main
    from drivewm.logs.reader import read_log

    (tmp_path / "cam.yaml").write_text(CALIBRATION)
    video = shared_data / "video/dashcam_highway/solidWhiteRight.mp4"
    rc = main(
        [
            "import-video",
            str(video),
            "--calibration",
            str(tmp_path / "cam.yaml"),
            "--out",
            str(tmp_path / "logs"),
            "--tag",
            "weather=clear",
        ]
    )
    assert rc == 0
    log = read_log(tmp_path / "logs/solidWhiteRight.mcap")
    assert log.rig.names == ["CAM_FRONT"] and len(log.images["CAM_FRONT"]) == 221
    assert log.images["CAM_FRONT"][0].decode().shape == (180, 320, 3)
    assert np.allclose(np.diff([f.timestamp_ns for f in log.images["CAM_FRONT"]]), 40e6, atol=1e3)  # 25 fps
    assert not np.isfinite(log.T_world_from_ego).any()  # unknown ego motion, not identity
    assert log.scene.tags["weather"] == "clear" and log.scene.tags["road_type"] == "unknown"
    assert (
        main(
            [
                "import-video",
                str(tmp_path / "missing.mp4"),
                "--calibration",
                str(tmp_path / "cam.yaml"),
                "--out",
                str(tmp_path / "x"),
            ]
        )
        == 2
    )
