"""ATE / RPE / TFE against closed-form values (derivations in the comments)."""

import numpy as np
import pytest

from drivewm.eval.trajectory_errors import (
    ate,
    heading_change_deg,
    path_length_m,
    path_ratio,
    rpe,
    tfe,
    umeyama,
    waypoint_heading_deg,
)
from drivewm.geometry import euler_to_R, make_T, rot_z


def circle(n=16, radius=10.0):
    """Planar circle with the heading along the tangent: T_world_from_ego (n, 4, 4)."""
    a = np.linspace(0, 1.5 * np.pi, n)
    return np.stack([make_T(rot_z(ai + np.pi / 2), [radius * np.cos(ai), radius * np.sin(ai), 0.0]) for ai in a])


def similarity(T, s0, R0, t0):
    out = T.copy()
    out[:, :3, :3] = R0 @ T[:, :3, :3]
    out[:, :3, 3] = s0 * T[:, :3, 3] @ R0.T + t0
    return out


def test_umeyama_recovers_exact_similarity():
    ref = circle()
    R0 = euler_to_R(0.3, -0.2, 1.1)
    est = similarity(ref, 0.37, R0, np.array([4.0, -2.0, 7.0]))
    sim = umeyama(est[:, :3, 3], ref[:, :3, 3])
    np.testing.assert_allclose(sim.apply_points(est[:, :3, 3]), ref[:, :3, 3], atol=1e-9)
    assert sim.scale == pytest.approx(1 / 0.37)


def test_ate_rpe_with_noise_match_closed_form():
    ref = circle(n=16)
    delta = 0.3
    # Noise along z (off the trajectory's plane), made zero-mean and uncorrelated with the planar positions.
    pattern = np.tile([1.0, -1.0, -1.0, 1.0], 4) * delta
    noisy = ref.copy()
    noisy[:, 2, 3] += pattern
    pc = ref[:, :3, 3] - ref[:, :3, 3].mean(0)
    # Make the noise exactly orthogonal to the centred x, y positions and to the constant.
    basis = np.stack([pc[:, 0], pc[:, 1], np.ones(16)], 1)
    pattern = pattern - basis @ np.linalg.lstsq(basis, pattern, rcond=None)[0]
    noisy[:, 2, 3] = pattern
    R0 = euler_to_R(0.1, 0.4, -2.0)
    est = similarity(noisy, 2.5, R0, np.array([1.0, 2.0, 3.0]))

    value, sim = ate(est, ref)
    # Umeyama (est -> ref): R = R0^T, scale = (1/s0) V / (V + d2) with V = mean|p_c|^2, d2 = mean n^2,
    # so the aligned points are mu + k (p_c + n), k = V / (V + d2), and
    # ATE^2 = (k-1)^2 V + k^2 d2 = V d2 / (V + d2).
    V = np.mean(np.sum(pc**2, axis=1))
    d2 = np.mean(pattern**2)
    assert value == pytest.approx(np.sqrt(V * d2 / (V + d2)), rel=1e-9)
    k = V / (V + d2)
    assert sim.scale == pytest.approx(k / 2.5, rel=1e-9)

    trans, rot = rpe(est, ref, delta=1, scale=sim.scale)
    # Rotations are only transformed by R0, so relative rotations agree: RPE rot = 0. The relative
    # translation error of step i is |k (dp_i + dn_i) - dp_i| in the reference ego frame.
    dp = np.diff(ref[:, :3, 3], axis=0)
    dn = np.diff(np.stack([np.zeros(16), np.zeros(16), pattern], 1), axis=0)
    expected = np.sqrt(np.mean(np.sum((k * (dp + dn) - dp) ** 2, axis=1)))
    assert trans == pytest.approx(expected, rel=1e-9)
    assert rot == pytest.approx(0.0, abs=1e-6)


def test_rpe_rotation_of_one_perturbed_frame():
    ref = circle(n=11)
    est = ref.copy()
    eps_deg = 2.0
    est[5, :3, :3] = est[5, :3, :3] @ rot_z(np.radians(eps_deg))
    _, rot = rpe(est, ref, delta=1)
    # Pairs (4, 5) and (5, 6) are each off by eps; 10 pairs in all.
    assert rot == pytest.approx(2 * eps_deg / 10, rel=1e-9)


def test_tfe_scale_only_alignment():
    ref = circle(n=11)
    fps = 10.0
    T0_inv = np.linalg.inv(ref[0])
    way = np.stack([(T0_inv @ T)[:3, 3] for T in ref[1:]])
    est = similarity(ref, 0.5, euler_to_R(0, 0, 0.7), np.array([3.0, 0, 0]))
    assert tfe(est, fps, way, 1 / fps) == pytest.approx(0.0, abs=1e-9)
    # Straight drive along x; waypoints 1 m to the left: the least-squares scale is
    # sum x^2 / sum x^2 = 1, so every waypoint is off by exactly 1 m.
    straight = np.stack([make_T(np.eye(3), [2.0 * i, 0, 0]) for i in range(11)])
    way_left = np.array([[2.0 * i, 1.0, 0.0] for i in range(1, 11)])
    assert tfe(straight, fps, way_left, 1 / fps) == pytest.approx(1.0, rel=1e-12)


def test_path_ratio_reads_a_standing_reconstruction_and_an_exploded_one():
    # 17 frames at 21.6 m/s and 10 fps: 16 steps of 2.16 m = 34.56 m
    drive = np.stack([make_T(np.eye(3), [2.16 * i, 0, 0]) for i in range(17)])
    standing = np.repeat(drive[:1], 17, axis=0)
    assert path_length_m(drive) == pytest.approx(34.56, rel=1e-12)
    assert path_ratio(drive, drive) == pytest.approx(1.0, rel=1e-12)
    assert path_ratio(standing, drive) == pytest.approx(1 / 34.56, rel=1e-12)  # floored at 1 m
    exploded = drive.copy()
    exploded[:, :3, 3] *= 12.0
    assert path_ratio(exploded, drive) == pytest.approx(12.0, rel=1e-12)
    # a circle's path is its arc, not its chord: 1.5 pi r in 15 chords of 2 r sin(0.05 pi)
    assert path_length_m(circle()) == pytest.approx(15 * 2 * 10 * np.sin(0.05 * np.pi), rel=1e-12)
    assert path_ratio(standing, standing) == 1.0  # a standing ego, a standing reconstruction


@pytest.mark.parametrize("turn_deg", [-40.0, -5.0, 0.0, 12.0, 60.0])
def test_heading_change_reads_a_turn_in_any_world_gauge(turn_deg):
    """An arc turning by turn_deg (left positive): the recovered heading change is the turn, whatever
    rotation, translation and scale the world frame has (structure from motion fixes none of them);
    the conditioned waypoints of the same arc give the same heading."""
    n = 17
    yaw = np.radians(np.linspace(0.0, turn_deg, n))
    step = 1.5
    xy = np.cumsum(np.stack([np.cos(yaw), np.sin(yaw)], 1) * step, 0) - [step, 0.0]
    T = np.stack([make_T(rot_z(a), np.array([x, y, 0.0])) for a, (x, y) in zip(yaw, xy, strict=True)])
    gauge = make_T(euler_to_R(0.3, -0.2, 1.1), np.array([5.0, -3.0, 2.0]))
    T_gauge = np.einsum("ij,njk->nik", gauge, T)
    T_gauge[:, :3, 3] *= 0.37
    assert heading_change_deg(T_gauge) == pytest.approx(turn_deg, abs=1e-6)
    waypoints = np.concatenate([xy[1:], np.zeros((n - 1, 1))], 1)  # after the first frame, as ClipMeta stores them
    expected_last_segment = np.degrees(np.arctan2(*(xy[-1] - xy[-2])[::-1]))
    assert waypoint_heading_deg(waypoints) == pytest.approx(expected_last_segment, abs=1e-6)
    assert np.sign(waypoint_heading_deg(waypoints)) == np.sign(turn_deg)


def test_conditioned_heading_of_an_ego_that_stops_and_creeps_back_is_its_turn():
    """A slow left turn of 30 deg (0.3 m steps) that stops and rolls back 4 cm a step for 4 steps, as
    highway-env's intersection ego does: the last segment points backwards (~ -150 deg) but the turn
    is the heading of the last metre driven; a standing ego (1 cm jitter) conditions no turn."""
    yaw = np.radians(np.linspace(0.0, 30.0, 12))
    xy = np.cumsum(np.stack([np.cos(yaw), np.sin(yaw)], 1) * 0.3, 0)
    back = xy[-1] - np.arange(1, 5)[:, None] * 0.04 * np.array([np.cos(yaw[-1]), np.sin(yaw[-1])])
    waypoints = np.concatenate([np.concatenate([xy, back]), np.zeros((16, 1))], 1)
    last = waypoints[-1, :2] - waypoints[-2, :2]
    assert abs(np.degrees(np.arctan2(last[1], last[0]))) > 140  # what the last segment alone reads
    assert waypoint_heading_deg(waypoints) == pytest.approx(27.0, abs=3.0)
    standing = np.random.default_rng(0).normal(0.0, 0.01, (16, 3))
    assert waypoint_heading_deg(standing) == 0.0


def rig_images(ego: np.ndarray, rig_name: str = "nuscenes6") -> dict[str, np.ndarray]:
    """T_world_from_cam (T, 4, 4) per camera of a rig driven along ``ego``."""
    from drivewm.geometry import load_rig

    return {c.name: ego @ c.T_ego_from_cam for c in load_rig(rig_name).cameras}


def straight_path(n=17, speed_m=1.5):
    return np.stack([make_T(np.eye(3), [speed_m * i, 0.0, 0.0]) for i in range(n)])


def test_image_pose_errors_align_on_a_straight_path_where_the_ego_path_cannot():
    """A straight drive: the ego positions are collinear, so an alignment fitted to them alone leaves
    the roll about the path free (on simulated clips 19-124 deg); fitted to every camera centre of the
    rig it recovers the exact similarity, and every image's error is 0."""
    from drivewm.eval.trajectory_errors import image_pose_errors

    ref = rig_images(straight_path())
    R0 = euler_to_R(0.4, 0.1, -0.7)
    est = {c: similarity(T, 0.5, R0, np.array([1.0, 2.0, 3.0])) for c, T in ref.items()}
    registered = {c: np.ones(len(T), bool) for c, T in ref.items()}
    errors = image_pose_errors(est, registered, ref)
    assert errors.position_m.max() < 1e-9 and errors.rotation_deg.max() < 1e-5  # arccos near 0: ~1e-6 deg
    assert errors.auc(0.25, 2.0) == pytest.approx(1.0)
    assert errors.sim.scale == pytest.approx(2.0)


def test_image_pose_auc_counts_errors_and_unregistered_images():
    """AUC = mean over images of max(0, 1 - max(dp / 0.25 m, dr / 2 deg)): a 1 deg rotation error on
    one image (its centre unchanged, so the alignment is too) costs that image half, and an
    unregistered image counts 0."""
    from drivewm.eval.trajectory_errors import image_pose_errors

    ref = rig_images(straight_path())
    est = {c: T.copy() for c, T in ref.items()}
    est["CAM_FRONT"][3, :3, :3] = est["CAM_FRONT"][3, :3, :3] @ rot_z(np.radians(1.0))
    registered = {c: np.ones(len(T), bool) for c, T in ref.items()}
    registered["CAM_BACK"][5] = False
    n = sum(len(T) for T in ref.values())
    errors = image_pose_errors(est, registered, ref)
    assert errors.images == n and len(errors.position_m) == n - 1
    assert errors.rotation_deg.max() == pytest.approx(1.0)
    assert errors.auc(0.25, 2.0) == pytest.approx((n - 2 + 0.5) / n)


def test_image_pose_errors_with_fewer_than_three_registered_images_score_every_image_zero():
    from drivewm.eval.trajectory_errors import image_pose_errors

    ref = rig_images(straight_path())
    registered = {c: np.zeros(len(T), bool) for c, T in ref.items()}
    registered["CAM_FRONT"][:2] = True  # two images: no similarity can be fitted
    errors = image_pose_errors(ref, registered, ref)
    assert len(errors.position_m) == 0 and errors.images == sum(len(T) for T in ref.values())
    assert errors.auc(0.25, 2.0) == 0.0
