"""The layout renderer's geometry: silhouettes are exact pinhole projections, clipped at the near plane,
depth-ordered; rendered for a simulated scene it lies on the simulator's own label map."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from drivewm.geometry import invert_T, load_rig, pixel_rays, project, transform_points
from drivewm.layout.classes import LABEL_ID
from drivewm.layout.clip_layout import STATIC, ClipLayout
from drivewm.layout.recording import layout_from_recording
from drivewm.layout.render import CLASS_RGB, LayoutRenderer
from drivewm.sim.boxes import NEAR_M
from drivewm.sim.conditions import condition_for
from drivewm.sim.config import SimConfig
from drivewm.sim.props import place_props
from drivewm.sim.render import Renderer
from drivewm.sim.scene import LaneBoundary, RoadMap, SceneRecording, SceneTick, box_from_center

RIG = load_rig("nuscenes6").scaled(320, 192, fit="stretch")


def _layout(boxes: list[tuple[str, tuple, tuple, float]], frames: int = 1) -> ClipLayout:
    """Static boxes (class, centre, size, yaw) in ego0, ego standing still, no road."""
    n = len(boxes)
    return ClipLayout(
        timestamps_ns=np.arange(frames, dtype=np.int64) * 100_000_000,
        T_ego0_from_ego=np.tile(np.eye(4), (frames, 1, 1)),
        box_frame=np.full(n, STATIC, np.int32),
        box_class=np.array([b[0] for b in boxes], dtype=np.str_),
        box_track=np.array([f"b{i}" for i in range(n)], dtype=np.str_),
        box_center=np.array([b[1] for b in boxes], float).reshape(-1, 3),
        box_size=np.array([b[2] for b in boxes], float).reshape(-1, 3),
        box_yaw=np.array([b[3] for b in boxes], float),
        line_kind=np.zeros(0, np.str_),
        line_paint=np.zeros(0, np.str_),
        line_start=np.zeros(1, np.int64),
        line_points=np.zeros((0, 3)),
    )


def _ray_cast(cam, boxes, with_ground: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Reference, per pixel centre: index of the nearest box the ray hits in front of the near plane
    (-1 none) and that hit's camera depth, by slab tests in each box's frame; rays meeting the ground
    (z = 0) first hit no box."""
    v, u = np.mgrid[0 : cam.height, 0 : cam.width]
    rays_cam = pixel_rays(cam.K, np.stack([u.ravel(), v.ravel()], axis=1).astype(float))  # (P, 3), z = 1
    rays_cam /= rays_cam[:, 2:3]
    R, o = cam.T_ego_from_cam[:3, :3], cam.T_ego_from_cam[:3, 3]
    d = rays_cam @ R.T  # ego-frame directions, camera depth as the parameter
    best, hit = np.full(len(d), np.inf), np.full(len(d), -1)
    for k, (_, center, size, yaw) in enumerate(boxes):
        c, s = np.cos(yaw), np.sin(yaw)
        Rb = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        o_b, d_b = (o - center) @ Rb, d @ Rb
        half = np.array(size) / 2
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (-half - o_b) / d_b, (half - o_b) / d_b
        near = np.nanmax(np.minimum(t1, t2), axis=1)
        far = np.nanmin(np.maximum(t1, t2), axis=1)
        t = np.where(near >= NEAR_M, near, far)  # the camera inside the slab range: its exit
        ok = (far >= near) & (t >= NEAR_M) & (t < best)
        best[ok], hit[ok] = t[ok], k
    if with_ground:
        with np.errstate(divide="ignore", invalid="ignore"):
            t_ground = np.where(d[:, 2] < 0, -o[2] / d[:, 2], np.inf)
        hit[t_ground < best] = -1
    return hit.reshape(cam.height, cam.width), best.reshape(cam.height, cam.width)


def _corners(center, size, yaw) -> np.ndarray:
    c, s = np.cos(yaw), np.sin(yaw)
    signs = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
    local = signs * np.array(size) / 2
    return local @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T + center


def test_box_corners_land_where_the_pinhole_projection_puts_them():
    """A car ahead and left: its rendered silhouette is the set of pixel centres inside the convex hull
    of its eight corners projected by geometry.project; pixels that disagree lie on the hull's edge."""
    box = ("car", (14.0, 2.2, 0.75), (4.6, 1.9, 1.5), 0.4)
    cam = RIG.camera("CAM_FRONT")
    _, labels = LayoutRenderer(RIG, _layout([box])).render_frame(0, labels=True)
    mask = labels[RIG.names.index("CAM_FRONT")] == LABEL_ID["vehicle"]
    uv, z = project(cam.K, transform_points(invert_T(cam.T_ego_from_cam), _corners(*box[1:])))
    assert (z > 0).all()
    hull = cv2.convexHull(uv.astype(np.float32))
    v, u = np.mgrid[0 : cam.height, 0 : cam.width]
    dist = np.array([cv2.pointPolygonTest(hull, (float(x), float(y)), True) for x, y in zip(u.ravel(), v.ravel())])
    inside = (dist > 0).reshape(mask.shape)
    assert mask.sum() > 400 and inside.sum() > 400
    disagree = np.flatnonzero((mask != inside).ravel())
    assert np.abs(dist[disagree]).max(initial=0) < 1e-3, f"{len(disagree)} pixels off the hull edge"
    lo, hi = uv.min(axis=0), uv.max(axis=0)  # the extreme corners bound the silhouette to the pixel
    rows, cols = np.nonzero(mask)
    assert cols.min() == int(np.ceil(lo[0])) and cols.max() == int(np.floor(hi[0]))
    assert rows.min() == int(np.ceil(lo[1])) and rows.max() == int(np.floor(hi[1]))


def test_boxes_are_clipped_at_the_near_plane_and_depth_ordered():
    """A building beside the ego that reaches behind the side cameras, a car in front of it and a pole
    in front of the car: every camera's label map is the ray-cast reference's (nearest hit in front of
    the near plane, ground first where it is nearer), up to pixels whose ray grazes an edge."""
    boxes = [
        ("building", (2.0, 9.0, 5.0), (40.0, 8.0, 10.0), 0.0),
        ("car", (8.0, 3.5, 0.75), (4.6, 1.9, 1.5), 0.2),
        ("pole", (6.0, 2.0, 3.0), (0.3, 0.3, 6.0), 0.0),
    ]
    _, labels = LayoutRenderer(RIG, _layout(boxes)).render_frame(0, labels=True)
    ids = np.array([LABEL_ID["building"], LABEL_ID["vehicle"], LABEL_ID["pole"]])
    seen = set()
    for v, cam in enumerate(RIG.cameras):
        hit, _ = _ray_cast(cam, boxes)
        want = np.where(hit >= 0, ids[np.maximum(hit, 0)], -1)
        got = np.where(np.isin(labels[v], ids), labels[v].astype(int), -1)
        wrong = got != want
        assert wrong.mean() < 0.002, f"{cam.name}: {wrong.sum()} pixels differ"
        edge = cv2.dilate((cv2.Laplacian(want.astype(np.float32), cv2.CV_32F) != 0).astype(np.uint8), np.ones((3, 3)))
        assert not (wrong & (edge == 0)).any(), f"{cam.name}: pixels differ away from any silhouette edge"
        seen |= set(np.unique(want[want >= 0]).tolist())
    assert seen == set(ids.tolist())  # every box is seen by some camera
    left = labels[RIG.names.index("CAM_FRONT_LEFT")]
    assert (left == LABEL_ID["building"]).mean() > 0.2  # the building fills the side view, clipped, not dropped


def test_front_faces_are_lighter_than_back_faces():
    """The heading cue: a car facing the camera shows its light front, one facing away its plain back."""
    cam = RIG.names.index("CAM_FRONT")

    def car_pixels(yaw: float) -> np.ndarray:
        img, labels = LayoutRenderer(RIG, _layout([("car", (12.0, 0.0, 0.75), (4.6, 1.9, 1.5), yaw)])).render_frame(
            0, True
        )
        return img[cam][labels[cam] == LABEL_ID["vehicle"]].astype(float)

    towards, away = car_pixels(np.pi), car_pixels(0.0)
    assert len(towards) > 300 and len(away) > 300
    assert towards.mean() > away.mean() + 40
    assert (
        np.abs(away.mean(axis=0) - np.array(CLASS_RGB["car"]) * 0.55).max() < 60
    )  # the back: the class colour, shaded


def _hand_made_scene(seed: int = 3) -> tuple[SceneRecording, RoadMap]:
    """A straight two-lane road with props placed as the simulator places them and three cars moving."""
    xs = np.linspace(-60.0, 200.0, 261)
    center = np.stack([xs, np.zeros_like(xs)], axis=1)
    road = RoadMap(
        [center - [0, 1.75], center + [0, 1.75]],
        [3.5, 3.5],
        [
            LaneBoundary(center, "dashed"),
            LaneBoundary(center - [0, 3.5], "solid"),
            LaneBoundary(center + [0, 3.5], "solid"),
        ],
        [center - [0, 3.5], center + [0, 3.5]],
        [np.array([[-60, -3.5], [200, -3.5], [200, 3.5], [-60, 3.5]], float)],
    )
    road.props = place_props(road, np.array([-100.0, -100.0]), np.array([250.0, 100.0]), seed, urban=True)
    ticks = []
    for k in range(4):
        T = np.eye(4)
        T[:2, 3] = [2.0 * k, -1.75]
        cars = [
            box_from_center("c1", "car", 14.0 + 1.5 * k, -1.75, 0.0, (4.5, 1.9, 1.5), (0.8, 0.1, 0.1)),
            box_from_center("c2", "van", 9.0 - 1.0 * k, 1.75, np.pi, (5.2, 2.0, 2.1), (0.9, 0.9, 0.9)),
            box_from_center("c3", "car", -12.0 + 2.5 * k, -1.75, 0.05, (4.4, 1.8, 1.45), (0.1, 0.2, 0.6)),
        ]
        ticks.append(SceneTick(k * 100_000_000, T, cars))
    return SceneRecording(road, ticks, {"drive_id": "hand"}), road


def _iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))


def test_layout_lies_on_the_simulators_own_label_map():
    """The simulator renders a scene with its exact labels; the layout of the same scene (no pixels),
    rendered for the same rig, covers the same vehicle, building and vegetation pixels (IoU over the six
    cameras and four ticks)."""
    rec, road = _hand_made_scene()
    renderer = Renderer(
        RIG,
        road,
        condition_for("clear", "day"),
        3,
        np.array([-100.0, -100.0]),
        np.array([250.0, 100.0]),
        True,
        labels=True,
    )
    sim = []
    for tick in rec.ticks:
        _, labels = renderer.render_with_labels(tick.T_world_from_ego, tick.agents, tick.timestamp_ns)
        sim.append(np.stack([labels[n] for n in RIG.names]))
    sim = np.stack(sim, axis=1)  # (V, T, H, W)
    _, layout_labels = LayoutRenderer(RIG, layout_from_recording(rec, SimConfig(duration_s=0.4), 0, 4)).render(
        labels=True
    )
    for name in ("vehicle", "building", "vegetation", "pole"):
        a, b = sim == LABEL_ID[name], layout_labels == LABEL_ID[name]
        assert a.sum() > 500, name
        assert _iou(a, b) > 0.99, f"{name}: IoU {_iou(a, b):.4f}"
    road_iou = _iou(
        np.isin(sim, [LABEL_ID["road"], LABEL_ID["lane_paint"]]),
        np.isin(layout_labels, [LABEL_ID["road"], LABEL_ID["lane_paint"]]),
    )
    assert road_iou > 0.97, f"road IoU {road_iou:.4f}"


@pytest.mark.slow
def test_layout_command_writes_videos_and_a_sheet(sim_clip_dir, tmp_path):
    """``drivewm layout``: one mp4 per clip and camera holding the renderer's frames (H.264 at crf 18),
    and a contact sheet."""
    from drivewm.cli import main
    from drivewm.clips.shards import iter_clips
    from drivewm.clips.video import decode_mp4

    assert main(["layout", str(sim_clip_dir), "--out", str(tmp_path), "--max-clips", "2", "--sheet-clips", "2"]) == 0
    clips = list(iter_clips(sim_clip_dir))
    picked = [clips[0], clips[len(clips) // 2]]
    assert sorted(p.name for p in tmp_path.glob("*.mp4")) == sorted(
        f"{c.key}.{cam}.mp4" for c in picked for cam in c.meta.cameras
    )
    want = LayoutRenderer(picked[1].meta.get_rig(), picked[1].layout()).render()
    cam = picked[1].meta.cameras[2]
    got = decode_mp4((tmp_path / f"{picked[1].key}.{cam}.mp4").read_bytes(), 17, "layout video")
    mse = np.mean((got.astype(float) - want[2].astype(float)) ** 2)
    assert 10 * np.log10(255**2 / mse) > 30
    sheet = cv2.imread(str(tmp_path / "contact_sheet.png"))
    assert sheet.shape[1] > 2 * 3 * 192 and sheet.shape[0] > 2 * 6 * 100  # frames beside layouts, two clips


def test_layout_command_without_any_layout_is_one_error(dashcam_clips, tmp_path, capsys):
    from drivewm.cli import main

    assert main(["layout", str(dashcam_clips), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    err = err[next(i for i, line in enumerate(err) if line.startswith("error:")) :]  # after the progress bar
    assert err[0] == "error: layout: no clip could be rendered (5 failed)"
    assert all("no layout" in line for line in err[1:]) and len(err) == 6
