"""The same layout from every source: a drivewm log, the same drive as a ROS 2 bag, and the simulator
without pixels."""

from __future__ import annotations

import dataclasses
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from drivewm.clips.shards import iter_clips
from drivewm.curate import curate, load_curate_config
from drivewm.layout import layout_from_recording
from drivewm.layout.clip_layout import STATIC
from drivewm.logs.reader import read_log
from drivewm.logs.types import AgentBox
from drivewm.sim.config import SimConfig
from drivewm.sim.scene import LaneBoundary, RoadMap, SceneRecording, SceneTick

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "logs"))  # the test exporter of ROS 2 bags
from ros2_writer import ros2_topic_map, write_log_ros2  # noqa: E402


def _shared_drive(name: str) -> SimConfig:
    """The SimConfig of one of tests/conftest.py's shared drives (loaded by path: tests/logs has a conftest too)."""
    spec = importlib.util.spec_from_file_location("shared_conftest", Path(__file__).parents[1] / "conftest.py")
    shared = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(shared)
    return SimConfig(**shared.SIM_COMMON, **shared.SIM_DRIVES[name])


def _world(layout, T_world_from_ego0):
    """Box centres (N, 3) and lines (P, 3) of a layout back in the world frame."""
    R, t = T_world_from_ego0[:3, :3], T_world_from_ego0[:3, 3]
    return layout.box_center @ R.T + t, layout.line_points @ R.T + t


@pytest.mark.slow
def test_ros2_bag_of_a_drive_curates_to_the_same_layout(tmp_path, sim_log_dir, sim_clip_dir):
    """highway_clear exported as a ROS 2 bag (road users as Detection3DArray in base_link, static objects
    and road as map-frame MarkerArrays), read through its topic map: the same layouts as the drivewm log's."""
    log = read_log(sim_log_dir / "highway_clear.mcap")
    bag = write_log_ros2(log, tmp_path / "bag" / "highway_clear.mcap", ego_pose="pose_stamped")
    tmap = dataclasses.asdict(ros2_topic_map(log, (), "pose_stamped"))
    del tmap["source"]
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(tmap))
    cfg = load_curate_config("test")
    cfg.topic_map = str(tmp_path / "map.yaml")
    curate([bag], tmp_path / "clips", cfg, progress=False)
    want = {c.key: c.layout() for c in iter_clips(sim_clip_dir) if c.key.startswith("highway_clear")}
    got = {c.key: c.layout() for c in iter_clips(tmp_path / "clips")}
    assert sorted(got) == sorted(want)
    for key, layout in got.items():
        w = want[key]
        np.testing.assert_allclose(layout.T_ego0_from_ego, w.T_ego0_from_ego, atol=1e-9)
        assert layout.box_frame.tolist() == w.box_frame.tolist()
        assert layout.box_class.tolist() == w.box_class.tolist()
        dynamic = layout.box_frame != STATIC
        assert layout.box_track[dynamic].tolist() == w.box_track[dynamic].tolist()  # markers rename static ids
        np.testing.assert_allclose(layout.box_center, w.box_center, atol=1e-6)
        np.testing.assert_allclose(layout.box_size, w.box_size, atol=0)
        np.testing.assert_allclose(np.angle(np.exp(1j * (layout.box_yaw - w.box_yaw))), 0, atol=1e-9)
        assert layout.line_kind.tolist() == w.line_kind.tolist() and layout.line_paint.tolist() == w.line_paint.tolist()
        np.testing.assert_allclose(layout.line_points, w.line_points, atol=1e-6)


def test_layout_from_a_recording_in_its_first_ego_frame():
    """A hand-made recording: a straight road, one car passing, one building; the layout puts them
    in the first tick's ego frame and keeps the props it is given."""
    xs = np.linspace(0.0, 300.0, 301)
    lane = np.stack([xs, np.zeros_like(xs)], axis=1)
    road = RoadMap(
        [lane],
        [3.5],
        [LaneBoundary(lane + [0, 1.75], "dashed"), LaneBoundary(lane - [0, 1.75], "solid")],
        [lane - [0, 1.75]],
        [np.array([[0, -1.75], [300, -1.75], [300, 1.75], [0, 1.75]], float)],
        [AgentBox("bldg0", "building", np.array([50.0, 20.0, 5.0]), np.array([10.0, 8.0, 10.0]), 0.0)],
    )
    ticks = []
    for k in range(3):
        T = np.eye(4)
        T[:3, 3] = [10.0 + 2 * k, 0.0, 0.0]
        car = AgentBox("car-3", "car", np.array([30.0 + 3 * k, 0.0, 0.75]), np.array([4.5, 1.9, 1.5]), 0.0)
        ticks.append(SceneTick(k * 100_000_000, T, [car]))
    rec = SceneRecording(road, ticks, {"drive_id": "hand"})
    layout = layout_from_recording(rec, SimConfig(duration_s=0.3), 0, 3)
    assert layout.num_frames == 3 and layout.box_frame.tolist() == [STATIC, 0, 1, 2]
    np.testing.assert_allclose(layout.box_center[0], [40.0, 20.0, 5.0])  # building, 10 m behind the world origin
    np.testing.assert_allclose(layout.box_center[1:, 0], [20.0, 23.0, 26.0])  # the car in ego0, frame by frame
    np.testing.assert_allclose(layout.T_ego0_from_ego[:, 0, 3], [0.0, 2.0, 4.0])
    assert layout.line_kind.tolist() == ["lane_center", "lane_boundary", "lane_boundary", "road_edge", "road_surface"]
    assert layout.line_paint.tolist() == ["", "dashed", "solid", "", ""]
    assert [len(layout.line(i)) for i in range(4)] == [2, 2, 2, 2]  # straight lines thinned to their ends


@pytest.mark.slow
def test_recording_without_pixels_gives_the_curated_layout(sim_clip_dir):
    """The traffic of highway_clear simulated again without rendering: its layout at the first clip's ticks
    is the curated clip's, object for object, once both are put back in the world (curation smooths the
    ego poses, so the two ego0 frames differ by centimetres)."""
    cfg = _shared_drive("highway_clear")
    from drivewm.sim.drives import record

    rec = record(cfg)
    clip = next(c for c in iter_clips(sim_clip_dir) if c.key == "highway_clear-000017")
    got = layout_from_recording(rec, cfg, start=17, num_frames=17)
    want = clip.layout()
    assert got.box_track.tolist() == want.box_track.tolist() and got.box_frame.tolist() == want.box_frame.tolist()
    boxes, lines = _world(got, rec.ticks[17].T_world_from_ego)
    want_boxes, want_lines = _world(want, clip.T_world_from_ego[0])
    np.testing.assert_allclose(boxes, want_boxes, atol=1e-9)
    np.testing.assert_allclose(lines, want_lines, atol=1e-9)
    rendered_at = np.stack([t.T_world_from_ego for t in rec.ticks[17:34]])  # both place each frame there
    np.testing.assert_allclose(rec.ticks[17].T_world_from_ego @ got.T_ego0_from_ego, rendered_at, atol=1e-9)
    np.testing.assert_allclose(clip.T_world_from_ego[0] @ want.T_ego0_from_ego, rendered_at, atol=1e-9)
