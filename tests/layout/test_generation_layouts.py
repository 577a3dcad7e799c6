"""Layouts to generate from: a clip folder's own, or a scenario simulated without pixels, drawn into
any rig at the generator's size; bad input is named in one line."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drivewm.errors import DrivewmError
from drivewm.geometry import load_rig
from drivewm.layout.sources import layout_frames, layouts_from_clips, layouts_from_scenario, scenario_config
from drivewm.sim.config import SimConfig
from drivewm.sim.paired import drive_id


def test_a_clip_folders_layouts_carry_their_trajectory_and_pair(sim_clip_dir):
    sources = layouts_from_clips(sim_clip_dir, limit=3)
    assert len(sources) == 3
    for s in sources:
        assert s.pair_id and s.waypoints.shape[1] == 3 and s.dt_s > 0
        assert np.linalg.norm(s.waypoints[-1, :2]) > 5  # the drive moves on
    frames = layout_frames(load_rig("front3"), sources[0], (80, 48), 9)
    assert frames.shape == (3, 9, 48, 80, 3)
    front = frames[1, 0]  # CAM_FRONT of front3: the road ahead fills the lower half, the sky the upper
    assert np.abs(front[30:].astype(int) - front[:8].mean(axis=(0, 1))).mean() > 20


def test_a_scenario_is_simulated_without_pixels_into_windows_of_the_drive(sim_clip_dir):
    cfg = SimConfig(source="highway", scenario="highway", seed=1, rig="nuscenes6", duration_s=4.0, fps=10.0)
    sources = layouts_from_scenario(cfg, 17, 2, 16)
    assert [s.key for s in sources] == [f"{drive_id(cfg)}-t000000", f"{drive_id(cfg)}-t000017"]
    assert sources[0].layout.num_frames == 17 and sources[0].layout.num_boxes > 0
    # the second window starts where the ego is 1.7 s on: its trajectory is its own, not the first's
    assert not np.allclose(sources[0].waypoints, sources[1].waypoints)
    assert scenario_config("merge", 3, 4.0, 10.0).source == "highway"
    assert scenario_config("grid", 3, 4.0, 10.0).source == "sumo"
    with pytest.raises(DrivewmError, match="--scenario 'moon'"):
        scenario_config("moon", 3, 4.0, 10.0)


def test_bad_layouts_are_named(sim_clip_dir, tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(DrivewmError, match="no clips found"):
        layouts_from_clips(empty)
    source = layouts_from_clips(sim_clip_dir, limit=1)[0]
    behind = dataclasses.replace(source.layout, box_center=source.layout.box_center * [-1, 1, 1] - [500, 0, 0])
    far_away = dataclasses.replace(source, layout=behind)
    with pytest.raises(DrivewmError, match=f"layout {source.key}: layout boxes: all"):
        layout_frames(load_rig("front1"), far_away, (80, 48), 5)
    with pytest.raises(DrivewmError, match="the model makes 40"):
        layout_frames(load_rig("front1"), source, (80, 48), 40)
