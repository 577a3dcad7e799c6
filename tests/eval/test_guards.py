"""The guards' building blocks (drivewm.eval.guards) on exact synthetic geometry: parallax beyond a
homography, travel direction and its verdicts, duplicate views, two-view rotations."""

from __future__ import annotations

import numpy as np
import pytest

from drivewm.eval.config import EpipolarConfig, GuardConfig
from drivewm.eval.epipolar import canonical_K
from drivewm.eval.guards import (
    angle_deg,
    direction_verdict,
    duplicate_views,
    ego_yaw_deg,
    parallax_count,
    travel_direction_cam,
)
from drivewm.eval.matching import Matches
from drivewm.geometry import load_rig, make_T, project, rot_z


def two_views(depth_m: np.ndarray, T_b_from_a: np.ndarray, K: np.ndarray, seed: int = 0) -> Matches:
    """Exact matches of points at ``depth_m`` (N,) along random rays of view a, seen from b."""
    rng = np.random.default_rng(seed)
    uv = rng.uniform([40, 40], [K[0, 2] * 2 - 40, K[1, 2] * 2 - 40], (len(depth_m), 2))
    rays = np.c_[(uv - K[:2, 2]) / [K[0, 0], K[1, 1]], np.ones(len(uv))]
    pts_b = rays * depth_m[:, None] @ T_b_from_a[:3, :3].T + T_b_from_a[:3, 3]
    uv_b, _ = project(K, pts_b)
    return Matches(uv, uv_b)


K_C = canonical_K(EpipolarConfig())
FORWARD_1M = make_T(np.eye(3), [0, 0, -1.0])  # T_b_from_a of a camera moving 1 m along its +z


def test_parallax_count_separates_depth_from_a_plane_or_a_zoom():
    rng = np.random.default_rng(1)
    scene = two_views(rng.uniform(5, 60, 300), FORWARD_1M, K_C)
    plane = two_views(np.full(300, 20.0), FORWARD_1M, K_C)  # a fronto-parallel plane: a homography (a zoom)
    assert parallax_count(scene, 1.0) > 100
    assert parallax_count(plane, 1.0) == 0


@pytest.mark.parametrize("sign", [1.0, -1.0])
def test_travel_direction_reads_the_sign_of_time(sign):
    rng = np.random.default_rng(2)
    T = make_T(rot_z(np.radians(1.0)) @ np.eye(3), [0.1, 0, -sign])  # mostly forward (or backward), a little yaw
    d = travel_direction_cam(two_views(rng.uniform(5, 60, 300), T, K_C), K_C, EpipolarConfig(), 1.0)
    expected = np.array([0, 0, 1.0])
    assert (angle_deg(d, expected) < 10) if sign > 0 else (angle_deg(d, expected) > 170)


def test_direction_verdicts_tell_reversed_shuffled_and_shifted_apart():
    cfg = GuardConfig()
    cams = ["F", "L", "R"]
    real = direction_verdict({c: [1.0, 2.0, 3.0] for c in cams}, cfg)
    reversed_ = direction_verdict({c: [178.0, 179.0, 177.0] for c in cams}, cfg)
    shuffled = direction_verdict({c: [2.0, 178.0, 3.0, 176.0] for c in cams}, cfg)
    shifted = direction_verdict({"F": [52.0, 55.0, 51.0], "L": [54.0, 53.0, 56.0], "R": [1.0, 2.0, 3.0]}, cfg)
    copied = direction_verdict({"F": [1.0, 2.0, 1.0], "L": [55.0, 56.0, 54.0], "R": [178.0, 179.0, 177.0]}, cfg)
    undecided = direction_verdict({c: [] for c in cams}, cfg)
    one_pair_each = direction_verdict({"F": [1.0], "L": [93.0], "R": [2.0]}, cfg)  # too few to judge a camera
    assert (real.time_ok, real.views_ok) == (True, True)
    assert reversed_.time_ok is False and shuffled.time_ok is False
    assert (shifted.time_ok, shifted.views_ok) == (True, False)
    assert (copied.time_ok, copied.views_ok) == (True, False)
    assert (undecided.time_ok, undecided.views_ok) == (None, None)
    assert (one_pair_each.time_ok, one_pair_each.views_ok) == (None, None)


def test_duplicate_views_finds_copies_and_mirrors_not_distinct_cameras():
    rig = load_rig("nuscenes6")
    rng = np.random.default_rng(3)
    h, w = rig.cameras[0].height, rig.cameras[0].width
    videos = {c: rng.integers(0, 255, (8, h, w, 3), dtype=np.uint8) for c in rig.names}
    assert duplicate_views(videos, rig, GuardConfig()) == []
    a, b, c = rig.names[:3]
    videos[b] = videos[a].copy()
    videos[c] = videos[a][:, :, ::-1].copy()
    found = duplicate_views(videos, rig, GuardConfig())
    assert f"{a}~{b}" in found and f"{a}~mirror({c})" in found


def test_ego_yaw_of_a_front_camera_rotation_is_the_turn():
    front = load_rig("nuscenes6").camera("CAM_FRONT")
    R_ec = front.T_ego_from_cam[:3, :3]
    R_cam = R_ec.T @ rot_z(np.radians(7.0)) @ R_ec  # the ego turns 7 deg left
    assert ego_yaw_deg(R_cam, front) == pytest.approx(7.0, abs=1e-9)
