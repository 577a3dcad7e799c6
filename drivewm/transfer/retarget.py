"""The target of a transfer: a weather and a time of day, and a clip's labels retold in it.

Everything but the look of a transferred clip stays the source's (timestamps, rig, ego poses,
trajectory, pair id, the other tags); :func:`retarget_meta` updates the ``weather`` and
``time_of_day`` tags and rewrites the captions with the template captioner from the updated tags
and the clip's measured motion. The prompt a transfer model is trained and run with is that
caption (:func:`target_captions`), so training and use see the same words.
"""

from __future__ import annotations

import dataclasses

from drivewm.clips.format import ClipMeta
from drivewm.curate.captions import ClipInfo, TemplateCaptioner
from drivewm.errors import DrivewmError
from drivewm.logs.types import TIMES_OF_DAY, WEATHERS


@dataclasses.dataclass(frozen=True)
class TargetCondition:
    """Where a clip is transferred to: a weather and a time of day (drivewm.logs.types names)."""

    weather: str
    """clear | overcast | rain | snow | fog."""
    time_of_day: str = "day"
    """day | dusk | night."""

    def validate(self) -> None:
        if self.weather not in WEATHERS or self.time_of_day not in TIMES_OF_DAY:
            raise DrivewmError(
                f"target condition {self.weather}/{self.time_of_day}: weather must be one of {list(WEATHERS)}, "
                f"time of day one of {list(TIMES_OF_DAY)}"
            )

    @property
    def name(self) -> str:
        """``weather:time_of_day``, the form ``drivewm simulate --conditions`` takes."""
        return f"{self.weather}:{self.time_of_day}"

    @classmethod
    def of(cls, meta: ClipMeta) -> TargetCondition | None:
        """The condition a clip's tags name, or None when they name none (e.g. imported video)."""
        weather, time_of_day = meta.tags.get("weather"), meta.tags.get("time_of_day")
        return cls(weather, time_of_day) if weather in WEATHERS and time_of_day in TIMES_OF_DAY else None


def target_captions(meta: ClipMeta, target: TargetCondition) -> tuple[str, dict[str, str]]:
    """(clip caption, {camera: view caption}) of ``meta``'s clip in ``target``: the template
    captioner over the clip's tags with the target's weather and time of day, and its motion."""
    tags = {**meta.tags, "weather": target.weather, "time_of_day": target.time_of_day}
    speed = meta.extra.get("speed_mps") if isinstance(meta.extra, dict) else None
    info = ClipInfo(tags, "", meta.get_rig().cameras, tags.get("manoeuvre", "unknown"), speed)
    return TemplateCaptioner().caption(info)


def retarget_meta(meta: ClipMeta, target: TargetCondition, key: str, record: dict) -> ClipMeta:
    """The metadata of ``meta``'s clip transferred to ``target`` under a new ``key``: tags and
    captions updated, every other label kept, ``record`` stored as ``extra["transfer"]`` (with
    the source clip's key, condition and captions)."""
    target.validate()
    caption, views = target_captions(meta, target)
    source = {"key": meta.key, "source_log": meta.source_log, "caption": meta.caption}
    source |= {"weather": meta.tags.get("weather", "unknown"), "time_of_day": meta.tags.get("time_of_day", "unknown")}
    return dataclasses.replace(
        meta,
        key=key,
        caption=caption,
        view_captions=views,
        tags={**meta.tags, "weather": target.weather, "time_of_day": target.time_of_day},
        extra={**meta.extra, "transfer": {**record, "target": target.name, "source": source}},
    )
