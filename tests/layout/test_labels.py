"""Exact label maps: they agree with the simulator's RGB render, travel through the log, and curation
keeps each one with the frame it labels."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest
from test_layout_render import RIG, _hand_made_scene

from drivewm.clips.shards import iter_clips
from drivewm.curate import curate, load_curate_config
from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.layout.classes import LABEL_CLASSES, LABEL_ID
from drivewm.layout.labels import label_png, labels_from_npz, labels_from_png, labels_to_npz
from drivewm.logs.reader import read_log
from drivewm.logs.types import SceneInfo
from drivewm.logs.writer import LogWriter, write_log
from drivewm.sim.conditions import condition_for
from drivewm.sim.config import SimConfig
from drivewm.sim.paired import drive_id
from drivewm.sim.render import Renderer


@pytest.fixture(scope="module")
def rendered():
    """The hand-made scene's first tick rendered in clear daylight with labels, and without its cars."""
    rec, road = _hand_made_scene()
    lo, hi = np.array([-100.0, -100.0]), np.array([250.0, 100.0])
    renderer = Renderer(RIG, road, condition_for("clear", "day"), 3, lo, hi, True, labels=True)
    tick = rec.ticks[1]
    images, labels = renderer.render_with_labels(tick.T_world_from_ego, tick.agents, tick.timestamp_ns)
    empty = renderer.render(tick.T_world_from_ego, [], tick.timestamp_ns)
    plain = Renderer(RIG, road, condition_for("clear", "day"), 3, lo, hi, True).render(
        tick.T_world_from_ego, tick.agents, tick.timestamp_ns
    )
    return renderer, images, labels, empty, plain


def test_labels_leave_the_images_as_they_are(rendered):
    _, images, _, _, plain = rendered
    assert all(np.array_equal(images[n], plain[n]) for n in RIG.names)


def test_sky_label_is_where_the_image_shows_sky(rendered):
    """Sky pixels carry the renderer's sky gradient, untouched (no fog on the sky); every other pixel
    shows a surface (almost never the sky's exact colour)."""
    renderer, images, labels, _, _ = rendered
    skies = 0
    for view in renderer.views:
        sky = labels[view.name] == LABEL_ID["sky"]
        same = (images[view.name] == view.sky).all(axis=-1)
        assert same[sky].all(), view.name
        assert same[~sky].mean() < 0.01, view.name
        skies += sky.sum()
    assert skies > 5000


def test_vehicle_label_is_where_the_cars_are(rendered):
    """The pixels that change when the cars are taken out of the scene are the vehicle pixels."""
    _, images, labels, empty, _ = rendered
    changed = np.stack([(images[n] != empty[n]).any(axis=-1) for n in RIG.names])
    vehicle = np.stack([labels[n] == LABEL_ID["vehicle"] for n in RIG.names])
    assert vehicle.sum() > 2000
    iou = (changed & vehicle).sum() / (changed | vehicle).sum()
    assert iou > 0.98, iou


def test_ground_and_object_labels_show_their_colours(rendered):
    """Lane paint is brighter than the asphalt around it, vegetation greener than red, buildings warmer
    than the sky-blue, terrain (grass) green."""
    _, images, labels, _, _ = rendered
    img = np.concatenate([images[n] for n in RIG.names]).reshape(-1, 3).astype(float)
    lab = np.concatenate([labels[n] for n in RIG.names]).ravel()
    mean = {name: img[lab == LABEL_ID[name]].mean(axis=0) for name in ("road", "lane_paint", "vegetation", "terrain")}
    assert mean["lane_paint"].mean() > mean["road"].mean() + 40
    assert mean["vegetation"][1] > mean["vegetation"][0] and mean["terrain"][1] > mean["terrain"][0]
    assert (lab == LABEL_ID["building"]).sum() > 1000 and (lab == LABEL_ID["pole"]).sum() > 100


def test_labels_do_not_change_the_drive():
    cfg = SimConfig(seed=3)
    assert drive_id(cfg) == drive_id(dataclasses.replace(cfg, labels=True))


def test_label_maps_round_trip_through_png_and_npz():
    labels = np.random.default_rng(0).integers(0, len(LABEL_CLASSES), (3, 48, 64), dtype=np.uint8)
    assert np.array_equal(labels_from_png(label_png(labels[1]), "x"), labels[1])
    data = labels_to_npz(labels, [1, 2, 3])
    assert np.array_equal(labels_from_npz(data, "clip k CAM"), labels) and data == labels_to_npz(labels, [1, 2, 3])
    bad = labels.copy()
    bad[2, 5, 7] = 40
    with pytest.raises(DrivewmError, match=r"^clip k CAM: labels hold id 40, not a class$"):
        labels_from_npz(labels_to_npz(bad, [1, 2, 3]), "clip k CAM")


def _stamped_log(path, stagger_ns: int, labels_after_images: bool):
    """A 24-tick front3 log at 64x48 whose label map of camera v at tick k is filled with (k + v) % 13, the
    image with grey level 60 + 6 k (staggered exposures, label maps logged after or before their images)."""
    rig = load_rig("front3").scaled(64, 48, fit="stretch")
    with LogWriter(path, rig, SceneInfo({"weather": "clear"}), "png", label_classes=LABEL_CLASSES) as w:
        for k in range(24):
            t = 1_000_000_000 + k * 100_000_000
            w.write_pose(t, np.eye(4) @ np.diag([1, 1, 1, 1.0]) + np.pad([[0, 0, 0, 0.5 * k]], ((0, 3), (0, 0))))
            for v, cam in enumerate(rig.cameras):
                image = np.full((48, 64, 3), 60 + 6 * k, np.uint8)
                image[::7, ::5] = 200  # texture for the filters
                label = np.full((48, 64), (k + v) % 13, np.uint8)
                when = t + v * stagger_ns
                if not labels_after_images:
                    w.write_labels(when, {cam.name: label})
                w.write_image(cam.name, when, image)
                if labels_after_images:
                    w.write_labels(when, {cam.name: label})
    return rig


@pytest.mark.parametrize(
    "stagger_ns,labels_after_images", [pytest.param(0, False, marks=pytest.mark.slow), (12_000_000, True)]
)
def test_curation_keeps_each_label_map_with_its_frame(tmp_path, stagger_ns, labels_after_images):
    """Every clip frame's label map is the one logged with that camera's image: (tick + camera) % 13,
    with staggered exposures and label maps arriving after their images too; at a smaller clip size
    too (nearest label)."""
    _stamped_log(tmp_path / "logs" / "d.mcap", stagger_ns, labels_after_images)
    cfg = load_curate_config("test")
    cfg.clip_frames, cfg.stride_frames, cfg.resolution = 5, 5, [32, 24]
    cfg.filters.min_ego_distance_m = 0.0
    curate([tmp_path / "logs" / "d.mcap"], tmp_path / "clips", cfg, progress=False)
    clips = list(iter_clips(tmp_path / "clips"))
    assert len(clips) >= 3  # of 4 windows (the filters may drop one)
    for clip in clips:
        start = (clip.meta.start_time_ns - 1_000_000_000) // 100_000_000
        for v, cam in enumerate(clip.meta.cameras):
            labels = clip.labels(cam)
            assert labels.shape == (5, 24, 32)
            assert [int(np.unique(f)[0]) for f in labels] == [(start + k + v) % 13 for k in range(5)]
            frames = np.median(clip.video(cam).reshape(5, -1), axis=1)  # the image of the same tick
            assert np.all(np.abs(frames - (60 + 6 * (start + np.arange(5)))) < 3)


def test_log_round_trip_keeps_label_maps(tmp_path):
    _stamped_log(tmp_path / "a.mcap", 0, False)
    log = read_log(tmp_path / "a.mcap")
    assert log.label_classes == LABEL_CLASSES and len(log.labels["CAM_FRONT"]) == 24
    again = read_log(write_log(log, tmp_path / "b.mcap"))
    assert again.label_classes == LABEL_CLASSES
    for cam in log.rig.names:
        assert [(f.timestamp_ns, f.data) for f in again.labels[cam]] == [
            (f.timestamp_ns, f.data) for f in log.labels[cam]
        ]
        assert len(again.images[cam]) == 24  # the label maps were not read as images


@pytest.mark.slow
def test_simulate_labels_end_to_end(tmp_path):
    """``drivewm simulate --labels`` logs a label map per image; curation carries them; the layout of each
    clip, rendered, covers the labels' vehicles (IoU)."""
    from drivewm.cli import main
    from drivewm.layout.render import LayoutRenderer

    argv = ["simulate", "--duration", "1.7", "--width", "320", "--height", "192", "--labels", "--seed", "4"]
    assert main([*argv, "--out", str(tmp_path / "logs")]) == 0
    (log_path,) = (tmp_path / "logs").glob("*.mcap")
    log = read_log(log_path)
    assert all(len(log.labels[c]) == len(log.images[c]) == 17 for c in log.rig.names)
    curate([log_path], tmp_path / "clips", load_curate_config("test"), progress=False)
    (clip,) = iter_clips(tmp_path / "clips")
    labels = np.stack([clip.labels(c) for c in clip.meta.cameras])  # (V, T, H, W)
    _, drawn = LayoutRenderer(clip.meta.get_rig(), clip.layout()).render(labels=True)
    a, b = labels == LABEL_ID["vehicle"], drawn == LABEL_ID["vehicle"]
    assert a.sum() > 1000 and (a & b).sum() / (a | b).sum() > 0.98
    sky = labels == LABEL_ID["sky"]
    assert cv2.cvtColor(clip.video("CAM_FRONT")[8], cv2.COLOR_RGB2HSV)[sky[0, 8], 2].mean() > 150  # bright sky


def test_view_shows_the_label_maps(tmp_path):
    """``drivewm view`` of a log with label maps: a SegmentationImage per label map under each camera,
    the class names in the recording's annotation context."""
    from rerun.chunk import RrdReader

    from drivewm.cli import main

    _stamped_log(tmp_path / "a.mcap", 0, False)
    assert main(["view", str(tmp_path / "a.mcap"), "--out", str(tmp_path / "a.rrd")]) == 0
    chunks = list(RrdReader(tmp_path / "a.rrd").stream().collect().stream())
    rows = [ch.to_record_batch() for ch in chunks if ch.entity_path == "/world/ego/CAM_FRONT/labels"]
    assert sum(rb.num_rows for rb in rows) == 24
    context = [ch.to_record_batch() for ch in chunks if ch.entity_path == "/world" and ch.is_static]
    assert any("vehicle" in str(rb.to_pydict()) for rb in context)
