import numpy as np

from drivewm.curate.config import TrajectoryConfig
from drivewm.curate.trajectory import future_waypoints, smooth_poses
from drivewm.geometry import T_from_xyz_yaw


def circle_drive(n=100, fps=10.0, speed=10.0, radius=50.0):
    """Ground-truth poses on a circle (counter-clockwise), yaw crossing +-pi."""
    t = np.arange(n) / fps
    ang = speed * t / radius
    poses = np.stack([T_from_xyz_yaw(radius * np.sin(a), radius * (1 - np.cos(a)), 0.0, a + 2.5) for a in ang])
    return (t * 1e9).astype(np.int64) + 10**18, poses


def rms_accel(p, t_ns):
    dt = np.diff(t_ns) * 1e-9
    v = np.diff(p, axis=0) / dt[:, None]
    a = np.diff(v, axis=0) / dt[1:, None]
    return float(np.sqrt((a**2).sum(1).mean()))


def test_kalman_rejects_gnss_jumps_and_bridges_nan():
    t, truth = circle_drive()
    rng = np.random.default_rng(0)
    noisy = truth.copy()
    noisy[:, :2, 3] += rng.normal(0, 0.3, (len(t), 2))  # GNSS jitter
    noisy[[30, 60], 0, 3] += 8.0  # multipath jumps
    noisy[45:50] = np.nan  # 0.5 s outage
    s = smooth_poses(t, noisy, TrajectoryConfig(position_sigma_m=0.3))
    assert s.rejected == 2 and s.missing == 5
    err = np.linalg.norm(s.xyz[:, :2] - truth[:, :2, 3], axis=1)
    raw = np.linalg.norm(noisy[:, :2, 3] - truth[:, :2, 3], axis=1)
    assert err.max() < 0.5 and np.sqrt(np.mean(err**2)) < 0.5 * np.sqrt(np.nanmean(raw[np.isfinite(raw)] ** 2))
    yaw_truth = np.unwrap(np.arctan2(truth[:, 1, 0], truth[:, 0, 0]))
    assert np.abs(s.yaw - yaw_truth).max() < 0.05  # unwrapped through +-pi


def test_no_finite_pose_means_unknown():
    t, truth = circle_drive(10)
    assert smooth_poses(t, np.full_like(truth, np.nan), TrajectoryConfig()) is None


def test_waypoints_in_first_ego_frame():
    t = (np.arange(17) * 1e8).astype(np.int64)
    poses = np.stack(
        [T_from_xyz_yaw(100 + 2.0 * i, 50.0, 0.0, np.pi / 2) for i in range(17)]
    )  # moving along world +x, facing +y
    wp, dt = future_waypoints(poses, t, 16)
    assert dt == 0.1 and wp.shape == (16, 3)
    # world +x is the ego's right (-y) when facing +y; first waypoint is frame 1
    np.testing.assert_allclose(wp[:, 1], -2.0 * np.arange(1, 17), atol=1e-9)
    np.testing.assert_allclose(wp[:, 0], 0.0, atol=1e-9)


def test_real_gnss_log_gives_smooth_trajectory(shared_data):
    from drivewm.logs.reader import read_log

    log = read_log(shared_data / "mcap/vehicle_gnss_imu/demo.mcap", "reductstore_demo", require_images=False)
    s = smooth_poses(log.pose_timestamps_ns, log.T_world_from_ego, TrajectoryConfig())
    raw_xyz = log.T_world_from_ego[:, :3, 3]
    raw, smooth = rms_accel(raw_xyz, log.pose_timestamps_ns), rms_accel(s.xyz, log.pose_timestamps_ns)
    # the raw stamps are irregular (4-75 ms) and the fixes jitter: ~3800 m/s^2 of apparent acceleration
    assert smooth < 5.0 and smooth < 0.01 * raw
    assert np.abs(s.xyz - raw_xyz).max() < 0.5  # smoothing stays within GNSS accuracy of the fixes
    assert np.linalg.norm(s.xyz[-1] - s.xyz[0]) > 50  # the car drives about 60 m


def test_importing_the_stage_loads_no_scipy_until_the_smoother_runs():
    """A fresh interpreter (as a spawned pool worker or the driver of a pool) that imports the curate
    stage and its executors holds neither filterpy nor scipy; the first smoothing loads filterpy."""
    import subprocess
    import sys

    code = (
        "import sys, numpy as np\n"
        "import drivewm.curate.executors, drivewm.curate.stage\n"
        "print(sorted(m for m in ('scipy', 'scipy.stats', 'filterpy') if m in sys.modules))\n"
        "from drivewm.curate.config import TrajectoryConfig\n"
        "from drivewm.curate.trajectory import smooth_poses\n"
        "smooth_poses(np.arange(3) * 10**8, np.tile(np.eye(4), (3, 1, 1)), TrajectoryConfig())\n"
        "print(sorted(m for m in ('scipy', 'scipy.stats', 'filterpy') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "[]"
    assert out[1] == "['filterpy', 'scipy', 'scipy.stats']"
