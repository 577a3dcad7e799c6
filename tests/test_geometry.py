import cv2
import numpy as np
import pytest

from drivewm.errors import DrivewmError
from drivewm.geometry import (
    R_to_quat_xyzw,
    backproject,
    euler_to_R,
    fundamental_from_T,
    invert_T,
    load_rig,
    make_T,
    project,
    quat_xyzw_to_R,
    rig_from_dict,
    sampson_distance_sq,
    transform_points,
)


def random_T(rng):
    R = euler_to_R(*rng.uniform(-np.pi, np.pi, 3))
    return make_T(R, rng.normal(size=3))


def test_invert_and_quaternion_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        T = random_T(rng)
        assert np.allclose(invert_T(T) @ T, np.eye(4), atol=1e-12)
        R = T[:3, :3]
        assert np.allclose(quat_xyzw_to_R(R_to_quat_xyzw(R)), R, atol=1e-12)


def test_project_backproject_round_trip():
    rng = np.random.default_rng(1)
    K = np.array([[300.0, 0, 160], [0, 310, 96], [0, 0, 1]])
    pts = rng.uniform([-5, -3, 2], [5, 3, 40], size=(50, 3))
    uv, z = project(K, pts)
    assert np.allclose(backproject(K, uv, z), pts)
    cv_uv, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), K, None)
    assert np.allclose(uv, cv_uv[:, 0], atol=1e-9)


@pytest.mark.parametrize("name,count", [("nuscenes6", 6), ("front3", 3), ("front1", 1)])
def test_named_rigs_load_and_look_outward(name, count):
    rig = load_rig(name)
    assert len(rig.cameras) == count
    for cam in rig.cameras:
        # the optical axis (camera +z) is horizontal-ish in the ego frame: cameras look at the road
        axis = cam.T_ego_from_cam[:3, 2]
        assert abs(axis[2]) < 0.1
    # a point 20 m ahead of the car is seen near the centre of CAM_FRONT
    front = rig.camera("CAM_FRONT")
    uv, z = project(
        front.K, transform_points(invert_T(front.T_ego_from_cam), np.array([[21.7, 0.0, front.T_ego_from_cam[2, 3]]]))
    )
    assert z[0] > 0 and abs(uv[0, 0] - front.K[0, 2]) < 1e-6


def test_fundamental_and_sampson_match_opencv():
    rng = np.random.default_rng(2)
    K = np.array([[300.0, 0, 160], [0, 300, 96], [0, 0, 1]])
    T_b_from_a = make_T(euler_to_R(0.0, 0.05, 0.3), [0.5, 0.0, 0.1])
    pts_a = rng.uniform([-5, -3, 4], [5, 3, 30], size=(40, 3))
    uv_a, _ = project(K, pts_a)
    uv_b, _ = project(K, transform_points(T_b_from_a, pts_a))
    F = fundamental_from_T(K, K, T_b_from_a)
    assert np.sqrt(sampson_distance_sq(F, uv_a, uv_b)).max() < 1e-9
    noisy = uv_b + rng.normal(scale=2.0, size=uv_b.shape)
    ours = sampson_distance_sq(F, uv_a, noisy)
    ha = np.concatenate([uv_a, np.ones((40, 1))], 1)
    hb = np.concatenate([noisy, np.ones((40, 1))], 1)
    theirs = [cv2.sampsonDistance(ha[i : i + 1].T, hb[i : i + 1].T, F) for i in range(40)]
    assert np.allclose(ours, theirs, rtol=1e-9)


def test_bad_rig_is_a_clear_error(tmp_path):
    with pytest.raises(DrivewmError, match="non-empty 'cameras'"):
        rig_from_dict({"name": "x", "cameras": []})
    with pytest.raises(DrivewmError, match="give K or hfov_deg"):
        rig_from_dict({"cameras": [{"name": "a", "width": 10, "height": 10, "xyz": [0, 0, 0]}]})
    with pytest.raises(DrivewmError, match="no such file or named rig"):
        load_rig("no_such_rig")
