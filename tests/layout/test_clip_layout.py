"""Layouts in clip shards: every object the log knows, per frame, in the clip's first ego frame."""

from __future__ import annotations

import dataclasses
import io
import tarfile

import numpy as np
import pytest

from drivewm.clips.shards import iter_clips
from drivewm.errors import DrivewmError
from drivewm.geometry import invert_T, load_rig
from drivewm.layout.build import RADIUS_M
from drivewm.layout.clip_layout import STATIC, layout_from_npz, layout_to_npz
from drivewm.logs.reader import read_log


@pytest.fixture(scope="module")
def highway(sim_log_dir, sim_clip_dir):
    clips = [c for c in iter_clips(sim_clip_dir) if c.key.startswith("highway_clear")]
    return read_log(sim_log_dir / "highway_clear.mcap"), clips


def _near(path_xy, xy, reach):
    return np.linalg.norm(path_xy - xy[:2], axis=1).min() <= RADIUS_M + reach


def test_curated_clips_carry_every_object_in_the_first_ego_frame(highway):
    """Per frame, the road users the log has at that tick (within reach of the clip's path) and every
    static object within reach, moved by the inverse of the clip's first ego pose (KEY.ego.npy, the
    frame of trajectory_ego); each frame placed at the log's own pose, the one its images were taken at."""
    log, clips = highway
    agents = dict(log.agents)
    logged = dict(zip(log.pose_timestamps_ns.tolist(), log.T_world_from_ego))
    assert len(clips) == 3
    for clip in clips:
        layout = clip.layout()
        ego = clip.T_world_from_ego
        T_ego0_from_world = invert_T(ego[0])
        raw = np.stack([logged[t] for t in clip.meta.timestamps_ns])
        np.testing.assert_allclose(layout.T_ego0_from_ego, T_ego0_from_world @ raw, atol=1e-12)
        assert layout.timestamps_ns.tolist() == clip.meta.timestamps_ns
        path = raw[:, :2, 3]
        for t, stamp in enumerate(clip.meta.timestamps_ns):
            want = [b for b in agents[stamp] if _near(path, b.center_xyz, np.linalg.norm(b.size_lwh[:2]) / 2)]
            rows = np.flatnonzero(layout.box_frame == t)
            assert layout.box_track[rows].tolist() == [b.track_id for b in want]
            assert layout.box_class[rows].tolist() == [b.category for b in want]
            centers = np.array([b.center_xyz for b in want]) @ T_ego0_from_world[:3, :3].T + T_ego0_from_world[:3, 3]
            np.testing.assert_allclose(layout.box_center[rows], centers, atol=1e-9)
            heading = np.array([b.yaw_rad for b in want]) - np.arctan2(ego[0][1, 0], ego[0][0, 0])
            np.testing.assert_allclose(np.angle(np.exp(1j * (layout.box_yaw[rows] - heading))), 0, atol=1e-9)
        static = layout.box_track[layout.box_frame == STATIC].tolist()
        reach = [b.track_id for b in log.static if _near(path, b.center_xyz, np.linalg.norm(b.size_lwh[:2]) / 2)]
        assert static == reach and {"building", "trunk", "crown", "pole", "lamp"} <= set(layout.box_class)
        assert set(layout.line_kind) == {"lane_center", "lane_boundary", "road_edge", "road_surface"}
        assert {"solid", "dashed"} <= set(layout.line_paint[layout.line_kind == "lane_boundary"])


def test_road_lines_stay_on_the_logged_lines(highway):
    """Thinned to the points that matter, each layout line lies within 2 cm of the logged polyline."""
    log, clips = highway
    layout = clips[0].layout()
    T_world_from_ego0 = clips[0].T_world_from_ego[0]
    logged = [r for r in log.road if r.kind == "lane_boundary"]
    for i in np.flatnonzero(layout.line_kind == "lane_boundary"):
        pts = layout.line(i) @ T_world_from_ego0[:3, :3].T + T_world_from_ego0[:3, 3]
        dense = np.concatenate([np.linspace(a, b, 20) for a, b in zip(pts[:-1], pts[1:])])
        best = min(_distance_to_polyline(dense, r.points_xyz).max() for r in logged)
        assert best < 0.021


def _distance_to_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    a, b = line[:-1], line[1:]
    ab = b - a
    s = np.clip(np.einsum("psk,sk->ps", points[:, None] - a[None], ab) / np.einsum("sk,sk->s", ab, ab), 0, 1)
    return np.linalg.norm(points[:, None] - (a[None] + s[..., None] * ab[None]), axis=2).min(axis=1)


def test_layout_member_round_trips_to_the_same_bytes(highway):
    _, clips = highway
    data = clips[1].layout_npz
    again = layout_to_npz(layout_from_npz(data, "clip"))
    assert again == data  # fixed member dates: the same layout, the same bytes
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:  # plain arrays, nothing pickled
        assert npz["box_class"].dtype.kind == "U" and int(npz["format_version"]) == 1


def _broken(layout, **fields):
    return layout_to_npz(dataclasses.replace(layout, **fields))


def test_bad_layouts_are_one_line_errors_naming_clip_and_field(highway):
    _, clips = highway
    layout = clips[0].layout()
    poses = layout.T_ego0_from_ego.copy()
    poses[4, 0, 3] = np.nan
    classes = layout.box_class.astype("<U16")
    classes[7] = "spaceship"
    cases = {
        "T_ego0_from_ego is not finite (frame 4)": _broken(layout, T_ego0_from_ego=poses),
        "box_class 'spaceship' is not one of": _broken(layout, box_class=classes),
        "box_size must be > 0": _broken(layout, box_size=-layout.box_size),
    }
    for message, data in cases.items():
        with pytest.raises(DrivewmError) as err:
            layout_from_npz(data, "clip highway_clear-000000")
        assert str(err.value).startswith("clip highway_clear-000000: layout ") and message in str(err.value)
        assert "\n" not in str(err.value)


def test_boxes_behind_every_camera_are_refused(highway):
    """A layout in the wrong frame (boxes moved 500 m behind the ego) is refused for a front rig."""
    _, clips = highway
    layout = clips[0].layout()
    rig = load_rig("front3")
    layout.check_seen_by(rig, "clip a")  # the true layout has boxes in front
    behind = dataclasses.replace(layout, box_center=layout.box_center - [500.0, 0.0, 0.0])
    with pytest.raises(DrivewmError, match=r"^clip a: layout boxes: all \d+ lie behind every camera of rig front3$"):
        behind.check_seen_by(rig, "clip a")


def test_clips_of_a_log_without_layout_have_none(dashcam_clips):
    """import-video logs know no objects: their clips curate as before, without a layout member."""
    clips = list(iter_clips(dashcam_clips))
    assert len(clips) == 5 and all(c.layout() is None and not c.has_layout for c in clips)
    for shard in dashcam_clips.glob("*.tar"):
        with tarfile.open(shard) as tar:
            assert not [m.name for m in tar if "layout" in m.name]


def test_a_damaged_layout_member_costs_only_the_layout(highway, tmp_path):
    """A clip whose layout bytes are garbage still reads (frames, poses, JSON); asking for its layout is
    a one-line error naming the clip."""
    from drivewm.clips.format import Clip

    _, clips = highway
    clip = clips[0]
    bad = Clip(clip.meta, clip.mp4, clip.T_world_from_ego, layout_npz=clip.layout_npz[: len(clip.layout_npz) // 2])
    with pytest.raises(DrivewmError, match=r"^clip highway_clear-000000: layout is not a plain \.npz"):
        bad.layout()
    assert bad.video(clip.meta.cameras[0]).shape[0] == 17
