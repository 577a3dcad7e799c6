"""The renderer draws a 3D point where the rig's pinhole model projects it, with a working depth test.

The reference is computed independently of the renderer: the marker's corners are projected with
drivewm.geometry.project and the pixels whose centres fall inside that polygon are the expected
silhouette (OpenCV convention: pixel centres at integer coordinates).
"""

from __future__ import annotations

import numpy as np
import pytest
from matplotlib.path import Path as MplPath

from drivewm.geometry import invert_T, load_rig, project, transform_points
from drivewm.sim.conditions import condition_for
from drivewm.sim.render import Renderer
from drivewm.sim.scene import LaneBoundary, RoadMap, box_from_center

T_WORLD_FROM_EGO = np.eye(4)
MARKER_M = 0.8


def _straight_road() -> RoadMap:
    x = np.linspace(-60, 120, 181)
    center = np.stack([x, np.zeros_like(x)], axis=1)
    right, left = center - [0, 1.75], center + [0, 1.75]
    return RoadMap(
        [center],
        [3.5],
        [LaneBoundary(right, "solid"), LaneBoundary(left, "dashed")],
        [right, left],
        [np.concatenate([right, left[::-1]])],
    )


@pytest.fixture(scope="module")
def renderer() -> Renderer:
    rig = load_rig("nuscenes6")
    return Renderer(
        rig,
        _straight_road(),
        condition_for("clear", "day"),
        0,
        np.array([-80.0, -80.0]),
        np.array([140.0, 80.0]),
        urban=False,
    )


def _marker(point, facing_xy: np.ndarray):
    """A thin red square centred on ``point`` (x, y, z), its face turned towards ``facing_xy``."""
    x, y, z = point
    yaw = float(np.arctan2(facing_xy[1] - y, facing_xy[0] - x))
    box = box_from_center("m", "marker", x, y, yaw, (0.002, MARKER_M, MARKER_M), (1.0, 0.0, 0.0))
    box.center_xyz[2] = z
    return box


def _red_mask(img: np.ndarray) -> np.ndarray:
    r, g, b = (img[..., c].astype(int) for c in range(3))
    return (r > 120) & (g < 60) & (b < 60)


def _expected_mask(cam, marker) -> np.ndarray:
    """Pixels whose centre lies inside the projection of the marker's face (geometry.project only)."""
    lateral = np.array([-np.sin(marker.yaw_rad), np.cos(marker.yaw_rad), 0.0]) * MARKER_M / 2
    up = np.array([0.0, 0.0, MARKER_M / 2])
    corners = marker.center_xyz + np.array([-lateral + up, lateral + up, lateral - up, -lateral - up])
    uv, _ = project(cam.K, transform_points(invert_T(cam.T_ego_from_cam), corners))
    vv, uu = np.mgrid[0 : cam.height, 0 : cam.width]
    inside = MplPath(uv).contains_points(np.stack([uu.ravel(), vv.ravel()], axis=1))
    return inside.reshape(cam.height, cam.width)


def _check_marker(renderer: Renderer, images: dict, name: str, marker, point) -> None:
    cam = renderer.rig.camera(name)
    found, expected = _red_mask(images[name]), _expected_mask(cam, marker)
    assert expected.sum() > 100 and found.sum() > 100, f"marker not visible in {name}"
    iou = (found & expected).sum() / (found | expected).sum()
    # Pixel-centre coverage is exact up to ties on the border: a handful of pixels at most.
    assert iou > 0.97, f"{name}: drawn silhouette overlaps the projected one with IoU {iou:.3f}"
    centroid = lambda m: np.array(np.nonzero(m)[::-1]).mean(axis=1)  # noqa: E731  (u, v)
    assert np.linalg.norm(centroid(found) - centroid(expected)) < 0.1
    uv, _ = project(cam.K, transform_points(invert_T(cam.T_ego_from_cam), np.array([point])))
    assert np.abs(centroid(found) - uv[0]).max() < 0.5 + 1e-6  # the centre, up to border quantisation


@pytest.mark.parametrize(
    "camera,point",
    [
        ("CAM_FRONT", (14.0, 1.2, 1.6)),
        ("CAM_FRONT_LEFT", (7.0, 7.5, 1.0)),
        ("CAM_BACK", (-7.0, -1.0, 0.9)),
        ("CAM_BACK_RIGHT", (-4.0, -9.0, 1.2)),
    ],
)
def test_marker_lands_on_its_projection(renderer: Renderer, camera: str, point) -> None:
    marker = _marker(point, renderer.rig.camera(camera).T_ego_from_cam[:2, 3])
    _check_marker(renderer, renderer.render(T_WORLD_FROM_EGO, [marker]), camera, marker, point)


def test_point_in_two_cameras_projects_in_both(renderer: Renderer) -> None:
    point = (10.0, 5.2, 1.3)  # 27.5 degrees left: inside CAM_FRONT and CAM_FRONT_LEFT (they overlap 20-35 degrees)
    marker = _marker(point, np.array([1.6, 0.25]))
    images = renderer.render(T_WORLD_FROM_EGO, [marker])
    for name in ("CAM_FRONT", "CAM_FRONT_LEFT"):
        _check_marker(renderer, images, name, marker, point)


def test_near_box_hides_far_marker(renderer: Renderer) -> None:
    marker = _marker((20.0, 0.0, 1.6), np.zeros(2))
    wall = box_from_center("w", "marker", 10.0, 0.0, 0.0, (0.3, 3.0, 3.0), (0.1, 0.1, 0.9))
    alone = renderer.render(T_WORLD_FROM_EGO, [marker])["CAM_FRONT"]
    hidden_after = renderer.render(T_WORLD_FROM_EGO, [marker, wall])["CAM_FRONT"]
    hidden_before = renderer.render(T_WORLD_FROM_EGO, [wall, marker])["CAM_FRONT"]
    assert _red_mask(alone).sum() > 50
    assert _red_mask(hidden_after).sum() == 0 and _red_mask(hidden_before).sum() == 0
    assert np.array_equal(hidden_after, hidden_before)  # drawing order does not matter: z-buffer
