"""A small synthetic drive (front3 rig at 64x48, 6 ticks) shared by the drive-log tests."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drivewm.geometry import euler_to_R, load_rig, make_T
from drivewm.logs.types import AgentBox, DriveLog, ImageFrame, RoadLine, SceneInfo
from drivewm.logs.writer import encode_image

TICKS = 6
T0_NS = 1_700_000_000_123_456_789
DT_NS = 100_000_000


def synthetic_rig():
    """front3 at 64x48, with distortion on one camera so that D has to round-trip too."""
    rig = load_rig("front3").scaled(64, 48, fit="stretch")
    rig.cameras[2] = dataclasses.replace(rig.cameras[2], distortion=np.array([-0.1, 0.01, 1e-4, -2e-4, 0.003]))
    return rig


def synthetic_image(tick: int, cam_index: int, h: int = 48, w: int = 64) -> np.ndarray:
    """A textured uint8 RGB image that differs per tick and camera."""
    rng = np.random.default_rng(100 * tick + cam_index)
    yy, xx = np.mgrid[0:h, 0:w]
    base = np.stack([(xx * 4 + tick * 9) % 256, (yy * 5 + cam_index * 40) % 256, (xx + yy) * 2 % 256], -1)
    return np.clip(base + rng.integers(0, 20, (h, w, 3)), 0, 255).astype(np.uint8)


def synthetic_pose(tick: int) -> np.ndarray:
    """A curving, slightly pitching and rolling drive; tick 3 is a NaN gap (fleet logs have them)."""
    if tick == 3:
        return np.full((4, 4), np.nan)
    R = euler_to_R(0.01 * tick, -0.02 * tick, 0.3 + 0.05 * tick)
    return make_T(R, [10.0 + 1.234567891234 * tick, -3.0 + 0.1 * tick**2, 0.05 * tick])


def synthetic_agents(tick: int) -> list[AgentBox]:
    return [
        AgentBox(
            "car-1", "car", np.array([20.0 + tick, 3.5, 0.8]), np.array([4.6, 1.9, 1.6]), 0.1 * tick, (0.9, 0.1, 0.2)
        ),
        AgentBox("truck-7", "truck", np.array([-15.0, -3.5, 1.6]), np.array([12.0, 2.5, 3.2]), -2.5, (0.2, 0.3, 0.9)),
    ]


def synthetic_road() -> list[RoadLine]:
    """Two lanes of a gently curving road: centre lines, a dashed divider, solid edges."""
    s = np.linspace(0.0, 40.0, 9)
    curve = 0.002 * s**2

    def line(offset: float) -> np.ndarray:
        return np.stack([10.0 + s, -3.0 + curve + offset, np.zeros_like(s)], axis=1)

    return [
        RoadLine("lane_center", line(-1.75)),
        RoadLine("lane_center", line(1.75)),
        RoadLine("lane_boundary", line(0.0), "dashed"),
        RoadLine("road_edge", line(-3.5), "solid"),
        RoadLine("road_edge", line(3.5), "solid"),
        RoadLine("road_surface", np.concatenate([line(-3.5), line(3.5)[::-1]])),
    ]


def synthetic_static() -> list[AgentBox]:
    """A building and a lamp post beside the road."""
    return [
        AgentBox("bldg0", "building", np.array([30.0, 12.0, 5.0]), np.array([14.0, 9.0, 10.0]), 0.2, (0.7, 0.6, 0.5)),
        AgentBox("pole1", "pole", np.array([18.0, 5.1, 3.75]), np.array([0.22, 0.22, 7.5]), -1.3, (0.45, 0.46, 0.48)),
    ]


def make_synthetic_log(path: str = "synthetic") -> DriveLog:
    rig = synthetic_rig()
    ts = [T0_NS + i * DT_NS for i in range(TICKS)]
    images = {
        cam.name: [ImageFrame(t, encode_image(synthetic_image(i, k)), "jpeg") for i, t in enumerate(ts)]
        for k, cam in enumerate(rig.cameras)
    }
    poses = np.stack([synthetic_pose(i) for i in range(TICKS)])
    scene = SceneInfo(
        {"weather": "snow", "time_of_day": "dusk", "road_type": "highway", "traffic_density": "low", "source": "test"},
        "a synthetic snowy drive",
    )
    agents = [(t, synthetic_agents(i)) for i, t in enumerate(ts)]
    stamps = np.array(ts, dtype=np.int64)
    return DriveLog(path, rig, images, stamps, poses, scene, agents, synthetic_road(), static=synthetic_static())


@pytest.fixture(scope="session")
def synthetic_log() -> DriveLog:
    return make_synthetic_log()


@pytest.fixture(scope="session")
def synthetic_mcap(tmp_path_factory, synthetic_log) -> str:
    """The synthetic drive written with drivewm's own writer."""
    from drivewm.logs.writer import write_log

    return str(write_log(synthetic_log, tmp_path_factory.mktemp("logs") / "synthetic.mcap"))


def _assert_same_log(
    got: DriveLog, want: DriveLog, rot_atol: float = 1e-12, agents: bool = True, road: bool = True
) -> None:
    """Same cameras (K, D, size exact; T_ego_from_cam to ``rot_atol``), same image bytes and
    times, same pose times, translations exact and rotations to ``rot_atol`` (the wire format is
    a quaternion), NaN gaps kept, same tags and description, same agents."""
    assert got.rig.names == want.rig.names
    for g, w in zip(got.rig.cameras, want.rig.cameras):
        assert (g.width, g.height) == (w.width, w.height)
        np.testing.assert_array_equal(g.K, w.K)
        np.testing.assert_array_equal(g.distortion, w.distortion)
        np.testing.assert_allclose(g.T_ego_from_cam, w.T_ego_from_cam, rtol=0, atol=rot_atol)
        np.testing.assert_array_equal(g.T_ego_from_cam[:3, 3], w.T_ego_from_cam[:3, 3])
    for name in want.rig.names:
        assert [(f.timestamp_ns, f.data, f.format) for f in got.images[name]] == [
            (f.timestamp_ns, f.data, f.format) for f in want.images[name]
        ]
    np.testing.assert_array_equal(got.pose_timestamps_ns, want.pose_timestamps_ns)
    np.testing.assert_array_equal(got.T_world_from_ego[:, :3, 3], want.T_world_from_ego[:, :3, 3])  # NaN == NaN here
    np.testing.assert_allclose(got.T_world_from_ego, want.T_world_from_ego, rtol=0, atol=rot_atol)
    assert got.scene == want.scene
    if road:
        assert [(r.kind, r.line_type) for r in got.road] == [(r.kind, r.line_type) for r in want.road]
        for g, w in zip(got.road, want.road):
            np.testing.assert_array_equal(g.points_xyz, w.points_xyz)
    if agents:
        assert [t for t, _ in got.agents] == [t for t, _ in want.agents]
        for (_, gb), (_, wb) in zip(got.agents, want.agents):
            _assert_same_boxes(gb, wb)
        _assert_same_boxes(got.static, want.static)


def _assert_same_boxes(got: list[AgentBox], want: list[AgentBox]) -> None:
    assert [(b.track_id, b.category) for b in got] == [(b.track_id, b.category) for b in want]
    for b, c in zip(got, want):
        np.testing.assert_array_equal(b.center_xyz, c.center_xyz)
        np.testing.assert_array_equal(b.size_lwh, c.size_lwh)
        assert abs(b.yaw_rad - c.yaw_rad) < 1e-12 and np.allclose(b.color_rgb, c.color_rgb, atol=1e-7)


@pytest.fixture(scope="session")
def assert_same_log():
    """Compare two DriveLogs field by field (see ``_assert_same_log``)."""
    return _assert_same_log
