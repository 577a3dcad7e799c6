"""The guards' building blocks (drivewm.eval.guards) on exact synthetic geometry: parallax beyond a
homography and the motion evidence it makes, the parallax a pair's travel demands, travel direction
and its verdicts, duplicate views, two-view rotations; and real simulated clips at 160x96 and
320x192, which no guard may void."""

from __future__ import annotations

import numpy as np
import pytest

from drivewm.eval.config import EpipolarConfig, EvalConfig, GuardConfig
from drivewm.eval.epipolar import canonical_K
from drivewm.eval.guards import (
    angle_deg,
    conditioned_speed_mps,
    direction_verdict,
    duplicate_views,
    ego_yaw_deg,
    expected_parallax_px,
    motion_demanded,
    motion_evidence,
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


def noisy(m: Matches, sigma_px: float, seed: int = 0) -> Matches:
    """``m`` with Gaussian keypoint noise on both sides."""
    rng = np.random.default_rng(seed)
    return Matches(m.uv_a + rng.normal(0, sigma_px, m.uv_a.shape), m.uv_b + rng.normal(0, sigma_px, m.uv_b.shape))


def test_motion_evidence_scales_with_the_matches_a_frame_pair_has():
    """A small frame's 20 matches of a scene with depth are evidence; a zoomed still's or a frozen
    pair's 600 are not; a view that one wall fills (94% of 700 matches on it) still is."""
    rng = np.random.default_rng(4)
    cfg, epi = GuardConfig(), EpipolarConfig()
    few = noisy(two_views(rng.uniform(5, 60, 20), FORWARD_1M, K_C, seed=5), 0.2)
    zoom = noisy(two_views(np.full(600, 20.0), FORWARD_1M, K_C, seed=6), 0.2)
    frozen = two_views(np.full(600, 20.0), np.eye(4), K_C, seed=7)
    depth = np.r_[np.full(660, 20.0), rng.uniform(5, 60, 40)]
    wall = noisy(two_views(depth, FORWARD_1M, K_C, seed=8), 0.2)
    assert parallax_count(few, 1.0) < epi.min_matches  # too few for a count of min_matches
    assert motion_evidence(few, cfg, epi, 1.0)
    assert not motion_evidence(zoom, cfg, epi, 1.0) and not motion_evidence(frozen, cfg, epi, 1.0)
    assert motion_evidence(wall, cfg, epi, 1.0)


def test_motion_is_demanded_where_the_travel_makes_parallax_visible():
    """f t / Z against 1 native px: a 160 px camera (f 114 px) driving 2.8 m between frames must show
    motion, one creeping 0.1 m need not; unknown travel (no poses, no trajectory) always must."""
    cfg = GuardConfig()
    assert expected_parallax_px(114.0, 2.8, cfg) == pytest.approx(114.0 * 2.8 / cfg.parallax_depth_m)
    assert motion_demanded(114.0, 2.8, cfg)
    assert not motion_demanded(114.0, 0.1, cfg)
    assert motion_demanded(114.0, None, cfg)
    waypoints = [[1.0 * (i + 1), 0.0, 0.0] for i in range(16)]  # 1 m each 0.1 s: 10 m/s
    assert conditioned_speed_mps(waypoints, 0.1) == pytest.approx(10.0)
    assert conditioned_speed_mps([], 0.1) is None


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
    one_off = direction_verdict({"F": [1.0, 2.0, 1.0], "L": [54.0, 53.0, 56.0], "R": [1.0, 2.0, 3.0]}, cfg)
    undecided = direction_verdict({c: [] for c in cams}, cfg)
    one_pair_each = direction_verdict({"F": [1.0], "L": [93.0], "R": [2.0]}, cfg)  # too few to judge a camera
    assert (real.time_ok, real.views_ok) == (True, True)
    assert reversed_.time_ok is False and shuffled.time_ok is False
    assert (shifted.time_ok, shifted.views_ok) == (True, False)
    assert (copied.time_ok, copied.views_ok) == (True, False)
    assert (one_off.time_ok, one_off.views_ok) == (True, True)  # one camera's E misled, not a view swap
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


GUARDS = ("guard_motion", "guard_time", "guard_views")


def unvoided(items) -> dict[str, dict]:
    """Per clip: the guards' verdicts and TSE of every clip whose guards voided it or failed one."""
    from drivewm.eval.suite import evaluate_item

    bad = {}
    for item in items:
        m = evaluate_item(item, EvalConfig(metrics=["tse", "cse"]), threads=1).metrics
        assert "error" not in m, m.get("error")
        if m.get("voided_by") or any(m.get(g) is False for g in GUARDS):
            bad[item.key] = {k: m.get(k) for k in (*GUARDS, "motion_fraction", "tse", "duplicate_views")}
    return bad


@pytest.mark.slow
def test_no_guard_voids_a_real_simulated_clip_at_160x96(small_clip_dir):
    """The CLI golden chain's clips (160x96, rain at dusk, 17 frames): a pair verifies a tenth of a
    320x192 pair's matches, and no guard may read that as no motion."""
    from drivewm.eval.inputs import load_items

    items = load_items(small_clip_dir)
    assert len(items) == 2 and items[0].rig.cameras[0].width == 160
    assert unvoided(items) == {}


@pytest.mark.slow
@pytest.mark.timeout(1800)
def test_no_guard_voids_a_real_simulated_clip_at_320x192(sim_clip_dir):
    """Every shared simulated clip (tests/conftest.py: highway clear and snow, roundabout, SUMO grid at
    night; 320x192, 17 frames) passes every guard."""
    from drivewm.eval.inputs import load_items

    items = load_items(sim_clip_dir)
    assert len(items) == 12 and items[0].rig.cameras[0].width == 320
    assert unvoided(items) == {}
