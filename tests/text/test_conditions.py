"""Generated clips' tags come from what the caption asks for (drivewm.text.conditions)."""

from __future__ import annotations

import itertools

import pytest

from drivewm.curate.captions import ClipInfo, TemplateCaptioner
from drivewm.logs.types import TIMES_OF_DAY, WEATHERS
from drivewm.text.conditions import KEYWORDS, caption_conditions


def test_keywords_cover_exactly_the_registries():
    assert set(KEYWORDS["weather"]) == set(WEATHERS) and set(KEYWORDS["time_of_day"]) == set(TIMES_OF_DAY)


@pytest.mark.parametrize("weather, time_of_day", itertools.product(WEATHERS, TIMES_OF_DAY))
def test_template_captions_read_back_as_their_tags(weather, time_of_day):
    tags = {"weather": weather, "time_of_day": time_of_day, "road_type": "highway", "traffic_density": "medium"}
    caption, _ = TemplateCaptioner().caption(ClipInfo(tags, "", [], "left turn", 12.0))
    assert caption_conditions(caption) == {"weather": weather, "time_of_day": time_of_day}, caption


@pytest.mark.parametrize(
    "caption, expected",
    [
        ("snowfall on a two-lane road, the car ahead brakes, we turn left", {"weather": "snow"}),
        ("a dark night drive past lit houses, turning left", {"time_of_day": "night"}),
        ("foggy morning on a city street", {"weather": "fog", "time_of_day": "day"}),
        ("today the road is busy", {}),  # whole words only: 'today' is not 'day'
        ("snow turning to rain at dusk", {"time_of_day": "dusk"}),  # two weathers: neither is claimed
        ("", {}),
    ],
)
def test_prompts_name_only_what_they_ask_for(caption, expected):
    assert caption_conditions(caption) == expected


@pytest.mark.parametrize(
    "prompt, manoeuvre, tags",
    [
        ("a dark night drive past lit houses, turning left", "left turn",
         {"weather": "clear", "time_of_day": "night", "road_type": "highway", "traffic_density": "medium"}),
        ("sunny clear afternoon at a roundabout, exiting right", "right turn",
         {"weather": "clear", "time_of_day": "day", "road_type": "roundabout", "traffic_density": "medium"}),
        ("steady rain on the motorway, straight ahead in light traffic", "straight",
         {"weather": "rain", "time_of_day": "day", "road_type": "highway", "traffic_density": "low"}),
        ("foggy evening in a congested city street", "stopping",
         {"weather": "fog", "time_of_day": "dusk", "road_type": "urban_grid", "traffic_density": "high"}),
    ],
)  # fmt: skip
def test_a_prompt_rewritten_into_the_template_is_the_captioners_own_caption_of_those_tags(prompt, manoeuvre, tags):
    """--prompt-template: what the prompt names, in the words the curated clips were captioned with
    (every view, as the template captioner writes a clip of those tags), nothing else."""
    from drivewm.curate.captions import prompt_view_captions
    from drivewm.geometry import load_rig

    cameras = load_rig("nuscenes6").cameras
    got = prompt_view_captions(prompt, cameras, manoeuvre, 20.0)
    _, want = TemplateCaptioner().caption(ClipInfo(tags, "", cameras, manoeuvre, 20.0))
    assert got == [want[c.name] for c in cameras]
    assert caption_conditions(got[0]) == {"weather": tags["weather"], "time_of_day": tags["time_of_day"]}
