"""ROS 2 bags (CompressedImage and raw Image, CameraInfo, TF chains, PoseStamped/Odometry) read
through a topic map give the same DriveLog as drivewm's own file."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import yaml
from ros2_writer import ros2_topic_map, write_log_ros2

from drivewm.logs.reader import read_log

RECEIVE_DELAY_NS = 3_000_000


@pytest.mark.parametrize("ego_pose", ["tf", "pose_stamped", "odometry"])
def test_ros2_bag_reads_as_same_drive(tmp_path, synthetic_log, assert_same_log, ego_pose):
    raw = (synthetic_log.rig.names[0],)  # one camera as raw sensor_msgs/Image, the others compressed
    path = write_log_ros2(
        synthetic_log, tmp_path / "bag.mcap", raw_cameras=raw, ego_pose=ego_pose, receive_delay_ns=RECEIVE_DELAY_NS
    )
    tmap = ros2_topic_map(synthetic_log, raw, ego_pose)
    tmap.tags, tmap.description = dict(synthetic_log.scene.tags), synthetic_log.scene.description
    got = read_log(path, topic_map=tmap)
    # The raw camera comes back as lossless PNG of the decoded JPEG; compare it by pixels.
    raw_frames = got.images[raw[0]]
    want_pixels = [f.decode() for f in synthetic_log.images[raw[0]]]
    assert all(f.format == "png" for f in raw_frames)
    assert all(np.array_equal(f.decode(), p) for f, p in zip(raw_frames, want_pixels))
    got.images[raw[0]] = synthetic_log.images[raw[0]]
    got.rig.name = synthetic_log.rig.name
    assert_same_log(got, synthetic_log, agents=False, road=False)  # header stamps, not log times (+3 ms)


def test_topic_map_from_yaml(tmp_path, synthetic_log):
    """The YAML form of a topic map reads the same; camera order follows the map."""
    path = write_log_ros2(synthetic_log, tmp_path / "bag.mcap", ego_pose="pose_stamped")
    tmap = ros2_topic_map(synthetic_log, (), "pose_stamped")
    as_dict = dataclasses.asdict(tmap)
    del as_dict["source"]  # set by the loader, not a YAML key
    as_dict["cameras"] = dict(reversed(list(as_dict["cameras"].items())))
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(as_dict, sort_keys=False))
    got = read_log(path, topic_map=tmp_path / "map.yaml")
    assert got.rig.names == synthetic_log.rig.names[::-1]
    assert len(got.pose_timestamps_ns) == len(synthetic_log.pose_timestamps_ns)


def test_ros2_bag_without_map_discovers_cameras_by_frame(tmp_path, synthetic_log):
    """No topic map: cameras named by frame_id, ego pose from the REP 105 map -> base_link TF."""
    got = read_log(write_log_ros2(synthetic_log, tmp_path / "bag.mcap"))
    assert sorted(got.rig.names) == sorted(f"{n.lower()}_optical_frame" for n in synthetic_log.rig.names)
    np.testing.assert_allclose(got.T_world_from_ego, synthetic_log.T_world_from_ego, atol=1e-12)


def test_shipped_nuscenes6_map_matches_the_exporter():
    """drivewm/topicmaps/drivewm_ros2_nuscenes6.yaml is the map the exporter's layout needs."""
    from drivewm.geometry import load_rig
    from drivewm.logs.topicmap import load_topic_map
    from drivewm.logs.types import DriveLog, SceneInfo

    rig = load_rig("nuscenes6")
    empty = DriveLog("x", rig, {}, np.zeros(0, np.int64), np.zeros((0, 4, 4)), SceneInfo({}))
    want = ros2_topic_map(empty, (), "pose_stamped")
    got = load_topic_map("drivewm_ros2_nuscenes6")
    assert list(got.cameras) == rig.names
    assert got.cameras == want.cameras and got.ego_pose == want.ego_pose and got.layout == want.layout
    assert (got.world_frame, got.ego_frame, got.rig_name) == (want.world_frame, want.ego_frame, want.rig_name)


@pytest.mark.parametrize("agents", ["detections", "markers"])
def test_ros2_bag_layout_reads_back_in_the_world_frame(tmp_path, synthetic_log, agents):
    """Road users published per tick in base_link (Detection3DArray or MarkerArray CUBEs), static objects
    and road lines as map-frame MarkerArrays come back placed in the world by the ego pose, as logged."""
    path = write_log_ros2(synthetic_log, tmp_path / "bag.mcap", agents=agents)
    got = read_log(path, topic_map=ros2_topic_map(synthetic_log, agents=agents))
    finite = [(t, b) for t, b in synthetic_log.agents if np.isfinite(dict(_poses(synthetic_log))[t]).all()]
    assert [t for t, _ in got.agents] == [t for t, _ in finite]  # the tick of the pose gap has no boxes
    for (_, gb), (_, wb) in zip(got.agents, finite):
        assert [b.category for b in gb] == [b.category for b in wb]
        if agents == "detections":
            assert [b.track_id for b in gb] == [b.track_id for b in wb]
        for b, c in zip(gb, wb):
            np.testing.assert_allclose(b.center_xyz, c.center_xyz, atol=1e-9)
            np.testing.assert_allclose(b.size_lwh, c.size_lwh, atol=0)
            assert abs(np.angle(np.exp(1j * (b.yaw_rad - c.yaw_rad)))) < 1e-9
    tracks = {b.track_id for _, boxes in got.agents for b in boxes}
    assert len(tracks) == 2  # each road user keeps its id over the ticks
    assert [(b.track_id.split("/")[0], b.category) for b in got.static] == [("building", "building"), ("pole", "pole")]
    for b, c in zip(got.static, synthetic_log.static):
        np.testing.assert_allclose(b.center_xyz, c.center_xyz, atol=1e-12)
    assert [(r.kind, r.line_type) for r in got.road] == [(r.kind, r.line_type) for r in synthetic_log.road]
    for g, w in zip(got.road, synthetic_log.road):
        np.testing.assert_allclose(g.points_xyz, w.points_xyz, atol=1e-12)


def _poses(log):
    return zip(log.pose_timestamps_ns.tolist(), log.T_world_from_ego)


def test_topic_map_renames_classes_and_line_kinds(tmp_path, synthetic_log):
    """A fleet's own names (a detector's class ids, a map's marker namespaces) become drivewm's."""
    path = write_log_ros2(synthetic_log, tmp_path / "bag.mcap")
    tmap = ros2_topic_map(synthetic_log)
    tmap.layout.classes = {"truck": "bus", "lane_boundary/dashed": "lane_boundary/solid", "road_edge": "lane_center"}
    got = read_log(path, topic_map=tmap)
    assert {b.category for _, boxes in got.agents for b in boxes} == {"car", "bus"}
    assert [(r.kind, r.line_type) for r in got.road][2:5] == [
        ("lane_boundary", "solid"),
        ("lane_center", "solid"),
        ("lane_center", "solid"),
    ]


def test_boxes_that_cannot_be_placed_are_left_out_with_a_warning(tmp_path, synthetic_log):
    """Detections in base_link, but the map reads no ego pose (its PoseStamped topic is not mapped): the
    road users cannot be placed in the world; the map-frame objects and the images still read."""
    path = write_log_ros2(synthetic_log, tmp_path / "bag.mcap", ego_pose="pose_stamped")
    got = read_log(path, topic_map=ros2_topic_map(synthetic_log), require_images=False)
    assert got.agents == [] and len(got.static) == 2 and len(got.road) == len(synthetic_log.road)
    assert any("frame 'base_link' left out" in w for w in got.warnings)
    assert all(len(frames) == 6 for frames in got.images.values())
