"""drivewm's own MCAP logs: write -> read gives the same drive; writes are atomic; bad input is refused."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader

from drivewm.errors import DrivewmError
from drivewm.logs.reader import read_log
from drivewm.logs.types import SceneInfo
from drivewm.logs.writer import LogWriter, write_log


def test_round_trip_same_drive(synthetic_mcap, synthetic_log, assert_same_log):
    got = read_log(synthetic_mcap)
    assert got.rig.name == "front3"
    assert_same_log(got, synthetic_log)
    assert np.isnan(got.T_world_from_ego[3]).all() and np.isfinite(got.T_world_from_ego[[0, 1, 2, 4, 5]]).all()


def test_rewrite_is_stable(synthetic_mcap, tmp_path, assert_same_log):
    first = read_log(synthetic_mcap)
    second = read_log(write_log(first, tmp_path / "again.mcap"))
    assert_same_log(second, first, rot_atol=1e-15)


def test_file_layout_is_the_contract(synthetic_mcap, synthetic_log):
    """Topics, schemas, encodings and log times as docs/DESIGN.md section 4 states them."""
    with open(synthetic_mcap, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        layout = {c.topic: (summary.schemas[c.schema_id].name, c.message_encoding) for c in summary.channels.values()}
        times = {}
        for _, channel, message in reader.iter_messages():
            times.setdefault(channel.topic, []).append(message.log_time)
    assert layout["/CAM_FRONT/image"] == ("foxglove.CompressedImage", "protobuf")
    assert layout["/CAM_FRONT/calibration"] == ("foxglove.CameraCalibration", "protobuf")
    assert layout["/tf_static"] == layout["/tf"] == ("foxglove.FrameTransforms", "protobuf")
    assert layout["/agents"] == layout["/static"] == layout["/road"] == ("foxglove.SceneUpdate", "protobuf")
    assert layout["/scene"] == ("drivewm.Scene", "json")
    assert times["/CAM_FRONT/image"] == list(synthetic_log.pose_timestamps_ns)
    assert times["/tf"] == list(synthetic_log.pose_timestamps_ns)
    assert times["/static"] == times["/road"] == [synthetic_log.pose_timestamps_ns[0]]  # once, at the start


def test_images_written_from_arrays_decode_close(tmp_path):
    from drivewm.geometry import load_rig

    rig = load_rig("front1").scaled(64, 48, fit="stretch")
    image = np.tile(np.arange(64, dtype=np.uint8)[None, :, None] * 4, (48, 1, 3))
    with LogWriter(tmp_path / "a.mcap", rig, SceneInfo({"weather": "clear"}), image_format="png") as w:
        w.write_pose(5, np.eye(4))
        w.write_images(5, {rig.names[0]: image})
    log = read_log(tmp_path / "a.mcap")
    frame = log.images[rig.names[0]][0]
    assert frame.format == "png" and frame.timestamp_ns == 5
    np.testing.assert_array_equal(frame.decode(), image)  # PNG is lossless


def test_writer_is_atomic(tmp_path):
    from drivewm.geometry import load_rig

    rig = load_rig("front1").scaled(64, 48, fit="stretch")
    path = tmp_path / "killed.mcap"
    with pytest.raises(RuntimeError):
        with LogWriter(path, rig, SceneInfo({})) as w:
            w.write_pose(1, np.eye(4))
            raise RuntimeError("simulator crashed")
    assert list(tmp_path.iterdir()) == []


def test_writer_refuses_bad_images(tmp_path):
    from drivewm.geometry import load_rig

    rig = load_rig("front1").scaled(64, 48, fit="stretch")
    with pytest.raises(DrivewmError, match="must be uint8 \\(48, 64, 3\\)"):
        with LogWriter(tmp_path / "b.mcap", rig, SceneInfo({})) as w:
            w.write_images(1, {rig.names[0]: np.zeros((48, 64), np.uint8)})
    with pytest.raises(DrivewmError, match="no camera named"):
        with LogWriter(tmp_path / "c.mcap", rig, SceneInfo({})) as w:
            w.write_images(1, {"CAM_NOPE": np.zeros((48, 64, 3), np.uint8)})
    assert list(tmp_path.iterdir()) == []


def test_two_writers_at_once_keep_their_own_channels(tmp_path):
    """Each writer has a private Foxglove context: interleaved writes never cross files."""
    from drivewm.geometry import load_rig

    front, back = load_rig("front1").scaled(64, 48, fit="stretch"), load_rig("front3").scaled(32, 24, fit="stretch")
    a, b = (
        LogWriter(tmp_path / "a.mcap", front, SceneInfo({"n": "a"})),
        LogWriter(tmp_path / "b.mcap", back, SceneInfo({"n": "b"})),
    )
    for t in range(3):
        a.write_pose(t, np.eye(4))
        b.write_pose(t, np.eye(4))
        a.write_images(t, {c.name: np.full((48, 64, 3), t, np.uint8) for c in front.cameras})
        b.write_images(t, {c.name: np.full((24, 32, 3), t, np.uint8) for c in back.cameras})
    a.close(), b.close()
    la, lb = read_log(tmp_path / "a.mcap"), read_log(tmp_path / "b.mcap")
    assert la.rig.names == front.names and lb.rig.names == back.names
    assert la.scene.tags == {"n": "a"} and lb.scene.tags == {"n": "b"}
    assert all(len(v) == 3 for v in [*la.images.values(), *lb.images.values()]) and len(la.pose_timestamps_ns) == 3
