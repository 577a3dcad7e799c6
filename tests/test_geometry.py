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
    nearest_rotation,
    project,
    quat_xyzw_to_R,
    rig_from_dict,
    rot_z,
    rotation_angle_deg,
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


def test_rotation_angle_of_a_rotation_read_from_text():
    """KITTI-style poses are printed with ~7 significant digits: a 0.001 deg rotation read back is
    off orthonormal by ~1e-7, and arccos((tr R - 1) / 2) of that raw matrix would say ~0.03 deg."""
    from scipy.spatial.transform import Rotation

    R = rot_z(np.radians(0.001))
    rng = np.random.default_rng(3)
    R_text = R + rng.uniform(-1, 1, (3, 3)) * 1e-7  # what "%.7e" round-off leaves
    raw = np.degrees(np.arccos(np.clip((np.trace(R_text) - 1) / 2, -1, 1)))
    assert raw > 0.01  # the naive formula is off by an order of magnitude
    assert rotation_angle_deg(R_text) == pytest.approx(0.001, abs=2e-5)
    assert rotation_angle_deg(R_text) == pytest.approx(np.degrees(Rotation.from_matrix(R_text).magnitude()), abs=2e-5)
    Q = nearest_rotation(R_text)
    assert np.allclose(Q @ Q.T, np.eye(3), atol=1e-14) and np.linalg.det(Q) == pytest.approx(1.0)
    big = euler_to_R(0.3, -1.1, 2.5)
    assert rotation_angle_deg(big) == pytest.approx(np.degrees(Rotation.from_matrix(big).magnitude()), rel=1e-12)


def _ray_hits(cam_from, cam_to, uv_to):
    """Pixels of ``cam_from`` seen along the rays of pixels ``uv_to`` (N, 2) of ``cam_to`` (same pose)."""
    from drivewm.geometry import pixel_rays

    uv, _ = project(cam_from.K, pixel_rays(cam_to.K, uv_to))
    return uv


@pytest.mark.parametrize(
    "size,fit,crop_px",
    [
        ((160, 96), "same", (0, 0)),  # /2
        ((640, 384), "same", (0, 0)),  # x2
        ((240, 144), "same", (0, 0)),  # x0.75
        ((160, 120), "stretch", (0, 0)),  # another aspect, stretched
        ((160, 80), "crop", (0, 8)),  # resized to 160x96, 8 rows cut top and bottom
        ((128, 96), "crop", (16, 0)),  # resized to 160x96, 16 columns cut left and right
    ],
)
def test_scaled_camera_maps_pixel_centres_like_cv2_resize(size, fit, crop_px):
    """An image that is linear in (u, v) stays linear under cv2.resize (bilinear, pixel centres at
    integers): the value at each new pixel names the old pixel position it was sampled at, which must
    be where the scaled camera's ray through that pixel hits the original camera."""
    cam = load_rig("front1").camera("CAM_FRONT")  # 320x192, cx = 159.5
    vv, uu = np.mgrid[0 : cam.height, 0 : cam.width].astype(np.float32)
    w, h = size
    if fit == "crop":
        s = max(w / cam.width, h / cam.height)
        full = (round(cam.width * s), round(cam.height * s))
    else:
        full = (w, h)
    ox, oy = crop_px
    resized = [cv2.resize(c, full, interpolation=cv2.INTER_LINEAR)[oy : oy + h, ox : ox + w] for c in (uu, vv)]
    new = cam.scaled(w, h, fit)
    assert (new.width, new.height) == (w, h)
    # Interior pixels only: bilinear sampling clamps at the border.
    v2, u2 = np.mgrid[4 : h - 4, 4 : w - 4]
    uv_new = np.stack([u2.ravel(), v2.ravel()], 1).astype(np.float64)
    expected = np.stack([resized[0][v2, u2].ravel(), resized[1][v2, u2].ravel()], 1)
    np.testing.assert_allclose(_ray_hits(cam, new, uv_new), expected, atol=2e-3)  # float32 images


def test_scaled_refuses_a_silent_aspect_change():
    cam = load_rig("front1").camera("CAM_FRONT")
    with pytest.raises(DrivewmError, match="aspect ratio"):
        cam.scaled(160, 120)
    with pytest.raises(DrivewmError, match="not 'same'"):
        cam.scaled(160, 96, "squash")
    assert cam.scaled(161, 96).width == 161  # one pixel of rounding is not an aspect change


@pytest.mark.parametrize(
    "yaml_text, message",
    [
        (
            "cameras:\n  - {name: c, width: 64, height: 48, hfov_deg: 60, xyz: [1, 0, 1], yaw_dg: 90}\n",
            "camera 'c': unknown key 'yaw_dg' (did you mean 'yaw_deg'?",
        ),
        (
            "cameras:\n  - {name: c, width: 64, height: 48, hfov_deg: 60, xyz: [1, 0, 1], distorsion: [0.1]}\n",
            "camera 'c': unknown key 'distorsion' (did you mean 'distortion'?",
        ),
        ("defaults: {widht: 64}\ncameras:\n  - {name: c}\n", "defaults: unknown key 'widht' (did you mean 'width'?"),
        ("camera:\n  - {name: c}\ncameras:\n  - {name: c}\n", "unknown key 'camera' (did you mean 'cameras'?"),
    ],
)
def test_a_misspelt_rig_key_is_refused_with_the_nearest_name(tmp_path, yaml_text, message):
    """Issue 70: a misspelt key had been ignored, leaving the calibration silently at its default (a camera
    looking forward instead of 90 degrees left, no distortion)."""
    path = tmp_path / "rig.yaml"
    path.write_text(yaml_text)
    with pytest.raises(DrivewmError) as err:
        load_rig(path)
    assert str(err.value).startswith(f"{path}: {message}") and "\n" not in str(err.value)
