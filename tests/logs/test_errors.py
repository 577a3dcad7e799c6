"""Bad input gives one clear DrivewmError naming the file."""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path

import pytest
from json_writer import write_log_json

from drivewm.errors import DrivewmError
from drivewm.logs.reader import read_log


def _cut(src: str, dst: Path, keep: float) -> Path:
    data = Path(src).read_bytes()
    dst.write_bytes(data[: int(len(data) * keep)])
    return dst


@pytest.mark.parametrize("keep", [0.5, 0.9, 0.999])
def test_truncated_file(tmp_path, synthetic_mcap, keep):
    path = _cut(synthetic_mcap, tmp_path / "cut.mcap", keep)
    with pytest.raises(DrivewmError, match=f"^{path}: truncated or corrupt MCAP"):
        read_log(path)


def test_random_bytes_and_empty_file(tmp_path):
    (tmp_path / "random.mcap").write_bytes(os.urandom(4096))
    with pytest.raises(DrivewmError, match=f"^{tmp_path / 'random.mcap'}: not an MCAP file"):
        read_log(tmp_path / "random.mcap")
    (tmp_path / "empty.mcap").write_bytes(b"")
    with pytest.raises(DrivewmError, match=f"^{tmp_path / 'empty.mcap'}: truncated or corrupt MCAP"):
        read_log(tmp_path / "empty.mcap")


def test_corrupt_chunk(tmp_path, synthetic_mcap):
    data = bytearray(Path(synthetic_mcap).read_bytes())
    middle = len(data) // 2
    data[middle : middle + 64] = bytes(64)
    (tmp_path / "bad.mcap").write_bytes(bytes(data))
    with pytest.raises(DrivewmError, match=f"^{tmp_path / 'bad.mcap'}: corrupt MCAP"):
        read_log(tmp_path / "bad.mcap")


def test_missing_file_and_unknown_topic_map(tmp_path, synthetic_mcap):
    with pytest.raises(DrivewmError, match="no such file"):
        read_log(tmp_path / "nope.mcap")
    with pytest.raises(DrivewmError, match="topic map 'no_such_map'"):
        read_log(synthetic_mcap, topic_map="no_such_map")


def test_topic_map_naming_a_missing_topic(shared_data):
    talker = shared_data / "mcap/rosbag2_tests/rosbag2_py/test/resources/mcap/talker/talker.mcap"
    with pytest.raises(
        DrivewmError,
        match=rf"^{talker}: topic map \S+/drivewm/topicmaps/reductstore_demo.yaml names topic\(s\) "
        r"\['/nissan/gps/duro/current_pose'\]",
    ):
        read_log(talker, topic_map="reductstore_demo", require_images=False)


def test_images_without_calibration(tmp_path, synthetic_log):
    names = synthetic_log.rig.names
    log = dataclasses.replace(
        synthetic_log, rig=synthetic_log.rig.subset(names[:2])
    )  # third camera loses its calibration
    path = write_log_json(log, tmp_path / "nocal.mcap")
    with pytest.raises(DrivewmError, match=rf"^{path}: images of camera\(s\) \['{names[2]}'\] have no calibration"):
        read_log(path)


def test_log_without_images(tmp_path, synthetic_log):
    log = dataclasses.replace(synthetic_log, images={})
    path = write_log_json(log, tmp_path / "noimages.mcap")
    with pytest.raises(DrivewmError, match=f"^{path}: log has no camera images"):
        read_log(path)
    assert len(read_log(path, require_images=False).pose_timestamps_ns) == len(synthetic_log.pose_timestamps_ns)


@pytest.mark.parametrize(
    "mapping, role, topic, schema",
    [
        ("cameras: {CAM_FRONT: {image: /tf, calibration: /CAM_FRONT/calibration}}", "image", "/tf", "FrameTransforms"),
        ("cameras: {CAM_FRONT: {image: /CAM_FRONT/image, calibration: /scene}}", "calibration", "/scene", "Scene"),
        ("ego_pose: {topic: /tf}", "ego_pose", "/tf", "FrameTransforms"),  # had been an AttributeError traceback
        ("ego_pose: {topic: /CAM_FRONT/image}", "ego_pose", "/CAM_FRONT/image", "CompressedImage"),  # had been ignored
    ],
)
def test_topic_map_naming_a_topic_of_the_wrong_type(tmp_path, synthetic_mcap, mapping, role, topic, schema):
    """A mapped topic whose schema is not one its role reads is refused, not decoded as something else
    (a TF topic mapped as images had been read as 20 'images' of transform bytes)."""
    (tmp_path / "map.yaml").write_text(mapping + "\n")
    with pytest.raises(
        DrivewmError,
        match=rf"^{synthetic_mcap}: topic map {tmp_path / 'map.yaml'}: {role} topic {topic} has schema '\S*{schema}'",
    ):
        read_log(synthetic_mcap, topic_map=tmp_path / "map.yaml", require_images=False)
