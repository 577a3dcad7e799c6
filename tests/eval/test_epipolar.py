import dataclasses

import cv2
import numpy as np
import pytest
from eval_euroc import load_euroc

from drivewm.eval.config import EpipolarConfig, MatchConfig
from drivewm.eval.consistency import native_px_per_canonical_px
from drivewm.eval.epipolar import (
    OK,
    TOO_FEW_MATCHES,
    calibrated_fundamental,
    canonical_K,
    fit_fundamental,
    normalised,
    rectify_matches,
    relative_pose,
    sampson_px,
    score_matches,
)
from drivewm.eval.matching import FrameMatcher, Matches
from drivewm.geometry import essential_from_T, rotation_angle_deg


def test_sampson_equals_opencv_sampson_distance():
    rng = np.random.default_rng(0)
    F = rng.normal(size=(3, 3))
    x_a = rng.uniform(0, 640, (200, 2))
    x_b = rng.uniform(0, 480, (200, 2))
    ours_sq = sampson_px(F, x_a, x_b) ** 2
    ha = np.concatenate([x_a, np.ones((200, 1))], 1)
    hb = np.concatenate([x_b, np.ones((200, 1))], 1)
    theirs = np.array([cv2.sampsonDistance(ha[i : i + 1].T, hb[i : i + 1].T, F) for i in range(200)])
    np.testing.assert_allclose(ours_sq, theirs, rtol=1e-9)
    assert ours_sq.max() > 1.0  # random points are far from the epipolar lines: the check is not vacuous


def test_canonical_K_focal_is_pinned():
    K = canonical_K(EpipolarConfig())
    assert K[0, 0] == pytest.approx(277.128, abs=1e-3) and K[0, 2] == 480 and K[1, 2] == 270


def test_too_few_matches_is_nan_with_status():
    cfg = EpipolarConfig()
    m = Matches(np.zeros((5, 2)), np.ones((5, 2)))
    F, _ = fit_fundamental(m, cfg)
    res = score_matches(F, m, cfg)
    assert F is None and np.isnan(res.median_px) and res.status == TOO_FEW_MATCHES


@pytest.fixture(scope="module")
def euroc_matches(shared_data):
    cam0, cam1, T_1_from_0, pairs = load_euroc(shared_data / "stereo" / "euroc_v101")
    matcher = FrameMatcher(MatchConfig())
    K_c = canonical_K(EpipolarConfig())
    rect = [
        rectify_matches(matcher.match(("c0", i), a, ("c1", i), b), cam0, cam1, K_c) for i, (a, b) in enumerate(pairs)
    ]
    return K_c, T_1_from_0, rect


def test_euroc_calibrated_sampson_median_below_0p3px(euroc_matches):
    K_c, T_1_from_0, rect = euroc_matches
    F = calibrated_fundamental(K_c, T_1_from_0)
    medians = [score_matches(F, m, EpipolarConfig()) for m in rect]
    assert all(r.status == OK for r in medians)
    values = np.array([r.median_px for r in medians])
    print("EuRoC calibrated Sampson medians (canonical px):", np.round(values, 3))
    assert np.all(values < 0.3)
    assert np.all(values > 0.005)  # real images are never perfect; an exact zero would mean a bug


def test_euroc_relative_rotation_median_within_0p08_degrees(euroc_matches, shared_data):
    """relative_pose on EuRoC's calibrated stereo matches: every rotation within 0.5 deg, the median
    within 0.08 deg, and no worse than OpenCV's USAC_ACCURATE at the canonical MAGSAC threshold."""
    K_c, T_1_from_0, rect = euroc_matches
    cam0, cam1, _, _ = load_euroc(shared_data / "stereo" / "euroc_v101")
    scale = 0.5 * (native_px_per_canonical_px(cam0, K_c) + native_px_per_canonical_px(cam1, K_c))
    ours, opencv = [], []
    for m in rect:
        T_est, inliers = relative_pose(m, K_c, EpipolarConfig(), scale)
        ours.append(rotation_angle_deg(T_est[:3, :3].T @ T_1_from_0[:3, :3]))
        t_dir = T_1_from_0[:3, 3] / np.linalg.norm(T_1_from_0[:3, 3])
        assert float(T_est[:3, 3] @ t_dir) > 0.97  # baseline direction within ~14 deg (11 cm baseline, scene at metres)
        x_a, x_b = normalised(m.uv_a, K_c), normalised(m.uv_b, K_c)
        E, mask = cv2.findEssentialMat(x_a, x_b, np.eye(3), cv2.USAC_ACCURATE, 0.999, 0.5 / K_c[0, 0])
        _, R, _, _ = cv2.recoverPose(E, x_a, x_b, np.eye(3), mask=mask)
        opencv.append(rotation_angle_deg(R.T @ T_1_from_0[:3, :3]))
    print(f"EuRoC rotation error median {np.median(ours):.3f} deg (USAC_ACCURATE at 0.5 px {np.median(opencv):.3f})")
    assert max(ours) < 0.5
    assert np.median(ours) <= 0.08
    assert np.median(ours) <= np.median(opencv)


def test_far_field_stereo_pair_keeps_its_inliers():
    """Two forward cameras 10 cm apart in the textured corridor (eval_synth): nearly every match is
    farther than 50 baselines (5 m), where cv2.recoverPose's default cut-off drops it. relative_pose
    keeps them as inliers, refines on them, and recovers the pose."""
    from eval_synth import PLANES, make_texture, render

    from drivewm.geometry import Rig, T_from_xyz_yaw, invert_T, load_rig, make_T

    front = load_rig("nuscenes6").camera("CAM_FRONT")
    left = dataclasses.replace(front, name="LEFT", T_ego_from_cam=make_T(np.eye(3), [0, 0.1, 0]) @ front.T_ego_from_cam)
    rig = Rig("stereo", [front, left])
    images = render(rig, T_from_xyz_yaw(-8.0, 0.0, 0.0, 0.0), [make_texture(i) for i in range(len(PLANES))])
    K_c = canonical_K(EpipolarConfig())
    m = rectify_matches(FrameMatcher(MatchConfig()).match(0, images["CAM_FRONT"], 1, images["LEFT"]), front, left, K_c)
    T_true = invert_T(left.T_ego_from_cam) @ front.T_ego_from_cam
    T_est, inliers = relative_pose(m, K_c, EpipolarConfig())
    E = essential_from_T(T_true)
    _, _, _, default_mask = cv2.recoverPose(E, m.uv_a, m.uv_b, K_c)  # OpenCV's 50-baseline cut-off
    print(
        f"far-field stereo: {len(m)} matches, {inliers.sum()} inliers, "
        f"{int((default_mask > 0).sum())} within 50 baselines"
    )
    assert (default_mask > 0).sum() < 0.2 * len(m)  # the scene is far: the old mask lost most matches
    assert inliers.sum() > 0.7 * len(m) and inliers.sum() > 100
    assert rotation_angle_deg(T_est[:3, :3].T @ T_true[:3, :3]) < 0.1
    t_dir = T_true[:3, 3] / np.linalg.norm(T_true[:3, 3])
    assert float(T_est[:3, 3] @ t_dir) > 0.95
