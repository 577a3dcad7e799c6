"""Staggered camera exposures: interpolated world state, logged exposure times, and images that
obey the epipolar geometry of the ego poses at their own exposure times (not at the tick)."""

from __future__ import annotations

import numpy as np
import pytest
from sim_matching import in_view_of, match, sift

from drivewm.cli import main
from drivewm.errors import DrivewmError
from drivewm.geometry import T_from_xyz_yaw, fundamental_from_T, invert_T, sampson_distance_sq, yaw_of
from drivewm.logs.reader import read_log
from drivewm.sim.exposure import exposure_offsets_ns, interpolate_pose, state_at
from drivewm.sim.scene import SceneTick, box_from_center

STAGGER_MS = 15.0  # 6 cameras over 75 ms, inside one 100 ms tick


def _box(track: str, x: float, yaw: float):
    return box_from_center(track, "car", x, 0.0, yaw, (4.5, 1.8, 1.5), (0.5, 0.5, 0.5))


def test_state_between_ticks_is_interpolated() -> None:
    a = SceneTick(0, T_from_xyz_yaw(0, 0, 0, np.pi - 0.1), [_box("v1", 0.0, np.pi - 0.1), _box("gone", 5, 0)], 10.0)
    b = SceneTick(
        100_000_000, T_from_xyz_yaw(2, 0, 0, -np.pi + 0.1), [_box("v1", 4.0, -np.pi + 0.1), _box("new", 9, 0)]
    )
    mid = state_at([a, b], 0, 25_000_000)
    np.testing.assert_allclose(mid.T_world_from_ego[:3, 3], [0.5, 0, 0], atol=1e-12)
    assert abs(abs(yaw_of(mid.T_world_from_ego)) - (np.pi - 0.05)) < 1e-9  # across +-pi along the shorter arc
    boxes = {x.track_id: x for x in mid.agents}
    assert set(boxes) == {"v1", "gone"} and boxes["v1"].center_xyz[0] == pytest.approx(1.0)
    assert abs(abs(boxes["v1"].yaw_rad) - (np.pi - 0.05)) < 1e-9
    late = {x.track_id for x in state_at([a, b], 0, 75_000_000).agents}
    assert late == {"v1", "new"}  # nearer the next tick: who left is gone, who entered is there
    assert state_at([a, b], 0, 0) is a
    T = interpolate_pose(a.T_world_from_ego, b.T_world_from_ego, 1.0)
    np.testing.assert_allclose(T, b.T_world_from_ego, atol=1e-12)


def test_stagger_must_fit_in_a_tick() -> None:
    assert exposure_offsets_ns(6, 15.0, 1e8) == [0, 15_000_000, 30_000_000, 45_000_000, 60_000_000, 75_000_000]
    with pytest.raises(DrivewmError, match="exposure_stagger_ms 25"):
        exposure_offsets_ns(6, 25.0, 1e8)


@pytest.fixture(scope="module")
def staggered_log(tmp_path_factory):
    out = tmp_path_factory.mktemp("stagger")
    argv = ["simulate", "--scenario", "highway", "--duration", "2", "--seed", "5", "--out", str(out)]
    assert main([*argv, "--exposure-stagger-ms", str(STAGGER_MS)]) == 0
    (path,) = out.glob("*.mcap")
    assert path.name == "highway_highway_clear_day_s0005_stagger15ms.mcap"
    return read_log(path)


def test_images_are_logged_at_their_exposure_times(staggered_log) -> None:
    log = staggered_log
    ticks = log.pose_timestamps_ns
    assert len(ticks) == 20 and np.all(np.diff(ticks) == 100_000_000)
    for i, cam in enumerate(log.rig.names):
        stamps = np.array([f.timestamp_ns for f in log.images[cam]])
        np.testing.assert_array_equal(stamps, ticks + int(i * STAGGER_MS * 1e6))


def _pose_at(log, t_ns: int) -> np.ndarray:
    k = int(np.searchsorted(log.pose_timestamps_ns, t_ns, side="right") - 1)
    t0, t1 = log.pose_timestamps_ns[k], log.pose_timestamps_ns[min(k + 1, len(log.pose_timestamps_ns) - 1)]
    w = 0.0 if t1 == t0 else (t_ns - t0) / (t1 - t0)
    return interpolate_pose(log.T_world_from_ego[k], log.T_world_from_ego[min(k + 1, len(log.T_world_from_ego) - 1)], w)


def test_images_obey_the_geometry_of_their_exposure_times(staggered_log) -> None:
    """CAM_FRONT_LEFT exposes 75 ms after CAM_FRONT (about 2 m of driving): its matches obey the
    epipolar geometry of the ego poses at the two exposure times, not the static rig's."""
    log = staggered_log
    ca, cb = log.rig.camera("CAM_FRONT"), log.rig.camera("CAM_FRONT_LEFT")
    F_rig = fundamental_from_T(ca.K, cb.K, invert_T(cb.T_ego_from_cam) @ ca.T_ego_from_cam)
    timed, rig_only = [], []
    for k in range(0, len(log.images[ca.name]) - 1, 3):
        fa, fb = log.images[ca.name][k], log.images[cb.name][k]
        xa, xb = match(sift(fa.decode()), sift(fb.decode()), ratio=0.75)
        shared = in_view_of(ca, cb, xa) & in_view_of(cb, ca, xb)
        xa, xb = xa[shared], xb[shared]
        T_world_from_a = _pose_at(log, fa.timestamp_ns) @ ca.T_ego_from_cam
        T_world_from_b = _pose_at(log, fb.timestamp_ns) @ cb.T_ego_from_cam
        F = fundamental_from_T(ca.K, cb.K, invert_T(T_world_from_b) @ T_world_from_a)
        timed.append(np.sqrt(sampson_distance_sq(F, xa, xb)))
        rig_only.append(np.sqrt(sampson_distance_sq(F_rig, xa, xb)))
    timed, rig_only = np.concatenate(timed), np.concatenate(rig_only)
    assert len(timed) >= 40, f"only {len(timed)} matches"
    assert np.median(timed) < 0.5, f"median Sampson error at the exposure times {np.median(timed):.3f} px"
    assert np.median(rig_only) > 4 * np.median(timed), (np.median(rig_only), np.median(timed))
