"""Generated samples are written as clips with a contact sheet laid out like curation's: one row per
camera in rig order (first/middle/last frame), the caption above."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np
import pytest

from drivewm.clips import iter_clips
from drivewm.curate.contact_sheet import thumb_width
from drivewm.generate.writer import GeneratedSample, sample_clip, write_samples
from drivewm.geometry import load_rig
from drivewm.text.conditions import caption_conditions


def _sample(rig, seed: int) -> GeneratedSample:
    """Six 160x96 views of 5 frames, each view a flat colour of its own (so rows can be told apart)."""
    v = len(rig.names)
    colours = np.random.default_rng(seed).integers(0, 256, (v, 3))
    videos = np.broadcast_to(colours[:, None, None, None, :], (v, 5, 96, 160, 3)).astype(np.uint8)
    waypoints = np.stack([np.arange(1, 6) * 1.0, np.zeros(5), np.zeros(5)], axis=1)
    return GeneratedSample(videos, rig, "snowy night", ["snowy night"] * v, waypoints, 0.5, {"seed": seed})


def test_contact_sheet_has_a_row_per_camera_like_the_curated_one(tmp_path):
    rig = load_rig("nuscenes6")
    samples = [_sample(rig, 0), _sample(rig, 1)]
    write_samples(tmp_path, samples, fps=10.0)
    sheet = cv2.cvtColor(cv2.imread(str(tmp_path / "contact_sheet.png")), cv2.COLOR_BGR2RGB)
    view_w = thumb_width(160)  # each view as on the curated sheet: 160x96 views at their own size
    view_h = round(96 * view_w / 160)
    assert (view_w, view_h) == (160, 96)
    caption_h = 20  # one caption line: 14 px + 6 px margin
    block_h = caption_h + len(rig.names) * view_h + 6  # 6 px white between clips
    assert sheet.shape == (len(samples) * block_h, 3 * view_w, 3)  # 6 camera rows, not one 2880x384 strip
    for i, s in enumerate(samples):
        for view in range(len(rig.names)):
            # the lower-right part of each row (clear of the camera label) is that camera's colour
            y = i * block_h + caption_h + view * view_h + view_h - 10
            patch = sheet[y - 20 : y, view_w - 60 : view_w - 10].reshape(-1, 3).astype(int)
            assert np.abs(patch - s.videos[view, 0, 0, 0]).max() <= 3, (i, view)
    clips = list(iter_clips(tmp_path))
    assert [c.meta.cameras for c in clips] == [rig.names, rig.names]
    assert clips[0].meta.tags == {"weather": "snow", "time_of_day": "night"}  # what eval's adherence checks


@pytest.mark.parametrize(
    "prompt, tags",
    [
        ("heavy snow on a highway, daytime, the ego car turns left", {"weather": "snow", "time_of_day": "day"}),
        ("thick fog over a divided highway", {"weather": "fog"}),
        ("a dark night drive past lit houses", {"time_of_day": "night"}),
        ("a clear day, then rain", {"time_of_day": "day"}),  # two weathers named: no weather asked for
        ("a drive on a road", {}),
    ],
)
def test_sample_tags_are_the_conditions_its_prompt_asks_for(prompt, tags):
    s = dataclasses.replace(_sample(load_rig("nuscenes6"), 0), caption=prompt)
    clip = sample_clip("sample_000", s, fps=10.0)
    assert clip.meta.tags == tags == caption_conditions(prompt)  # the one reader of prompts (drivewm.text)


@pytest.mark.parametrize(
    "prompt, caption",
    [
        ("Steady rain on the motorway.", "The front camera view of steady rain on the motorway, during the day."),
        ("a dark road through fields", "The front camera view of a dark road through fields."),
        ("snow at dusk, turning left", "The front camera view of snow at dusk, turning left."),
        ("fog from dusk to night", "The front camera view of fog from dusk to night."),  # two times named: as it is
        ("The front camera view of rain.", "The front camera view of rain."),  # the captions' own form: verbatim
    ],
)
def test_a_prompt_naming_no_time_of_day_asks_for_daylight(prompt, caption):
    """Every training caption names its time of day; a prompt without one had left the models between
    day, dusk and night (rain came out night-dark), so it is completed with the captions' daylight phrase."""
    from drivewm.generate.captions import view_captions

    caps = view_captions(prompt, load_rig("nuscenes6"))  # CAM_FRONT, CAM_FRONT_RIGHT, ...
    verbatim = "camera view" in prompt
    assert caps[0] == caption and caps[1] == (caption if verbatim else caption.replace("front", "front-right", 1))


@pytest.mark.parametrize(
    "turn, phrase", [("left", "turning left"), ("right", "turning right"), ("straight", "driving straight")]
)
def test_template_captions_take_the_manoeuvre_and_speed_of_the_trajectory(turn, phrase):
    from drivewm.generate.captions import template_view_captions
    from drivewm.geometry import load_rig
    from drivewm.multiview.trajectories import resolve_trajectory

    rig = load_rig("nuscenes6")
    caps = template_view_captions("snow at night", rig, resolve_trajectory(turn, 16, 0.1, 20.0), 0.1)
    assert len(caps) == 6 and caps[0].startswith("The front camera view of a snow night drive on a highway")
    assert caps[0].endswith(f"the ego vehicle {phrase} at 72 km/h.")
