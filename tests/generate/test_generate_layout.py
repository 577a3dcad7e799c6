"""``drivewm generate --layout CLIPS`` and ``--scenario NAME``: a layout model regenerates each window of
a drive in the asked condition along its own ego path, and each clip keeps its window's pair id and
layout, so the simulator's truth of that window scores it."""

from __future__ import annotations

import pytest

from drivewm.cli import main
from drivewm.clips import iter_clips
from drivewm.clips.shards import read_clips


@pytest.mark.slow
def test_layout_clips_are_regenerated_with_their_pair_and_layout(layout_model, sim_clip_dir, tmp_path):
    command = ["generate", "--model", str(layout_model["tokens"]), "--prompt", "heavy snow at night", "--steps", "2"]
    assert main([*command, "--layout", str(sim_clip_dir), "--set", "layout_clips=2", "--out", str(tmp_path / "g")]) == 0
    sources = {c.key: c for c in read_clips(sim_clip_dir)}
    generated = list(iter_clips(tmp_path / "g"))
    assert len(generated) == 2
    for gen in generated:
        source = sources[gen.meta.extra["layout"]]
        assert gen.meta.pair_id == source.meta.pair_id != ""
        assert gen.meta.tags["weather"] == "snow" and gen.meta.tags["time_of_day"] == "night"
        assert gen.meta.extra["post_processing"] == [] and gen.meta.extra["trajectory"] == "layout"
        assert gen.layout().num_boxes == source.layout().num_boxes
        assert gen.meta.trajectory_ego[-1][0] > 1.0  # along the source's own path, not straight by default
    assert main([*command, "--scenario", "merge", "--out", str(tmp_path / "s")]) == 0
    (scenario,) = list(iter_clips(tmp_path / "s"))
    assert scenario.meta.pair_id.startswith("highway-merge-s0000-") and scenario.meta.extra["scenario"] == "merge"


def test_layout_generation_refuses_what_it_cannot_do(layout_model, sim_clip_dir, tmp_path, capsys):
    plain = ["generate", "--model", str(layout_model["none"]), "--prompt", "x", "--steps", "1"]
    assert main([*plain, "--layout", str(sim_clip_dir), "--out", str(tmp_path / "a")]) == 2
    assert "not trained with a layout" in capsys.readouterr().err
    empty = tmp_path / "no_clips"
    empty.mkdir()
    layout = ["generate", "--model", str(layout_model["tokens"]), "--prompt", "x", "--steps", "1"]
    assert main([*layout, "--layout", str(empty), "--out", str(tmp_path / "b")]) == 2
    assert "no clips found" in capsys.readouterr().err
    assert main([*layout, "--scenario", "moon", "--out", str(tmp_path / "c")]) == 2
    assert "--scenario 'moon'" in capsys.readouterr().err
    assert not any((tmp_path / d).exists() and any((tmp_path / d).iterdir()) for d in "abc")


FIVE_CAMERAS = """\
# Five cameras written for this test: none of them is in the model's training rig (CAM_FRONT of nuscenes6).
name: five_test
defaults: {width: 80, height: 48}
cameras:
  - {name: CAM_A, hfov_deg: 90, xyz: [1.6,  0.0, 1.5], yaw_deg:    0}
  - {name: CAM_B, hfov_deg: 90, xyz: [1.2,  0.8, 1.5], yaw_deg:   72}
  - {name: CAM_C, hfov_deg: 90, xyz: [-0.9, 0.6, 1.5], yaw_deg:  144}
  - {name: CAM_D, hfov_deg: 90, xyz: [-0.9, -0.6, 1.5], yaw_deg: -144}
  - {name: CAM_E, hfov_deg: 90, xyz: [1.2, -0.8, 1.5], yaw_deg:  -72}
"""


@pytest.mark.slow
@pytest.mark.parametrize("rig", ["front3", "five_test.yaml"])
def test_a_layout_model_generates_for_a_rig_it_never_trained_on(layout_model, tmp_path, rig):
    """The model trained on one CAM_FRONT; a packaged rig (front3) and a 5-camera YAML written here work from
    the rig alone: one view per camera, each with the scenario's layout drawn through that camera."""
    from drivewm.geometry import load_rig

    (tmp_path / "five_test.yaml").write_text(FIVE_CAMERAS)
    rig_arg = str(tmp_path / rig) if rig.endswith(".yaml") else rig
    command = ["generate", "--model", str(layout_model["tokens"]), "--prompt", "fog at dusk", "--steps", "1"]
    assert main([*command, "--scenario", "highway", "--rig", rig_arg, "--out", str(tmp_path / "g")]) == 0
    (clip,) = list(iter_clips(tmp_path / "g"))
    want = load_rig(rig_arg).names
    assert clip.meta.get_rig().names == want
    for camera in want:
        video = clip.video(camera)
        assert video.shape[0] == 17 and video.std() > 1.0  # frames per camera, not blank
    layout = clip.layout()
    assert layout.num_frames == 17 and layout.num_boxes > 0
