"""The real ROS 2 MCAP files in ../shared/data/mcap load: several writers, zstd and uncompressed
chunks, empty channels, a bag split over three files, and a real car's GNSS pose log."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from drivewm.errors import DrivewmError
from drivewm.logs.mcap_source import iter_messages, log_files
from drivewm.logs.reader import read_log

ROSBAGS = "mcap/rosbag2_tests"
SPLIT_BAG = "mcap/rosbag2_tests/rosbag2_py/test/resources/mcap/reindex_test_bags/multiple_files"
GNSS_LOG = "mcap/vehicle_gnss_imu/demo.mcap"


def _drives(shared_data: Path) -> list[Path]:
    """Every bag: the split bag as one folder, every other .mcap as a file."""
    split = shared_data / SPLIT_BAG
    files = [p for p in sorted((shared_data / ROSBAGS).rglob("*.mcap")) if p.parent != split]
    return files + [split]


def test_every_rosbag2_test_bag_loads(shared_data):
    drives = _drives(shared_data)
    assert len(drives) == 7
    for drive in drives:
        log = read_log(drive, require_images=False)  # no cameras, no poses in these bags
        assert log.rig.names == [] and len(log.pose_timestamps_ns) == 0
        with pytest.raises(DrivewmError, match=f"{drive}: log has no camera images"):
            read_log(drive)


def test_split_bag_is_one_drive_in_time_order(shared_data):
    files = log_files(shared_data / SPLIT_BAG)
    assert [f.name for f in files] == [f"multiple_files_{i}.mcap" for i in range(3)]
    messages = [m for f in files for m in iter_messages(f, lambda c: c.topic == "/chatter")]
    assert len(messages) == 1324 + 1324 + 529  # counts from the files' summaries
    times = np.array([m.log_time_ns for m in messages])
    assert np.all(np.diff(times) >= 0)
    assert {m.data.data for m in messages} == {"test"}  # std_msgs/String decoded from CDR


def test_gnss_car_log_gives_ego_poses(shared_data):
    log = read_log(shared_data / GNSS_LOG, topic_map="reductstore_demo", require_images=False)
    xyz = log.T_world_from_ego[:, :3, 3]
    assert len(log.pose_timestamps_ns) == 314 and np.isfinite(log.T_world_from_ego).all()
    assert np.all(np.diff(log.pose_timestamps_ns) > 0)
    assert 15.0 < (log.pose_timestamps_ns[-1] - log.pose_timestamps_ns[0]) / 1e9 < 16.0
    assert 55.0 < np.linalg.norm(np.diff(xyz, axis=0), axis=1).sum() < 65.0  # about 60 m driven
    R = log.T_world_from_ego[:, :3, :3]
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape), atol=1e-9)
    assert log.scene.tags["source"] == "fleet"
    assert not [w for w in log.warnings if "no ego poses" in w]
    bare = read_log(shared_data / GNSS_LOG, require_images=False)  # no topic map: the pose topic is not known
    assert len(bare.pose_timestamps_ns) == 0
    assert "no ego poses: the log has no transforms; map its pose topic with ego_pose.topic" in " ".join(bare.warnings)
