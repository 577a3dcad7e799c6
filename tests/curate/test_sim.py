"""Simulated nuscenes6 logs curated by the shared fixture (drivewm/recipes/curate/test.yaml)."""

from pathlib import Path

import numpy as np

from drivewm.clips import iter_clips, read_manifest
from drivewm.curate import load_curate_config
from drivewm.geometry import yaw_of
from drivewm.logs.reader import read_log

# Smoothing error bound on the simulator's exact poses with the default filter (measured: at most
# 0.14 m and 0.33 deg, in highway-env's abrupt lane changes; the filter expects 0.3 m GNSS noise).
MAX_POSITION_ERROR_M = 0.2
MAX_YAW_ERROR_DEG = 0.6


def test_sim_clips_have_every_camera_synced_and_logged_poses(sim_log_dir, sim_clip_dir):
    cfg = load_curate_config("test")
    logs = {p.stem: read_log(p) for p in sim_log_dir.glob("*.mcap")}
    clips = list(iter_clips(sim_clip_dir))
    assert {Path(c.meta.source_log).stem for c in clips} == set(logs)  # every drive gives clips (night too)
    for clip in clips:
        log = logs[Path(clip.meta.source_log).stem]
        assert clip.meta.cameras == log.rig.names and len(clip.meta.cameras) == 6
        videos = clip.videos()
        assert videos.shape == (6, cfg.clip_frames, 192, 320, 3)
        assert clip.meta.sync_error_ns <= cfg.sync_tolerance_ms * 1e6
        assert np.allclose(np.diff(clip.meta.timestamps_ns), 1e9 / cfg.fps, atol=cfg.sync_tolerance_ms * 1e6)
        idx = np.searchsorted(log.pose_timestamps_ns, clip.meta.timestamps_ns)
        logged = log.T_world_from_ego[idx]
        pos_err = np.linalg.norm(clip.T_world_from_ego[:, :3, 3] - logged[:, :3, 3], axis=1).max()
        yaw_err = max(
            abs((yaw_of(a) - yaw_of(b) + np.pi) % (2 * np.pi) - np.pi) for a, b in zip(clip.T_world_from_ego, logged)
        )
        assert pos_err < MAX_POSITION_ERROR_M and np.degrees(yaw_err) < MAX_YAW_ERROR_DEG, (clip.key, pos_err, yaw_err)
        # the waypoints are the logged motion seen from the first frame: ~speed * 1.6 s ahead
        assert len(clip.meta.trajectory_ego) == cfg.trajectory_waypoints
        ahead = np.linalg.inv(logged[0]) @ np.append(logged[-1, :3, 3], 1.0)
        assert np.linalg.norm(np.array(clip.meta.trajectory_ego[-1]) - ahead[:3]) < 2 * MAX_POSITION_ERROR_M


def test_sim_manifest_and_captions(sim_log_dir, sim_clip_dir):
    rows = read_manifest(sim_clip_dir)
    assert len(rows) == len(list(iter_clips(sim_clip_dir)))
    weathers = {r["tags"]["weather"] for r in rows}
    assert {"clear", "snow"} <= weathers
    night = [r for r in rows if r["tags"]["time_of_day"] == "night"]
    assert night and all("night" in r["caption"] for r in night)
    assert all("km/h" in r["caption"] for r in rows)
    assert (sim_clip_dir / "contact_sheet.png").is_file() and (sim_clip_dir / "report.json").is_file()
