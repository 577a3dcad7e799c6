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


def caption_conditions(caption: str) -> dict[str, str]:
    """``{"weather": ..., "time_of_day": ...}`` for the fields the caption names unambiguously."""
    text = caption.lower()
    out = {}
    for field, values in KEYWORDS.items():
        named = [v for v, words in values.items() if any(re.search(rf"\b{re.escape(w)}\b", text) for w in words)]
        if len(named) == 1:
            out[field] = named[0]
    return out
