"""The weather and time of day a caption asks for, read by keywords: the ``tags`` of a generated clip.

A generated clip's tags say what was prompted, so ``drivewm eval``'s adherence can check the clip
against them (as it checks a curated clip against its log's scene tags). Keyword sets cover the
words the template captioner and the benchmark prompts use; a field the caption does not name is
left out (never guessed), and a caption naming two values of one field names neither.
"""

from __future__ import annotations

import re

#: field -> value -> words (lower case, matched as whole words) that ask for it.
KEYWORDS: dict[str, dict[str, tuple[str, ...]]] = {
    "weather": {
        "snow": ("snow", "snowy", "snowfall", "snowing", "blizzard"),
        "fog": ("fog", "foggy", "mist", "misty", "haze"),
        "rain": ("rain", "rainy", "raining", "downpour", "drizzle"),
        "overcast": ("overcast", "cloudy", "grey sky", "gray sky"),
        "clear": ("clear", "sunny", "cloudless"),
    },
    "time_of_day": {
        "night": ("night", "nighttime", "dark"),
        "dusk": ("dusk", "sunset", "twilight", "evening", "dawn"),
        "day": ("day", "daytime", "daylight", "afternoon", "morning", "noon"),
    },
}


def named_values(caption: str, field: str) -> list[str]:
    """The values of ``field`` (weather, time_of_day) whose words the caption uses, in KEYWORDS order."""
    text = caption.lower()
    return [v for v, words in KEYWORDS[field].items() if any(re.search(rf"\b{re.escape(w)}\b", text) for w in words)]


def caption_conditions(caption: str) -> dict[str, str]:
    """``{"weather": ..., "time_of_day": ...}`` for the fields the caption names unambiguously."""
    out = {}
    for field in KEYWORDS:
        named = named_values(caption, field)
        if len(named) == 1:
            out[field] = named[0]
    return out
