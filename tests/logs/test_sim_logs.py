"""The simulator's logs (the shared ``sim_log_dir`` fixture) meet the drive-log contract."""

from __future__ import annotations

import numpy as np
import pytest

from drivewm.geometry import load_rig
from drivewm.logs.reader import read_log
from drivewm.logs.writer import write_log


@pytest.fixture(scope="module")
def sim_logs(sim_log_dir):
    return {p.stem: read_log(p) for p in sorted(sim_log_dir.glob("*.mcap"))}


def test_sim_logs_follow_the_contract(sim_logs):
    rig = load_rig("nuscenes6")
    assert sorted(sim_logs) == ["highway_clear", "highway_snow", "roundabout_clear", "sumo_grid_night"]
    for name, log in sim_logs.items():
        assert log.rig.names == rig.names, name
        for got, want in zip(log.rig.cameras, rig.cameras):
            np.testing.assert_allclose(got.K, want.K, rtol=0, atol=1e-9)
            np.testing.assert_allclose(got.T_ego_from_cam, want.T_ego_from_cam, rtol=0, atol=1e-12)
        assert len(log.pose_timestamps_ns) == 60 and np.isfinite(log.T_world_from_ego).all()  # 6 s at 10 fps
        assert np.allclose(np.diff(log.pose_timestamps_ns), 100_000_000, atol=1)
        for frames in log.images.values():
            assert [f.timestamp_ns for f in frames] == list(log.pose_timestamps_ns)
        assert log.images["CAM_FRONT"][30].decode().shape == (192, 320, 3)
        assert set(log.scene.tags) >= {"weather", "time_of_day", "road_type", "traffic_density", "source"}
        assert log.scene.description and len(log.agents) == 60


def test_sim_log_tags_say_the_conditions(sim_logs):
    assert sim_logs["highway_snow"].scene.tags["weather"] == "snow"
    assert sim_logs["sumo_grid_night"].scene.tags["time_of_day"] == "night"
    assert sim_logs["sumo_grid_night"].scene.tags["source"] == "sumo"


def test_sim_log_round_trips(sim_logs, tmp_path, assert_same_log):
    log = sim_logs["roundabout_clear"]
    assert_same_log(read_log(write_log(log, tmp_path / "again.mcap")), log, rot_atol=1e-15)


def test_sim_logs_carry_the_static_objects_and_road_surface(sim_logs):
    """/static holds the props the renderer draws (lamps, trees, buildings), beside the road, and /road
    the outlines of the paved surface besides the lane lines."""
    from matplotlib.path import Path as MplPath

    for name, log in sim_logs.items():
        categories = {b.category for b in log.static}
        assert categories == {"pole", "lamp", "trunk", "crown", "building"}, name
        surfaces = [MplPath(r.points_xyz[:, :2]) for r in log.road if r.kind == "road_surface"]
        assert surfaces and {r.kind for r in log.road} >= {"lane_boundary", "road_edge", "road_surface"}
        on_road = np.zeros(len(log.static), dtype=bool)
        for s in surfaces:
            on_road |= s.contains_points(np.array([b.center_xyz[:2] for b in log.static]))
        lamps = np.array([b.category == "lamp" for b in log.static])  # lamp heads hang over the road
        assert not on_road[~lamps].any(), name
        assert all(b.center_xyz[2] > 0 and np.all(b.size_lwh > 0) for b in log.static)
        assert len({b.track_id for b in log.static}) == len(log.static)
